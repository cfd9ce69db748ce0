"""What a ``juno`` start costs: building the parser imports no command's library code, so
``juno --help`` and every subcommand start without the diagnosis (its import pulls in SciPy's
optimizers, about half a second); the diagnosis's candidate names, the choices of
``juno diagnose --candidates``, are written out in the command and kept equal to the catalogue."""

from __future__ import annotations

import subprocess
import sys

import pytest

from juno.cli import build_parser
from juno.commands.diagnose import CANDIDATE_NAMES
from juno.diagnose import CANDIDATES


def test_the_candidate_choices_are_the_catalogues_names_sorted():
    assert CANDIDATE_NAMES == tuple(sorted(CANDIDATES))


def test_building_the_parser_does_not_import_the_diagnosis():
    """In a fresh interpreter (this one has imported juno.diagnose already): the parser of every
    subcommand built, and juno.diagnose still not imported."""
    code = ("import sys\n"
            "from juno.cli import build_parser\n"
            "build_parser()\n"
            "print(sorted(m for m in sys.modules if m == 'juno.diagnose' or m.startswith('juno.diagnose.')))\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "[]", proc.stdout


def test_an_unknown_candidate_is_refused_with_the_catalogues_names(capsys):
    with pytest.raises(SystemExit) as stop:
        build_parser().parse_args(["diagnose", "campaign", "--candidates", "soil_patch", "no_such_cause"])
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert "no_such_cause" in err and all(name in err for name in CANDIDATES), err
