"""No output ever destroys an input or a user's file (juno.outputs, checked by every subcommand).

Specification:

* an output path (``--json``, ``--out``, ``--plots``, synthesize's ``OUT``) that is, contains or
  lies inside an input (the campaign folder and its files, a ``--params`` file, the FMU) is
  refused with exit code 2 and one line naming both paths (a file given as a ``--param`` value,
  such as a terrain grid, is an input too);
* a folder output that is replaced whole (``report --out``, ``diagnose --plots``) must be new,
  empty, or written by the same command before (its marker file); ``synthesize --overwrite``
  replaces only a campaign that synthesize wrote; a folder holding a user's files is refused;
* a file output that is a directory, or whose parent cannot be written, is refused;
* all of it before any computation: the only line on stderr (progress messages on) is the
  refusal, and every input file's checksum is unchanged afterwards.

The commands run in this process (``juno.cli.main``) for speed; one case runs the real
``juno`` console script.
"""

from __future__ import annotations

import json
import shutil

import pytest

from harness_fixtures import run_juno
from hostile_cases import checksums, refused
from juno.outputs import (PLOTS_MARKER, REPORT_MARKER, OutputError, check_output_dir, check_output_file,
                          is_synthesized_campaign, marked_directory)

pytest_plugins = ["harness_fixtures"]

#: Seed of the short synthetic campaign every case starts from (a copy per test).
CAMPAIGN_SEED = 301


@pytest.fixture
def work(tmp_path, small_campaign, fmu_path):
    """tmp_path holding: C (a campaign), P/C (a campaign inside a folder with notes), U (a user's
    folder), params.json (an identify result), fmu.fmu (a copy of the FMU), file.txt."""
    src = small_campaign(CAMPAIGN_SEED).path
    shutil.copytree(src, tmp_path / "C")
    shutil.copytree(src, tmp_path / "P" / "C")
    (tmp_path / "P" / "notes.txt").write_text("field notes\n")
    (tmp_path / "U").mkdir()
    (tmp_path / "U" / "thesis.tex").write_text("\\chapter{Results}\n")
    (tmp_path / "params.json").write_text('{"params": {"soil.kh": 158000, "soil.eta": 0.5, '
                                          '"soil.gamma": 0.08, "soil.Kvx": 0.8}}\n')
    shutil.copy(fmu_path, tmp_path / "fmu.fmu")
    (tmp_path / "file.txt").write_text("a file, not a folder\n")
    (tmp_path / "L").symlink_to(tmp_path / "C")
    return tmp_path


