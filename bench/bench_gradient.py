"""A design gradient in seconds: what a user waits for, in new processes.

``python bench/bench_gradient.py [--out bench/results/gradient.json] [--quick]``

On the paper problem (L1, L2) with the objective's defaults (evaluation window
(0.1, 0.3] s, 25 ensemble windows of 2 ms), each configuration runs in a new Python
process with an empty cache folder, then again in another new process with the
folder the first one filled (:mod:`jaxcrank.runs.cache`):

- ``ready_s``: from the process's start (the parent's clock, just before it starts
  Python) until the value-and-gradient program is compiled or loaded;
- ``trace_s``, ``xla_s``: its tracing (or loading the traced program) and XLA's
  compile (or loading the executable);
- ``run_s``: one objective value with its ensemble gradient, after compilation
  (median of three calls); ``value_deg`` and ``gradient_deg_per_m`` of that call.

Configurations: the default (forward-mode windows with ``rodas4``, one after another)
against reverse-mode windows (``Ensemble(window_adjoint=diffrax.RecursiveCheckpointAdjoint())``) in the same
run. Then the command line end to end: ``jaxcrank optimize --grid 0`` cold (empty
cache) and warm (a second run in a new process), wall seconds and iterations.
``--quick`` uses an evaluation window of (0.1, 0.12] s and 2 windows (a smoke run).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _common import machine

ROOT = Path(__file__).resolve().parents[1]

CHILD = r"""
import json, statistics, sys, time
spawned = float(sys.argv[1])
settings = json.loads(sys.argv[2])
import numpy as np
from jaxcrank import cache
cache.enable(sys.argv[3])
from optim.ensemble import Ensemble
from optim.optimize import programs
from optim.presets import paper_problem
import dataclasses
import diffrax
settings = dict(settings)
if settings.pop("window_gradient", "forward") == "reverse":
    settings["window_adjoint"] = diffrax.RecursiveCheckpointAdjoint()
prob = paper_problem(Ensemble(**settings))
vg, _ = programs(dataclasses.replace(prob, start=None))
u = np.asarray(prob.start_unit())
t = time.perf_counter()
lowered = vg.lower(u, 1.0)
trace = time.perf_counter() - t
t = time.perf_counter()
lowered.compile()
xla = time.perf_counter() - t
ready = time.time() - spawned
runs = []
for _ in range(3):
    t = time.perf_counter()
    value, grad = vg(u, 1.0)
    grad.block_until_ready()
    runs.append(time.perf_counter() - t)
grad_si = np.asarray(grad) / np.asarray(prob.span)
print(json.dumps({"ready_s": ready, "trace_s": trace, "xla_s": xla, "run_s": statistics.median(runs),
                  "runs_s": runs, "value_deg": float(value), "gradient_deg_per_m": grad_si.tolist()}))
"""


def child(settings: dict, folder: Path) -> dict:
    """One new process: its times (see the module docstring)."""
    spawned = time.time()
    out = subprocess.run(
        [sys.executable, "-c", CHILD, repr(spawned), json.dumps(settings), str(folder)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def cli(folder: Path, out: Path, extra: list[str]) -> dict:
    """``jaxcrank optimize --grid 0`` in a new process: wall seconds, iterations, result."""
    tic = time.perf_counter()
    subprocess.run(
        [sys.executable, "-m", "jaxcrank.runs.cli", "optimize", "--grid", "0", "--quiet", "--out", str(out)]
        + ["--cache-dir", str(folder)]
        + extra,
        cwd=ROOT,
        check=True,
        capture_output=True,
    )
    wall = time.perf_counter() - tic
    result = json.loads((out / "result.json").read_text())
    return {
        "wall_s": wall,
        "iterations": result["iterations"],
        "optimiser_seconds": result["wall_seconds_this_call"],
        "final_design_SI": result["final_design_SI"],
        "final_objective_deg": result["final_objective_deg"],
        "start_objective_deg": result["start_objective_deg"],
        "reduction_percent": result["reduction_percent"],
        "converged": result["converged"],
        "stop_reason": result["stop_reason"],
    }


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "gradient.json")
    ap.add_argument("--quick", action="store_true", help="a short window (smoke run)")
    args = ap.parse_args(argv)
    base = dict(t_end=0.12, windows=2) if args.quick else {}
    configs = {
        "forward_rodas4 (default)": base,
        "reverse_rodas4": {**base, "window_gradient": "reverse"},
    }
    res = {
        "machine": machine(),
        "quick": args.quick,
        "objective": base or "defaults",
        "load_average_start": os.getloadavg()[0],
        "configs": {},
    }
    with tempfile.TemporaryDirectory() as tmp:
        for i, (name, settings) in enumerate(configs.items()):
            folder = Path(tmp) / f"cache{i}"
            cold = child(settings, folder)
            warm = child(settings, folder)
            res["configs"][name] = {"settings": settings, "cold": cold, "warm": warm}
            print(name, json.dumps(res["configs"][name]), flush=True)
        folder = Path(tmp) / "cli"
        extra = ["--t-end", "0.12", "--windows", "2", "--iterations", "3"] if args.quick else []
        res["cli"] = {
            "command": "jaxcrank optimize --grid 0 " + " ".join(extra),
            "cold": cli(folder, Path(tmp) / "run1", extra),
            "warm": cli(folder, Path(tmp) / "run2", extra),
        }
        print("cli", json.dumps(res["cli"]), flush=True)
    res["load_average_end"] = os.getloadavg()[0]
    d = res["configs"]["forward_rodas4 (default)"]
    res["targets"] = {
        "run_s <= 2": d["cold"]["run_s"] <= 2.0,
        "cold compile (trace + xla) <= 20 s": d["cold"]["trace_s"] + d["cold"]["xla_s"] <= 20.0,
        "warm ready_s <= 5": d["warm"]["ready_s"] <= 5.0,
        "cli cold wall_s <= 60": res["cli"]["cold"]["wall_s"] <= 60.0,
    }
    res["speedup_run_forward_vs_reverse"] = statistics.mean(
        [res["configs"]["reverse_rodas4"][k]["run_s"] / d[k]["run_s"] for k in ("cold", "warm")]
    )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(res, indent=2))
    print(json.dumps(res["targets"], indent=2))


if __name__ == "__main__":
    os.environ.setdefault("PYTHONUNBUFFERED", "1")
    main()
