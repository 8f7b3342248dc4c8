"""Benchmark: the paper run with the generic mechanism formulation against the old
slider-crank-specific code, measured in the same run.

    taskset -c 1 python bench/formulation.py [--old-commit cdff866] [--repeats 7]
        [--compile-repeats 3] [--out bench/results/formulation.json]

The old code is the package ``jaxcrank`` at ``--old-commit`` (the last commit before the
generic formulation), extracted with ``git archive`` into a temporary folder as the
package ``jaxcrank_old``, so both import side by side. The run is the one of
``jaxcrank simulate`` on the paper preset: 0.4 s (four revolutions at 600 rpm), tsit5,
rtol = atol = 1e-6, ten samples per degree, the headline metrics tracked after the first
revolution.

Measured:

- the solve after compilation: old and new alternate in one process, each run's process
  CPU time and wall time, the minimum over ``--repeats`` (other load on the machine only
  adds time, so the minimum of interleaved runs is the fairest ratio);
- compilation: each variant in a fresh process, the first call's wall time minus a second
  call's, with JAX's own trace, lowering and backend-compile durations, the minimum over
  ``--compile-repeats`` processes;
- the vector field alone: a ``lax.fori_loop`` of 10 000 evaluations (the mechanism a
  compile-time constant), ns per evaluation, interleaved, minimum of CPU time.

Steps and metrics of both runs are written too (they agree to the solve's noise). Pin the
process to one core (``taskset``): XLA's CPU threads would otherwise make CPU time and wall
time differ.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(REPO))  # this checkout's jaxcrank, whatever is installed
T1 = 0.4  # s, as `jaxcrank simulate`
SAMPLES_PER_DEGREE = 10.0
FIELD_CALLS = 10_000


def extract_old(commit: str, into: Path) -> Path:
    """The package ``jaxcrank`` at ``commit`` as ``into/jaxcrank_old`` (it imports itself
    only relatively, so the folder's name is the package's)."""
    archive = subprocess.run(["git", "-C", str(REPO), "archive", commit, "jaxcrank"], check=True, capture_output=True)
    subprocess.run(["tar", "-x", "-C", str(into)], input=archive.stdout, check=True)
    (into / "jaxcrank").rename(into / "jaxcrank_old")
    return into


def load(variant: str):
    """(package, solve module, model module) of ``variant`` ("new" or "old")."""
    if variant == "new":
        import jaxcrank as pkg
        from jaxcrank import model
        from jaxcrank.numerics import solve
    else:
        import jaxcrank_old as pkg
        from jaxcrank_old import model
        from jaxcrank_old.numerics import solve
    return pkg, solve, model


def paper_run(variant: str):
    """A function that runs the paper solve of ``variant`` and returns the Simulation."""
    import jax

    pkg, solve, _ = load(variant)
    mech = pkg.paper()
    speed = float(mech.speed) if variant == "new" else float(mech.crank_speed)
    import math

    n_samples = int(round(math.degrees(speed * T1) * SAMPLES_PER_DEGREE)) + 1
    period = float(mech.period)
    options = solve.SolveOptions()

    def run():
        sim = solve.simulate(mech, T1, n_samples=n_samples, options=options, metrics_start=period)
        jax.block_until_ready(sim.ys)
        return sim

    return run


def field_loop(variant: str):
    """A compiled loop of FIELD_CALLS vector-field evaluations at changing states."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    pkg, _, model = load(variant)
    mech = pkg.paper()
    y0 = jnp.asarray(np.random.default_rng(0).normal(size=model.state_size(mech)) * 0.1)

    @jax.jit
    def loop(y):
        return jax.lax.fori_loop(0, FIELD_CALLS, lambda k, y: y + 1e-12 * model.vector_field(k * 1e-6, y, mech), y)

    jax.block_until_ready(loop(y0))
    return lambda: jax.block_until_ready(loop(y0))


def worker(variant: str) -> dict:
    """In a fresh process: the first call (trace, compile, run) and a second (run)."""
    import jax

    durations: dict[str, float] = {}

    def listen(event, seconds, **_):
        durations[event] = durations.get(event, 0.0) + seconds

    jax.monitoring.register_event_duration_secs_listener(listen)
    run = paper_run(variant)
    start = time.perf_counter()
    run()
    first = time.perf_counter() - start
    start = time.perf_counter()
    run()
    second = time.perf_counter() - start
    pick = {
        "trace_s": "/jax/core/compile/jaxpr_trace_duration",
        "lower_s": "/jax/core/compile/jaxpr_to_mlir_module_duration",
        "backend_compile_s": "/jax/core/compile/backend_compile_duration",
    }
    return {
        "first_call_s": first,
        "second_call_s": second,
        "compile_s": first - second,
        **{k: durations.get(v, 0.0) for k, v in pick.items()},
    }


