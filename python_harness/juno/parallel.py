"""Batches of independent tasks: serially, in a local process pool, or on a Dask cluster.

One small API for every batch the harness runs (parameter sweeps, multi-start and per-run
identification, the candidate fits of ``diagnose``, the finite-difference Jacobian of the
joint fit)::

    results = map_tasks(fn, items, workers=None, scheduler=None)

* results come back in the order of ``items``, whatever order the tasks finish in;
* ``workers=1`` (and no scheduler) runs ``fn`` in this process, one item after the other;
  ``workers=None`` means ``os.cpu_count()`` local worker processes (never more than items;
  1 when this is itself a worker process);
* ``scheduler="tcp://host:port"`` runs the tasks on that Dask distributed cluster
  (``Client.map`` with ``pure=False``, results collected in input order); Dask is imported
  only then;
* a task that raises stops the batch with :class:`TaskError`, which names the task's index
  and item and chains the original exception (``__cause__``).

For several batches in a row (an optimiser calling back many times) keep one pool open::

    with TaskPool(workers=2) as pool:
        a = pool.map(fn, items)
        b = pool.map(fn, other_items)

For tasks that become possible only when others are done (a search's short fits, then the long
fit from the best of them), :meth:`TaskPool.flow` runs :class:`Task` objects and calls back
as each finishes, and the callback may add tasks; a task added with a higher priority starts
before the tasks still waiting, so a long pole is not queued behind short tasks.

Determinism: the functions mapped here are pure functions of their item (a simulation with
given parameters), so where a task runs cannot change its result: serial, pooled and Dask
results are identical bit for bit.  Each process (or Dask worker thread) that runs FMU tasks
holds its own FMU instance, made once: :func:`local_fmu`.  An FMU instance never crosses a
process boundary.

Local pools use the ``fork`` start method where the platform has it (workers start in
milliseconds, with the parent's modules already imported), else the platform default.  A
worker only runs the tasks it is sent, so the parent's other threads (if any) do not matter.

Workers never outlive the process that started them, however it ends: each worker ignores
SIGINT (Ctrl-C reaches the whole process group; the parent alone handles it), asks the kernel
for SIGTERM when its parent dies (Linux ``prctl(PR_SET_PDEATHSIG)``), and, on every platform,
a watchdog thread ends it when its parent process is gone (polled every
:data:`WATCHDOG_PERIOD` seconds).  On SIGTERM a worker runs its exit finalizers (its FMU's
extracted folder is removed) and exits.  A pool left by an exception (Ctrl-C, a failed task)
terminates its workers instead of waiting for their running tasks.
"""

from __future__ import annotations

import atexit
import concurrent.futures
import concurrent.futures.process
import contextlib
import ctypes
import heapq
import itertools
import multiprocessing
import os
import signal
import sys
import threading
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from multiprocessing.util import _run_finalizers
from typing import Any, Callable, Iterable, Sequence

__all__ = ["map_tasks", "TaskPool", "Task", "BackgroundTask", "TaskError", "SchedulerError", "resolve_workers",
           "local_fmu", "FMUHandle", "CONNECT_TIMEOUT"]

#: Seconds to wait for a Dask scheduler to answer before giving up.
CONNECT_TIMEOUT = 10.0

#: Seconds between a worker's checks that its parent process is still alive.
WATCHDOG_PERIOD = 0.25

#: prctl option asking for a signal when the parent dies (linux/prctl.h).
_PR_SET_PDEATHSIG = 1


class TaskError(RuntimeError):
    """A task of a batch raised.  ``index`` and ``item`` say which; ``__cause__`` is the error."""

    def __init__(self, index: int, item: Any, error: BaseException):
        super().__init__(f"task {index}{_describe(item)} failed: {type(error).__name__}: {error}")
        self.index = index
        self.item = item
        self.error = error


def _describe(item: Any) -> str:
    """`` on item X`` for a plain number or short text; nothing for other items (a message
    never shows an object's repr)."""
    if isinstance(item, bool) or not isinstance(item, (int, float, str)):
        return ""
    text = f"{item:g}" if isinstance(item, float) else str(item)
    return f" on item {text}" if len(text) <= 80 else ""


class SchedulerError(ConnectionError):
    """The Dask scheduler could not be reached (or Dask is not installed)."""


