"""Scale-out (juno.parallel): batches run serially, in a local process pool or on a Dask cluster,
and where they run changes nothing.

* map_tasks returns results in input order even when later items finish first; workers=1 runs
  in this process, a pool elsewhere.
* A failing task stops the batch with a TaskError naming the item, the original error chained.
* A flow (TaskPool.flow) runs the tasks its callback adds as results arrive, everywhere alike;
  the waiting task of highest priority starts first.
* A scheduler that cannot be reached gives a SchedulerError naming its address (API and CLI).
* A parameter sweep, the joint fit, a multi-start identification and a diagnosis's batch of
  fits (a soil patch's search split into tasks) give the same numbers, bit for bit, serially,
  in a local pool and on a Dask cluster (an in-process LocalCluster with
  two worker threads, each with its own FMU instance, talking TCP so every task is pickled).
"""

from __future__ import annotations

import os
import pickle
import socket
import time

import numpy as np
import pytest

from harness_fixtures import say
from juno import parallel
from juno.identify import (PAPER_INITIAL, JointResiduals, from_search, identify_joint, identify_multistart,
                           prepare_run, to_search)
from juno.parallel import SchedulerError, Task, TaskError, TaskPool, map_tasks
from juno.simulator import SOIL_PARAMETERS, InputSignals
from juno.sweep import SUMMARY_COLUMNS, grid, sweep

pytest_plugins = ["harness_fixtures"]

SMALL_SEED = 11


# ------------------------------------------------------------- tasks (module level: picklable)

def late_square(x: int) -> int:
    """x squared, the earlier items taking longer (so they finish last in a pool)."""
    time.sleep(0.03 * (6 - x))
    return x * x


def square_positive(x: int) -> int:
    if x < 0:
        raise ValueError(f"negative input {x}")
    return x * x


def where(_item) -> int:
    return os.getpid()


def nested(_item) -> tuple[int, list[int]]:
    """A task that runs a batch of its own with the default number of workers."""
    return os.getpid(), map_tasks(where, range(3))


# ---------------------------------------------------------------------------- fixtures

@pytest.fixture(scope="module")
def scheduler():
    """Address of a Dask LocalCluster: 2 worker threads in this process, over TCP."""
    from distributed import LocalCluster

    start = time.perf_counter()
    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=False, protocol="tcp",
                           host="127.0.0.1", dashboard_address=None)
    say(f"Dask LocalCluster at {cluster.scheduler_address} started in {time.perf_counter() - start:.1f} s")
    try:
        yield cluster.scheduler_address
    finally:
        cluster.close()


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


# ------------------------------------------------------------------------- map_tasks

@pytest.mark.parametrize("mode", ["serial", "pool", "dask"])
def test_results_come_back_in_input_order(mode, request):
    kwargs = {"serial": {"workers": 1}, "pool": {"workers": 2},
              "dask": {"scheduler": request.getfixturevalue("scheduler") if mode == "dask" else None}}[mode]
    items = list(range(6))
    seen = []
    results = map_tasks(late_square, items, on_result=lambda i, r: seen.append(i), **kwargs)
    assert results == [x * x for x in items]
    assert seen == items, "on_result must be called in input order"


def test_workers_one_runs_here_and_a_pool_elsewhere():
    assert map_tasks(where, range(3), workers=1) == [os.getpid()] * 3
    pids = map_tasks(where, range(4), workers=2)
    assert os.getpid() not in pids
    assert map_tasks(where, [], workers=2) == []


def test_a_batch_inside_a_worker_runs_in_that_worker():
    """No pools inside pools: the default inside a worker process is 1 (the cores are taken)."""
    for pid, inner in map_tasks(nested, range(2), workers=2):
        assert pid != os.getpid() and inner == [pid] * 3


def test_a_background_task_runs_in_a_process_of_its_own_and_gives_its_result_or_error():
    with parallel.BackgroundTask(where, None) as task:
        assert task.result() != os.getpid()
    with parallel.BackgroundTask(square_positive, -4) as task:
        with pytest.raises(ValueError, match="negative input -4"):
            task.result()
    here = parallel.BackgroundTask(where, None, background=False)
    assert here.result() == os.getpid()
    with pytest.raises(ValueError, match="negative input -2"):
        parallel.BackgroundTask(square_positive, -2, background=False).result()


