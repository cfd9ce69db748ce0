"""Hostile arguments are refused before any computation, with one line naming what is wrong.

Specification:

* every numeric option is range-checked by argparse: a count is a positive integer, a seed an
  integer >= 0, a duration or resolution a positive finite number, a noise scale >= 0, a
  strength from 0 to 1 (``--max-evaluations -5``, ``--noise -1``, ``--stop-time inf`` ...);
* ``--param NAME=VALUE`` (and sweep's ``--vary``) is checked against the FMU's variable table:
  an unknown name is refused naming close matches, an Integer refuses 1.5, a Real refuses NaN
  and values outside the variable's [min, max], an output is not a parameter;
* ``--params FILE`` that is not an identify result names the file and what is missing;
* every refusal: exit code 2, one line ``juno CMD: error: ...``, no traceback, no object repr
  or ``np.float64(...)``, and every input file unchanged.
"""

from __future__ import annotations

import json
import shutil

import pytest

from harness_fixtures import run_juno
from hostile_cases import refused
from juno.cli import main
from juno.parallel import TaskError, map_tasks

pytest_plugins = ["harness_fixtures"]

CAMPAIGN_SEED = 301


@pytest.fixture
def work(tmp_path, small_campaign):
    """tmp_path holding C (a short campaign) and the --params files of the cases."""
    shutil.copytree(small_campaign(CAMPAIGN_SEED).path, tmp_path / "C")
    files = {
        "not_json.json": '{"params": {"soil.kh": 1,\n  oops}\n',
        "a_list.json": "[1, 2, 3]\n",
        "three_of_four.json": json.dumps({"joint": {"params": {"soil.kh": 1.6e5, "soil.eta": 0.5,
                                                               "soil.gamma": 0.08}}}),
        "text_value.json": json.dumps({"params": {"soil.kh": "high", "soil.eta": 0.5, "soil.gamma": 0.08,
                                                  "soil.Kvx": 0.8}}),
    }
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    return tmp_path