@dataclass(frozen=True)
class Task:
    """One task of a flow (:meth:`TaskPool.flow`): ``fn(item)``, with a ``key`` handed back
    with its result.  Of the tasks waiting to start, the one with the highest ``priority``
    starts first; equal priorities start in the order they were added."""

    key: Any
    fn: Callable[[Any], Any]
    item: Any
    priority: int = 0


def resolve_workers(workers: int | None, n_items: int | None = None) -> int:
    """The number of local workers: ``workers`` (>= 1), else ``os.cpu_count()`` - but 1 inside
    a worker process (a task that runs a batch of its own does not start a pool of its own:
    the cores are taken already); at most ``n_items`` when given (an idle worker is only
    start-up cost)."""
    if workers is None:
        n = (os.cpu_count() or 1) if multiprocessing.parent_process() is None else 1
    else:
        n = int(workers)
        if n < 1:
            raise ValueError(f"workers must be at least 1, got {workers}")
    if n_items is not None:
        n = max(1, min(n, n_items))
    return n


#: Seconds a terminated worker gets to run its exit finalizers before it is killed.
TERMINATE_GRACE = 2.0


def _reap(processes: list) -> None:
    """Wait for terminated workers; kill those still alive after TERMINATE_GRACE.  Why the kill:
    a worker's SIGTERM handler is Python code, which runs only between bytecodes; a worker
    forked while another thread of the parent held a lock (the import lock, say) may block on
    it for ever and never run the handler, and the parent's exit would then wait for it."""
    deadline = time.monotonic() + TERMINATE_GRACE
    for proc in processes:
        with contextlib.suppress(OSError, ValueError, AssertionError):  # already gone
            proc.join(timeout=max(0.0, deadline - time.monotonic()))
    for proc in processes:
        with contextlib.suppress(OSError, ValueError, AssertionError):
            if proc.is_alive():
                proc.kill()
                proc.join(timeout=5.0)


def _join_manager(executor) -> None:
    """Wait for a ProcessPoolExecutor shut down without waiting (its workers terminated) to finish
    its own clean-up, and take its management thread off the interpreter's exit hook.  Why: the
    thread closes the pipe that wakes it, and CPython 3.11's exit hook (concurrent.futures.process
    ._python_exit) checks that the pipe is open and writes to it without a lock, so an exit
    (SIGTERM, Ctrl-C) while the thread is closing it, or once the pipe's descriptor is gone,
    prints an ignored OSError's traceback on stderr after juno's own message; on two busy cores
    the join's grace does not always cover it.  The hook has nothing left to do for this pool:
    its workers are gone and the thread, if it still runs, is joined at exit as every
    non-daemon thread is."""
    thread = getattr(executor, "_executor_manager_thread", None)
    if thread is not None:
        thread.join(timeout=TERMINATE_GRACE)
        wakeups = getattr(concurrent.futures.process, "_threads_wakeups", None)
        if wakeups is not None:
            wakeups.pop(thread, None)


def _pool_context():
    methods = multiprocessing.get_all_start_methods()
    return multiprocessing.get_context("fork" if "fork" in methods else None)


def _exit_worker(code: int) -> None:
    """End this worker now, after its exit finalizers (FMU instances and their folders)."""
    try:
        _run_finalizers(0)
    finally:
        os._exit(code)


def _watch_parent(parent_pid: int) -> None:
    while True:
        time.sleep(WATCHDOG_PERIOD)
        if os.getppid() != parent_pid:
            _exit_worker(1)


