"""`juno bench` judges a real-time target only where the issue sets it: at the FMU's default
settings (the automatic step).  A run at a fixed step shows its real-time factor with no target
and no verdict, however fast or slow it is; a run at the default is judged, and can miss.

The C programs and the FMU are replaced by stand-ins that report chosen timings
(python_harness/juno/bench.py's _run_c and _traces; a fake fmu.simulate), so the table's rules
are checked without timing anything."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from juno import bench
from juno.bench import TRACE_COLUMNS, Report

DURATION = {"drawbar": 30.0, "terrain": 60.0}


def _bench_fmu_json(rtf: float, paths: tuple[str, ...]) -> dict[str, Any]:
    """What bench_fmu --json reports when both runs go ``rtf`` times real time."""
    runs = []
    for scenario, duration in DURATION.items():
        for path in paths:
            wall = duration / rtf
            runs.append({"scenario": scenario, "path": path, "duration": duration, "ok": True, "total_s": wall,
                         "stepping_s": wall, "stepping_cpu_s": wall, "steps": duration / 1e-3, "cpu_share": 1.0,
                         "final_x": 4.0})
    return {"solver_step": 1e-3, "comm_step": 0.01, "runs": runs, "maxrss_mb": 1.0}


@pytest.fixture
def stand_ins(monkeypatch):
    """bench_fmu at fixed steps 100 times faster than the target, at the default (no step
    arguments) half as fast as it; every trace the reference itself (accuracy 0)."""
    def run_c(cmd: list[str], say) -> dict[str, Any]:
        at_default = "--solver-step" not in cmd
        only = cmd[cmd.index("--only") + 1:cmd.index("--only") + 2] if "--only" in cmd else ["direct", "fmi"]
        return _bench_fmu_json(bench.TARGETS["rtf_c"] / 2 if at_default else bench.TARGETS["rtf_c"] * 100,
                               tuple(only))

    def traces(exe, fmu_dir, grid, args, prefix, say) -> dict[str, np.ndarray]:
        t = np.arange(0.0, 10.0, 0.02)
        trace = np.column_stack([t] + [np.full_like(t, 1.0 + k) for k in range(len(TRACE_COLUMNS) - 1)])
        return {name: trace for name in DURATION}

    monkeypatch.setattr(bench, "_run_c", run_c)
    monkeypatch.setattr(bench, "_traces", traces)


class SlowAtTheDefault:
    """A stand-in for juno.simulator.JunoFMU: 10 times faster than the fmpy target at a fixed
    1 ms step, half as fast as it at its default."""

    variables = {"solver.tolerance": type("V", (), {"start": "4e-4"})(),
                 "solver.step": type("V", (), {"start": "0.02"})()}

    def simulate(self, params, inputs, duration, comm_step):
        fixed = params.get("solver.tolerance") == 0.0
        factor = bench.TARGETS["rtf_fmpy"] * (10 if fixed else 0.5)
        time.sleep(duration / factor)
        return {"x": np.array([0.0, 4.0])}


def _table(stand_ins) -> list[dict[str, Any]]:
    rep = Report(lambda text: None)
    bench.bench_fmu_c(rep, Path("bench_fmu"), Path("fmu"), Path("grid.asc"), 5, lambda text: None)
    bench.bench_fmpy(rep, SlowAtTheDefault(), Path("grid.asc"), 1, lambda text: None)
    return rep.figures


def test_every_real_time_target_is_judged_on_a_run_at_the_default_settings(stand_ins):
    real_time = [f for f in _table(stand_ins) if f["unit"] == "x RT"]
    assert real_time
    for f in real_time:
        assert "at_default" in f, f"{f['label']} does not say whether it is at the default settings"
        if f["target"]:
            assert f["at_default"], f"{f['label']}: a real-time target on a run at a fixed step"


def test_a_run_at_a_fixed_step_has_no_verdict_however_fast(stand_ins):
    fixed = [f for f in _table(stand_ins) if f["unit"] == "x RT" and not f["at_default"]]
    assert {f["key"] for f in fixed} >= {"rtf_c_drawbar_direct", "rtf_c_terrain_fmi", "rtf_c_terrain_direct_10ms",
                                         "rtf_c_drawbar_direct_1ms", "rtf_fmpy_terrain"}
    for f in fixed:
        assert f["target"] == "" and f["met"] is None, f["label"]
        assert "the real-time target applies to the default" in f["note"], f["label"]


def test_a_run_at_the_default_is_judged_and_can_miss(stand_ins):
    default = {f["key"]: f for f in _table(stand_ins) if f["unit"] == "x RT" and f["at_default"]}
    # from C through model_do_step and through the FMI functions, and through fmpy: each run
    assert set(default) == {f"rtf_{how}_{scenario}{path}_auto" for scenario in DURATION
                            for how, path in (("c", "_direct"), ("c", "_fmi"), ("fmpy", ""))}
    for f in default.values():
        assert f["target"] and f["met"] is False, f["label"]
