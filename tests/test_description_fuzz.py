"""Descriptions fuzzed like designs: drawn malformed or unassemblable linkages
(tests/bad_descriptions.py, hypothesis) given to ``jaxcrank simulate --config``: each ends
in one line on standard error that names the problem, exit status 2, and nothing written;
never a traceback, a NaN or a run directory. The default suite draws 60; the slow test
draws 240 and, with $JAXCRANK_FUZZ_RECORD set, records every draw
(``bench/fuzz_descriptions.py`` writes them to bench/results/fuzz_descriptions.json)."""

from __future__ import annotations

import contextlib
import io
import json
import os
import tempfile
from pathlib import Path

import pytest
import tomli_w
from hypothesis import HealthCheck, assume, given, settings

from jaxcrank.runs import cli

from . import bad_descriptions


def _settings(n):
    return settings(
        max_examples=n, deadline=None, database=None, derandomize=True, suppress_health_check=list(HealthCheck)
    )


def _refused(case) -> dict:
    name, how, data = case
    try:
        text = tomli_w.dumps(data)
    except (TypeError, ValueError):  # a value TOML cannot hold (a list of mixed types)
        assume(False)
    with tempfile.TemporaryDirectory() as tmp:
        path, out = Path(tmp) / "bad.toml", Path(tmp) / "run"
        path.write_text(text)
        err = io.StringIO()
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            code = cli.main(["simulate", "--config", str(path), "--out", str(out), "--quiet", "--no-cache"])
        lines = [line for line in err.getvalue().splitlines() if not line.endswith("(loading JAX)")]
        written = out.exists()
    message = lines[0] if lines else ""
    record = {"linkage": name, "broken": how, "exit": code, "lines": len(lines), "written": written}
    record["message"] = message.replace(str(path), "bad.toml")
    assert code == 2 and not written and len(lines) == 1, record
    assert message.startswith(f"jaxcrank: error: {path}: "), record
    return record


def _record(record: dict) -> None:
    path = os.environ.get("JAXCRANK_FUZZ_RECORD")
    if path:
        with open(path, "a") as fh:
            fh.write(json.dumps(record) + "\n")


@_settings(60)
@given(bad_descriptions.breakage())
def test_drawn_bad_descriptions_end_in_one_named_line(case):
    _refused(case)


@pytest.mark.slow
@_settings(240)
@given(bad_descriptions.breakage())
def test_240_drawn_bad_descriptions_end_in_one_named_line(case):
    _record(_refused(case))
