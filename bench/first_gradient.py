"""The default design command, cold and with a warm compilation cache: how long to the first exact
gradient, and to the end?

``python bench/first_gradient.py [--problem design]`` runs ``jaxcrank optimize --problem NAME`` twice
in fresh processes with one new cache folder: the first compiles everything (cold), the second loads
the compiled programs (warm). It writes ``bench/results/first_gradient.json``: per run the wall time
of the command, ``result.json``'s ``time_to_first_gradient_s`` (from the evaluator's making, the way
in included) and ``seconds_this_call``, the final objective and the cache folder's size.
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


def _size(folder: Path) -> int:
    return sum(f.stat().st_size for f in folder.rglob("*") if f.is_file())


def main(argv=None) -> int:
    from _common import machine

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--problem", default="design")
    p.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "first_gradient.json")
    args = p.parse_args(argv)
    runs = []
    with tempfile.TemporaryDirectory() as tmp:
        cache = Path(tmp) / "cache"
        for label in ("cold", "warm"):
            out = Path(tmp) / label
            cmd = ["jaxcrank", "optimize", "--problem", args.problem, "--out", str(out), "--cache-dir", str(cache)]
            tic = time.perf_counter()
            subprocess.run(cmd + ["--quiet"], check=True, cwd=ROOT)
            wall = time.perf_counter() - tic
            result = json.loads((out / "result.json").read_text())
            runs.append(
                {
                    "cache": label,
                    "command": " ".join(cmd),
                    "wall_s": wall,
                    "time_to_first_gradient_s": result["time_to_first_gradient_s"],
                    "seconds_this_call": result["seconds_this_call"],
                    "final_objective_deg": result["final_objective_deg"],
                    "stop_reason": result["stop_reason"],
                    "cache_bytes_after": _size(cache),
                }
            )
            print(
                f"{label}: {wall:.0f} s, first gradient {result['time_to_first_gradient_s']:.1f} s, "
                f"final {result['final_objective_deg']:.5f} deg",
                flush=True,
            )
    out = {"command": "python bench/first_gradient.py " + " ".join(sys.argv[1:]), "runs": runs, "machine": machine()}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(out, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
