"""The diagnosis's results as typed records: a judged candidate, a head-to-head comparison, a pair
of tied models and the run that would tell them apart, and the whole diagnosis.  Each record's
``to_json()`` is the plain JSON object ``juno diagnose --json`` writes (NaN and infinities are
made null by juno.core.write_json)."""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Any, Protocol

import numpy as np

from ..campaign import MissingColumn
from ..sensor_noise import NoiseStatement
from .verdict import Unexplained


def _plain(value: Any) -> Any:
    """``value`` with every record in it (anything with a ``to_json``) as its JSON object."""
    if hasattr(value, "to_json"):
        return value.to_json()
    if isinstance(value, list):
        return [_plain(v) for v in value]
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    return value


def _fields_json(record: Any, omit_if_none: tuple[str, ...] = ()) -> dict[str, Any]:
    """A record's fields in their declared order as a JSON object; the fields named in
    ``omit_if_none`` are left out when they are None."""
    return {f.name: _plain(getattr(record, f.name)) for f in fields(record)
            if not (f.name in omit_if_none and getattr(record, f.name) is None)}


class Ranked(Protocol):
    """What ranking and head-to-head comparisons need of a model: its name, its held-out relative
    gain over the reference and the number of parameters it adds."""

    name: str
    gain: float
    n_params: int


@dataclass(frozen=True)
class Contender:
    """A model in a ranking that is not a judged candidate (a branch's final model)."""

    name: str
    gain: float
    n_params: int


@dataclass(frozen=True)
class Ablation:
    """A candidate's fit against the same fit with its extension switched off: the held-out relative
    gain and the paired test's z, overall and per kind of run."""

    gain: float
    z: float
    z_by_kind: dict[str, float]
    gain_by_kind: dict[str, float]

    def to_json(self) -> dict[str, Any]:
        return _fields_json(self)


@dataclass(frozen=True)
class ScanRegistration:
    """One scan's registration (juno.registration.ScanEvidence): the scan file as the manifest
    names it, the terrain runs on it, the registration applied to it (FMU names terrain.offsetX,
    Y, Z in m, terrain.offsetYaw in rad, terrain.slopeX, Y; all 0 when it stays as it is), its held-out mean squared
    scaled residual of height, pitch and roll as scanned and registered and their ratio (None
    when its runs are too short to test), and whether the pose shows it misregistered."""

    scan: str
    runs: list[str]
    offsets: dict[str, float]
    held_out_ms_as_scanned: float | None
    held_out_ms_registered: float | None
    ratio: float | None
    misregistered: bool

    def to_json(self) -> dict[str, Any]:
        return _fields_json(self)


@dataclass(frozen=True)
class KinematicEvidence:
    """The registration's held-out evidence on the measured pose (juno.registration): mean squared
    scaled residual of height, pitch and roll with the scans as they are and registered (pooled
    over the scans), their ratio, the relative gain, whether it is significant (some scan's own
    evidence passes registration.HELD_OUT_RATIO), and each scan's registration (``scans``, left
    out when not known)."""

    held_out_ms_as_scanned: float
    held_out_ms_registered: float
    ratio: float
    gain: float
    significant: bool
    scans: list[ScanRegistration] | None = None

    def misregistered(self) -> list[ScanRegistration]:
        """The scans the pose shows misregistered."""
        return [s for s in self.scans or [] if s.misregistered]

    def to_json(self) -> dict[str, Any]:
        return _fields_json(self, omit_if_none=("scans",))


@dataclass(frozen=True)
class JudgedCandidate:
    """One candidate's fit judged against its reference (judging.judge): held-out relative gain
    and paired-test z over all runs and per kind of run, whether the extension acts, the ablation
    and kinematic evidence where given, held-out mean squared scaled residual before and after,
    the fitted soil and extension, and the fit's cost (evaluations, failures, wall time in s).
    A failed fit has ``error`` set, ``status`` "failed", no gain and no parameters."""

    name: str
    cause: str
    gain: float
    z: float
    significant: bool
    acts: bool
    status: str
    failed_evaluations: int
    error: str | None = None
    gain_by_kind: dict[str, float] = field(default_factory=dict)
    z_by_kind: dict[str, float] = field(default_factory=dict)
    ablation: Ablation | None = None
    kinematic: KinematicEvidence | None = None
    judged_on: list[str] = field(default_factory=list)
    held_out_mse_before: float = float("nan")
    held_out_mse_after: float = float("nan")
    test_mse: float = float("nan")
    train_mse: float = float("nan")
    #: parameters the extension adds (0 for a failed fit, which is charged for none)
    n_params: int = 0
    soil: dict[str, float] = field(default_factory=dict)
    extension: dict[str, float] = field(default_factory=dict)
    #: the fitted soil's parameters at a bound of the search (judging.soil_at_bounds): such a fit
    #: names no cause
    soil_at_bounds: list[str] = field(default_factory=list)
    evaluations: int = 0
    wall_time: float = 0.0

    def to_json(self) -> dict[str, Any]:
        if self.error:
            return {"name": self.name, "cause": self.cause, "error": self.error, "status": self.status,
                    "failed_evaluations": self.failed_evaluations, "significant": self.significant,
                    "acts": self.acts, "gain": self.gain, "z": self.z}
        return {"name": self.name, "cause": self.cause, "gain": self.gain, "z": self.z,
                "gain_by_kind": self.gain_by_kind, "z_by_kind": self.z_by_kind, "acts": self.acts,
                "ablation": _plain(self.ablation), "kinematic": _plain(self.kinematic),
                "judged_on": self.judged_on,
                "held_out_mse_before": self.held_out_mse_before, "held_out_mse_after": self.held_out_mse_after,
                "significant": self.significant, "test_mse": self.test_mse, "train_mse": self.train_mse,
                "n_params": self.n_params, "soil": self.soil, "extension": self.extension,
                "soil_at_bounds": self.soil_at_bounds, "evaluations": self.evaluations, "failed_evaluations": self.failed_evaluations,
                "status": self.status, "wall_time": self.wall_time}


