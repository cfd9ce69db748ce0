"""The campaign format's names (run kinds, columns, the manifest's file name) and the records a
read campaign is made of: the manifest (:class:`Campaign`, :class:`RunSpec`, :class:`RigSetup`) and
the data of a run (:class:`RunData`, a time series; :class:`RigTable`, a testbed's steady points)."""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Optional, Union

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError

PathLike = Union[str, "os.PathLike[str]"]
FloatArray = NDArray[np.float64]

MANIFEST_NAME = "campaign.json"
KINDS = ("drawbar", "terrain", "wheel_rig")
#: The kinds whose CSV is a time series (read_run_csv); a wheel_rig run is a table (read_rig_csv).
TIME_SERIES_KINDS = ("drawbar", "terrain")
BASE_REQUIRED = ("time", "torque_left", "torque_right", "omega_left", "omega_right", "pos_x", "pos_y", "pos_z")
REQUIRED_COLUMNS: dict[str, tuple[str, ...]] = {
    "drawbar": BASE_REQUIRED + ("drawbar_force",),
    "terrain": BASE_REQUIRED,
}
OPTIONAL_COLUMNS = (
    "roll", "pitch", "yaw",
    "acc_x", "acc_y", "acc_z", "gyro_x", "gyro_y", "gyro_z",
)
KNOWN_COLUMNS = BASE_REQUIRED + ("drawbar_force",) + OPTIONAL_COLUMNS
ANGLE_COLUMNS = ("roll", "pitch", "yaw")
"""Columns unwrapped (made continuous) before interpolation by :func:`aligned`."""
#: The unit of each measured column of a run CSV (what a stated sensor noise is in).
COLUMN_UNITS = {"torque_left": "N m", "torque_right": "N m", "omega_left": "rad/s", "omega_right": "rad/s",
                "pos_x": "m", "pos_y": "m", "pos_z": "m", "drawbar_force": "N", "roll": "rad", "pitch": "rad",
                "yaw": "rad", "acc_x": "m/s^2", "acc_y": "m/s^2", "acc_z": "m/s^2", "gyro_x": "rad/s",
                "gyro_y": "rad/s", "gyro_z": "rad/s"}
#: The columns whose sensor noise a manifest may state (``sensor_noise``): every measured column.
NOISE_COLUMNS = tuple(COLUMN_UNITS)

#: A wheel_rig table: the testbed's set point of each row (inputs of the simulation, a value in
#: every row) and the measured columns (an empty cell: not measured at that point), each of which
#: may carry a per-point standard deviation ``<column>_std`` in the same unit.
RIG_INPUTS = ("vertical_load", "slip", "slip_angle")
RIG_REQUIRED = ("vertical_load", "slip", "drawbar_pull")
RIG_MEASURED = ("drawbar_pull", "torque", "sinkage", "lateral_force")
RIG_STD_SUFFIX = "_std"
RIG_COLUMNS = RIG_INPUTS + RIG_MEASURED + tuple(c + RIG_STD_SUFFIX for c in RIG_MEASURED)
#: Keys of a wheel_rig run's "wheel" object (m, m, m, count); the first two are required.
RIG_WHEEL_KEYS = ("radius", "width", "lug_height", "lug_count")

_ID_RE = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]*")


@dataclass(frozen=True)
class RigSetup:
    """The single-wheel testbed of a ``wheel_rig`` run (manifest keys ``wheel`` and
    ``carriage_speed``).

    Attributes:
        radius: wheel radius (m), to the rim (lugs not included).
        width: wheel width (m).
        lug_height: height of the lugs (grousers) beyond the rim (m); 0 for a smooth wheel.
        lug_count: number of lugs around the rim; 0 for a smooth wheel.
        carriage_speed: the carriage's forward speed (m/s), or None when not given.
    """

    radius: float
    width: float
    lug_height: float = 0.0
    lug_count: int = 0
    carriage_speed: Optional[float] = None

    @property
    def lugged(self) -> bool:
        return self.lug_height > 0.0


#: The IMU mounting of a run whose manifest entry names none (RunSpec.imu_mount): the campaign's.
DEFAULT_IMU_MOUNT = "campaign"


