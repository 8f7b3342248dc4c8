"""Start-up time of the command line: ``jaxcrank --help`` and each command's ``--help``.

    python bench/cli_startup.py [--repeats 7] [--label NAME] [--out bench/results/cli_startup.json]

Each case runs in a new Python process (``python -c`` running the CLI's ``main`` as the
``jaxcrank`` script does) ``--repeats`` times; the JSON gets the median and minimum wall
time (s) and whether JAX, diffrax and optax were imported. Results accumulate under
``--label`` (e.g. ``before`` and ``after`` a change) in the JSON file.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

from _common import machine

ROOT = Path(__file__).resolve().parent.parent
CASES = {
    "jaxcrank --help": ["--help"],
    "jaxcrank simulate --help": ["simulate", "--help"],
    "jaxcrank optimize --help": ["optimize", "--help"],
}
PROBE = """
import sys
from jaxcrank.runs.cli import main
try:
    main({argv!r})
except SystemExit:
    pass
print("MODULES", *[m for m in ("jax", "diffrax", "optax") if m in sys.modules], file=sys.stderr)
"""


def run_case(argv: list[str], repeats: int) -> dict:
    walls, loaded = [], None
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    for _ in range(repeats):
        tic = time.perf_counter()
        proc = subprocess.run(
            [sys.executable, "-c", PROBE.format(argv=argv)], cwd=ROOT, env=env, capture_output=True, text=True
        )
        walls.append(time.perf_counter() - tic)
        line = [ln for ln in proc.stderr.splitlines() if ln.startswith("MODULES")]
        if proc.returncode != 0 or not line:
            raise RuntimeError(f"{argv}: exit {proc.returncode}: {proc.stderr[-2000:]}")
        loaded = line[0].split()[1:]
    return {"median_s": statistics.median(walls), "min_s": min(walls), "repeats": repeats, "imported": loaded}


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--repeats", type=int, default=7)
    p.add_argument("--label", default="current")
    p.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "cli_startup.json")
    args = p.parse_args()
    data = json.loads(args.out.read_text()) if args.out.exists() else {"runs": {}}
    rows = {}
    for name, argv in CASES.items():
        rows[name] = run_case(argv, args.repeats)
        print(f"{args.label}: {name}: median {rows[name]['median_s']:.2f} s, imports {rows[name]['imported']}")
    data["runs"][args.label] = {"cases": rows, "machine": machine()}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(data, indent=2))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