@dataclass(frozen=True)
class Duel:
    """A head-to-head comparison (judging.head_to_head): whether ``challenger`` (more parameters,
    larger raw gain) explains the held-out data significantly better than ``leader``; the paired
    test's z per kind of run and the challenger's relative gain against the leader.  ``stage`` is
    "final models" when the compared models are branches' final models (search.choose_branch),
    "near tie" when the challenger is the ranking's leader and ``leader`` the runner-up
    within NEAR_TIE of it, whose own second round the comparison decides (search.tie_settled),
    and "ripple" when the drive torques ripple with the wheel angle, ``leader`` is the best
    runner-up whose cause makes that ripple and the challenger the leader whose cause makes none,
    which stays first only by winning (judging.ripple_maker_leads); "final models, ripple" when
    the same is asked of branches' final models (search.choose_branch)."""

    leader: str
    challenger: str
    z_by_kind: dict[str, float]
    gain: float
    challenger_better: bool
    stage: str | None = None

    def to_json(self) -> dict[str, Any]:
        return _fields_json(self, omit_if_none=("stage",))


@dataclass(frozen=True)
class TiedPair:
    """The steady drawbar run that would tell a model reported equally good from the cause
    (juno.telling_apart): ``models`` (the cause first), throttle (-), load (N), each model's
    steady slip there, their difference, the largest difference within the campaign's loads,
    and the slip ladders over every load at that throttle."""

    models: list[str]
    throttle: float
    load_N: float
    slip: dict[str, float]
    difference: float
    difference_within_campaign: float
    ladder: dict[str, list[float]]

    @classmethod
    def from_telling_apart(cls, found: dict[str, Any]) -> TiedPair:
        """The record of one of juno.telling_apart.telling_apart's results."""
        return cls(**{f.name: found[f.name] for f in fields(cls)})

    def to_json(self) -> dict[str, Any]:
        return _fields_json(self)


@dataclass(frozen=True)
class Baseline:
    """The base model's fit: soil, held-out and training mean squared scaled residual, held-out
    RMS per signal (in the signal's units), status and failed evaluations, and the constant its
    pitch residuals hold on the drawbar runs' training blocks, by IMU mounting (mounting -> rad,
    measured - simulated; sensor_offset.mounting_offsets; empty without a measured pitch): the
    IMU's mounting offsets that every fit and comparison takes off where the mounting is free
    (Criteria.pitch_offset_free)."""

    soil: dict[str, float]
    test_mse: float
    train_mse: float
    rms: dict[str, float]
    status: str
    failed_evaluations: int
    pitch_offset: dict[str, float] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        return _fields_json(self)


@dataclass(frozen=True)
class Criteria:
    """The thresholds the diagnosis judged by and how the terrain runs were replayed: block
    length (s), z and gain thresholds, tie ratio, terrain segment (s or None), the terrain drive
    and each drive's training loss (at the base model, and the lowest over every fitted model
    with that model's name), the negligible change of the paired test, the registration's
    held-out ratio, and how many replicas with fresh sensor noise each terrain run's evidence is
    judged against (0 without a terrain run; terrain_replicas.py), and whether the IMU's pitch
    offset was a free nuisance (sensor_offset.py; False where the manifest says the mounting is
    calibrated)."""

    block_s: float
    z_min: float
    gain_min: float
    tie_ratio: float
    terrain_segment_s: float | None
    terrain_drive: str
    terrain_drive_training_loss: dict[str, float]
    terrain_drive_settled: dict[str, dict[str, Any]]
    negligible_change: float
    registration_held_out_ratio: float
    terrain_replicas: int = 0
    pitch_offset_free: bool = True

    def to_json(self) -> dict[str, Any]:
        return _fields_json(self)


