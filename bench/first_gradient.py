"""The default design command, cold and with a warm compilation cache: how long to the first exact
gradient, and to the end?

``python bench/first_gradient.py`` runs ``jaxcrank optimize --problem design`` twice in fresh
processes with one new cache folder: the first compiles everything (cold), the second loads the
compiled programs (warm). Then, with the same cache, the same problem as a problem file (the
constrained solver's programs, compiled once here) and a variant that differs from it only in its
numbers (the crank 10 % slower, the stroke 230 mm instead of 240 mm), whose programs are the same.
It writes ``bench/results/first_gradient.json``: per run the wall time of the command,
``result.json``'s ``time_to_first_gradient_s`` (from the evaluator's making, the way in included)
and its seconds by phase, the final objective and the cache folder's size.
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


def _variant(speed_factor: float = 0.9, stroke: str = "0.230") -> str:
    """The design problem's file with the crank's speed times ``speed_factor`` and the stroke ``stroke``
    (m): only numbers change."""
    import math

    from optim import presets

    text = presets.problem_text("design")
    speed = speed_factor * 600.0 * 2.0 * math.pi / 60.0
    driver = f'preset = "paper"\n\n[mechanism.driver]\nspeed = {speed!r}  # rad/s\n'
    changed = text.replace('preset = "paper"\n', driver, 1)
    changed = changed.replace("stroke = 0.240", f"stroke = {stroke}", 1)
    assert changed.count("[mechanism.driver]") == 1 and f"stroke = {stroke}" in changed, "the design file changed"
    return changed


#: a design of the unit box where the design problem and its variant are both periodic, period 1
SHARED_DESIGN = (0.0658, 0.634, 0.167, 0.157, 0.893, 0.0753, 0.049, 0.5625, 0.7557)


def _in_process() -> list[dict]:
    """The problem file and its variant in one process (no cache folder), each's outputs and exact
    Jacobian at `SHARED_DESIGN`: the seconds each evaluator spent compiling gradient programs, the
    orbit's period and dynamic subspace (the program's structure besides the problem's)."""
    import numpy as np

    from optim import spec
    from optim.constrained import QuantityEvaluator

    out = []
    with tempfile.TemporaryDirectory() as tmp:
        for label, text in (("file", _variant(1.0, "0.240")), ("file variant", _variant())):
            path = Path(tmp) / "problem.toml"
            path.write_text(text)
            problem, _ = spec.load(path)
            x = np.asarray(problem.lower) + np.asarray(SHARED_DESIGN) * np.subtract(problem.upper, problem.lower)
            ev = QuantityEvaluator(problem)
            tic = time.perf_counter()
            _, _, info = ev.outputs_and_jacobian(x)
            steady = ev.steady_at(x)
            out.append({
                "problem": label, "regime": info["regime"], "period_revolutions": steady.period_revolutions,
                "dynamic_subspace": int(np.sum(np.asarray(steady.active))), "seconds": time.perf_counter() - tic,
                "gradient_compile_s": ev.compile_seconds,
            })  # fmt: skip
            print(f"in process, {label}: compiling {ev.compile_seconds:.1f} s", flush=True)
    return out


def main(argv=None) -> int:
    from _common import machine

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "first_gradient.json")
    args = p.parse_args(argv)
    runs = []
    with tempfile.TemporaryDirectory() as tmp:
        cache = Path(tmp) / "cache"
        variant, as_file = Path(tmp) / "design-variant.toml", Path(tmp) / "design.toml"
        variant.write_text(_variant())
        as_file.write_text(_variant(speed_factor=1.0, stroke="0.240"))  # the same problem, as a file
        runs_ = (("cold", "design"), ("warm", "design"), ("file", str(as_file)), ("file variant", str(variant)))
        for label, problem in runs_:
            out = Path(tmp) / label.replace(" ", "_")
            cmd = ["jaxcrank", "optimize", "--problem", problem, "--out", str(out), "--cache-dir", str(cache)]
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
                    "seconds_this_call": result.get("seconds_this_call", result.get("seconds")),
                    "problem": problem if problem == "design" else Path(problem).name,
                    "final_objective": result.get("final_objective_deg", result.get("objective_final")),
                    "stop_reason": result.get("stop_reason"),
                    "cache_bytes_after": _size(cache),
                }
            )
            print(
                f"{label}: {wall:.0f} s, first gradient {result['time_to_first_gradient_s']:.1f} s, "
                f"final {runs[-1]['final_objective']:.5f}",
                flush=True,
            )
    shared = _in_process()
    out = {
        "command": "python bench/first_gradient.py " + " ".join(sys.argv[1:]),
        "runs": runs,
        "in_process": shared,
        "machine": machine(),
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(out, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