def compile_times(old_path: Path, repeats: int) -> dict:
    out: dict[str, list] = {"new": [], "old": []}
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(REPO), str(old_path), os.environ.get("PYTHONPATH", "")]))
    for _ in range(repeats):
        for variant in ("old", "new"):
            proc = subprocess.run(
                [sys.executable, __file__, "--worker", variant], check=True, capture_output=True, text=True, env=env
            )
            out[variant].append(json.loads(proc.stdout.strip().splitlines()[-1]))
    best = {v: {k: min(r[k] for r in runs) for k in runs[0]} for v, runs in out.items()}
    return {"best": best, "runs": out}


def interleaved(fns: dict, repeats: int) -> dict:
    """Minimum process CPU time and wall time of each function, called in turn."""
    best = {k: {"cpu_s": float("inf"), "wall_s": float("inf")} for k in fns}
    for _ in range(repeats):
        for k, fn in fns.items():
            c0, w0 = time.process_time(), time.perf_counter()
            fn()
            c1, w1 = time.process_time(), time.perf_counter()
            best[k]["cpu_s"] = min(best[k]["cpu_s"], c1 - c0)
            best[k]["wall_s"] = min(best[k]["wall_s"], w1 - w0)
    return best


def git_hash(ref: str) -> str:
    return subprocess.run(
        ["git", "-C", str(REPO), "rev-parse", ref], check=True, capture_output=True, text=True
    ).stdout.strip()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--old-commit", default="cdff866", help="the commit of the old code (default cdff866)")
    parser.add_argument("--repeats", type=int, default=7, help="interleaved solves of each (default 7)")
    parser.add_argument("--compile-repeats", type=int, default=3, help="fresh processes per variant (default 3)")
    parser.add_argument("--out", type=Path, default=HERE / "results" / "formulation.json")
    parser.add_argument("--worker", choices=("new", "old"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        print(json.dumps(worker(args.worker)))
        return

    with tempfile.TemporaryDirectory() as tmp:
        old_path = extract_old(args.old_commit, Path(tmp))
        sys.path.insert(0, str(old_path))
        import jax
        import numpy as np
        from _common import machine

        compiled = compile_times(old_path, args.compile_repeats)
        runs = {v: paper_run(v) for v in ("old", "new")}
        sims = {v: run() for v, run in runs.items()}  # compile both
        solve_best = interleaved(runs, args.repeats)
        fields = {v: field_loop(v) for v in ("old", "new")}
        field_best = interleaved(fields, args.repeats)

    def metrics(sim):
        return {k: float(np.asarray(v)) for k, v in (sim.metrics or {}).items()}

    m_old, m_new = metrics(sims["old"]), metrics(sims["new"])
    common = sorted(set(m_old) & set(m_new))
    result = {
        "machine": machine(pinned_cpus=sorted(os.sched_getaffinity(0)), jax_x64=bool(jax.config.jax_enable_x64)),
        "commits": {"new": git_hash("HEAD"), "old": git_hash(args.old_commit)},
        "run": {
            "what": "jaxcrank simulate on the paper preset",
            "t1_s": T1,
            "solver": "tsit5",
            "rtol": 1e-6,
            "atol": 1e-6,
            "samples_per_degree": SAMPLES_PER_DEGREE,
            "metrics_start": "one period",
        },
        "solve": {
            "repeats": args.repeats,
            "old": solve_best["old"],
            "new": solve_best["new"],
            "ratio_cpu": solve_best["new"]["cpu_s"] / solve_best["old"]["cpu_s"],
            "ratio_wall": solve_best["new"]["wall_s"] / solve_best["old"]["wall_s"],
            "steps": {v: int(s.num_steps) for v, s in sims.items()},
            "rejected_steps": {v: int(s.num_rejected) for v, s in sims.items()},
        },
        "compile": {
            "repeats": args.compile_repeats,
            "old": compiled["best"]["old"],
            "new": compiled["best"]["new"],
            "ratio": compiled["best"]["new"]["compile_s"] / compiled["best"]["old"]["compile_s"],
            "runs": compiled["runs"],
        },
        "vector_field": {
            "calls": FIELD_CALLS,
            "old_ns_per_call": field_best["old"]["cpu_s"] / FIELD_CALLS * 1e9,
            "new_ns_per_call": field_best["new"]["cpu_s"] / FIELD_CALLS * 1e9,
            "ratio": field_best["new"]["cpu_s"] / field_best["old"]["cpu_s"],
        },
        "metrics_old_vs_new": {k: {"old": m_old[k], "new": m_new[k]} for k in common},
        "note": "minimum over interleaved repeats of process CPU time (solve, field) and over fresh processes "
        "(compile: first call minus second call; trace/lower/backend_compile from jax.monitoring)",
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    s, c, f = result["solve"], result["compile"], result["vector_field"]
    print(
        f"solve  old {s['old']['cpu_s']:.3f} s  new {s['new']['cpu_s']:.3f} s  ratio {s['ratio_cpu']:.3f} (cpu), "
        f"{s['ratio_wall']:.3f} (wall); steps {s['steps']}"
    )
    print(f"compile old {c['old']['compile_s']:.1f} s  new {c['new']['compile_s']:.1f} s  ratio {c['ratio']:.2f}")
    print(f"field  old {f['old_ns_per_call']:.0f} ns  new {f['new_ns_per_call']:.0f} ns  ratio {f['ratio']:.3f}")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
