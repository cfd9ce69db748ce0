"""The documents are current, self-contained and describe the present.

Fast (no simulation): the generated parts are regenerated in memory and compared with the
committed files, every relative link is followed, and the repository's documents and sources
are searched for references to documents outside the repository and for work-history notes.
"""

from __future__ import annotations

import importlib.util
import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"
EXAMPLE = DOCS / "example-campaign"

#: Markdown files whose links must resolve.
DOCUMENTS = sorted([ROOT / "README.md", *DOCS.rglob("*.md")])
#: Sources searched for references to outside documents (text files only).
SOURCE_DIRS = ("python_harness", "fmu_src", "modelDescription", "tests/python", "tests/c", "tests/conformance",
               "scripts", "bench", "cmake")
SOURCE_SUFFIXES = {".py", ".c", ".h", ".sh", ".cmake", ".md", ".txt", ".supp"}
#: Where work-history notes are searched for (what a reader of the current version sees).
HISTORY_PATHS = ("README.md", "docs", "python_harness/juno", "fmu_src")

# Built from pieces so that this file does not match its own search.
OUTSIDE = re.compile("|".join([r"model" + r"-notes", r"interfaces" + r"\.md", r"\.\./" + r"shared",
                               r"\bissue" + r" [0-9]+"]), re.IGNORECASE)
HISTORY = re.compile(r"\bsession" + r" [0-9]|\bseeds?" + r" [0-9]{3,}", re.IGNORECASE)
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")


