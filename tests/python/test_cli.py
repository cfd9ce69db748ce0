"""The ``juno`` command as a user runs it (.venv/bin/juno, as the README describes it).

* ``juno --help`` lists simulate, identify, validate, synthesize, report (and diagnose when the
  harness has it); every subcommand has ``--help``.
* ``juno simulate`` runs each scenario, with a physically sensible end state; ``--json`` writes
  valid JSON and ``--out`` a CSV of the outputs.
* Errors (missing campaign, bad --param, bad options) exit with code 2 and a one-line message
  that names what is wrong, never a traceback.  The refusals run ``juno.cli.main`` in the test's
  process (run_juno_here: the console script's code without a Python start-up per case); help,
  the usage error and the runs go through .venv/bin/juno.
"""

from __future__ import annotations

import csv
import importlib.util
import json
import re

import numpy as np
import pytest

from harness_fixtures import run_juno, run_juno_here, say
from juno.scenarios import SCENARIOS
from juno.simulator import SOIL_PARAMETERS

pytest_plugins = ["harness_fixtures"]

REQUIRED_SUBCOMMANDS = ("simulate", "identify", "validate", "synthesize", "report")


def listed_subcommands(help_text: str) -> list[str]:
    """Subcommand names from the argparse ``{a,b,c}`` / indented list in ``juno --help``."""
    names = re.findall(r"^\s{4}(\w+)\s", help_text, flags=re.M)
    return [n for n in names if n not in ("COMMAND",)]


def one_line_error(proc, *needles: str) -> str:
    """Exit code 2, no traceback, exactly one line on stderr (``--quiet``) naming ``needles``."""
    assert "Traceback" not in proc.stderr, proc.stderr
    assert proc.returncode == 2, f"exit code {proc.returncode}, stderr:\n{proc.stderr}"
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, f"expected a one-line message, got:\n{proc.stderr}"
    for needle in needles:
        assert needle in lines[0], f"message does not name {needle!r}: {lines[0]}"
    return lines[0]


# ---------------------------------------------------------------------------- help

def test_help_lists_the_subcommands():
    proc = run_juno("--help")
    assert proc.returncode == 0, proc.stderr
    listed = listed_subcommands(proc.stdout)
    say(f"juno --help lists: {listed}")
    for name in REQUIRED_SUBCOMMANDS:
        assert name in listed, f"juno --help does not list {name}:\n{proc.stdout}"
    has_diagnose = importlib.util.find_spec("juno.diagnose") is not None
    if has_diagnose:
        assert "diagnose" in listed, "juno.diagnose exists but juno --help does not list diagnose"


def _subcommands() -> list[str]:
    from juno.cli import build_parser

    actions = [a for a in build_parser()._actions if a.__class__.__name__ == "_SubParsersAction"]
    return list(actions[0].choices) if actions else []


@pytest.mark.parametrize("name", _subcommands())
def test_every_subcommand_has_help(name):
    proc = run_juno(name, "--help")
    assert proc.returncode == 0, f"juno {name} --help: exit {proc.returncode}\n{proc.stderr[-600:]}"
    assert "Traceback" not in proc.stderr
    assert proc.stdout.startswith(f"usage: juno {name}"), proc.stdout[:200]
    assert "--json" in proc.stdout, f"juno {name} --help does not offer --json"


def test_subcommands_are_the_listed_ones():
    listed = listed_subcommands(run_juno("--help").stdout)
    assert sorted(listed) == sorted(_subcommands())
    assert set(REQUIRED_SUBCOMMANDS) <= set(listed)


def test_no_subcommand_is_a_usage_error():
    proc = run_juno()
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert "usage: juno" in proc.stderr


# ---------------------------------------------------------------------- simulate

@pytest.mark.parametrize("scenario", sorted(SCENARIOS))
def test_simulate_runs_each_scenario(tmp_path, scenario):
    out_json, out_csv = tmp_path / "result.json", tmp_path / "result.csv"
    proc = run_juno("simulate", "--scenario", scenario, "--json", out_json, "--out", out_csv, "--quiet")
    assert proc.returncode == 0, proc.stderr
    assert f"scenario {scenario}" in proc.stdout
    result = json.loads(out_json.read_text())
    final = result["final"]
    duration = SCENARIOS[scenario].stop_time
    assert final["time"] == pytest.approx(duration)
    with open(out_csv, newline="") as fh:
        rows = list(csv.reader(fh))
    header, body = rows[0], np.array(rows[1:], dtype=float)
    assert header[0] == "time" and {"x", "y", "vx", "omegaLeft", "torqueLeftApplied"} <= set(header)
    assert len(body) == round(duration / 0.05) + 1
    assert np.all(np.isfinite(body))
    assert body[-1, header.index("x")] == pytest.approx(final["x"], rel=1e-9, abs=1e-12)
    say(f"simulate {scenario}: x {final['x']:.3f} m, y {final['y']:.3f} m, yaw {final['yaw']:.3f} rad, "
        f"vx {final['vx']:.4f} m/s")
    if scenario == "rest":
        # a rover standing on flat ground does not creep
        assert abs(final["x"]) < 1e-3 and abs(final["y"]) < 1e-3 and abs(final["vx"]) < 1e-3
    elif scenario == "straight":
        assert final["x"] > 1.0 and abs(final["y"]) < 0.01 and abs(final["yaw"]) < 0.01
    elif scenario == "drawbar":
        assert final["vx"] > 0 and final["x"] > 0.5 and abs(final["y"]) < 0.01
    elif scenario == "turn":
        # right side faster: a left (positive yaw) turn
        assert final["yaw"] > 0.5 and final["omegaRight"] > final["omegaLeft"]


