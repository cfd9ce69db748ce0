"""Validation on the 3-D terrain (juno.validate) and the report (juno.report.write_report).

* A measured column is compared only between its first and last sample: a sensor that stops
  before the run ends leaves the rest of the run uncompared, not compared with its last value.
* On a synthetic campaign, the true soil validates with much smaller RMS errors of position and
  drive torque than the paper's initial guess.
* The gridded LIDAR scan reproduces the true surface (juno.synthesize.mound_surface) within
  about 1 cm RMS inside the scanned area.
* The report shows the spread between the paper-style runs (a table listing every run and
  every parameter), the joint fit and the validation, and links only figures it wrote.
"""

from __future__ import annotations

import json
import math
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from harness_fixtures import say
from juno.campaign import format_run_csv, load_campaign, read_run_csv
from juno.pointcloud import read_esri_ascii
from juno.simulator import SOIL_PARAMETERS
from juno.synthesize import TERRAIN_X, TERRAIN_Y, mound_surface
from juno.validate import COMPARED, GRID_CELL, SETTLING, validate_run

pytest_plugins = ["harness_fixtures"]

#: "much smaller": the true soil's RMS error is below this fraction of the initial guess's.
POSITION_RATIO = 1 / 3
TORQUE_RATIO = 1 / 2
SURFACE_RMS = 0.01   # m
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def planar_rms(v) -> float:
    return math.hypot(v.rms["pos_x"], v.rms["pos_y"])


def torque_rms(v) -> float:
    return math.sqrt(0.5 * (v.rms["torque_left"] ** 2 + v.rms["torque_right"] ** 2))


# ------------------------------------------------------------------------- validation

def test_validation_compares_every_signal_over_the_run(terrain_campaign, terrain_validation):
    for v in (terrain_validation.truth, terrain_validation.initial):
        assert set(v.rms) == set(COMPARED)
        assert all(math.isfinite(x) and x >= 0 for x in v.rms.values()), v.rms
        assert v.grid_cell == GRID_CELL
        assert v.time[0] == pytest.approx(0.0)
        assert v.time[-1] == pytest.approx(30.0 * terrain_campaign.time_scale, abs=0.11)
        for name in COMPARED:
            assert v.measured[name].shape == v.time.shape == v.simulated[name].shape
            assert np.all(np.isfinite(v.simulated[name])), f"simulated {name} is not finite"


def test_a_sensor_that_stops_early_is_compared_only_up_to_its_last_sample(small_campaign, harness_fmu, tmp_path):
    source = small_campaign(502)
    root = tmp_path / "campaign"
    shutil.copytree(source.path, root)
    path = root / "runs" / "t3d.csv"
    run = read_run_csv(path, "terrain")
    columns = dict(run.columns)
    stop = float(run.time[0] + 0.5 * (run.time[-1] - run.time[0]))
    columns["torque_left"] = np.where(run.time > stop, np.nan, columns["torque_left"])
    path.write_text(format_run_csv(columns))

    whole = validate_run(harness_fmu, source.campaign, "t3d", source.soil, tmp_path / "whole")
    cut = validate_run(harness_fmu, load_campaign(root), "t3d", source.soil, tmp_path / "cut")

    last = float(run.time[run.time <= stop][-1] - run.time[0])
    after = cut.time > last
    assert after.any() and np.all(np.isnan(cut.measured["torque_left"][after]))
    kept = (whole.time >= SETTLING) & (whole.time <= last)
    expected = math.sqrt(float(np.mean((whole.measured["torque_left"][kept] - whole.simulated["torque_left"][kept]) ** 2)))
    assert cut.rms["torque_left"] == pytest.approx(expected, rel=1e-9)
    assert cut.rms["torque_right"] == pytest.approx(whole.rms["torque_right"], rel=1e-9)


def test_true_soil_validates_much_better_than_the_initial_guess(terrain_validation):
    t, i = terrain_validation.truth, terrain_validation.initial
    pos = (planar_rms(t), planar_rms(i))
    torque = (torque_rms(t), torque_rms(i))
    say(f"terrain validation RMS, true soil vs paper initial guess: position {pos[0]:.4f} vs {pos[1]:.4f} m "
        f"(ratio {pos[0] / pos[1]:.3f}); torque {torque[0]:.2f} vs {torque[1]:.2f} N m "
        f"(ratio {torque[0] / torque[1]:.3f}); speed {t.rms['speed']:.4f} vs {i.rms['speed']:.4f} m/s")
    assert pos[0] < POSITION_RATIO * pos[1], f"position RMS: truth {pos[0]:.4f} m, initial guess {pos[1]:.4f} m"
    assert torque[0] < TORQUE_RATIO * torque[1], f"torque RMS: truth {torque[0]:.2f}, initial guess {torque[1]:.2f}"