@dataclass(frozen=True)
class RunSpec:
    """One run of the manifest.

    Attributes:
        id: run id (letters, digits, ``_ . -``; unique in the campaign).
        kind: "drawbar", "terrain" or "wheel_rig".
        file: CSV path relative to the campaign folder, as written in the manifest.
        steady_window: (start, end) in s where the averaged identification looks, or None.
        terrain: LIDAR file relative to the campaign folder (terrain runs), else None.
        extra: any other keys of the run's manifest entry, kept as read.
        rig: the testbed's wheel and carriage (wheel_rig runs), else None.
        sensor_noise: the sensor noise stated in the manifest for this run's columns (column ->
            1 sigma in the column's units): the campaign's ``sensor_noise``, with the run's own
            ``sensor_noise`` in its place for the columns that states; {} when none is stated.
        imu_mount: the IMU mounting this run was measured with (the run's ``imu_mount``): runs
            that name the same one share one pitch offset in the diagnosis (an IMU taken off and
            mounted again between days has one offset per mounting); DEFAULT_IMU_MOUNT, the
            campaign's one mounting, where the manifest names none.
    """

    id: str
    kind: str
    file: str
    steady_window: Optional[tuple[float, float]] = None
    terrain: Optional[str] = None
    extra: dict[str, Any] = field(default_factory=dict)
    rig: Optional[RigSetup] = None
    sensor_noise: dict[str, float] = field(default_factory=dict)
    imu_mount: str = DEFAULT_IMU_MOUNT


@dataclass(frozen=True)
class Campaign:
    """A loaded, checked manifest.

    Attributes:
        root: the campaign folder.
        name: campaign name (the folder's name when the manifest has none).
        runs: the runs in manifest order.
        rover: FMU parameter overrides by FMU name (``{"wheel.width": 0.254}``); numbers stay
            int or float as written, strings stay strings.
        extra: other top-level manifest keys, kept as read.
        sensor_noise: the sensor noise the manifest states for every time-series run (column ->
            1 sigma in the column's units); a run's own statement is in its RunSpec.
        imu_mounting: how the IMU's mounting is known (the manifest's ``imu_mounting``): "free"
            (the default: its pitch offset is unknown, and the diagnosis takes it as a nuisance)
            or "calibrated" (the pitch is measured against a mounting calibrated on the rover:
            no offset is taken off).

    A loaded campaign is a snapshot of its folder: :func:`~juno.campaign.read_run` keeps every
    run it has read and checked here (keyed by the file and its size and modification time, so a
    file rewritten since is read again), and the phases of one analysis that each need a run
    read its file once.  The runs kept are not pickled: a campaign sent to a worker process
    carries its manifest only, and the worker reads what it needs.
    """

    root: Path
    name: str
    runs: tuple[RunSpec, ...]
    rover: dict[str, Union[float, int, str]] = field(default_factory=dict)
    extra: dict[str, Any] = field(default_factory=dict)
    sensor_noise: dict[str, float] = field(default_factory=dict)
    imu_mounting: str = "free"
    #: the runs read so far: (file, kind, run id) -> (file's size and modification time, RunData)
    _runs_read: dict[Any, Any] = field(default_factory=dict, init=False, repr=False, compare=False)

    def __getstate__(self) -> dict[str, Any]:
        state = dict(self.__dict__)
        state["_runs_read"] = {}
        return state

    @property
    def manifest_path(self) -> Path:
        return self.root / MANIFEST_NAME

    def run(self, run_id: str) -> RunSpec:
        """The run with this id (KeyError if none)."""
        for spec in self.runs:
            if spec.id == run_id:
                return spec
        raise KeyError(f"{self.manifest_path}: no run with id {run_id!r} (runs: {[r.id for r in self.runs]})")

    def runs_of_kind(self, kind: str) -> list[RunSpec]:
        """Runs of kind "drawbar", "terrain" or "wheel_rig", in manifest order."""
        return [r for r in self.runs if r.kind == kind]

    def run_path(self, run: Union[RunSpec, str]) -> Path:
        """Absolute path of a run's CSV."""
        spec = self.run(run) if isinstance(run, str) else run
        return self.root / spec.file

    def terrain_path(self, run: Union[RunSpec, str]) -> Optional[Path]:
        """Path of a run's LIDAR file, or None (drawbar runs)."""
        spec = self.run(run) if isinstance(run, str) else run
        return None if spec.terrain is None else self.root / spec.terrain


