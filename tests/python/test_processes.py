"""No worker process outlives ``juno``, however it ends (juno.parallel, juno.cli).

Specification:

* Ctrl-C (SIGINT to the whole process group, as a terminal sends it) during a pooled batch:
  exit code 130, one line ``juno: interrupted`` on stderr (no worker traceback), no worker left;
* SIGTERM to ``juno``: a clean exit, code 143, one line ``juno: terminated``, no worker left;
* after Ctrl-C or SIGTERM, nothing of juno's or its workers' left in the temporary folder;
* SIGKILL to ``juno`` (no clean-up possible in it): its workers still die, by the parent-death
  signal (Linux) or their watchdog;
* a pool worker ignores SIGINT, has the parent-death signal armed, and its watchdog ends it
  when its parent is gone.

The batch is ``juno sweep`` over 40 points of 60 s simulations on 2 workers: it runs for far
longer than the test waits, so a signal always lands while the pool is busy.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import subprocess
import sys
import time

import pytest

from harness_fixtures import juno_command
from juno.parallel import WATCHDOG_PERIOD, _watch_parent, map_tasks

pytest_plugins = ["harness_fixtures"]

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")

# A sweep that is still simulating when the signal comes: 4,000 runs of 60 s, each some tens of
# milliseconds at the default step, about half a minute of work for two workers (it is stopped
# long before it would end).
SWEEP = ["sweep", "--vary", "soil.kh=1e5:5e5:4000", "--stop-time", "60", "--workers", "2", "--quiet"]


def children_of(pid: int) -> list[int]:
    """Process ids whose parent is ``pid`` (from /proc/*/stat)."""
    found = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat") as f:
                stat = f.read()
        except OSError:
            continue
        if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
            found.append(int(entry))
    return found


def alive(pid: int) -> bool:
    """True while ``pid`` exists and is not a zombie."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def start_pooled_juno(tmp_path):
    """``juno sweep`` in its own session, once both pool workers run: (process, worker ids).  Its
    temporary folder (TMPDIR) is ``tmp_path / "tmp"``, empty at the start."""
    err = open(tmp_path / "stderr.txt", "w")
    (tmp_path / "tmp").mkdir()
    proc = subprocess.Popen([juno_command(), *SWEEP], stdout=subprocess.DEVNULL, stderr=err,
                            start_new_session=True, env={**os.environ, "TMPDIR": str(tmp_path / "tmp")})
    deadline = time.monotonic() + 30
    workers: list[int] = []
    while len(workers) < 2:
        assert proc.poll() is None, f"juno ended early: {(tmp_path / 'stderr.txt').read_text()}"
        assert time.monotonic() < deadline, "the pool did not start within 30 s"
        time.sleep(0.05)
        workers = children_of(proc.pid)
    time.sleep(0.5)   # the workers are simulating now
    return proc, workers


def wait_gone(pids: list[int], timeout: float) -> list[int]:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and any(alive(p) for p in pids):
        time.sleep(0.05)
    return [p for p in pids if alive(p)]


@pytest.mark.parametrize("how, code, line", [
    ("SIGINT", 130, "juno: interrupted"),
    ("SIGTERM", 143, "juno: terminated"),
    ("SIGKILL", -signal.SIGKILL, None),
])
def test_no_worker_outlives_juno(how, code, line, tmp_path):
    proc, workers = start_pooled_juno(tmp_path)
    try:
        sig = getattr(signal, how)
        if sig == signal.SIGINT:
            os.killpg(proc.pid, sig)        # Ctrl-C: the terminal signals the whole group
        else:
            os.kill(proc.pid, sig)
        assert proc.wait(timeout=15) == code
        left = wait_gone(workers, timeout=5.0)
        assert not left, f"workers {left} outlived juno after {how}"
        if line is not None:
            lines = [ln for ln in (tmp_path / "stderr.txt").read_text().splitlines() if ln.strip()]
            assert lines == [line], f"stderr after {how}: {lines}"
            # and no temporary file of juno's or its workers' (the FMUs they extracted) is left
            left_behind = sorted(str(p.relative_to(tmp_path)) for p in (tmp_path / "tmp").rglob("*"))
            assert not left_behind, f"left in the temporary folder after {how}: {left_behind[:5]}"
    finally:
        for pid in [proc.pid, *workers]:
            if alive(pid):
                os.kill(pid, signal.SIGKILL)
        proc.wait(timeout=5)


def _worker_state(_):
    import ctypes
    libc = ctypes.CDLL(None, use_errno=True)
    sig = ctypes.c_int(0)
    libc.prctl(2, ctypes.byref(sig), 0, 0, 0)          # PR_GET_PDEATHSIG
    return os.getpid(), signal.getsignal(signal.SIGINT) == signal.SIG_IGN, sig.value


def test_a_pool_worker_ignores_ctrl_c_and_dies_with_its_parent():
    states = map_tasks(_worker_state, range(4), workers=2)
    assert all(pid != os.getpid() for pid, _, _ in states), "ran in pool workers"
    assert all(ignores for _, ignores, _ in states), "a worker would print a KeyboardInterrupt traceback"
    assert all(sig == signal.SIGTERM for _, _, sig in states), "no parent-death signal armed"


def test_the_watchdog_ends_a_worker_whose_parent_is_gone():
    """The portable fallback: the worker sees that its parent is not the one it started with."""
    ctx = multiprocessing.get_context("fork")
    child = ctx.Process(target=_watch_parent, args=(os.getpid() + 10 ** 6,))   # never its parent
    start = time.monotonic()
    child.start()
    child.join(timeout=10 * WATCHDOG_PERIOD + 5)
    assert child.exitcode == 1, f"exit code {child.exitcode}"
    assert time.monotonic() - start < 10 * WATCHDOG_PERIOD + 5