# Each case: the command and the paths its message must name ({w} is the work folder).
CASES = {
    "report C --out C": (["report", "{w}/C", "--out", "{w}/C"], ["{w}/C"]),
    "report P/C --out P": (["report", "{w}/P/C", "--out", "{w}/P"], ["{w}/P", "{w}/P/C"]),
    "report C --out C/runs": (["report", "{w}/C", "--out", "{w}/C/runs"], ["{w}/C/runs", "{w}/C"]),
    "report C/campaign.json --out C": (["report", "{w}/C/campaign.json", "--out", "{w}/C"], ["{w}/C"]),
    "report C --out L (a link to C)": (["report", "{w}/C", "--out", "{w}/L"], ["{w}/L", "{w}/C"]),
    "report C --out U (a user's folder)": (["report", "{w}/C", "--out", "{w}/U"], ["{w}/U", "juno report"]),
    "report C --out file.txt": (["report", "{w}/C", "--out", "{w}/file.txt"], ["{w}/file.txt"]),
    "diagnose C --plots C": (["diagnose", "{w}/C", "--plots", "{w}/C"], ["{w}/C"]),
    "diagnose C --plots C/terrain": (["diagnose", "{w}/C", "--plots", "{w}/C/terrain"], ["{w}/C/terrain"]),
    "diagnose C --plots U": (["diagnose", "{w}/C", "--plots", "{w}/U"], ["{w}/U"]),
    "identify C --json C/campaign.json": (["identify", "{w}/C", "--json", "{w}/C/campaign.json"],
                                          ["{w}/C/campaign.json", "{w}/C"]),
    "identify C --json C": (["identify", "{w}/C", "--json", "{w}/C"], ["{w}/C"]),
    "identify C --json C/runs/dbp1.csv": (["identify", "{w}/C", "--json", "{w}/C/runs/dbp1.csv"],
                                          ["{w}/C/runs/dbp1.csv"]),
    "identify C --json U (a directory)": (["identify", "{w}/C", "--json", "{w}/U"], ["{w}/U", "directory"]),
    "identify C --json file.txt/x.json": (["identify", "{w}/C", "--json", "{w}/file.txt/x.json"],
                                          ["{w}/file.txt/x.json", "not a directory"]),
    "identify C --json /proc/...": (["identify", "{w}/C", "--json", "/proc/juno-no-such/x.json"],
                                    ["/proc/juno-no-such/x.json", "cannot write"]),
    "simulate --campaign C --out C/runs/x.csv": (["simulate", "--campaign", "{w}/C", "--out", "{w}/C/runs/x.csv"],
                                                 ["{w}/C/runs/x.csv", "{w}/C"]),
    "simulate --fmu F --out F": (["simulate", "--fmu", "{w}/fmu.fmu", "--out", "{w}/fmu.fmu"], ["{w}/fmu.fmu"]),
    "simulate --param terrain.file=T --out T": (["simulate", "--param", "terrain.file={w}/file.txt", "--out",
                                                 "{w}/file.txt"], ["{w}/file.txt"]),
    "simulate --out D (a directory)": (["simulate", "--out", "{w}/U"], ["{w}/U", "directory"]),
    "simulate --out x --json x": (["simulate", "--out", "{w}/x.csv", "--json", "{w}/x.csv"], ["{w}/x.csv"]),
    "validate C --params p --json p": (["validate", "{w}/C", "--params", "{w}/params.json", "--json",
                                        "{w}/params.json"], ["{w}/params.json"]),
    "sweep --fmu F --out F": (["sweep", "--vary", "soil.kh=1e5", "--fmu", "{w}/fmu.fmu", "--out",
                                     "{w}/fmu.fmu"], ["{w}/fmu.fmu"]),
    "synthesize U --overwrite": (["synthesize", "{w}/U", "--overwrite"], ["{w}/U", "juno synthesize"]),
    "synthesize U": (["synthesize", "{w}/U"], ["{w}/U", "--overwrite"]),
    "synthesize P --overwrite": (["synthesize", "{w}/P", "--overwrite"], ["{w}/P"]),
    "synthesize file.txt --overwrite": (["synthesize", "{w}/file.txt", "--overwrite"], ["{w}/file.txt"]),
}


@pytest.mark.parametrize("case", list(CASES))
def test_an_output_that_would_destroy_a_file_is_refused_before_any_work(case, work, capsys):
    args, needles = CASES[case]
    refused(capsys, work, args, needles)


def test_the_juno_command_refuses_report_over_its_campaign(work):
    """The console script as a user runs it: one line, exit 2, the campaign intact."""
    before = checksums(work)
    proc = run_juno("report", work / "C", "--out", work / "C", timeout=60)
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert proc.returncode == 2 and len(lines) == 1, proc.stderr
    assert str(work / "C") in lines[0]
    assert checksums(work) == before


# ------------------------------------------------------------ the rules themselves