class _ColumnTable:
    """Access by column name to a table whose ``columns`` map names to float arrays (NaN = no
    value in that row): what a run's samples and a testbed's points share."""

    columns: dict[str, FloatArray]

    def __contains__(self, name: object) -> bool:
        return name in self.columns

    def __getitem__(self, name: str) -> FloatArray:
        return self.columns[name]

    def has(self, name: str) -> bool:
        """True when the column exists and has at least one value."""
        return name in self.columns and bool(np.any(~np.isnan(self.columns[name])))


@dataclass
class RunData(_ColumnTable):
    """The samples of one run CSV.

    Attributes:
        path: the CSV file.
        kind: "drawbar" or "terrain".
        columns: known column name -> float array (one entry per row, NaN = no sample),
            including ``time``; columns absent from the file are absent here.
        extra: unknown columns, kept as read (float arrays, or str arrays if not all numeric).
        lines: 1-based line number of each row in the file (for messages).
        run_id: the manifest id, when read through :func:`read_run`.
        stated_noise: the sensor noise the manifest states for the run's columns (column -> 1
            sigma, the column's units; RunSpec.sensor_noise), when read through :func:`read_run`;
            every other column's is estimated from its samples (juno.sensor_noise.sensor_noise).
    """

    path: Path
    kind: str
    columns: dict[str, FloatArray]
    extra: dict[str, np.ndarray] = field(default_factory=dict)
    lines: Optional[NDArray[np.int64]] = None
    run_id: Optional[str] = None
    stated_noise: dict[str, float] = field(default_factory=dict)

    @property
    def time(self) -> FloatArray:
        """Row times (s), strictly increasing, no NaN."""
        return self.columns["time"]

    def __len__(self) -> int:
        return int(self.time.shape[0])

    def samples(self, name: str) -> tuple[FloatArray, FloatArray]:
        """(times, values) of the column's own non-empty samples.

        Raises:
            InputError: the column is absent or has no samples.
        """
        if name not in self.columns:
            raise InputError(f"the run has no column {name!r}", self.path, None, name)
        v = self.columns[name]
        ok = ~np.isnan(v)
        if not ok.any():
            raise InputError(f"column {name!r} has no samples", self.path, None, name)
        return self.time[ok], v[ok]


@dataclass
class RigTable(_ColumnTable):
    """The points of one wheel_rig table (:func:`read_rig_csv`).

    Attributes:
        path: the CSV file.
        columns: known column name -> float array (one entry per row; NaN = not measured at
            that point). The inputs ``vertical_load`` and ``slip`` are always present and have
            a value in every row; ``slip_angle`` too when the file has it.
        extra: unknown columns, kept as read (float arrays, or str arrays if not all numeric).
        lines: 1-based line number of each row in the file (for messages).
        run_id: the manifest id, when read through :func:`read_run`.
    """

    path: Path
    columns: dict[str, FloatArray]
    extra: dict[str, np.ndarray] = field(default_factory=dict)
    lines: Optional[NDArray[np.int64]] = None
    run_id: Optional[str] = None
    kind: str = "wheel_rig"

    def __len__(self) -> int:
        return int(self.columns["slip"].shape[0])

    @property
    def slip_angle(self) -> FloatArray:
        """Slip angle of each point (rad); zeros when the file has no such column."""
        return self.columns.get("slip_angle", np.zeros(len(self)))

    def std(self, name: str) -> Optional[FloatArray]:
        """The per-point standard deviations of a measured column, or None when not given."""
        return self.columns.get(name + RIG_STD_SUFFIX)


class AlignedColumns(dict):
    """Result of :func:`aligned`: column name -> values on the requested times.

    ``coverage[name]`` is a bool array, True where the requested time lies between the column's
    first and last sample (outside, the end value is held, not extrapolated).
    """

    def __init__(self) -> None:
        super().__init__()
        self.coverage: dict[str, NDArray[np.bool_]] = {}
