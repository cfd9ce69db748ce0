"""The rover's and the soil's constants come from one place: the FMU (juno.rover_model).

The harness reads the wheel radius, the rover's mass and geometry and the soil's strength from
the start values in the FMU's modelDescription.xml, lets a campaign's ``rover`` block override
them, and draws Eqn 5 of Petersen & McPhee (2013) with one function.  These tests pin the values
read to the XML (read here independently of fmpy) and to the paper's rover, check that a
campaign's value wins, that the package imports without an FMU, and that no module of the
harness types the rover's numbers again.
"""

from __future__ import annotations

import math
import os
import re
import subprocess
import sys
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import numpy as np
import pytest

from juno import rover_model
from juno.rover_model import SOIL_PARAMETERS, fmu_defaults, rover, traction_ratio

pytest_plugins = ["harness_fixtures"]

HARNESS = Path(__file__).resolve().parents[2] / "python_harness" / "juno"


def _xml_start_values(fmu_path: str) -> dict[str, str]:
    """Start values (as written) of the FMU's variables, read from its modelDescription.xml."""
    with zipfile.ZipFile(fmu_path) as z:
        root = ET.fromstring(z.read("modelDescription.xml"))
    out = {}
    for var in root.iter("ScalarVariable"):
        for child in var:
            if "start" in child.attrib:
                out[var.attrib["name"]] = child.attrib["start"]
    return out


def test_the_constants_are_the_start_values_of_the_fmus_model_description(fmu_path):
    """Every constant equals its parameter's start value in modelDescription.xml, bit for bit."""
    xml = _xml_start_values(fmu_path)
    r = rover(fmu_path=fmu_path)
    for field, name in rover_model._FMU_NAMES.items():
        assert getattr(r, field) == float(xml[name]), (field, name)
    assert r.weight == float(xml["rover.mass"]) * float(xml["env.gravity"])


def test_the_fmus_rover_is_the_papers_juno(fmu_path):
    """The paper's Juno rover: a 22 in wheel (0.2794 m radius), 317.7 kg,
    g = 9.81, the dry-sand strength assumed for Eqn 5 (C = 1000 Pa, phi = 0.5236 rad, 30 deg)."""
    r = rover(fmu_path=fmu_path)
    assert r.wheel_radius == 0.2794 == 11 * 0.0254
    assert (r.mass, r.gravity, r.cohesion, r.friction_angle) == (317.7, 9.81, 1000.0, 0.5236)
    assert (r.wheelbase, r.track, r.pivot_height) == (0.82, 1.35, 0.15)


def test_the_soil_parameters_are_fmu_parameters_whose_defaults_are_the_papers_table_2(fmu_path):
    """The four fitted names are FMU parameters, and their defaults are Table 2's soil."""
    from juno.synthesize import TABLE2
    defaults = fmu_defaults(fmu_path)
    assert SOIL_PARAMETERS == ("soil.kh", "soil.eta", "soil.gamma", "soil.Kvx")
    assert {k: defaults[k] for k in SOIL_PARAMETERS} == TABLE2


def test_every_module_uses_the_one_tuple_of_soil_parameter_names():
    """The names the harness fits are one object, not copies typed again: every module of the
    harness that has a SOIL_PARAMETERS has that one, and the modules that fit the soil have it."""
    import importlib
    import pkgutil

    import juno
    modules = [importlib.import_module(m.name) for m in pkgutil.walk_packages(juno.__path__, "juno.")
               if not m.name.startswith("juno.commands")]
    having = {m.__name__: m.SOIL_PARAMETERS for m in modules if hasattr(m, "SOIL_PARAMETERS")}
    assert {"juno.simulator", "juno.identify.base", "juno.identify.joint", "juno.report",
            "juno.diagnose"} <= set(having), sorted(having)
    assert [name for name, names in having.items() if names is not SOIL_PARAMETERS] == []


def test_a_campaigns_rover_block_overrides_the_fmus_values(fmu_path):
    """The campaign's value wins where it gives one; the rest stay the FMU's."""
    base = rover(fmu_path=fmu_path)
    r = rover({"wheel.radius": 0.3, "rover.mass": 250, "terrain.file": "ground.asc"}, fmu_path=fmu_path)
    assert (r.wheel_radius, r.mass) == (0.3, 250.0)
    assert (r.track, r.cohesion) == (base.track, base.cohesion)


def test_a_traverse_without_pivot_height_or_wheel_radius_takes_the_fmus():
    from juno.registration import Traverse
    one = np.zeros(1)
    tr = Traverse(one, one, one, one, None, 0.82, 1.35)
    assert (tr.pivot_height, tr.wheel_radius) == (rover().pivot_height, rover().wheel_radius)
    assert Traverse(one, one, one, one, None, 0.82, 1.35, pivot_height=0.2, wheel_radius=0.3).wheel_radius == 0.3


def test_steady_averages_carry_the_campaigns_wheel_radius(small_campaign):
    """The paper-style fit scales speed by the rover's wheel radius: the campaign's, if it gives one."""
    from juno.campaign import load_campaign
    from juno.identify import steady_averages
    campaign = load_campaign(small_campaign(7).path)
    run = campaign.runs_of_kind("drawbar")[0]
    assert steady_averages(campaign, run).wheel_radius == rover().wheel_radius
    campaign.rover["wheel.radius"] = 0.3
    assert steady_averages(campaign, run).wheel_radius == 0.3


def test_eqn_5_traction_ratio():
    """F_t / F_n = (A C / F_n + tan phi) tanh(s / K_vx): zero at no slip, odd in slip, and the
    Mohr-Coulomb limit at large slip."""
    s = np.array([-0.5, 0.0, 0.2, 50.0])
    ratio = traction_ratio(s, 0.8, 800.0, 0.05, 1000.0, math.radians(30))
    limit = 0.05 * 1000.0 / 800.0 + math.tan(math.radians(30))
    assert ratio[1] == 0.0
    assert ratio[2] == pytest.approx(limit * math.tanh(0.25), rel=1e-15)
    assert ratio[0] == pytest.approx(-limit * math.tanh(0.5 / 0.8), rel=1e-15)
    assert ratio[3] == pytest.approx(limit, rel=1e-15)


def test_no_module_of_the_harness_types_the_rovers_numbers_again():
    """0.2794 (wheel radius) and 317.7 (mass) are read from the FMU, never typed in the harness."""
    typed = []
    for path in sorted(HARNESS.glob("*.py")):
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            if re.search(r"(?<![\d.])(0\.2794|317\.7)(?!\d)", line):
                typed.append(f"{path.name}:{n}: {line.strip()}")
    assert not typed, "\n".join(typed)


def test_the_package_imports_without_an_fmu_and_says_which_fmu_is_missing(tmp_path):
    """Nothing is read at import: with no FMU the modules import, and asking for a constant
    names the missing file."""
    missing = tmp_path / "none.fmu"
    code = ("import juno.cli, juno.identify, juno.registration, juno.report, juno.diagnose, juno.synthesize\n"
            "from juno.rover_model import rover\n"
            "try:\n    rover()\nexcept FileNotFoundError as e:\n    print(e)\n")
    env = {**os.environ, "JUNO_FMU": str(missing)}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert str(missing) in out.stdout and "FMU not found" in out.stdout
