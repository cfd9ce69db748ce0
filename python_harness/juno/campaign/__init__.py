"""Measured campaigns: read, check, align, derive, write.

A campaign is a folder::

    campaign.json          manifest
    runs/NAME.csv          one file per experiment run
    terrain/NAME.xyz       LIDAR points (m): "x y z" text, .pts, PLY or LAS (juno.scan_formats)
    runs/RIG.csv           a single-wheel testbed table (kind ``wheel_rig``)

Reading is strict: anything that breaks the format is refused with an
:class:`~juno.errors.InputError` naming the file, the line (1-based, the CSV header is line 1)
and the column or key. Input files are only ever read, never written.

Run CSV columns (SI units): ``time`` (s, strictly increasing, never empty), ``torque_left``,
``torque_right`` (N m per side), ``omega_left``, ``omega_right`` (rad/s), ``pos_x``, ``pos_y``,
``pos_z`` (m, total station), ``drawbar_force`` (N, drawbar runs), optional IMU ``roll``,
``pitch``, ``yaw`` (rad), ``acc_*``, ``gyro_*``. An empty cell means "no sample at this time"
(sensors run at different rates) and becomes NaN. Every cell of a known column is empty or a
finite decimal number. Unknown columns are kept in :attr:`RunData.extra` and otherwise ignored:
as float arrays when every cell is empty or a finite number, else as the raw text.

A ``wheel_rig`` run is a single-wheel testbed's table, one row per steady point, not a time
series (:func:`read_rig_csv`): ``vertical_load`` (N), ``slip`` (-), ``drawbar_pull`` (N), optional
``torque`` (N m), ``sinkage`` (m), ``slip_angle`` (rad), ``lateral_force`` (N) and a standard
deviation ``<column>_std`` of each measured column; the wheel is described in the manifest
(:class:`RigSetup`).

Where each part lives: ``records`` (the format's names and the records of a read campaign),
``manifest`` (``campaign.json``), ``tables`` (the run CSVs and LIDAR points), ``signals``
(resampling and quantities derived from the samples), ``optional`` (what the optional columns
buy, and which a campaign lacks), ``writing`` (a campaign written atomically).  Everything
public is imported from ``juno.campaign``.
"""

from __future__ import annotations

from .manifest import load_campaign
from .optional import OPTIONAL_COLUMN_USES, MissingColumn, missing_columns
from .records import (ANGLE_COLUMNS, BASE_REQUIRED, COLUMN_UNITS, DEFAULT_IMU_MOUNT, KINDS, KNOWN_COLUMNS,
                      MANIFEST_NAME, NOISE_COLUMNS, OPTIONAL_COLUMNS,
                      REQUIRED_COLUMNS, RIG_COLUMNS, RIG_INPUTS, RIG_MEASURED, RIG_REQUIRED, RIG_STD_SUFFIX,
                      RIG_WHEEL_KEYS, TIME_SERIES_KINDS, AlignedColumns, Campaign, RigSetup, RigTable, RunData,
                      RunSpec)
from .signals import aligned, forward_speed, steady_average, travel_direction
from .tables import read_any, read_rig, read_rig_csv, read_run, read_run_csv, read_terrain_points
from .writing import format_rig_csv, format_run_csv, write_campaign

__all__ = [
    "KINDS", "TIME_SERIES_KINDS", "REQUIRED_COLUMNS", "BASE_REQUIRED", "OPTIONAL_COLUMNS", "KNOWN_COLUMNS",
    "ANGLE_COLUMNS", "COLUMN_UNITS", "NOISE_COLUMNS", "MANIFEST_NAME", "RIG_INPUTS", "RIG_REQUIRED", "RIG_MEASURED", "RIG_STD_SUFFIX",
    "DEFAULT_IMU_MOUNT",
    "RIG_COLUMNS", "RIG_WHEEL_KEYS",
    "Campaign", "RunSpec", "RigSetup", "RunData", "RigTable", "AlignedColumns",
    "load_campaign", "read_run", "read_run_csv", "read_rig", "read_rig_csv", "read_any", "read_terrain_points",
    "OPTIONAL_COLUMN_USES", "MissingColumn", "missing_columns",
    "aligned", "steady_average", "forward_speed", "travel_direction",
    "format_run_csv", "format_rig_csv", "write_campaign",
]