def test_each_measured_columns_noise_is_estimated_from_the_data(terrain_validation):
    """The RMS errors come with the sensor noise of each measured column, estimated from the
    column itself: on a synthetic campaign it is the noise the sensors were given (within 30 %),
    so an RMS error can be read in units of it."""
    from juno.synthetic_design import PAPER_SENSORS

    v = terrain_validation.truth
    for sensor in PAPER_SENSORS:
        if sensor.column not in COMPARED:
            continue
        typical = float(np.nanmedian(np.abs(v.measured[sensor.column])))   # NaN beyond its samples
        sigma = sensor.sigma + sensor.relative * typical
        assert 0.7 * sigma <= v.noise[sensor.column] <= 1.3 * sigma, (sensor.column, v.noise[sensor.column], sigma)
        assert v.noise_ratio(sensor.column) == pytest.approx(v.rms[sensor.column] / v.noise[sensor.column])
    assert math.isnan(v.noise["speed"]) and math.isnan(v.noise_ratio("speed"))   # derived, not measured


def test_gridded_terrain_reproduces_the_true_surface(terrain_campaign, terrain_validation):
    grid = read_esri_ascii(terrain_validation.grid_file)   # the file the FMU reads
    assert grid.cell == pytest.approx(GRID_CELL)
    assert np.allclose(grid.z, terrain_validation.grid.z, atol=1e-9)
    xmin, xmax, ymin, ymax = grid.extent
    assert xmin <= TERRAIN_X[0] and xmax >= TERRAIN_X[1] and ymin <= TERRAIN_Y[0] and ymax >= TERRAIN_Y[1]
    # every grid node inside the scanned area, and a denser set of points between them
    inside_x = (grid.x >= TERRAIN_X[0]) & (grid.x <= TERRAIN_X[1])
    inside_y = (grid.y >= TERRAIN_Y[0]) & (grid.y <= TERRAIN_Y[1])
    X, Y = np.meshgrid(grid.x[inside_x], grid.y[inside_y])
    node_err = grid.z[np.ix_(inside_y, inside_x)] - mound_surface(X, Y, terrain_campaign.seed)
    rng = np.random.default_rng(5)
    px, py = rng.uniform(*TERRAIN_X, 20000), rng.uniform(*TERRAIN_Y, 20000)
    point_err = grid.height(px, py) - mound_surface(px, py, terrain_campaign.seed)
    rms_nodes = float(np.sqrt(np.mean(node_err ** 2)))
    rms_points = float(np.sqrt(np.mean(point_err ** 2)))
    say(f"gridded scan vs true surface inside the scanned area: RMS {rms_nodes * 1000:.2f} mm at "
        f"{node_err.size} nodes, {rms_points * 1000:.2f} mm at random points, max |error| "
        f"{np.abs(point_err).max() * 1000:.1f} mm (gridding took {terrain_validation.seconds['gridding']:.1f} s)")
    assert rms_nodes < SURFACE_RMS and rms_points < SURFACE_RMS
    assert abs(float(np.mean(point_err))) < 0.003, "the grid is biased in height"


# ------------------------------------------------------------------------------ report

def markdown_table_after(text: str, heading: str) -> list[list[str]]:
    """The rows (cells stripped) of the first Markdown table after ``heading``."""
    start = text.index(heading)
    rows = []
    for line in text[start:].splitlines()[1:]:
        if line.startswith("|"):
            rows.append([c.strip() for c in line.strip().strip("|").split("|")])
        elif rows:
            break
    return rows