@dataclass(frozen=True)
class ResidualAnalysis:
    """Where the base model is wrong: mean and RMS scaled residual per "run/signal", and the
    overall mean square."""

    by_run_signal: dict[str, dict[str, float]]
    overall_mse: float

    def to_json(self) -> dict[str, Any]:
        return _fields_json(self)


@dataclass(frozen=True)
class ExtendedModel:
    """The model with every named cause: its name ("a+b"), causes, soil, extension parameters,
    held-out mean squared scaled residual, held-out RMS per signal, and its pitch offsets (as
    Baseline's); with no cause named, only ``name`` None and no causes."""

    name: str | None
    causes: list[str]
    soil: dict[str, float] | None = None
    extension: dict[str, float] | None = None
    test_mse: float | None = None
    rms: dict[str, float] | None = None
    pitch_offset: dict[str, float] | None = None

    def to_json(self) -> dict[str, Any]:
        if self.name is None:
            return {"name": None, "causes": self.causes}
        return _fields_json(self)


@dataclass(frozen=True)
class GainStep:
    """What one named cause gained over its reference (held-out relative gain, z, held-out mean
    squared scaled residual before and after)."""

    cause: str
    relative: float
    z: float
    held_out_mse_before: float
    held_out_mse_after: float

    def to_json(self) -> dict[str, Any]:
        return _fields_json(self)


@dataclass(frozen=True)
class SignalGain:
    """One signal's held-out RMS (its units) before and after the extension, and the relative gain."""

    before: float
    after: float
    relative: float

    def to_json(self) -> dict[str, Any]:
        return _fields_json(self)


@dataclass(frozen=True)
class CauseGain:
    """The gain of the model with every named cause over the base model on the held-out blocks of
    the runs ``judged_on``: mean squared scaled residual before and after, relative gain, the
    first cause's z, each cause's step, per signal, and the registration's pose evidence when
    the registration is a cause."""

    held_out_mse_before: float
    held_out_mse_after: float
    judged_on: list[str]
    relative: float
    z: float
    steps: list[GainStep]
    per_signal: dict[str, SignalGain]
    registration: KinematicEvidence | None = None

    def to_json(self) -> dict[str, Any]:
        return _fields_json(self, omit_if_none=("registration",))


@dataclass(frozen=True)
class NoCauseGain:
    """With no cause named: the base model's held-out mean squared scaled residual (before and
    after alike), no gain, and the best candidate with its gain (None and 0 without candidates)."""

    held_out_mse_before: float
    held_out_mse_after: float
    relative: float
    best_candidate: str | None
    best_candidate_gain: float

    def to_json(self) -> dict[str, Any]:
        return _fields_json(self)


@dataclass(frozen=True)
class PlotData:
    """What the residual figures need (not part of the JSON): every residual's run, signal, time
    and block, the training mask, the base model's residuals and the extended model's (None
    when no cause is named)."""

    problem_meta: dict[str, np.ndarray]
    train: np.ndarray
    base_residuals: np.ndarray
    best_residuals: np.ndarray | None


@dataclass(frozen=True)
class DiagnosisResult:
    """The whole diagnosis: the cause(s) named strongest first and their physical explanation,
    the candidates reported equally good and the runs that would tell them apart, every
    head-to-head comparison, every candidate judged (ranked) and the second round, the base
    model, the criteria, where the base model is wrong, the extended model and its gain, the
    wall time (s), the optional columns the campaign's runs lack with what that costs
    (juno.campaign.missing_columns; [] when none is missing), and each measured column's sensor
    noise, stated in the manifest or estimated from its samples (juno.sensor_noise.noise_statements)."""

    cause: str
    causes: list[str]
    explanation: str
    equally_good: list[str]
    telling_apart: list[TiedPair]
    head_to_head: list[Duel]
    candidates: list[JudgedCandidate]
    second_round: list[JudgedCandidate]
    baseline: Baseline
    criteria: Criteria
    residual_analysis: ResidualAnalysis
    extended: ExtendedModel
    gain: CauseGain | NoCauseGain
    wall_time: float
    plot_data: PlotData | None = None
    unexplained: Unexplained | None = None        # structure the named causes (or none) leave
    structure: dict[str, Any] | None = None       # residual structure tests: "base", "extended"
    missing_columns: list[MissingColumn] = field(default_factory=list)
    sensor_noise: list[NoiseStatement] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        """The JSON object of ``juno diagnose --json`` (everything but the figures' data)."""
        return {f.name: _plain(getattr(self, f.name)) for f in fields(self) if f.name != "plot_data"}


def public_json(result: DiagnosisResult) -> dict[str, Any]:
    """The JSON object of ``juno diagnose --json`` (DiagnosisResult.to_json)."""
    return result.to_json()