# Each case: the arguments ({w}: the work folder) and what the message must name.
CASES = {
    "identify --max-evaluations -5": (["identify", "{w}/C", "--max-evaluations", "-5"],
                                      ["--max-evaluations", "-5", "positive integer"]),
    "identify --max-evaluations 2.5": (["identify", "{w}/C", "--max-evaluations", "2.5"], ["--max-evaluations"]),
    "identify --starts 0": (["identify", "{w}/C", "--starts", "0"], ["--starts", "0"]),
    "identify --workers 0": (["identify", "{w}/C", "--workers", "0"], ["--workers"]),
    "identify --seed -1": (["identify", "{w}/C", "--seed", "-1"], ["--seed", "-1"]),
    "synthesize --noise -1": (["synthesize", "{w}/new", "--noise", "-1"], ["--noise", "-1"]),
    "synthesize --noise nan": (["synthesize", "{w}/new", "--noise", "nan"], ["--noise", "nan"]),
    "synthesize --strength 1.5": (["synthesize", "{w}/new", "--strength", "1.5"], ["--strength", "0 to 1"]),
    "synthesize --time-scale 0": (["synthesize", "{w}/new", "--time-scale", "0"], ["--time-scale"]),
    "simulate --stop-time inf": (["simulate", "--stop-time", "inf"], ["--stop-time", "inf"]),
    "simulate --output-interval -0.1": (["simulate", "--output-interval", "-0.1"], ["--output-interval"]),
    "simulate --param drive.mode=1.5": (["simulate", "--param", "drive.mode=1.5"], ["drive.mode", "Integer"]),
    "simulate --param drive.mode=7": (["simulate", "--param", "drive.mode=7"], ["drive.mode", "[0, 2]"]),
    "simulate --param soil.kh=1e9": (["simulate", "--param", "soil.kh=1e9"], ["soil.kh", "range"]),
    "simulate --param wheel.radius=279.4 (mm)": (["simulate", "--param", "wheel.radius=279.4"],
                                                 ["wheel.radius=279.4:", "[0.01, 5] m", "millimetres (0.2794 m)",
                                                  "Give it in m"]),
    "simulate --param rover.mass=317700 (g)": (["simulate", "--param", "rover.mass=317700"],
                                               ["[60, 2000] kg", "grams (317.7 kg)"]),
    "simulate --param soil.phi=30 (deg)": (["simulate", "--param", "soil.phi=30"], ["rad", "degrees (0.5236 rad)"]),
    "simulate --param soil.kh=nan": (["simulate", "--param", "soil.kh=nan"], ["soil.kh", "finite"]),
    "simulate --param soil.gama=0.1": (["simulate", "--param", "soil.gama=0.1"], ["soil.gama", "soil.gamma"]),
    "simulate --param vx=1 (an output)": (["simulate", "--param", "vx=1"], ["vx", "not a parameter"]),
    "simulate --param =1": (["simulate", "--param", "=1"], ["--param"]),
    "sweep --vary drive.mode=0,1.5": (["sweep", "--vary", "drive.mode=0,1.5"], ["--vary", "drive.mode"]),
    "sweep --vary soil.eta=0.5:3:2": (["sweep", "--vary", "soil.eta=0.5:3:2"], ["soil.eta", "range"]),
    "sweep --window -1": (["sweep", "--vary", "soil.kh=1e5", "--window", "-1"], ["--window"]),
    "validate --cell 0": (["validate", "{w}/C", "--cell", "0"], ["--cell"]),
    "validate --params not_json": (["validate", "{w}/C", "--params", "{w}/not_json.json"],
                                   ["{w}/not_json.json", "line 2"]),
    "validate --params a_list": (["validate", "{w}/C", "--params", "{w}/a_list.json"],
                                 ["{w}/a_list.json", "identify result"]),
    "validate --params three_of_four": (["validate", "{w}/C", "--params", "{w}/three_of_four.json"],
                                        ["{w}/three_of_four.json", "soil.Kvx"]),
    "validate --params text_value": (["validate", "{w}/C", "--params", "{w}/text_value.json"],
                                     ["{w}/text_value.json", "soil.kh", "high"]),
    "validate --params the manifest": (["validate", "{w}/C", "--params", "{w}/C/campaign.json"],
                                       ["{w}/C/campaign.json", "identify result", "soil.kh"]),
    "diagnose --terrain-segments 0": (["diagnose", "{w}/C", "--terrain-segments", "0"], ["--terrain-segments"]),
    "diagnose --workers -2": (["diagnose", "{w}/C", "--workers", "-2"], ["--workers"]),
    "bench --repeats 2": (["bench", "--repeats", "2"], ["--repeats", ">= 5"]),
    "bench --long-repeats 0": (["bench", "--long-repeats", "0"], ["--long-repeats"]),
}


@pytest.mark.parametrize("case", list(CASES))
def test_a_hostile_argument_is_refused_with_one_clean_line(case, work, capsys):
    args, needles = CASES[case]
    refused(capsys, work, args, needles)


def test_the_juno_command_refuses_a_negative_count_in_one_line():
    """The console script as a user runs it (argparse's usage is in --help, not in the error)."""
    proc = run_juno("identify", "no-such-campaign", "--max-evaluations", "-5", timeout=60)
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert proc.returncode == 2 and len(lines) == 1, proc.stderr
    assert "--max-evaluations" in lines[0] and "-5" in lines[0]


class Opaque:
    """An item whose repr would be an object address."""


def _fail(item):
    raise ValueError(f"cannot handle {type(item[0]).__name__}")


def test_a_failed_task_is_named_without_an_object_repr():
    with pytest.raises(TaskError) as info:
        map_tasks(_fail, [(Opaque(), 1.5)], workers=1)
    text = str(info.value)
    assert "task 0" in text and "cannot handle Opaque" in text
    assert "object at 0x" not in text and "Opaque object" not in text


def test_a_missing_fmu_says_how_to_build_it_and_how_to_point_at_it(tmp_path, capsys):
    """Outside the checkout (or before the build) the FMU is not found: the message says how to
    build it and the two ways to give its path."""
    missing = tmp_path / "JunoRover.fmu"
    assert main(["simulate", "--fmu", str(missing), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert str(missing) in err and "cmake --build" in err and "--fmu" in err and "JUNO_FMU" in err
    assert len(err.strip().splitlines()) == 1