def _generator():
    spec = importlib.util.spec_from_file_location("generate_docs", ROOT / "scripts" / "generate_docs.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("generate_docs", module)
    spec.loader.exec_module(module)
    return module


def _without_code(text: str) -> str:
    """The Markdown text with fenced code blocks and inline code removed (links there are examples)."""
    text = re.sub(r"^```.*?^```", "", text, flags=re.S | re.M)
    return re.sub(r"`[^`\n]*`", "", text)


def _text_files(paths) -> list[Path]:
    out = []
    for rel in paths:
        p = ROOT / rel
        if p.is_file():
            out.append(p)
        elif p.is_dir():
            out += [f for f in sorted(p.rglob("*")) if f.is_file() and
                    (f.suffix in SOURCE_SUFFIXES or f.name == "CMakeLists.txt") and "__pycache__" not in f.parts]
    return out


def test_every_relative_link_and_image_resolves_to_a_file_in_the_repository():
    assert DOCUMENTS, "no documents found"
    broken = []
    for doc in DOCUMENTS:
        for target in LINK.findall(_without_code(doc.read_text(encoding="utf-8"))):
            if re.match(r"[a-z][a-z0-9+.-]*:", target) or target.startswith("#"):
                continue          # a web address or an anchor in the same page
            path = (doc.parent / target.split("#", 1)[0]).resolve()
            if not path.exists() or not path.is_relative_to(ROOT):
                broken.append(f"{doc.relative_to(ROOT)}: ({target})")
    assert not broken, "links that lead nowhere in the repository:\n" + "\n".join(broken)


def test_every_repository_path_the_documents_name_exists():
    """A file named in code font (`fmu_src/contact.c`, `tests/c/test_terrain.c`) is there: a
    renamed or removed file shows up here rather than as a dead pointer for the reader."""
    named = re.compile(r"`((?:fmu_src|tests|scripts|python_harness|bench|modelDescription|cmake|docs)/[\w./-]+)`")
    missing = []
    for doc in DOCUMENTS:
        for path in named.findall(doc.read_text(encoding="utf-8")):
            if not (ROOT / path).exists():
                missing.append(f"{doc.relative_to(ROOT)}: {path}")
    assert not missing, "paths named in the documents that do not exist:\n" + "\n".join(missing)


def test_the_map_of_checks_names_every_test_file():
    """docs/checks.md's table of tests says where each kind of check lives: every test source
    (Python, C, conformance drivers, fuzz targets) is named there, so a newcomer who reads it finds
    every test, and a new test file is placed in the map when it lands."""
    text = (DOCS / "checks.md").read_text(encoding="utf-8")
    sources = [*sorted((ROOT / "tests/python").glob("test_*.py")), *sorted((ROOT / "tests/c").glob("test_*.c")),
               *sorted((ROOT / "tests/conformance").glob("*.c")), *sorted((ROOT / "tests/fuzz").glob("*.c"))]
    unnamed = [str(f.relative_to(ROOT)) for f in sources if f.name not in text and f.stem not in text]
    assert sources and not unnamed, "test files docs/checks.md does not name:\n" + "\n".join(unnamed)


def test_the_architecture_names_every_source_of_the_fmus_and_module_of_the_harness():
    """docs/architecture.md places every C source of the FMUs and every module and package of the
    harness (the command modules apart: one per command, by the rule stated there), and
    docs/diagnosis.md's table every module of the diagnosis: a newcomer finds where each concept
    lives."""
    harness = ROOT / "python_harness" / "juno"
    architecture = (DOCS / "architecture.md").read_text(encoding="utf-8")
    diagnosis = (DOCS / "diagnosis.md").read_text(encoding="utf-8")
    unnamed = []
    for path in sorted(harness.rglob("*.py")):
        rel = path.relative_to(harness)
        if path.name == "__init__.py" or rel.parts[0] == "commands":
            continue
        where, text = ("diagnosis.md", diagnosis) if rel.parts[0] == "diagnose" else ("architecture.md", architecture)
        if f"`{path.name}`" not in text:
            unnamed.append(f"{rel} (in docs/{where})")
    for path in sorted((ROOT / "fmu_src").glob("*.[ch]")):
        if path.name not in architecture and path.stem not in architecture:
            unnamed.append(f"fmu_src/{path.name} (in docs/architecture.md)")
    assert not unnamed, "modules the documents' module tables do not name:\n" + "\n".join(unnamed)


def test_no_document_or_source_refers_to_documents_outside_the_repository():
    files = _text_files(["README.md", "docs", "CMakeLists.txt", *SOURCE_DIRS])
    hits = [f"{f.relative_to(ROOT)}:{n}: {line.strip()[:100]}"
            for f in files for n, line in enumerate(f.read_text(encoding="utf-8", errors="replace").splitlines(), 1)
            if OUTSIDE.search(line)]
    assert not hits, "references to documents outside the repository:\n" + "\n".join(hits)


def test_documents_and_code_describe_the_present_without_work_history():
    files = _text_files(HISTORY_PATHS)
    hits = [f"{f.relative_to(ROOT)}:{n}: {line.strip()[:100]}"
            for f in files for n, line in enumerate(f.read_text(encoding="utf-8", errors="replace").splitlines(), 1)
            if HISTORY.search(line)]
    assert not hits, "work-history notes (sessions, seed diaries):\n" + "\n".join(hits)


def test_generated_tables_and_sections_match_the_fmu_and_the_results_files():
    """docs/reference/variables.md is the built FMU's modelDescription.xml; the README's and the
    docs' generated sections are the committed results files. Regenerate with
    scripts/generate_docs.py after changing either."""
    gen = _generator()
    fmu = ROOT / "build" / "JunoRover.fmu"
    assert fmu.is_file(), "build/JunoRover.fmu is not built (cmake --build build)"
    stale = gen.stale_parts(fmu)
    assert not stale, f"stale generated documents (run .venv/bin/python scripts/generate_docs.py): {stale}"


def test_the_variables_table_lists_every_variable_of_the_fmu_with_its_unit():
    gen = _generator()
    table = gen.variables_table(ROOT / "build" / "JunoRover.fmu")
    rows = [line for line in table.splitlines() if line.startswith("| `")]
    names = [re.match(r"\| `([^`]+)`", r).group(1) for r in rows]
    assert len(names) == len(set(names)) > 100
    for name, unit in (("soil.kh", "N/m^(2+eta)"), ("x", "m"), ("drawbarForce", "N"), ("wheelRR.slip", "1")):
        row = rows[names.index(name)]
        assert f"| {unit} |" in row, row


def test_readme_is_short_and_keeps_the_two_commands():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 200
    assert "bash scripts/main.sh" in text and "bash scripts/test.sh" in text
    assert "BSD-2-Clause" in text and (ROOT / "LICENSE").is_file()


def test_headline_never_quotes_detection_rates_without_a_study():
    """Without a committed study the README says the rates are not measured and how to measure them."""
    gen = _generator()
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    if not gen.DETECTION_JSON.is_file():
        assert "not measured at this commit" in text and gen.DETECTION_COMMAND in text


def test_the_example_campaign_loads_and_every_run_and_scan_reads():
    from juno.campaign import load_campaign, read_run, read_terrain_points

    campaign = load_campaign(EXAMPLE)
    kinds = sorted(run.kind for run in campaign.runs)
    assert kinds == ["drawbar", "terrain"]
    for run in campaign.runs:
        data = read_run(campaign, run)
        assert len(data) >= 50, f"{run.id}: {len(data)} rows"
        for column in ("torque_left", "omega_left", "pos_x"):
            assert data.has(column)
        if run.kind == "terrain":
            points = read_terrain_points(campaign, run)
            assert points.shape[1] == 3 and len(points) >= 100


def test_the_example_campaign_raises_no_plausibility_finding():
    """The example users copy is clean: no warning a user would have to explain away."""
    plausibility = pytest.importorskip("juno.plausibility")
    from juno.campaign import load_campaign

    findings = [str(f) for f in plausibility.check_campaign(load_campaign(EXAMPLE))]
    assert not findings, "\n".join(findings)


def test_the_example_campaigns_terrain_run_stays_over_its_scan():
    """The terrain run's measured path lies inside the scanned area (with a wheelbase's margin)."""
    from juno.campaign import load_campaign, read_run, read_terrain_points

    campaign = load_campaign(EXAMPLE)
    run = campaign.runs_of_kind("terrain")[0]
    data, points = read_run(campaign, run), read_terrain_points(campaign, run)
    _, x = data.samples("pos_x")
    _, y = data.samples("pos_y")
    lo, hi = points[:, :2].min(axis=0), points[:, :2].max(axis=0)
    margin = 0.41          # m: half the wheelbase, from the chassis reference point to an axle
    assert lo[0] <= x.min() - margin and x.max() + margin <= hi[0]
    assert lo[1] <= y.min() - margin and y.max() + margin <= hi[1]


def test_a_detection_study_is_tabled_with_its_provenance():
    """With a study, the pages quote its cases per effect and say where and when it ran."""
    gen = _generator()
    study = {"cases": [{"effect": "none", "correct": True}, {"effect": "none", "correct": True},
                       {"effect": "grouser", "correct": True}, {"effect": "grouser", "correct": False},
                       {"effect": "drivetrain_loss+slip_sinkage", "correct": True}],
             "table": "| hidden effect | cases |\n|---|---|\n| none | 2 |",
             "provenance": {"command": "scripts/detection_rates.py --seeds 2", "commit": "abc1234",
                            "started": "2026-01-01 00:00 UTC", "finished": "2026-01-01 01:00 UTC",
                            "machine": "test machine"}}
    summary = gen.detection_summary(study)
    assert "none 2/2" in summary and "grouser 1/2" in summary and "abc1234" in summary
    assert "slip_sinkage" not in summary          # pairs are tabled on the page, not in the one-line summary
    assert "alternative forms" not in summary and "decoys" not in summary    # none in this study
    page = gen.detection_page(study)
    for text in ("abc1234", "test machine", "2026-01-01 00:00 UTC", "--seeds 2", study["table"]):
        assert text in page
    assert "not measured" not in page


def test_a_study_of_forms_and_decoys_is_summed_up_by_kind():
    """Alternative forms and decoys are counted as two groups beside the catalog effects: the
    one-line summary stays short however many forms the study hid."""
    gen = _generator()
    cases = ([{"effect": "none", "correct": True, "kind": "catalog"}]
             + [{"effect": "soil_strip", "correct": ok, "kind": "form"} for ok in (True, True, False)]
             + [{"effect": "side_drag", "correct": ok, "kind": "decoy", "design": "alt"} for ok in (True, False)])
    study = {"cases": cases, "table": "",
             "provenance": {"command": "c", "commit": "abc1234", "started": "s", "finished": "f", "machine": "m"}}
    summary = gen.detection_summary(study)
    assert "none 1/1" in summary
    assert "alternative forms named as their mechanism 2/3" in summary
    assert "decoys outside the catalog naming no catalog cause 1/2" in summary
    assert "soil_strip" not in summary and "side_drag" not in summary


def test_side_by_side_studies_stop_together_when_one_fails(tmp_path):
    """A study that fails stops the others still running (no process is left behind) and fails
    the whole: no results page is written from part of the studies."""
    import os
    import subprocess
    import time

    gen = _generator()
    pid_file = tmp_path / "slow.pid"
    slow = [sys.executable, "-c", f"import os, pathlib, time; pathlib.Path({str(pid_file)!r}).write_text(str(os.getpid())); "
                                  "time.sleep(60)"]
    failing = [sys.executable, "-c", "import sys, time; time.sleep(1.0); sys.exit(3)"]
    t0 = time.monotonic()
    with pytest.raises(subprocess.CalledProcessError) as failed:
        gen._run_side_by_side([slow, failing], at_once=2)
    assert failed.value.returncode == 3
    assert time.monotonic() - t0 < 30               # the slow study was stopped, not waited for
    with pytest.raises(ProcessLookupError):
        os.kill(int(pid_file.read_text()), 0)      # and it is gone
