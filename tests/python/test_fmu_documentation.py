"""What the FMU carries for its users: documentation/index.html (what the model is, the default
experiment, a picture, every variable with its unit) and extra/JunoRover_ref.csv, the default
experiment's reference result, which a fresh simulation reproduces."""

from __future__ import annotations

import csv
import html
import io
import sys
import zipfile
from pathlib import Path

import numpy as np
from fmpy import read_model_description

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "scripts"))
from make_reference_result import REFERENCE, default_experiment  # noqa: E402


def _read(fmu_path: str, name: str) -> bytes:
    with zipfile.ZipFile(fmu_path) as z:
        return z.read(name)


def test_the_documentation_names_every_variable_with_its_unit(fmu_path):
    page = _read(fmu_path, "documentation/index.html").decode("utf-8")
    md = read_model_description(fmu_path)
    for v in md.modelVariables:
        row = f"<tr><td><code>{html.escape(v.name, quote=True)}</code></td><td>{v.causality}</td>"
        assert row in page, f"{v.name} is not in documentation/index.html"
        if v.unit:
            assert f"{row}<td>{v.type}</td><td>{html.escape(v.unit, quote=True)}</td>" in page, v.name
    assert f"JunoRover {md.version}" in page and "Default experiment" in page
    _read(fmu_path, "documentation/wheel-and-drawbar.png")      # the picture the page shows
    assert 'src="wheel-and-drawbar.png"' in page


def test_the_reference_result_is_the_committed_one_and_a_fresh_run_reproduces_it(fmu_path):
    packed = _read(fmu_path, "extra/JunoRover_ref.csv").decode("utf-8")
    assert packed == REFERENCE.read_text()
    rows = list(csv.reader(io.StringIO(packed)))
    names, values = rows[0], np.array(rows[1:], dtype=float)
    exp = read_model_description(fmu_path).defaultExperiment
    assert values[0, 0] == float(exp.startTime) and values[-1, 0] == float(exp.stopTime)
    fresh = default_experiment(fmu_path)
    assert list(fresh.dtype.names) == names
    # The reference result checks the model, not a compiler's rounding: another compiler or
    # optimisation level may differ in the last digits, never by a part in a million.
    for k, name in enumerate(names):
        np.testing.assert_allclose(fresh[name], values[:, k], rtol=1e-6, atol=1e-9, err_msg=name)
