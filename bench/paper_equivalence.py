"""The paper run on this checkout against an earlier commit, in one run: trajectories over
the first 20 ms and the 0.4 s metrics, beside the same comparison of each code with
itself after a rounding-level change of its start (every state entry + 1e-15 scaled
units). After the first impacts the motion amplifies rounding, so two formulations that
differ only in rounding differ as much as one code does from itself. For the 0.4 s
metrics each code also runs ``--starts`` starts (every entry + k * 1e-15, k = 0, 1, ...):
their mean and standard deviation per code, and the difference of the two means in units
of its standard error.

    python bench/paper_equivalence.py --base cdff866 [--starts 8] [--repeats 3]
    # -> bench/results/paper_equivalence.json

Speed, both codes in the same run, on one pinned core: the paper solve (0.4 s, 14401
samples, metrics after 0.1 s) compiled with the mechanism's numbers as constants, the
least of seven rounds that take the codes in turn, after compilation, per solver step
(this code also with the numbers as the program's inputs, as its command line compiles
them), in ``--processes`` fresh processes (the speed of a compiled program varies from
one process to the next) and their median; and the paper run as a user runs it,
``jaxcrank simulate --no-figures --quiet`` in ``--repeats`` fresh processes of each code
taken in turn (this code with no cache, with its cache warm, and with
``--fold-parameters``), the processes' wall times and the solve phases their summaries
report.

The earlier commit's package is copied (from ``git worktree``) under the name
``jaxcrank_base`` and imported beside this one.
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import platform
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
COLUMNS = ["slider_x", "rod_x", "ecc_B_x", "ecc_B_y", "ecc_C_x", "ecc_C_y", "force_B_normal", "driving_moment"]
TIMES = [0.001, 0.00125, 0.0015, 0.002, 0.005, 0.01, 0.02, 0.1, 0.4]
PERTURBATION = 1e-15


def _base_package(commit: str, where: Path) -> None:
    tree = where / "tree"
    subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(tree), commit], check=True,
                   capture_output=True)  # fmt: skip
    try:
        shutil.copytree(tree / "jaxcrank", where / "pkg" / "jaxcrank_base")
    finally:
        subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tree)], check=True)
    for path in (where / "pkg" / "jaxcrank_base").rglob("*.py"):
        text = path.read_text()
        text = re.sub(r"\bfrom jaxcrank\b", "from jaxcrank_base", text)
        text = re.sub(r"\bimport jaxcrank\b", "import jaxcrank_base", text)
        path.write_text(text)


def _run(package, perturbation: float):
    import jax.numpy as jnp

    mech = package.paper()
    model, outputs = package.model, package.outputs
    ts = jnp.linspace(0.0, 0.4, 14401)
    y0 = model.initial_state(mech) + perturbation
    sim = package.simulate(mech, ts=ts, y0=y0, metrics_start=0.1)
    cols = outputs.trajectory(sim)
    return {k: np.asarray(cols[k]) for k in ["t", *COLUMNS]}, {k: float(v) for k, v in sim.metrics.items()}


def _solve_costs(variants: dict, rounds: int = 7) -> dict:
    """Per variant (``name: (package, values)``), the paper solve's least wall time after
    compilation over ``rounds`` rounds that take the variants in turn (so that a change of
    the machine's speed touches every variant alike), and per solver step."""
    import jax
    import jax.numpy as jnp

    ts = np.asarray(jnp.linspace(0.0, 0.4, 14401))
    prepared = {}
    for name, (package, values) in variants.items():
        mech = package.paper()
        if values:  # the numbers as arguments of the jitted function: traced, inputs of the program
            run = jax.jit(lambda m, package=package: package.simulate(m, ts=ts, metrics_start=0.1, throw=False))
            call = functools.partial(run, package.solve.as_values(mech))
        else:  # the numbers closed over: constants of the program
            call = jax.jit(
                lambda package=package, mech=mech: package.simulate(mech, ts=ts, metrics_start=0.1, throw=False)
            )
        sim = jax.block_until_ready(call())
        prepared[name] = (call, int(sim.num_steps) + int(sim.num_rejected))
    best = {name: float("inf") for name in variants}
    for _ in range(rounds):
        for name, (call, _) in prepared.items():
            best[name] = min(best[name], _wall(lambda call=call: jax.block_until_ready(call())))
    return {
        name: {"best_s": best[name], "steps_incl_rejected": steps, "us_per_step": best[name] / steps * 1e6}
        for name, (_, steps) in prepared.items()
    }


VARIANTS = {"base_constants": ("jaxcrank_base", False), "this_constants": ("jaxcrank", False),
            "this_values": ("jaxcrank", True)}  # fmt: skip


def _solve_costs_in_processes(pkg_path: Path, processes: int, core: int) -> dict:
    """[`_solve_costs`] of the three variants in ``processes`` fresh processes (a program's
    speed varies from one compilation and process to the next): each process's numbers,
    and per variant the median over processes of its least time per step."""
    env = dict(os.environ, PYTHONPATH=f"{ROOT}{os.pathsep}{pkg_path}")
    per_process = []
    for _ in range(processes):
        cmd = ["taskset", "-c", str(core), sys.executable, str(Path(__file__).resolve()), "--solve-cost-only"]
        done = subprocess.run(cmd, env=env, check=True, capture_output=True, text=True)
        per_process.append(json.loads(done.stdout.strip().splitlines()[-1]))
    median = {name: float(np.median([p[name]["us_per_step"] for p in per_process])) for name in VARIANTS}
    return {
        "processes": per_process,
        "median_us_per_step": median,
        "median_over_base": {name: median[name] / median["base_constants"] for name in VARIANTS},
    }


def _wall(fn) -> float:
    start = time.perf_counter()
    fn()
    return time.perf_counter() - start


def _cli_runs(pkg_path: Path, repeats: int, core: int) -> dict:
    """``--repeats`` fresh processes of each code's ``simulate`` on the paper defaults, in turn."""
    variants = {
        "base": ("jaxcrank_base", []),
        "this_no_cache": ("jaxcrank", ["--no-cache"]),
        "this_warm_cache": ("jaxcrank", []),
        "this_fold_parameters": ("jaxcrank", ["--no-cache", "--fold-parameters"]),
    }
    runs = {name: [] for name in variants}
    with tempfile.TemporaryDirectory() as tmp:
        env = dict(os.environ, PYTHONPATH=f"{ROOT}{os.pathsep}{pkg_path}", JAXCRANK_CACHE_DIR=str(Path(tmp) / "cache"))
        for k in range(repeats + 1):  # the first round warms this code's cache and is not kept
            for name, (module, extra) in variants.items():
                out = Path(tmp) / name
                cmd = ["taskset", "-c", str(core), sys.executable, "-m", f"{module}.runs.cli", "simulate"]
                cmd += ["--out", str(out), "--no-figures", "--quiet", *extra]
                start = time.perf_counter()
                subprocess.run(cmd, env=env, check=True, capture_output=True, cwd=tmp)
                wall = time.perf_counter() - start
                if k == 0:
                    continue
                summary = json.loads((out / "summary.json").read_text())
                row = {"process_s": wall, "wall_time_s": summary["wall_time_s"], "steps": summary["solver"]["steps"]}
                if "phases_s" in summary:
                    row["phases_s"] = summary["phases_s"]
                    row["solve_us_per_step"] = (
                        summary["phases_s"]["solve"]
                        / (summary["solver"]["steps"] + summary["solver"]["rejected_steps"])
                        * 1e6
                    )
                runs[name].append(row)
    medians = {name: float(np.median([r["process_s"] for r in rows])) for name, rows in runs.items()}
    solve = {
        name: float(np.median([r["solve_us_per_step"] for r in rows]))
        for name, rows in runs.items()
        if rows and "solve_us_per_step" in rows[0]
    }
    return {
        "repeats": repeats,
        "runs": runs,
        "median_process_s": medians,
        "median_solve_us_per_step": solve,
        "median_process_over_base": {name: m / medians["base"] for name, m in medians.items()},
    }


def _divergence(a, b) -> dict:
    t = a["t"]
    out = {}
    for tt in TIMES:
        i = int(np.searchsorted(t, tt)) + 1
        out[f"{tt:g}"] = {k: float(np.max(np.abs(a[k][:i] - b[k][:i]))) for k in COLUMNS}
    return out


def _relative_first_ms(a, b) -> dict:
    """Per column, the largest difference over the first millisecond over the largest |value| there."""
    i = int(np.searchsorted(a["t"], 1e-3)) + 1
    return {k: float(np.max(np.abs(a[k][:i] - b[k][:i])) / max(np.max(np.abs(b[k][:i])), 1e-300)) for k in COLUMNS}


def _over_starts(spread: dict) -> dict:
    """Per metric both codes share: each code's mean and sample standard deviation over its
    starts, and the difference of the means over its standard error."""
    out = {}
    for key in sorted(set(spread["this"][0]) & set(spread["base"][0])):
        a = np.array([m[key] for m in spread["this"]])
        b = np.array([m[key] for m in spread["base"]])
        se = float(np.sqrt(a.var(ddof=1) / a.size + b.var(ddof=1) / b.size))
        out[key] = {
            "this_mean": float(a.mean()),
            "this_std": float(a.std(ddof=1)),
            "base_mean": float(b.mean()),
            "base_std": float(b.std(ddof=1)),
            "difference_over_standard_error": float((a.mean() - b.mean()) / se) if se > 0 else 0.0,
        }
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--base", default="cdff866", help="the earlier commit (default: the last slider-crank-only one)")
    p.add_argument("--starts", type=int, default=8, help="starts per code for the metrics' spread (>= 2)")
    p.add_argument("--repeats", type=int, default=3, help="fresh command-line processes per code (0: none)")
    p.add_argument("--core", type=int, default=0, help="the CPU core everything is pinned to")
    p.add_argument("--processes", type=int, default=5, help="fresh processes that each time the three solves")
    p.add_argument("--solve-cost-only", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "paper_equivalence.json")
    args = p.parse_args(argv)
    if args.solve_cost_only:  # one process of _solve_costs_in_processes: the packages are on PYTHONPATH
        import importlib

        print(json.dumps(_solve_costs({k: (importlib.import_module(m), v) for k, (m, v) in VARIANTS.items()})))
        return 0
    with tempfile.TemporaryDirectory() as tmp:
        _base_package(args.base, Path(tmp))
        sys.path.insert(0, str(Path(tmp) / "pkg"))
        import jaxcrank_base

        import jaxcrank

        os.sched_setaffinity(0, {args.core})
        runs, spread = {}, {"this": [], "base": []}
        for name, package in (("this", jaxcrank), ("base", jaxcrank_base)):
            for k in range(max(args.starts, 2)):
                runs[(name, k * PERTURBATION)] = _run(package, k * PERTURBATION)
                spread[name].append(runs[(name, k * PERTURBATION)][1])
        solve_cost = _solve_costs_in_processes(Path(tmp) / "pkg", args.processes, args.core)
        cli_runs = _cli_runs(Path(tmp) / "pkg", args.repeats, args.core) if args.repeats > 0 else None
    head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "HEAD"], capture_output=True, text=True).stdout.strip()
    metrics = {name: runs[(name, 0.0)][1] for name in ("this", "base")}
    metrics.update({f"{name}_perturbed": runs[(name, PERTURBATION)][1] for name in ("this", "base")})
    result = {
        "command": f"python bench/paper_equivalence.py --base {args.base} --starts {args.starts} "
        f"--repeats {args.repeats} --processes {args.processes}",
        "this_commit": head,
        "base_commit": args.base,
        "machine": platform.processor() or platform.machine(),
        "cpu_count": os.cpu_count(),
        "perturbation_scaled": PERTURBATION,
        "max_abs_difference_up_to_t_s": {
            "this_vs_base": _divergence(runs[("this", 0.0)][0], runs[("base", 0.0)][0]),
            "base_vs_base_perturbed": _divergence(runs[("base", 0.0)][0], runs[("base", PERTURBATION)][0]),
            "this_vs_this_perturbed": _divergence(runs[("this", 0.0)][0], runs[("this", PERTURBATION)][0]),
        },
        "relative_difference_first_ms_this_vs_base": _relative_first_ms(runs[("this", 0.0)][0], runs[("base", 0.0)][0]),
        "metrics_after_0.1_s": metrics,
        "metrics_over_starts": _over_starts(spread),
        "solve_cost": solve_cost,
        "command_line": cli_runs,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
