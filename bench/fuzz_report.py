"""Run the slow property test over drawn designs (tests/test_fuzz.py,
``test_drawn_designs_of_every_structure``: 10 seeded designs for each of the 6
contact laws x 3 joint layouts of the slider-crank) and tabulate what was drawn and how it ended.

Writes ``bench/results/fuzz.json`` (every design: drawn numbers, status, steps, energy
residual, bound ratios) and the generated section of ``docs/reliability.md`` (between
its ``fuzz-report`` markers).

    python bench/fuzz_report.py              # runs the slow test (~5 min on 2 cores)
    python bench/fuzz_report.py --from-json  # only rewrites the docs from bench/results/fuzz.json

Needs the ``test`` extra (hypothesis, pytest).
"""

from __future__ import annotations

import collections
import json
import os
import platform
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "reliability.md"
START, END = "<!-- fuzz-report:start -->", "<!-- fuzz-report:end -->"


def _run_slow_test(record: Path) -> tuple[int, float, str]:
    env = dict(os.environ, JAXCRANK_FUZZ_RECORD=str(record), PYTHONPATH=str(ROOT))
    cmd = [
        sys.executable,
        "-m",
        "pytest",
        "tests/test_fuzz.py",
        "-o",
        "addopts=",
        "-m",
        "slow",
        "-k",
        "every_structure",
        "-p",
        "no:cacheprovider",
        "-q",
    ]
    tic = time.perf_counter()
    res = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True)
    summary = [ln for ln in res.stdout.splitlines() if re.search(r"\d+ (passed|failed)", ln)]
    return res.returncode, time.perf_counter() - tic, summary[-1] if summary else f"exit status {res.returncode}"


def _fmt(x, spec=".2g"):
    return "" if x is None else format(x, spec)


