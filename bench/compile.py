"""Compile time of ``jaxcrank simulate`` for every preset and the docs' linkages, in one run.

For each mechanism, two fresh processes of the command as a user runs it
(``jaxcrank simulate --no-figures --quiet``, its defaults: 4 revolutions, 10 samples a
degree), each pinned to one core:

- **cold**: an empty cache folder; the solve's program is traced and compiled;
- **warm**: the same folder and a ``--set`` variant (gravity 9.80665 m/s^2: another design
  of the same structure); the program is loaded from the cache.

Each run's ``summary.json`` gives the phases' seconds (``phases_s``: ``compile``, the
tracing and compilation of the solve or its loading; ``solve``; ``outputs``); the process's
wall time is recorded beside them. The target: every cold compile within 2x the paper
preset's, every warm one within 2 s.

    python bench/compile.py [--only NAME ...] [--core N]   # -> bench/results/compile.json
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import machine  # noqa: E402

LINKAGES = ROOT / "docs" / "linkages"
#: the docs' linkages (TOML files) beside the presets
USER = ("crank-rocker", "crank-shaper", "watt-six-bar", "stephenson-six-bar")
VARIANT = "gravity=9.80665"


def _run(source: list[str], cache: Path, out: Path, core: int | None, extra=()) -> dict:
    command = ["jaxcrank", "simulate", *source, "--out", str(out), "--no-figures", "--quiet", *extra]
    if core is not None:
        command = ["taskset", "-c", str(core), *command]
    env = {**__import__("os").environ, "JAXCRANK_CACHE_DIR": str(cache)}
    start = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True, env=env)
    wall = time.perf_counter() - start
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(command)} failed:\n{done.stderr[-2000:]}")
    summary = json.loads((out / "summary.json").read_text())
    return {
        "compile_s": summary["phases_s"]["compile"],
        "solve_s": summary["phases_s"]["solve"],
        "outputs_s": summary["phases_s"]["outputs"],
        "from_cache": summary["program_from_cache"],
        "process_s": wall,
        "steps": summary["solver"]["steps"],
    }


def measure(name: str, core: int | None) -> dict:
    """Cold and warm runs of one mechanism (a preset name, or a docs linkage)."""
    source = ["--config", str(LINKAGES / f"{name}.toml")] if name in USER else ["--mechanism", name]
    with tempfile.TemporaryDirectory() as tmp:
        cache, out = Path(tmp) / "cache", Path(tmp) / "run"
        cold = _run(source, cache, out, core)
        warm = _run(source, cache, out, core, extra=("--set", VARIANT))
    return {"source": " ".join(source), "cold": cold, "warm": warm}


def main(argv=None) -> int:
    from jaxcrank.physics.presets import PRESETS

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--only", nargs="*", help="mechanisms to measure (default: every preset and the docs' linkages)")
    p.add_argument("--core", type=int, default=0, help="the CPU core each process is pinned to (default 0)")
    p.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "compile.json")
    args = p.parse_args(argv)
    names = args.only or ["paper", *(n for n in PRESETS if n not in ("paper", "slider-crank")), *USER]
    if "paper" not in names:
        names = ["paper", *names]
    rows = {}
    for name in names:
        rows[name] = measure(name, args.core)
        r = rows[name]
        print(f"{name:>20}: cold {r['cold']['compile_s']:6.1f} s, warm {r['warm']['compile_s']:5.2f} s", flush=True)
    paper = rows["paper"]["cold"]["compile_s"]
    for r in rows.values():
        r["cold_over_paper"] = r["cold"]["compile_s"] / paper
    worst_cold = max(rows, key=lambda n: rows[n]["cold_over_paper"])
    worst_warm = max(rows, key=lambda n: rows[n]["warm"]["compile_s"])
    result = {
        "command": "python bench/compile.py" + (f" --only {' '.join(args.only)}" if args.only else ""),
        "what": "jaxcrank simulate (defaults, --no-figures --quiet) in fresh processes pinned to one core: cold "
        "(empty cache folder) and warm (same folder, --set " + VARIANT + "); compile = tracing and "
        "compiling the solve, or loading it",
        "machine": machine(core=args.core),
        "mechanisms": rows,
        "summary": {
            "paper_cold_compile_s": paper,
            "worst_cold": {"mechanism": worst_cold, "over_paper": rows[worst_cold]["cold_over_paper"]},
            "worst_warm": {"mechanism": worst_warm, "compile_s": rows[worst_warm]["warm"]["compile_s"]},
            "cold_within_2x_paper": all(r["cold_over_paper"] <= 2.0 for r in rows.values()),
            "warm_within_2_s": all(r["warm"]["compile_s"] <= 2.0 for r in rows.values()),
        },
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps(result["summary"], indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