def test_report_shows_the_spread_between_runs(noisy_report, noisy_paper):
    text = (noisy_report / "report.md").read_text()
    assert "### Spread between runs" in text
    rows = markdown_table_after(text, "### Spread between runs")
    header, separator, body = rows[0], rows[1], rows[2:]
    run_ids = [p.result.run_id for p in noisy_paper]
    assert all(set(c) <= set("-: ") for c in separator)
    for run_id in run_ids:
        assert run_id in header, f"run {run_id} missing from the spread table header {header}"
    assert [r[0] for r in body] == list(SOIL_PARAMETERS), body
    for row in body:
        k = row[0]
        for run_id, p in zip(run_ids, noisy_paper):
            shown = float(row[header.index(run_id)])
            assert shown == pytest.approx(p.result.final[k], rel=1e-3), f"{k} of {run_id}: {shown}"
        vals = [p.result.final[k] for p in noisy_paper]
        spread = float(row[-1].rstrip("%")) / 100
        assert spread == pytest.approx(max(vals) / min(vals) - 1, rel=1e-3, abs=1e-3)
    say("report spread table:\n" + "\n".join(" | ".join(r) for r in rows))


def test_report_has_the_joint_fit_and_validation_tables(noisy_report, noisy_joint, noisy_paper):
    text = (noisy_report / "report.md").read_text()
    joint = markdown_table_after(text, "## 2. Joint identification")
    assert [r[0] for r in joint[2:]] == list(SOIL_PARAMETERS)
    for row in joint[2:]:
        assert float(row[1]) == pytest.approx(noisy_joint.params[row[0]], rel=1e-3)
    validation = markdown_table_after(text, "## 4. Validation on the 3-D terrain")
    best = min(noisy_paper, key=lambda p: p.result.cost).result.run_id
    assert [(r[0], r[1]) for r in validation[2:]] == [("t3d", "joint fit"), ("t3d", f"paper-style {best}")]
    assert all(len(r) == len(validation[0]) for r in validation)
    truth = markdown_table_after(text, "## Synthetic truth")
    assert [r[0] for r in truth[2:]] == list(SOIL_PARAMETERS)
    # the IMU's mounting offset the joint fit took as a free parameter, in degrees
    offset = noisy_joint.pitch_offset["campaign"]
    assert noisy_joint.pitch_offset_free
    assert (f"The measured pitch reads {np.degrees(offset):+.2f} deg ({offset * 1e3:+.2f} mrad) from the fitted "
            "model's: the IMU's mounting, a free parameter of the fit") in text


def test_identify_prints_the_mounting_offset_and_what_the_fit_made_of_it():
    """A free offset is the mounting's, a parameter of the fit; with a calibrated mounting it is
    what the fitted model's pitch residuals hold; several mountings are named; no pitch, no line."""
    from dataclasses import replace

    from juno.commands.identify import pitch_offset_lines
    from juno.identify import JointResult
    fit = JointResult(dict.fromkeys(SOIL_PARAMETERS, 1.0), {}, {}, np.eye(4), {}, 1.0, 1, 0.0,
                      pitch_offset={"campaign": float(np.radians(-0.5))})
    assert pitch_offset_lines(fit) == [
        "joint: the pitch reads -0.50 deg (-8.73 mrad) from the fitted model's: the IMU's mounting, a free parameter "
        'of the fit (imu_mounting "free"; "calibrated" holds it at none)']
    calibrated = replace(fit, pitch_offset_free=False, pitch_offset={"day1": 0.01, "day2": -0.01})
    assert pitch_offset_lines(calibrated) == [
        "joint: the pitch reads +0.57 deg (+10.00 mrad) on the mounting day1, -0.57 deg (-10.00 mrad) on the mounting "
        "day2 from the fitted model's; the manifest says the IMU's mounting is calibrated, so the fit took no offset"]
    assert pitch_offset_lines(replace(fit, pitch_offset={})) == []


def test_report_links_only_figures_it_wrote(noisy_report):
    text = (noisy_report / "report.md").read_text()
    links = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", text)
    expected = {"run_dbp1.png", "run_dbp2.png", "run_dbp3.png", "fig10_traction_ratio.png",
                "validation_t3d.png", "path_t3d.png"}
    assert expected <= set(links), f"links {links}"
    for link in links:
        assert not Path(link).is_absolute() and ".." not in Path(link).parts, link
        png = noisy_report / link
        assert png.is_file(), f"{link} is linked but missing"
        assert png.read_bytes()[:8] == PNG_MAGIC, f"{link} is not a PNG"
    summary = json.loads((noisy_report / "summary.json").read_text())
    assert [p["run"] for p in summary["paper"]] == ["dbp1", "dbp2", "dbp3"]
    assert set(summary["joint"]["params"]) == set(SOIL_PARAMETERS)