def test_a_marked_folder_is_replaced_and_an_unmarked_one_never(tmp_path):
    out = tmp_path / "report"
    with marked_directory(out, REPORT_MARKER, "juno report") as tmp:
        (tmp / "report.md").write_text("first\n")
    assert (out / REPORT_MARKER).is_file() and (out / "report.md").read_text() == "first\n"
    (out / "stale.png").write_text("from the first report\n")
    with marked_directory(out, REPORT_MARKER, "juno report") as tmp:
        (tmp / "report.md").write_text("second\n")
    assert sorted(p.name for p in out.iterdir()) == [REPORT_MARKER, "report.md"], "replaced whole"
    assert (out / "report.md").read_text() == "second\n"

    # A plots folder is not a report folder: the markers are distinct.
    with pytest.raises(OutputError, match="juno diagnose --plots"):
        check_output_dir(out, [], "--plots", PLOTS_MARKER, "juno diagnose --plots")

    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "thesis.tex").write_text("keep\n")
    with pytest.raises(OutputError, match="mine"):
        with marked_directory(mine, REPORT_MARKER, "juno report"):
            raise AssertionError("the body must not run")
    assert sorted(p.name for p in mine.iterdir()) == ["thesis.tex"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mine", "report"], "a temporary was left behind"


def test_a_folder_filled_while_the_report_was_built_is_not_replaced(tmp_path):
    out = tmp_path / "report"
    with pytest.raises(OutputError, match="report"):
        with marked_directory(out, REPORT_MARKER, "juno report") as tmp:
            (tmp / "report.md").write_text("new\n")
            out.mkdir()
            (out / "data.csv").write_text("the user's, written meanwhile\n")
    assert sorted(p.name for p in out.iterdir()) == ["data.csv"]


def test_an_empty_or_new_folder_and_a_file_juno_wrote_are_accepted(tmp_path):
    (tmp_path / "empty").mkdir()
    check_output_dir(tmp_path / "empty", [], "--out", REPORT_MARKER, "juno report")
    check_output_dir(tmp_path / "new" / "deeper", [], "--out", REPORT_MARKER, "juno report")
    (tmp_path / "old.json").write_text('{"written_by": "juno 0.1.0 identify", "paper": []}\n')
    check_output_file(tmp_path / "old.json", [tmp_path / "input.csv"], "--json")
    (tmp_path / "old.csv").write_text("time,x,y,wheelFL.slip\n0.0,0.0,0.0,0.0\n")
    check_output_file(tmp_path / "old.csv", [], "--out")
    (tmp_path / "empty.json").write_text("")
    check_output_file(tmp_path / "empty.json", [], "--json")
    check_output_file(tmp_path / "new" / "x.json", [], "--json")


@pytest.mark.parametrize("name, content", [
    ("notes.txt", "my notes\n"),
    ("other.json", '{"paper": []}\n'),                                      # a JSON juno did not write
    ("campaign.json", '{"name": "another campaign", "runs": []}\n'),
    ("dbp1.csv", "time,torque_left,torque_right,omega_left,omega_right,pos_x,pos_y,pos_z,drawbar_force\n0,1,1,1,1,0,0,0,5\n"),
])
def test_a_users_file_at_an_output_path_is_refused_and_kept(tmp_path, name, content):
    """A file output replaces an existing file only when juno wrote it: a user's notes, another
    campaign's manifest or a measured run given by a mistyped option stay as they are."""
    target = tmp_path / name
    target.write_text(content)
    with pytest.raises(OutputError, match="exists and was not written by juno"):
        check_output_file(target, [], "--json")
    assert target.read_text() == content


def test_every_json_result_names_juno_as_its_writer(tmp_path):
    """What write_json writes, a later run may replace (and nothing else)."""
    from juno.core import write_json
    from juno.outputs import written_by_juno

    out = tmp_path / "result.json"
    write_json(str(out), {"soil": {"soil.kh": 2.0e5}}, "validate")
    assert json.loads(out.read_text())["written_by"].startswith("juno ")
    assert json.loads(out.read_text())["written_by"].endswith(" validate")
    assert written_by_juno(out)
    check_output_file(out, [], "--json")


def test_only_what_synthesize_writes_counts_as_a_synthesized_campaign(work):
    assert is_synthesized_campaign(work / "C")
    assert not is_synthesized_campaign(work / "P")
    assert not is_synthesized_campaign(work / "U")
    (work / "C" / "runs" / "notes.txt").write_text("mine\n")
    assert not is_synthesized_campaign(work / "C"), "a user's file inside it"