def _table(records) -> str:
    groups = collections.defaultdict(list)
    for r in records:
        groups[(r["law"], r["clearance joints"])].append(r)
    lines = [
        "| contact law | clearance at | designs | ok | max_steps | solver_failed | non_finite | "
        "steps (max, ok) | max energy residual / scale | max deviation / bound (slider, rod, pins) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for (law, joints), rs in sorted(groups.items()):
        ok = [r for r in rs if r["status"] == "ok"]
        count = collections.Counter(r["status"] for r in rs)
        ratios = [max(r["bound_ratios"].get(k, 0.0) for r in ok) if ok else None for k in ("slider_x", "rod_x")]
        pins = max((v for r in ok for k, v in r["bound_ratios"].items() if k.startswith("ecc")), default=None)
        lines.append(
            f"| {law} | {joints} | {len(rs)} | {count['ok']} | {count['max_steps']} | {count['solver_failed']} | "
            f"{count['non_finite']} | {max((r['steps'] for r in ok), default='')} | "
            f"{_fmt(max((r['energy_residual_over_scale'] for r in ok), default=None))} | "
            f"{_fmt(ratios[0], '.3f')}, {_fmt(ratios[1], '.3f')}, {_fmt(pins, '.6f')} |"
        )
    return "\n".join(lines)


def _ranges(records) -> str:
    keys = [
        ("rpm", "crank speed, rpm", ".4g"),
        ("clearance_B_m", "clearance B, m", ".2e"),
        ("clearance_C_m", "clearance C, m", ".2e"),
        ("friction", "friction coefficient", ".3g"),
        ("rod_over_min", "rod_length over crank_length + abs(offset)", ".3g"),
    ]
    lines = ["| drawn | min | max | ok designs at the min/max decile |", "|---|---|---|---|"]
    for key, label, spec in keys:
        drawn = [r for r in records if r[key] is not None]  # an ideal joint has no clearance
        vals = sorted(r[key] for r in drawn)
        lo, hi = vals[len(vals) // 10], vals[-len(vals) // 10 - 1]
        low_ok = sum(r["status"] == "ok" for r in drawn if r[key] <= lo)
        low_n = sum(r[key] <= lo for r in drawn)
        high_ok = sum(r["status"] == "ok" for r in drawn if r[key] >= hi)
        high_n = sum(r[key] >= hi for r in drawn)
        lines.append(
            f"| {label} | {format(vals[0], spec)} | {format(vals[-1], spec)} | {low_ok}/{low_n}, {high_ok}/{high_n} |"
        )
    return "\n".join(lines)


def _failures(records) -> str:
    bad = [r for r in records if r["status"] != "ok"]
    if not bad:
        return "No drawn design failed."
    lines = [
        "| contact law | clearance at | rpm | clearance B, C (m) | friction | status | message (start) |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in bad:
        lines.append(
            f"| {r['law']} | {r['clearance joints']} | {r['rpm']:.4g} | {_fmt(r['clearance_B_m'], '.2e') or 'ideal'}, "
            f"{_fmt(r['clearance_C_m'], '.2e') or 'ideal'} | {r['friction']:.3g} | {r['status']} | "
            f"{r['message'][:110].replace('|', '/')}... |"
        )
    return "\n".join(lines)


def main():
    import jax

    import jaxcrank  # noqa: F401  (the XLA options the test runs with)
    from tests import fuzz

    out = ROOT / "bench" / "results" / "fuzz.json"
    if "--from-json" in sys.argv[1:]:
        result = json.loads(out.read_text())
        records, rc = result["records"], result["pytest"]["returncode"]
        pytest_line, wall = result["pytest"]["summary"], result["pytest"]["wall_s"]
        counts = collections.Counter(r["status"] for r in records)
    else:
        with tempfile.TemporaryDirectory() as tmp:
            record = Path(tmp) / "records.jsonl"
            rc, wall, pytest_line = _run_slow_test(record)
            records = [json.loads(ln) for ln in record.read_text().splitlines()] if record.exists() else []
        counts = collections.Counter(r["status"] for r in records)
        result = _result(fuzz, jax, rc, wall, pytest_line, records, counts)
        out.write_text(json.dumps(result, indent=1))
    _write_doc(fuzz, records, counts, pytest_line)
    print(
        f"{len(records)} designs: {dict(counts)}; pytest: {pytest_line.strip()} ({wall:.0f} s); wrote {out} and {DOC}"
    )
    return rc


def _result(fuzz, jax, rc, wall, pytest_line, records, counts):
    return {
        "command": "python bench/fuzz_report.py",
        "pytest": {"returncode": rc, "summary": pytest_line, "wall_s": wall},
        "note": "2-core machine shared with other jobs: wall time is contended and includes "
        f"{len(fuzz.STRUCTURES)} compilations",
        "settings": {
            "t1_s": fuzz.T1,
            "samples": fuzz.N_SAMPLES,
            "max_steps": fuzz.MAX_STEPS,
            "energy_rtol": fuzz.ENERGY_RTOL,
            "structures": len(fuzz.STRUCTURES),
        },
        "designs": len(records),
        "status_counts": dict(counts),
        "versions": {"python": platform.python_version(), "jax": jax.__version__},
        "records": records,
    }


def _write_doc(fuzz, records, counts, pytest_line):
    section = "\n".join(
        [
            START,
            f"Generated by `python bench/fuzz_report.py` (the slow test "
            f"`tests/test_fuzz.py::test_drawn_designs_of_every_structure`; raw records in "
            f"`bench/results/fuzz.json`). pytest: {pytest_line.strip()} (2 shared, busy cores: "
            f"{len(fuzz.STRUCTURES)} compilations).",
            "",
            f"{len(records)} designs, each simulated for {fuzz.T1 * 1e3:g} ms ({fuzz.N_SAMPLES} samples) from the "
            f"pins-centred start with a budget of {fuzz.MAX_STEPS} steps: "
            + ", ".join(f"{k} {v}" for k, v in sorted(counts.items()))
            + ". "
            f"Energy residual tolerance: {fuzz.ENERGY_RTOL:g} of the energy scale (largest kinetic energy + "
            "|driver work| + dissipated work); bounds: `SliderCrank.deviation_bounds` (slider x, rod x) and "
            "clearance + largest penetration (pin eccentricity); a ratio <= 1 is inside.",
            "",
            _table(records),
            "",
            "Drawn ranges, and how many designs ended ok in the lowest and highest tenth of each:",
            "",
            _ranges(records),
            "",
            "Designs that did not solve (each reported with its status and message, never NaN):",
            "",
            _failures(records),
            END,
        ]
    )
    text = DOC.read_text()
    DOC.write_text(text[: text.index(START)] + section + text[text.index(END) + len(END) :])


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    sys.exit(main())