def test_workers_must_be_positive():
    with pytest.raises(ValueError, match="workers must be at least 1"):
        map_tasks(where, range(2), workers=0)


@pytest.mark.parametrize("mode", ["serial", "pool", "dask"])
def test_a_failing_task_is_named(mode, request):
    kwargs = {"serial": {"workers": 1}, "pool": {"workers": 2},
              "dask": {"scheduler": request.getfixturevalue("scheduler") if mode == "dask" else None}}[mode]
    with pytest.raises(TaskError) as info:
        map_tasks(square_positive, [1, 2, 3, -7, 5, -9], **kwargs)
    err = info.value
    assert err.index == 3 and err.item == -7, "the first failure in input order"
    assert isinstance(err.__cause__, ValueError)
    assert "task 3" in str(err) and "-7" in str(err) and "negative input -7" in str(err)


def chains_of_squares(pool: TaskPool, start: list[int]) -> dict[int, list[int]]:
    """Each start's chain of squares: a task squares its item; while the square is below 1000,
    the callback adds a task for square + 1 (a task that needs the one before)."""
    chains: dict[int, list[int]] = {x: [] for x in start}

    def then(task: Task, result: int) -> list[Task]:
        chains[task.key].append(result)
        return [Task(task.key, square_positive, result + 1)] if result < 1000 else []
    pool.flow([Task(x, square_positive, x) for x in start], then)
    return chains


@pytest.mark.parametrize("mode", ["serial", "pool", "dask"])
def test_a_flow_runs_the_tasks_its_results_add(mode, request):
    kwargs = {"serial": {"workers": 1}, "pool": {"workers": 2},
              "dask": {"scheduler": request.getfixturevalue("scheduler") if mode == "dask" else None}}[mode]
    with TaskPool(**kwargs) as pool:
        chains = chains_of_squares(pool, [1, 2, 3])
    assert chains == {1: [1, 4, 25, 676, 458329], 2: [4, 25, 676, 458329], 3: [9, 100, 10201]}


def test_a_flow_starts_the_waiting_task_of_highest_priority_first():
    """Serially every task waits its turn: a task added later with a higher priority goes
    before the ones added earlier; equal priorities keep the order they were added in."""
    order = []

    def then(task: Task, result: int) -> list[Task]:
        order.append(task.key)
        return [Task("urgent", square_positive, 1, priority=5)] if task.key == "a" else []
    with TaskPool(workers=1) as pool:
        pool.flow([Task(k, square_positive, 2) for k in ("a", "b", "c")], then)
    assert order == ["a", "urgent", "b", "c"]


@pytest.mark.parametrize("mode", ["serial", "pool", "dask"])
def test_a_failing_task_of_a_flow_is_named(mode, request):
    kwargs = {"serial": {"workers": 1}, "pool": {"workers": 2},
              "dask": {"scheduler": request.getfixturevalue("scheduler") if mode == "dask" else None}}[mode]
    with TaskPool(**kwargs) as pool:
        with pytest.raises(TaskError) as info:
            pool.flow([Task(x, square_positive, x) for x in (1, -3, 2)], lambda task, result: [])
    assert info.value.index == 1 and info.value.item == -3 and isinstance(info.value.__cause__, ValueError)


def test_an_unreachable_scheduler_is_named():
    address = f"tcp://127.0.0.1:{free_port()}"
    start = time.perf_counter()
    with pytest.raises(SchedulerError) as info:
        map_tasks(square_positive, [1, 2], scheduler=address, connect_timeout=1.0)
    assert address in str(info.value)
    assert time.perf_counter() - start < 15.0


def test_the_cli_names_an_unreachable_scheduler(monkeypatch, capsys, fmu_path):
    from juno.cli import main

    monkeypatch.setattr(parallel, "CONNECT_TIMEOUT", 1.0)
    address = f"tcp://127.0.0.1:{free_port()}"
    code = main(["sweep", "--fmu", fmu_path, "--stop-time", "0.5", "--vary", "soil.kh=1e5,2e5",
                 "--scheduler", address, "--quiet"])
    err = capsys.readouterr().err
    assert code == 2
    assert f"cannot connect to the Dask scheduler at '{address}'" in err


