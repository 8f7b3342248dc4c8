"""The docs page "Design your own mechanism": its problem file is the one in docs/problems, and
``jaxcrank optimize --problem`` runs it as printed to a design that satisfies every constraint."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "design-your-own.md"
FILE = ROOT / "docs" / "problems" / "crank-rocker-pin-force.toml"


def test_the_page_prints_the_problem_file_and_the_command_that_runs_it():
    text = PAGE.read_text()
    block = re.search(r"```toml\n(.*?)```", text, re.S).group(1)
    assert block == FILE.read_text()
    assert "jaxcrank optimize --problem docs/problems/crank-rocker-pin-force.toml --out runs/pin-force" in text


@pytest.mark.slow
def test_the_page_problem_runs_to_a_design_that_satisfies_every_constraint(tmp_path):
    """The run (minutes) ends feasible although the start violates the metric constraint; the
    peak pin force falls; result.json holds every term and constraint with value, bounds and
    satisfied, at the start and the end."""
    out = tmp_path / "pin-force"
    run = subprocess.run(
        [
            sys.executable,
            "-m",
            "jaxcrank.runs.cli",
            "optimize",
            "--problem",
            str(FILE.relative_to(ROOT)),
            "--out",
            str(out),
            "--quiet",
            "--no-cache",
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=1800,
    )
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-3000:]
    res = json.loads((out / "result.json").read_text())
    assert res["feasible"] is True
    for entry in res["objectives"] + res["constraints"]:
        assert {"quantity", "value", "lower", "upper", "satisfied", "start"} <= set(entry)
    assert all(c["satisfied"] for c in res["constraints"])
    metric = next(c for c in res["constraints"] if c["quantity"] == "rms_rocker_angle_deviation_deg")
    assert metric["start_satisfied"] is False and metric["value"] <= metric["upper"]
    assert res["objective_final"] < res["objective_start"]
    for name in ("history.csv", "history.png", "rounds.json", "problem.toml"):
        assert (out / name).exists(), name
    header = (out / "history.csv").read_text().splitlines()[0].split(",")
    assert {"f", "merit", "term:peak_contact_force_B_N"} <= set(header) and "objective_deg" not in header
