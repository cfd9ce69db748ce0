"""Identification of the soil parameters a = [k_h, eta, gamma, K_vx].

Two ways:

* :func:`identify_paper` - the paper's: for one drawbar run, the steady-
  window averages of drawbar force and drive torques are the (constant)
  inputs, the averages of forward speed and wheel spins the objectives;
  the cost is Eqns 10-13 with the paper's weights, minimised by an
  unconstrained Nelder-Mead from the paper's initial guess.  Three averaged
  numbers cannot pin four parameters: the result reports that.
* :func:`identify_joint` - beyond the paper: one fit over all drawbar runs
  (and optionally the terrain run) using the whole measured time series,
  in transformed parameters that keep the search physical (log for
  positive values, logit for gamma), a trust-region Gauss-Newton fit of the
  scaled residuals (or Nelder-Mead then that polish), with the parameter
  covariance from the Jacobian (inflated for time-correlated residuals),
  the replay's own bias measured by a parametric bootstrap at the fit
  (a refit of the runs simulated with the fitted soil) as the systematic
  part of each uncertainty, and an identifiability report.

A failed fit is an error, never a result.  Every objective evaluation is logged
(:class:`EvaluationLog`: how many, how many failed, the first failure's run, file, time
and FMU message); a fit whose optimum failed, or over which more than
MAX_FAILED_FRACTION of the evaluations failed, raises :class:`FitError` naming the first
failure.  A parameter the data does not see (a zero Jacobian column) or a fit that did
not move is reported "not identified", with no uncertainty, never "pinned".

Both use every core (juno.parallel): the joint fit evaluates the runs of one residual
vector, and the points of its finite-difference Jacobian, as parallel tasks (each worker
process holds its own FMU instance); :func:`identify_paper_runs` fits the drawbar runs in
parallel and :func:`identify_multistart` runs joint fits from several starting points in
parallel.  Where a task runs does not change its result: the fits are identical, bit for bit,
to the serial ones (``workers=1``).  With ``scheduler="tcp://host:port"`` the tasks run on a
Dask distributed cluster instead.

Where each part lives: ``base`` (the constants, failures, search space and scans every fit
shares), ``paper`` (the paper's per-run fit), ``replay`` (a measured run made ready to replay,
and its residuals), ``joint`` (the joint fit and its doubts), ``replay_bias`` (the bootstrap of the replay's own
bias), ``multistart`` (joint fits from
several starts).  Everything public is imported from ``juno.identify``.
"""

from __future__ import annotations

from .base import (AT_LIMIT, FAILED_COST, FAILED_RESIDUAL, IDENTIFY_STEP, MAX_FAILED_FRACTION, PAPER_INITIAL,
                   SOIL_SEARCH_BOUNDS, STEP_NEEDS, ZERO_COLUMN, EvaluationLog, FitError, SearchBound, base_parameters,
                   from_search, gridded_scans, require_runs, soil_at_search_bounds, terrain_grids, to_search)
from .paper import PaperResult, SteadyAverages, identify_paper, identify_paper_runs, paper_cost, steady_averages
from .replay import (INCREMENT_SIGNALS, JOINT_SIGNALS, POSITION_LAG, REPLAY_DRIVES, REPLAY_MOTOR, REPLAY_SPIN_DAMPING,
                     SEGMENT_SETTLE, SEGMENT_SPEED_WINDOW, SETTLING_TIME, SPIN_TRACKER, TERRAIN_SIGNALS, PreparedRun,
                     Segment, prepare_run, restart_segments, run_residuals, torque_replay_throttle)
from .joint import (EVALUATION_LIMIT, STRUCTURE_BLOCK, JointResiduals, JointResult, classify, correlation_inflation,
                    fit_doubts, identify_joint)
from .multistart import MultiStartResult, identify_multistart, multistart_points
from .replay_bias import MEASURED_OUTPUTS, WORLD_STEP, ReplayBias, replay_bias, synthetic_run

__all__ = [
    "EVALUATION_LIMIT", "AT_LIMIT", "FAILED_COST", "FAILED_RESIDUAL", "IDENTIFY_STEP", "MAX_FAILED_FRACTION", "PAPER_INITIAL",
    "SOIL_SEARCH_BOUNDS", "STEP_NEEDS", "ZERO_COLUMN", "EvaluationLog", "FitError", "SearchBound",
    "base_parameters", "from_search", "gridded_scans", "require_runs", "soil_at_search_bounds",
    "terrain_grids", "to_search", "PaperResult", "SteadyAverages", "identify_paper", "identify_paper_runs",
    "paper_cost", "steady_averages", "INCREMENT_SIGNALS", "JOINT_SIGNALS", "POSITION_LAG", "REPLAY_DRIVES",
    "REPLAY_MOTOR", "REPLAY_SPIN_DAMPING", "SEGMENT_SETTLE", "SEGMENT_SPEED_WINDOW", "SETTLING_TIME",
    "SPIN_TRACKER", "TERRAIN_SIGNALS", "PreparedRun", "Segment", "prepare_run", "restart_segments",
    "run_residuals", "torque_replay_throttle", "STRUCTURE_BLOCK", "JointResiduals", "JointResult", "classify",
    "correlation_inflation", "fit_doubts", "identify_joint", "MultiStartResult", "identify_multistart",
    "multistart_points", "MEASURED_OUTPUTS", "WORLD_STEP", "ReplayBias", "replay_bias", "synthetic_run",
]
