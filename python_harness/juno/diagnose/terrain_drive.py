"""How the terrain runs are replayed: following the measured spins or driven by the measured torque
(identify.REPLAY_DRIVES); drawbar runs always follow the measured spins.

choose_terrain_drive picks one per campaign, blind, for the candidates' fits: the one whose replay
at the base model fits the terrain run's training blocks better; once they are fitted,
settle_terrain_drive chooses again over every model, and that replay is the one every model is
judged on.  Neither drive is right everywhere: replayed by torque, the rover's pace follows the
model's traction, which is what the candidates explain, but it drifts along its path when the
model is wrong; replayed by the measured spins it stays on its path but its torques carry the
model's error.  Which replay fits the training blocks better is the blind, per-campaign choice."""

from __future__ import annotations

from dataclasses import replace
from typing import Any, Sequence

import numpy as np

from ..campaign import Campaign
from ..identify import REPLAY_DRIVES
from ..simulator import JunoFMU
from .fitting import FitResult, fit_loss, replayed
from .problem import Problem, build_problem, residuals_for, run_kinds


def drive_problems(campaign: Campaign, problem: Problem, terrain_segment: float | None = None
                   ) -> dict[str, Problem]:
    """The problem with its terrain runs replayed by each drive of identify.REPLAY_DRIVES, by
    drive; ``problem`` is the spin replay's (build_problem's default).  Their residuals line up:
    the drive changes how the terrain runs are replayed, not what is compared."""
    return {drive: problem if drive == "spin" else
            replace(build_problem(campaign, problem.fmu_path, problem.grid_file, terrain_segment, drive),
                    ripple_lugs=problem.ripple_lugs)
            for drive in REPLAY_DRIVES}


def choose_terrain_drive(campaign: Campaign, problem: Problem, base: FitResult,
                         terrain_segment: float | None = None, problems: dict[str, Problem] | None = None
                         ) -> tuple[Problem, FitResult, str, dict[str, float]]:
    """The problem (and the base model's FitResult on it) with the terrain run replayed by the
    drive of identify.REPLAY_DRIVES whose replay at the base model has the lower fit_loss on the
    terrain run's training blocks; that drive; and that loss for each drive.  ``problem`` and
    ``base`` are those of the spin replay (build_problem's default).  The base fit uses the
    drawbar runs only, so it is the same for every drive, and so are the drawbar runs'
    residuals: only the terrain runs are replayed.  The held-out blocks are not looked at.
    ``problems``: drive_problems's (built here if not given).

    It is settle_terrain_drive over the base model alone.  This choice is the one the
    candidates are fitted with; once they are fitted, settle_terrain_drive chooses again over
    every fitted model."""
    problems = problems or drive_problems(campaign, problem, terrain_segment)
    drive, best, (base_replayed,) = settle_terrain_drive(problems, "spin", [base])
    return problems[drive], base_replayed, drive, {d: v["loss"] for d, v in best.items()}


def settle_terrain_drive(problems: dict[str, Problem], current: str, fits: Sequence[FitResult]
                         ) -> tuple[str, dict[str, Any], list[FitResult]]:
    """The drive by which the terrain runs are replayed for judging: of the drives in
    ``problems`` (drive_problems), the one under which some model of ``fits`` (the base model and
    every fitted candidate, whose terrain runs ``current`` replayed) has the lowest fit_loss on
    the terrain runs' training blocks.  Returns that drive, the lowest loss under each drive
    with the model that reached it ({drive: {"loss", "model"}}), and ``fits`` with their terrain
    runs replayed by that drive (a failed fit is passed on as it is).  The held-out blocks are
    not looked at, and every model is then judged under the same replay, so their gains compare.

    Why not choose_terrain_drive's choice at the base model alone: with an effect hidden, the
    base model is wrong, and a wrong model replayed open loop by the measured torque drifts off
    the measured path, so the spin replay, which imposes the kinematics, looks better at the
    base model even where the right model is replayed far better by the torque; judged on the
    spin replay, the right model can then look no better than the base model."""
    any_problem = problems[current]
    terrain = run_kinds(any_problem) == "terrain"
    train = any_problem.train & terrain
    replays: dict[str, list[FitResult]] = {}
    best: dict[str, Any] = {}
    fmu = JunoFMU(any_problem.fmu_path)
    try:
        for drive, problem in problems.items():
            replays[drive] = []
            for res in fits:
                if res.error or res.residuals.size == 0:
                    replays[drive].append(res)
                    continue
                r = res.residuals if drive == current else _terrain_replayed(fmu, problem, res, terrain)
                replays[drive].append(replayed(problem, res.name, res.params, r, res.evaluations, res.wall_time,
                                               res.failed_evaluations))
                loss = fit_loss(r[train])
                loss = float(loss) if np.isfinite(loss) else np.inf
                if drive not in best or loss < best[drive]["loss"]:
                    best[drive] = {"loss": loss, "model": res.name}
    finally:
        fmu.close()
    drive = min(best, key=lambda d: best[d]["loss"]) if best else current
    return drive, best, replays.get(drive, list(fits))


def _terrain_replayed(fmu: JunoFMU, problem: Problem, res: FitResult, terrain: np.ndarray) -> np.ndarray:
    """``res``'s residuals with its terrain runs (``terrain``: their residuals) replayed as in
    ``problem``; NaN there if the replay fails."""
    r = res.residuals.copy()
    terrain_r = residuals_for(fmu, problem, res.params, ("terrain",))
    r[terrain] = np.nan if terrain_r is None else terrain_r
    return r