def test_simulate_param_changes_the_result(tmp_path):
    soft, stiff = tmp_path / "soft.json", tmp_path / "stiff.json"
    for path, kh in ((soft, 1.0e5), (stiff, 4.0e5)):
        proc = run_juno("simulate", "--scenario", "rest", "--stop-time", "2", "--param", f"soil.kh={kh}",
                        "--json", path, "--quiet")
        assert proc.returncode == 0, proc.stderr
    sink_soft = json.loads(soft.read_text())["final"]["wheelFL.sinkage"]
    sink_stiff = json.loads(stiff.read_text())["final"]["wheelFL.sinkage"]
    assert sink_soft > sink_stiff > 0, (sink_soft, sink_stiff)


def test_simulate_a_measured_run_and_validate_with_json(tmp_path, small_campaign):
    c = small_campaign(101)
    out_json = tmp_path / "sim.json"
    proc = run_juno("simulate", "--campaign", c.path, "--run", "dbp2", "--json", out_json, "--quiet")
    assert proc.returncode == 0, proc.stderr
    assert "run dbp2" in json.loads(out_json.read_text())["label"]

    params = tmp_path / "params.json"
    params.write_text(json.dumps({"params": c.truth["soil"]}))
    out_json = tmp_path / "validate.json"
    proc = run_juno("validate", c.path, "--params", params, "--json", out_json, "--quiet")
    assert proc.returncode == 0, proc.stderr
    result = json.loads(out_json.read_text())
    assert result["soil"] == pytest.approx(c.truth["soil"])
    assert set(result["rms"]) == {"t3d"}
    assert all(isinstance(v, float) and v >= 0 for v in result["rms"]["t3d"].values())


# ------------------------------------------------------------------------- errors

@pytest.mark.parametrize("args, needles", [
    (("identify", "{missing}"), ("{missing}",)),
    (("validate", "{missing}"), ("{missing}",)),
    (("report", "{missing}", "--out", "{tmp}/report"), ("{missing}",)),
    (("simulate", "--campaign", "{missing}"), ("{missing}",)),
    (("synthesize", "{tmp}/c", "--effect", "bogus_effect"), ("bogus_effect",)),
], ids=["identify", "validate", "report", "simulate", "synthesize-effect"])
def test_missing_campaign_and_bad_arguments_exit_2_with_one_line(tmp_path, args, needles, capsys):
    subst = {"missing": str(tmp_path / "no-such-campaign"), "tmp": str(tmp_path)}
    proc = run_juno_here(capsys, *[a.format(**subst) for a in args], "--quiet")
    one_line_error(proc, *[n.format(**subst) for n in needles])
    assert not (tmp_path / "report").exists() and not (tmp_path / "c").exists()


@pytest.mark.parametrize("param, needle", [
    ("soil.kh", "soil.kh"),                 # no '='
    ("no.such.parameter=1", "no.such.parameter"),
    ("soil.kh=-5", "soil.kh"),              # outside the FMU's range
    ("soil.gamma=1.5", "soil.gamma"),
    ("soil.kh=abc", "soil.kh"),             # not a number
], ids=["no-equals", "unknown-name", "out-of-range", "gamma-above-1", "not-a-number"])
def test_bad_param_exits_2_naming_it(param, needle, capsys):
    proc = run_juno_here(capsys, "simulate", "--scenario", "rest", "--stop-time", "1", "--param", param, "--quiet")
    one_line_error(proc, needle)