# ---------------------------------------------------------------------------- sweeps

SWEEP_STOP = 1.5   # s


def small_sweep(fmu, **kwargs):
    points = grid({"soil.kh": [1.5e5, 3e5], "soil.eta": [0.4, 0.6]})
    return sweep(fmu, points, {"drive.mode": 2},
                 InputSignals.constant(drawbarForce=200.0, throttleLeft=0.45, throttleRight=0.45), SWEEP_STOP,
                 **kwargs)


def test_a_sweep_is_identical_serially_in_a_pool_and_on_dask(harness_fmu, scheduler):
    serial = small_sweep(harness_fmu, workers=1)
    assert [p.params for p in serial] == [{"soil.kh": 1.5e5, "soil.eta": 0.4}, {"soil.kh": 1.5e5, "soil.eta": 0.6},
                                          {"soil.kh": 3e5, "soil.eta": 0.4}, {"soil.kh": 3e5, "soil.eta": 0.6}]
    assert all(p.error is None for p in serial)
    assert all(set(p.summary) == set(SUMMARY_COLUMNS) for p in serial)
    assert all(np.isfinite(list(p.summary.values())).all() for p in serial)
    # The points differ (a sweep that returned one point four times would pass the comparisons below).
    assert len({p.summary["mean.wheelFL.sinkage"] for p in serial}) == 4
    assert small_sweep(harness_fmu, workers=2) == serial
    assert small_sweep(harness_fmu, scheduler=scheduler) == serial


def test_a_sweep_keeps_a_refused_point_with_its_reason(harness_fmu):
    points = sweep(harness_fmu, [{"soil.kh": -1.0}, {"soil.kh": 2e5}], {"drive.mode": 2},
                   InputSignals.constant(throttleLeft=0.3, throttleRight=0.3), 0.5, workers=2)
    assert "soil.kh" in points[0].error and np.isnan(points[0].summary["mean.vx"])
    assert points[1].error is None and np.isfinite(points[1].summary["mean.vx"])


def test_the_sweep_command_writes_what_the_api_computes(harness_fmu, fmu_path, tmp_path, capsys):
    from juno.cli import main

    out = tmp_path / "sweep.csv"
    code = main(["sweep", "--fmu", fmu_path, "--stop-time", str(SWEEP_STOP), "--param", "soil.gamma=0.2",
                 "--vary", "soil.kh=1.5e5,3e5", "--vary", "soil.eta=0.4:0.6:2", "--workers", "2",
                 "--out", str(out), "--quiet"])
    assert code == 0, capsys.readouterr().err
    rows = [line.split(",") for line in out.read_text().splitlines()]
    assert rows[0] == ["soil.kh", "soil.eta"] + list(SUMMARY_COLUMNS) + ["error"]
    assert len(rows) == 5
    # The drawbar scenario (juno.scenarios.SCENARIOS) with the fixed parameter, recomputed serially.
    api = sweep(harness_fmu, grid({"soil.kh": [1.5e5, 3e5], "soil.eta": [0.4, 0.6]}),
                {"drive.mode": 2, "soil.gamma": 0.2},
                InputSignals.constant(drawbarForce=400.0, throttleLeft=0.45, throttleRight=0.45), SWEEP_STOP,
                workers=1)
    for row, point in zip(rows[1:], api):
        assert [float(v) for v in row[:2]] == list(point.params.values())
        assert [float(v) for v in row[2:-1]] == [point.summary[c] for c in SUMMARY_COLUMNS]
        assert row[-1] == ""


# ------------------------------------------------------------------- identification

