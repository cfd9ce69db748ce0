"""The main job end to end on a fresh clone: ``bash scripts/main.sh`` (README, "The two commands").

The repository's committed state is cloned with ``git clone`` into a temporary folder, so only
committed files count; the clone sets itself up (its own .venv and FMU build), synthesizes the
demo campaign shortened by ``JUNO_TIME_SCALE=0.25``, and writes ``out/report/report.md``.  The job
is started in the background (harness_fixtures.py) and takes one to two minutes, most of it the
report's fits and diagnosis; harness_fixtures marks it ``slow`` (it stays in the default run and
in CI).
"""

from __future__ import annotations

import json
import re
import subprocess

import pytest

from harness_fixtures import MAIN_JOB_TIME_SCALE, RUN_LENGTHS, say
from juno.simulator import SOIL_PARAMETERS

pytest_plugins = ["harness_fixtures"]

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
SECTIONS = ("## 1. Identification the paper's way", "### Spread between runs", "## 2. Joint identification",
            "## 3. Traction ratio against slip", "## 4. Validation on the 3-D terrain")
FIGURES = {"run_dbp1.png", "run_dbp2.png", "run_dbp3.png", "fig10_traction_ratio.png", "validation_t3d.png",
           "path_t3d.png"}


def table_after(text: str, heading: str) -> list[list[str]]:
    rows = []
    for line in text[text.index(heading):].splitlines()[1:]:
        if line.startswith("|"):
            rows.append([c.strip() for c in line.strip().strip("|").split("|")])
        elif rows:
            break
    return rows


def test_main_job_runs_end_to_end_on_a_fresh_clone(main_job):
    code = main_job.wait()
    say(f"bash scripts/main.sh in a fresh clone (JUNO_TIME_SCALE={MAIN_JOB_TIME_SCALE}): exit {code} after "
        f"{main_job.wall_time:.0f} s")
    assert code == 0, f"bash scripts/main.sh exited with {code}\n{main_job.log_tail()}"
    clone = main_job.clone
    log = main_job.log()
    report_text = (clone / "out/report/report.md").read_text() if (clone / "out/report/report.md").is_file() else ""
    if "## Timings" in report_text:
        for step in table_after(report_text, "## Timings")[2:]:
            say(f"  main job step: {step[0]}: {step[1]} s")

    # the shortened demo campaign
    campaign = json.loads((clone / "out/demo-campaign/campaign.json").read_text())
    assert [r["id"] for r in campaign["runs"]] == ["dbp1", "dbp2", "dbp3", "t3d"]
    last = (clone / "out/demo-campaign/runs/dbp1.csv").read_text().strip().splitlines()[-1]
    assert float(last.split(",")[0]) == pytest.approx(RUN_LENGTHS["dbp1"] * float(MAIN_JOB_TIME_SCALE), abs=0.05)

    # the report, its tables and figures
    report_dir = clone / "out/report"
    text = (report_dir / "report.md").read_text()
    for heading in SECTIONS:
        assert heading in text, f"report.md has no '{heading}'"
    spread = table_after(text, "### Spread between runs")
    assert all(run in spread[0] for run in ("dbp1", "dbp2", "dbp3")), spread[0]
    assert [r[0] for r in spread[2:]] == list(SOIL_PARAMETERS)
    joint = table_after(text, "## 2. Joint identification")
    assert [r[0] for r in joint[2:]] == list(SOIL_PARAMETERS)
    validation = table_after(text, "## 4. Validation on the 3-D terrain")
    assert len(validation) >= 3 and all(len(r) == len(validation[0]) for r in validation)
    links = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", text)
    assert FIGURES <= set(links), f"figure links {links}"
    for link in links:
        png = report_dir / link
        assert png.is_file(), f"report.md links {link}, which does not exist"
        assert png.read_bytes()[:8] == PNG_MAGIC, f"{link} is not a PNG"
    summary = json.loads((clone / "out/report.json").read_text())
    assert set(summary["joint"]) == set(SOIL_PARAMETERS)
    assert "main: report at out/report/report.md" in log

    # the job writes only ignored outputs: the clone's tracked files are untouched, nothing stray
    status = subprocess.run(["git", "status", "--porcelain"], cwd=clone, capture_output=True, text=True)
    assert status.returncode == 0 and status.stdout == "", f"git status after the main job:\n{status.stdout}"