@pytest.mark.parametrize("command", ["identify", "validate", "diagnose"])
@pytest.mark.parametrize("override, needles", [
    ({"wheel.widht": 0.254}, ("campaign.json", "wheel.widht", "did you mean wheel.width")),
    ({"wheel.width": 254}, ("campaign.json", "wheel.width=254", "out of the FMU's range")),
], ids=["misspelt", "in-mm"])
def test_a_bad_rover_override_in_the_manifest_exits_2_naming_its_line(tmp_path, small_campaign, command, override,
                                                                      needles, capsys):
    """The campaign's ``rover`` overrides are checked against the FMU before any simulation:
    the file, the line and the rule, not a worker's KeyError half-way through."""
    import shutil

    root = tmp_path / "campaign"
    shutil.copytree(small_campaign(101).path, root)
    manifest = root / "campaign.json"
    doc = json.loads(manifest.read_text())
    doc["rover"] = {**doc.get("rover", {}), **override}
    manifest.write_text(json.dumps(doc, indent=1))
    line = next(i for i, text in enumerate(manifest.read_text().splitlines(), start=1) if next(iter(override)) in text)
    proc = run_juno_here(capsys, command, root, "--quiet")
    one_line_error(proc, *needles, f"line {line}")


def test_missing_params_file_exits_2_naming_it(tmp_path, small_campaign, capsys):
    c = small_campaign(101)
    missing = tmp_path / "no-such-params.json"
    one_line_error(run_juno_here(capsys, "validate", c.path, "--params", missing, "--quiet"), str(missing))


def test_unknown_run_exits_2_naming_it(small_campaign, capsys):
    c = small_campaign(101)
    proc = run_juno_here(capsys, "simulate", "--campaign", c.path, "--run", "no_such_run", "--quiet")
    one_line_error(proc, "no_such_run")


def test_zero_output_interval_exits_2_with_one_line(capsys):
    proc = run_juno_here(capsys, "simulate", "--scenario", "rest", "--output-interval", "0", "--quiet")
    one_line_error(proc, "output")


def test_zero_stop_time_is_refused(capsys):
    proc = run_juno_here(capsys, "simulate", "--scenario", "drawbar", "--stop-time", "0", "--quiet")
    one_line_error(proc, "stop")


def test_negative_stop_time_is_refused(capsys):
    proc = run_juno_here(capsys, "simulate", "--scenario", "rest", "--stop-time", "-1", "--quiet")
    one_line_error(proc, "stop")


def test_validate_params_without_soil_exits_2_naming_the_parameter(tmp_path, small_campaign, capsys):
    c = small_campaign(101)
    params = tmp_path / "params.json"
    params.write_text(json.dumps({"params": {k: 1.0 for k in SOIL_PARAMETERS if k != "soil.Kvx"}}))
    one_line_error(run_juno_here(capsys, "validate", c.path, "--params", params, "--quiet"), "soil.Kvx")


# ------------------------------------------------------------- what a paper-style fit prints

def _paper_fit(rank: int, converged: bool, status: str = "ok"):
    from juno.identify import PaperResult, SteadyAverages
    soil = dict.fromkeys(SOIL_PARAMETERS, 1.0)
    avg = SteadyAverages("dbp1", (3.0, 6.5), 700.0, 170.0, 170.0, 0.07, 0.65, 0.65, 0.2794)
    return PaperResult("dbp1", soil, soil, 0.3, 600, converged, avg, rank, status=status)


def test_a_paper_fit_that_pins_every_parameter_and_converged_needs_no_caveat():
    from juno.commands.identify import paper_fit_caveats
    assert paper_fit_caveats(_paper_fit(rank=4, converged=True)) == []


def test_a_paper_fit_says_when_it_did_not_converge_and_which_directions_the_data_leave_open():
    from juno.commands.identify import paper_fit_caveats
    caveats = paper_fit_caveats(_paper_fit(rank=2, converged=False))
    assert len(caveats) == 2
    assert caveats[0].startswith("not converged within 600 evaluations")
    assert "rank 2/4" in caveats[1] and "only 2 combinations of the 4 parameters" in caveats[1]


def test_a_paper_fit_that_did_not_move_is_said_to_be_no_estimate():
    from juno.commands.identify import paper_fit_caveats
    caveats = paper_fit_caveats(_paper_fit(rank=0, converged=False, status="not identified"))
    assert caveats == ["not identified: the fit did not move from its start or the averages see no parameter; "
                       "these values are not an estimate"]


def test_juno_identify_paper_prints_the_caveats_of_the_fits_it_reports(tmp_path, small_campaign):
    """On a short synthetic campaign: every fit the JSON calls unconverged or rank-deficient gets its
    caveat printed under its values."""
    c = small_campaign(11)
    out = tmp_path / "identify.json"
    proc = run_juno("identify", str(c.path), "--method", "paper", "--json", str(out))
    assert proc.returncode == 0, proc.stderr
    for fit in json.loads(out.read_text())["paper"]:
        lines = [ln for ln in proc.stdout.splitlines() if ln.startswith(fit["run_id"] + ": ")]
        assert (not fit["converged"]) == any("not converged" in ln or "not an estimate" in ln for ln in lines), lines
        assert (fit["jacobian_rank"] < 4) == any(f"rank {fit['jacobian_rank']}/4:" in ln for ln in lines), lines
