"""How much the terrain runs' held-out loss moves with their sensors' noise: the spread the terrain
runs' evidence is judged against (judging.z_by_kind).

Why: the drawbar runs are replayed on flat ground following the measured spins, and their
held-out blocks are close to independent units, as the paired test assumes.  A terrain run is
replayed open loop over its scan, and the replayed rover drifts along its path: consecutive
held-out blocks share the drift, and which model drifts less is partly the luck of the noise in
the inputs that drive it.  The paired test then overstates the evidence either way.  Measured
on an alternative-design campaign hiding Coulomb plus viscous drivetrain friction (torque-driven
terrain replay): the model at the truth left a held-out mean square of 4.3 on the terrain run,
the base model 3.5 and the drivetrain-loss candidate 5.5; the paired test called the candidate
significantly worse there (z -3.2, a veto) and the truth nearly so (z -2.2), while replays with
fresh sensor noise put the candidate's difference from the base model at 0.9 of its spread.

Method (a parametric bootstrap, as the structure test's, juno.residual_structure): REPLICAS
times, every column of each terrain run's measurements gets fresh white noise at its sensor
noise, stated in the manifest or estimated from the column (juno.sensor_noise), and the run is
prepared from those samples exactly as the measured run is (the replay's inputs and start pose
from the noisy inputs, the compared outputs noisy too).  Every model is replayed on the same replicas, so two models'
replica losses are paired.  A model's replica loss is its held-out terrain mean square (capped
as the judging caps it, judging.capped_square).  For a reference and a candidate, the standard
deviation of their loss difference over the replicas is the standard error of the observed
difference, and the observed difference over it is the replica z (replica_z).  Deterministic:
the noise is drawn from a fixed seed, in run order, once per problem.

Assumptions, named: sensor noise is white at the sample rate (sensor_noise); adding noise to
noisy samples doubles its variance, so the spread estimates the data's own at about that noise
level (the replay's sensitivity is taken as the same at both levels); a replica that a model
cannot replay loses the rover, and its held-out residuals count at the cap."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..campaign import Campaign, RunData, load_campaign, read_run
from ..identify import prepare_run
from ..sensor_noise import sensor_noise
from ..simulator import JunoFMU
from .judging import capped_square
from .problem import Problem, residuals_or_failure, run_kinds

#: Replicas of every terrain run (each model replays each once): the same count as the structure
#: test's (residual_structure.REPLICAS); the spread of a difference from 20 has a relative error
#: of about 16 %.
REPLICAS = 20
#: The seed of the replicas' noise.
SEED = 0
#: The measured columns that carry sensor noise (time does not).
NOISY_COLUMNS = ("torque_left", "torque_right", "omega_left", "omega_right", "drawbar_force",
                 "pos_x", "pos_y", "pos_z", "roll", "pitch", "yaw")


def _noisy(rng: np.random.Generator, data: RunData) -> RunData:
    """A copy of ``data`` whose noisy columns carry fresh white noise at each one's sensor noise
    (stated in the manifest or estimated, juno.sensor_noise.sensor_noise), on their own samples (empty cells stay empty)."""
    columns = dict(data.columns)
    for name in NOISY_COLUMNS:
        if not data.has(name):
            continue
        t, v = data.samples(name)
        sigma = sensor_noise(data, name)
        values = columns[name].copy()
        own = ~np.isnan(values)
        values[own] = values[own] + sigma * rng.standard_normal(int(own.sum()))
        columns[name] = values
    return RunData(data.path, data.kind, columns, data.extra, data.lines, data.run_id, dict(data.stated_noise))


@dataclass
class TerrainReplicas:
    """The terrain runs of a problem, each REPLICAS times with fresh sensor noise (module
    docstring), and every model's replica losses, remembered by its parameters.  Picklable: the
    FMU and the remembered losses stay in the process that made them."""

    problems: list[Problem]
    held_out: np.ndarray                  # over the terrain runs' residuals, in problem order
    fmu_path: str
    _losses: dict[tuple, np.ndarray] = field(default_factory=dict, repr=False)
    _fmu: JunoFMU | None = field(default=None, repr=False)

    def __getstate__(self):
        state = dict(self.__dict__)
        state["_losses"], state["_fmu"] = {}, None
        return state

    def losses(self, params: dict[str, object]) -> np.ndarray:
        """The model's held-out terrain loss (capped mean square of its scaled residuals) on each
        replica; a replica it cannot replay counts at the cap."""
        key = tuple((k, v if isinstance(v, str) else float(v)) for k, v in sorted(params.items()))
        known = self._losses.get(key)
        if known is not None:
            return known
        if self._fmu is None:
            self._fmu = JunoFMU(self.fmu_path)
        out = np.empty(len(self.problems))
        for i, replica in enumerate(self.problems):
            r, _failure = residuals_or_failure(self._fmu, replica, params, ("terrain",))
            squares = capped_square(r[self.held_out]) if r is not None else capped_square(np.full(
                int(self.held_out.sum()), np.inf))
            out[i] = float(np.mean(squares))
        self._losses[key] = out
        return out

    def close(self) -> None:
        if self._fmu is not None:
            self._fmu.close()
            self._fmu = None


def terrain_replicas(problem: Problem, campaign: Campaign | None = None) -> TerrainReplicas | None:
    """The problem's TerrainReplicas, made on first use and kept on the problem; None without a
    terrain run."""
    if problem.terrain_replicas is not None:
        return problem.terrain_replicas
    terrain_runs = [p for p in problem.prepared if p.kind == "terrain"]
    if not terrain_runs:
        return None
    campaign = campaign or load_campaign(problem.campaign_root)
    rng = np.random.default_rng(SEED)
    measured = {p.run_id: read_run(campaign, p.run_id) for p in terrain_runs}
    replicas = []
    for _i in range(REPLICAS):
        noisy_runs = []
        for p in terrain_runs:
            spec = campaign.run(p.run_id)
            noisy_runs.append(prepare_run(campaign, spec, data=_noisy(rng, measured[p.run_id]),
                                          terrain_file=p.params["terrain.file"], segment=problem.terrain_segment,
                                          drive=problem.terrain_drive, scales="nominal"))
            noisy_runs[-1].params.update({k: p.params[k] for k in ("solver.step", "solver.tolerance")})
        replicas.append(Problem(problem.campaign_root, problem.grid_file, problem.fmu_path, noisy_runs))
    held_out = ~problem.train[run_kinds(problem) == "terrain"]
    problem.terrain_replicas = TerrainReplicas(replicas, held_out, problem.fmu_path)
    return problem.terrain_replicas
