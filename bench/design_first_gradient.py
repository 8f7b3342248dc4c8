"""Time to the first exact gradient on every problem of the design family, cold and with a warm
compilation cache.

``python bench/design_first_gradient.py`` runs, for each problem of ``bench/bench_design.py``'s
family, the way in of ``ours`` (the same classification, seed 0) and then the optimiser until its
first exact gradient, each in a fresh process pinned to one core, with JAX's persistent
compilation cache and jaxcrank's program cache in a folder of its own:

- ``cold``: an empty folder, so everything is traced and compiled;
- ``warm``: the same folder again, so the steady-state solve and the gradient programs load;
- ``family``: one folder shared by the family, filled by the preset problem first: each other
  problem starts with the programs the preset compiled (the problems differ only in numbers:
  stroke, crank speed, a bound), so it shows what a designer gets on a new problem of a family.

It writes ``bench/results/design_first_gradient.json`` after every run (``--resume`` skips the
runs there): per run the CPU seconds from the evaluator's making to the first gradient (the way in
and every compilation included, as ``first_gradient_cpu_s`` in ``design.json``), the process's CPU
and wall seconds to then, the seconds spent compiling gradient programs and what the way in
classified. ``bench/bench_design.py --merge`` copies the table into ``design.json``.

    python bench/design_first_gradient.py [--work runs/design-first-gradient] [--resume]   # ~30 min on 2 cores
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "bench" / "results" / "design_first_gradient.json"
FAMILY_FIRST = "preset"


def one(name: str, cache_dir: Path) -> dict:
    """In this process: the way in and the optimiser's first exact gradient on problem ``name``
    with the caches in ``cache_dir``; the row of the table."""
    import jax
    import numpy as np

    jax.config.update("jax_enable_x64", True)
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_design import CLASSIFY, LEARNING_RATE, build, timed_evaluator

    from jaxcrank.runs import cache
    from optim.optimize import Settings, optimize
    from optim.optimizers import adam
    from optim.starts import periodic_start
    from optim.steady import RegimeGuard

    cache.enable(cache_dir)
    cache.checks_as_nan_from_now()
    tic = time.perf_counter()
    problem = build(name)
    ev = timed_evaluator(problem, 3600.0)
    search = periodic_start(problem, count=CLASSIFY, seed=0, evaluator=ev, progress=False)
    way_in_cpu = ev.elapsed()
    settings = Settings(optimizer=adam(LEARNING_RATE), max_iterations=1, guard=RegimeGuard(max_halvings=3))
    structure = {}
    if search.periodic:
        optimize(search.problem, settings, progress=False, evaluator=ev)
        steady = ev.steady_at(np.asarray(search.problem.start))  # classified: no new solve
        # a compiled program is keyed by the problem without its numbers and by these
        period, active = int(steady.period_revolutions), int(np.sum(steady.active))
        structure = {"period_revolutions": period, "dynamic_subspace": active}
    return {
        **structure,
        "problem": name,
        "first_gradient_cpu_s": getattr(ev, "first_gradient_cpu", None),
        "way_in_cpu_s": way_in_cpu,
        "classified": search.describe()["classified"],
        "start_periodic": bool(search.periodic),
        "gradient_compile_s": ev.compile_seconds,
        "process_cpu_s": time.process_time(),
        "wall_s_from_problem": time.perf_counter() - tic,
    }


def _run(name: str, cache_dir: Path, core: int | None) -> dict:
    command = [sys.executable, __file__, "--one", name, "--cache", str(cache_dir)]
    if core is not None:
        command = ["taskset", "-c", str(core)] + command
    out = subprocess.run(command, check=True, capture_output=True, text=True, cwd=ROOT)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--work", type=Path, default=ROOT / "runs" / "design-first-gradient", help="the cache folders")
    p.add_argument("--out", type=Path, default=OUT)
    p.add_argument("--resume", action="store_true", help="keep the runs in --out and do the others")
    p.add_argument("--core", type=int, default=0, help="the core every run is pinned to")
    p.add_argument("--one", help=argparse.SUPPRESS)
    p.add_argument("--cache", type=Path, help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.one:
        print(json.dumps(one(args.one, args.cache)))
        return 0
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from _common import machine
    from bench_design import PROBLEMS

    from jaxcrank.runs.sweep_table import atomic_write

    data = json.loads(args.out.read_text()) if args.resume and args.out.exists() else {"runs": []}
    done = {(r["problem"], r["cache"]) for r in data["runs"]}
    if not args.resume and args.work.exists():
        raise SystemExit(f"{args.work} exists: remove it, or pass --resume (its caches are part of the runs)")
    others = [n for n in PROBLEMS if n != FAMILY_FIRST]
    plan = [(n, label) for n in PROBLEMS for label in ("cold", "warm")] + [(n, "family") for n in others]
    for name, label in plan:
        if (name, label) in done:
            continue
        folder = args.work / ("family" if label == "family" else name)
        if label == "family" and not folder.exists():  # the family's folder starts as the preset's, warm
            shutil.copytree(args.work / FAMILY_FIRST, folder)
        row = {**_run(name, folder, args.core), "cache": label}
        data["runs"].append(row)
        data.update(
            command="python bench/design_first_gradient.py",
            family_filled_by=FAMILY_FIRST,
            machine=machine(load_average=list(os.getloadavg())),
        )
        args.out.parent.mkdir(parents=True, exist_ok=True)
        atomic_write(args.out, lambda f: f.write(json.dumps(data, indent=1, default=float).encode()))
        print(f"{name} {label}: first gradient at {row['first_gradient_cpu_s']} CPU-s", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