def _worker_init(parent_pid: int, death_signal: bool) -> None:
    """Initializer of every local pool worker: Ctrl-C is the parent's business, SIGTERM ends
    the worker cleanly, and the worker dies with its parent (see the module docstring).

    ``death_signal``: use prctl(PR_SET_PDEATHSIG); only when the pool was made on the main
    thread (the kernel signals the child when the *thread* that forked it ends)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, lambda signum, frame: _exit_worker(128 + signum))
    if death_signal and sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0)
        except (OSError, AttributeError):  # no prctl: the watchdog below still ends the worker
            pass
    if os.getppid() != parent_pid:   # the parent died before the death signal was armed
        _exit_worker(1)
    threading.Thread(target=_watch_parent, args=(parent_pid,), name="juno-parent-watchdog",
                     daemon=True).start()


def _connect(scheduler: str, timeout: float):
    """A ``dask.distributed.Client`` connected to ``scheduler``, or :class:`SchedulerError`."""
    try:
        from distributed import Client
    except ImportError as exc:  # pragma: no cover - distributed is a pinned dependency
        raise SchedulerError(f"--scheduler {scheduler}: the Dask 'distributed' package is not installed "
                             f"(pip install -r python_harness/requirements.txt)") from exc
    try:
        return Client(scheduler, timeout=timeout, set_as_default=False)
    except Exception as exc:  # OSError, TimeoutError, ValueError for a malformed address
        raise SchedulerError(f"cannot connect to the Dask scheduler at '{scheduler}' within {timeout:g} s: "
                             f"{type(exc).__name__}: {exc}") from exc


class TaskPool:
    """Runs batches of tasks; a context manager that owns its workers (or Dask client).

    ``workers``: local processes (None: ``os.cpu_count()``; 1: in this process, no pool).
    ``scheduler``: address of a Dask scheduler; overrides ``workers``.
    ``connect_timeout``: seconds to wait for the scheduler (default :data:`CONNECT_TIMEOUT`).
    ``max_items``: the largest batch expected, to cap the local pool's size.
    """

    def __init__(self, workers: int | None = None, scheduler: str | None = None,
                 connect_timeout: float | None = None, max_items: int | None = None):
        self.scheduler = scheduler or None
        self.workers = resolve_workers(workers, max_items) if self.scheduler is None else None
        self._executor: ProcessPoolExecutor | None = None
        self._client = None
        if self.scheduler is not None:
            self._client = _connect(self.scheduler, CONNECT_TIMEOUT if connect_timeout is None else connect_timeout)
        elif self.workers > 1:
            on_main_thread = threading.current_thread() is threading.main_thread()
            self._executor = ProcessPoolExecutor(max_workers=self.workers, mp_context=_pool_context(),
                                                 initializer=_worker_init,
                                                 initargs=(os.getpid(), on_main_thread))

    @property
    def parallel(self) -> bool:
        """True when tasks run outside this process."""
        return self._executor is not None or self._client is not None

    def map(self, fn: Callable[[Any], Any], items: Iterable[Any],
            on_result: Callable[[int, Any], None] | None = None) -> list:
        """``[fn(item) for item in items]``, in input order (see the module docstring).

        ``on_result(index, result)`` is called in input order as results become available.
        """
        items = list(items)
        if self._client is not None:
            futures = self._client.map(fn, items, pure=False)
            return self._collect(items, futures, on_result)
        if self._executor is not None:
            futures = [self._executor.submit(fn, item) for item in items]
            return self._collect(items, futures, on_result)
        results = []
        for i, item in enumerate(items):
            try:
                result = fn(item)
            except Exception as exc:
                raise TaskError(i, item, exc) from exc
            results.append(result)
            if on_result:
                on_result(i, result)
        return results

    def flow(self, tasks: Iterable[Task], then: Callable[[Task, Any], Iterable[Task]]) -> None:
        """Runs ``tasks`` and every task added on the way: ``then(task, result)`` is called in
        this process as each task's result arrives, and returns the tasks that can start now
        (one that needed that result, say).  Returns when no task is left.

        Serially, the waiting task of highest priority runs next.  In a local pool no more
        tasks than workers are handed out at a time, so a task added later with a higher
        priority starts before the tasks still waiting; on a Dask cluster each task is
        submitted when added, with its priority.  Results arrive in the order tasks finish: the
        tasks are pure functions of their items (module docstring), so only that order, not a
        result, can change with where they run, and ``then`` must not depend on it.  A task
        that raises stops the flow with :class:`TaskError`, whose index is the order in which
        the task was added."""
        counter = itertools.count()
        waiting: list[tuple[int, int, Task]] = []

        def add(new: Iterable[Task]) -> None:
            for task in new:
                heapq.heappush(waiting, (-task.priority, next(counter), task))
        add(tasks)
        if self._client is not None:
            self._flow_on_dask(waiting, add, then)
            return
        capacity = self.workers if self._executor is not None else 1
        running: dict[Any, tuple[int, Task]] = {}
        try:
            while waiting or running:
                while waiting and len(running) < capacity:
                    _, index, task = heapq.heappop(waiting)
                    if self._executor is None:
                        try:
                            result = task.fn(task.item)
                        except Exception as exc:
                            raise TaskError(index, task.item, exc) from exc
                        add(then(task, result))
                        continue
                    running[self._executor.submit(task.fn, task.item)] = (index, task)
                if not running:
                    continue
                done, _ = concurrent.futures.wait(running, return_when=concurrent.futures.FIRST_COMPLETED)
                for future in sorted(done, key=lambda f: running[f][0]):
                    index, task = running.pop(future)
                    try:
                        result = future.result()
                    except Exception as exc:
                        raise TaskError(index, task.item, exc) from exc
                    add(then(task, result))
        except BaseException:
            for future in running:
                future.cancel()
            raise

    def _flow_on_dask(self, waiting: list, add: Callable[[Iterable[Task]], None],
                      then: Callable[[Task, Any], Iterable[Task]]) -> None:
        """:meth:`flow` on the Dask cluster: every task submitted when added (Dask's own
        ``priority`` orders them), results taken as they come."""
        from distributed import as_completed
        submitted: dict[Any, tuple[int, Task]] = {}
        finished = as_completed(loop=self._client.loop)

        def submit_waiting() -> None:
            while waiting:
                _, index, task = heapq.heappop(waiting)
                future = self._client.submit(task.fn, task.item, pure=False, priority=task.priority)
                submitted[future.key] = (index, task)
                finished.add(future)
        submit_waiting()
        try:
            for future in finished:
                index, task = submitted.pop(future.key)
                try:
                    result = future.result()
                except Exception as exc:
                    raise TaskError(index, task.item, exc) from exc
                add(then(task, result))
                submit_waiting()
        except BaseException:
            for future in list(finished.futures):
                future.cancel()
            raise

    @staticmethod
    def _collect(items: Sequence[Any], futures: list, on_result) -> list:
        """Results in input order; the first failure (in input order) cancels the rest."""
        results = []
        try:
            for i, future in enumerate(futures):
                try:
                    result = future.result()
                except Exception as exc:
                    raise TaskError(i, items[i], exc) from exc
                results.append(result)
                if on_result:
                    on_result(i, result)
        except BaseException:
            for future in futures:
                future.cancel()
            raise
        return results

    def close(self, terminate: bool = False) -> None:
        """Release the workers: wait for them (normal end), or with ``terminate`` (the batch
        was abandoned: Ctrl-C, SIGTERM, a failed task) stop them without waiting for their
        running tasks."""
        if self._executor is not None:
            if terminate:
                # The executor has no public way to stop running tasks; its worker processes do.
                processes = list((getattr(self._executor, "_processes", None) or {}).values())
                for proc in processes:
                    with contextlib.suppress(OSError, ValueError, AssertionError):  # already gone
                        proc.terminate()
                self._executor.shutdown(wait=False, cancel_futures=True)
                _reap(processes)
                _join_manager(self._executor)
            else:
                self._executor.shutdown(wait=True, cancel_futures=True)
            self._executor = None
        if self._client is not None:
            self._client.close()
            self._client = None

    def __enter__(self) -> "TaskPool":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close(terminate=exc_type is not None)


def map_tasks(fn: Callable[[Any], Any], items: Iterable[Any], *, workers: int | None = None,
              scheduler: str | None = None, connect_timeout: float | None = None,
              on_result: Callable[[int, Any], None] | None = None) -> list:
    """``[fn(item) for item in items]`` in input order, serially (``workers=1``), in a local
    process pool (default: ``os.cpu_count()`` processes) or on the Dask cluster at
    ``scheduler``.  ``fn`` and the items must be picklable (module-level functions) unless the
    batch runs serially.  Raises :class:`TaskError` naming the first failed item (in input
    order), :class:`SchedulerError` if the scheduler cannot be reached."""
    items = list(items)
    if not items:
        return []
    with TaskPool(workers, scheduler, connect_timeout, max_items=len(items)) as pool:
        return pool.map(fn, items, on_result)


class BackgroundTask:
    """``fn(item)`` computed in a worker process of its own, started at once, while this process
    goes on (``background=True``; the worker as a pool's, see the module docstring); or computed
    here and now (``background=False``).  :meth:`result` waits for it and returns it, or raises
    what it raised.  A context manager: leaving it ends the worker (terminated if still running
    when an exception leaves the block)."""

    def __init__(self, fn: Callable[[Any], Any], item: Any, background: bool = True):
        self._executor: ProcessPoolExecutor | None = None
        self._future = None
        self._value: Any = None
        self._error: BaseException | None = None
        if background:
            on_main_thread = threading.current_thread() is threading.main_thread()
            self._executor = ProcessPoolExecutor(max_workers=1, mp_context=_pool_context(), initializer=_worker_init,
                                                 initargs=(os.getpid(), on_main_thread))
            self._future = self._executor.submit(fn, item)
        else:
            try:
                self._value = fn(item)
            except Exception as exc:
                self._error = exc

    def result(self) -> Any:
        """The task's result (waiting for it); raises the task's exception if it raised."""
        if self._future is not None:
            return self._future.result()
        if self._error is not None:
            raise self._error
        return self._value

    def close(self, terminate: bool = False) -> None:
        """Ends the worker: waits for it, or (``terminate``) stops it without waiting."""
        if self._executor is not None:
            processes = list((getattr(self._executor, "_processes", None) or {}).values()) if terminate else []
            for proc in processes:
                with contextlib.suppress(OSError, ValueError, AssertionError):  # already gone
                    proc.terminate()
            self._executor.shutdown(wait=not terminate, cancel_futures=True)
            _reap(processes)
            _join_manager(self._executor)
            self._executor = None

    def __enter__(self) -> "BackgroundTask":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close(terminate=exc_type is not None)


# ------------------------------------------------------------------ per-worker FMU

_local = threading.local()


def local_fmu(fmu_path: str | os.PathLike, solver_step: float | None = None):
    """This process's (this thread's) :class:`~juno.simulator.JunoFMU` for ``fmu_path``,
    extracted and instantiated once and reused by every later task here.

    Keyed by process id as well: a forked worker never touches (or closes) its parent's
    instance.  Closed (its extracted folder removed) when the process exits."""
    from .simulator import JunoFMU

    key = (os.getpid(), os.fspath(fmu_path), solver_step)
    cache = getattr(_local, "fmus", None)
    if cache is None or getattr(_local, "pid", None) != os.getpid():
        cache = _local.fmus = {}
        _local.pid = os.getpid()
    fmu = cache.get(key)
    if fmu is None:
        fmu = JunoFMU(fmu_path, solver_step)
        cache[key] = fmu
        if multiprocessing.parent_process() is not None:
            # A pool's worker process ends with os._exit (no atexit): multiprocessing's own
            # exit hook runs its finalizers.
            from multiprocessing.util import Finalize
            Finalize(fmu, fmu.close, exitpriority=10)
        else:
            atexit.register(fmu.close)
    return fmu


class FMUHandle:
    """A picklable reference to an FMU for tasks.

    In the process and thread that made it, :meth:`get` returns the caller's own
    :class:`~juno.simulator.JunoFMU`; anywhere else (a pool's worker process, a Dask worker,
    a Dask worker thread of an in-process cluster) that process's (thread's) copy from
    :func:`local_fmu`.  Pickled, it is just the FMU's path and solver step.
    """

    def __init__(self, fmu):
        self.fmu_path = os.fspath(fmu.fmu_path)
        self.solver_step = fmu.solver_step
        self._fmu = fmu
        self._owner = (os.getpid(), threading.get_ident())

    def get(self):
        """The FMU to simulate with here."""
        return self._fmu if self.is_local else local_fmu(self.fmu_path, self.solver_step)

    @property
    def is_local(self) -> bool:
        """True in the process and thread that made the handle (where it holds the caller's FMU)."""
        return self._fmu is not None and self._owner == (os.getpid(), threading.get_ident())

    def __getstate__(self):
        return {"fmu_path": self.fmu_path, "solver_step": self.solver_step}

    def __setstate__(self, state):
        self.fmu_path = state["fmu_path"]
        self.solver_step = state["solver_step"]
        self._fmu = None
        self._owner = None