def same_fit(a, b) -> list[str]:
    """Differences between two joint fits (empty if identical bit for bit)."""
    diffs = [f"{k}: {a.params[k]!r} != {b.params[k]!r}" for k in SOIL_PARAMETERS if a.params[k] != b.params[k]]
    diffs += [f"sigma {k}: {a.std[k]!r} != {b.std[k]!r}" for k in SOIL_PARAMETERS if a.std[k] != b.std[k]]
    if a.cost != b.cost:
        diffs.append(f"cost {a.cost!r} != {b.cost!r}")
    if a.evaluations != b.evaluations:
        diffs.append(f"evaluations {a.evaluations} != {b.evaluations}")
    if a.singular_values != b.singular_values:
        diffs.append("singular values differ")
    return diffs


@pytest.fixture(scope="module")
def small(small_campaign):
    return small_campaign(SMALL_SEED)


def test_the_residual_function_travels_without_its_fmu(harness_fmu, small):
    """Pickled, the joint fit's residual function is the data and the FMU's path; unpickled here
    it simulates with this process's own FMU copy and gives the same residuals."""
    c = small.campaign
    prepared = [prepare_run(c, r) for r in c.runs_of_kind("drawbar")]
    fun = JointResiduals(harness_fmu, prepared)
    copy = pickle.loads(pickle.dumps(fun))
    assert copy.pool is None and copy.handle._fmu is None
    x = to_search(small.soil)
    r = fun(x)
    assert np.array_equal(copy(x), r)
    assert copy.handle.get() is not harness_fmu
    assert r.shape == (fun.size,) and np.all(np.abs(r) < 1e3)


def test_joint_and_multistart_fits_are_identical_wherever_they_run(harness_fmu, small, scheduler):
    c = small.campaign
    timings = {}

    def timed(label, fn):
        t = time.perf_counter()
        out = fn()
        timings[label] = time.perf_counter() - t
        return out

    serial = timed("joint, serial", lambda: identify_joint(harness_fmu, c, workers=1))
    pooled = timed("joint, 2 processes", lambda: identify_joint(harness_fmu, c, workers=2))
    dask = timed("joint, Dask", lambda: identify_joint(harness_fmu, c, scheduler=scheduler))
    assert same_fit(pooled, serial) == []
    assert same_fit(dask, serial) == []
    truth = small.soil
    assert all(abs(serial.params[k] / truth[k] - 1) < 0.2 for k in SOIL_PARAMETERS), serial.params

    multi = timed("multi-start x2, Dask", lambda: identify_multistart(harness_fmu, c, 2, scheduler=scheduler))
    assert multi.starts[0] == from_search(to_search(PAPER_INITIAL)) and multi.starts[1] != multi.starts[0]
    second = timed("second start, serial", lambda: identify_joint(harness_fmu, c, initial=multi.starts[1], workers=1))
    say("wall times on the short campaign: " + ", ".join(f"{k} {v:.1f} s" for k, v in timings.items()))
    # Each start's fit is the serial fit from that start (the first start is the paper's guess).
    assert same_fit(multi.fits[0], serial) == []
    assert same_fit(multi.fits[1], second) == []
    assert multi.best is min(multi.fits, key=lambda f: f.cost)
    say(f"multi-start: costs {[f.cost for f in multi.fits]}, spread {multi.spread}")


def test_a_diagnosis_batch_with_a_split_patch_search_is_the_same_on_dask(small_campaign, fmu_path, scheduler):
    from juno.diagnose.candidates import CANDIDATES
    from juno.diagnose.fitting import run_jobs
    from test_diagnose_replays import SEED, patch_job, same_fits

    patch = patch_job(small_campaign(SEED, "soil_patch").campaign, fmu_path)
    jobs = [patch, (patch[0], CANDIDATES["drivetrain_loss"], dict(PAPER_INITIAL), None, 3)]
    serial = run_jobs(jobs, 1, None, lambda message: None)
    on_dask = run_jobs(jobs, None, scheduler, lambda message: None)
    assert [same_fits(a, b) for a, b in zip(on_dask, serial)] == [[], []]


def test_a_pool_keeps_running_batches_until_closed():
    with TaskPool(workers=2) as pool:
        assert pool.parallel
        assert pool.map(square_positive, [1, 2, 3]) == [1, 4, 9]
        assert pool.map(square_positive, [4]) == [16]
    with TaskPool(workers=1) as pool:
        assert not pool.parallel
