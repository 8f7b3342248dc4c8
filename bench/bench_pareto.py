"""Pareto fronts three ways: the epsilon-constraint front with exact gradients (optim.pareto)
against a brute-force grid and NSGA-II (pymoo), on the same two objectives and the same truth.

The problem is ``bench/pareto-four-bar.toml``: the four-bar preset (``jaxcrank.four_bar()``, 600
rpm, 0.5 mm radial clearance at B and C) with the coupler and rocker lengths as variables, the
first objective the paper's Eq. 19 (``rms_transmission_angle_error_deg``, deg) and the second the
peak contact force at B (``peak_contact_force_B_N``, N), both over the steady orbit.

- ``gradient``: [`optim.pareto.run_front`][] (two anchors and ``points - 2`` epsilon points, each
  ``--iterations`` Adam steps of ``--rounds`` augmented-Lagrangian rounds, warm-started);
- ``grid``: every design of an ``--grid`` x ``--grid`` grid over the box (serpentine order, each
  steady state warm-started from its neighbour's);
- ``nsga2``: pymoo's NSGA-II, ``--population`` designs for ``--generations`` generations (seed 1).

The same truth: every design of every method is measured by
[`optim.constrained.QuantityEvaluator.outputs_at`][] (the metrics over one period of the steady
orbit; where the motion is not periodic, their long-run statistical values), through
[`optim.pareto.measure`][]. Each method's feasible non-dominated designs are its front; all fronts
are scored by the 2-D hypervolume against one reference, the nadir of the union of the fronts plus
10 % of its range. NSGA-II's hypervolume is recorded after every evaluation (its archive of all
designs so far) with the CPU time then, and so the CPU time it took to reach the gradient front's
hypervolume (None: not within its budget). CPU seconds are ``time.process_time()`` of this process
(XLA's threads included), compilation included: JAX's caches and the compiled gradient programs
are dropped before each method, so each compiles its own.

Usage: ``python bench/bench_pareto.py [--grid 5] [--generations 3] [--population 8] [--points 5]
[--iterations 8] [--rounds 1] [--learning-rate 0.3] [--settle 10]``; writes ``bench/results/pareto.json`` (and the
three fronts' figure ``bench/results/pareto.png``).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import shutil
import tempfile
import time
from pathlib import Path

import jax
import numpy as np
from _common import machine

from optim import constrained, pareto, spec
from optim.programs import forget_programs

ROOT = Path(__file__).resolve().parent
PROBLEM = ROOT / "pareto-four-bar.toml"
#: a front point's entries in the JSON's ``fronts``
SHOWN = ("design_SI", "objective", "quantity")
#: the target the benchmark is read against
TARGET = {"hypervolume_of_grid_within": 0.01, "cpu_faster_than_nsga2": 5.0}


def fresh() -> None:
    """Drop JAX's compiled programs and the gradient programs: the next method compiles its own."""
    jax.clear_caches()
    forget_programs()


def evaluate(problem, front, designs, label: str) -> list[dict]:
    """Measure ``designs`` in order with one evaluator (each warm-started from the last periodic
    steady state): per design its values ([`optim.pareto.measure`][]) and the CPU seconds since the
    method started (its first evaluation compiles)."""
    ev = constrained.QuantityEvaluator(pareto.bounded(problem, front, math.inf, 1.0))
    out, tic = [], time.process_time()
    for k, x in enumerate(designs):
        values = pareto.measure(ev, problem, front, x)
        out.append({"design_SI": [float(v) for v in x], **values, "cpu_seconds": time.process_time() - tic})
        print(f"{label} {k + 1}/{len(designs)}: {values['objective']:.5g}, {values['quantity']:.5g}", flush=True)
    return out


def objectives(points) -> np.ndarray:
    """(points, 2): (f1, f2) of the feasible points, NaN for the others."""
    rows = [[p["objective"], p["second"]] if p["feasible"] else [math.nan, math.nan] for p in points]
    return np.asarray(rows, dtype=float).reshape(-1, 2)


def front_of(points) -> list[dict]:
    """The feasible non-dominated points."""
    mask = pareto.nondominated(objectives(points)) if points else []
    return [p for p, m in zip(points, mask) if m]


def nsga2(problem, front, population: int, generations: int) -> list[dict]:
    """NSGA-II's archive: every design it evaluated, in order, measured as ``evaluate`` does."""
    from pymoo.algorithms.moo.nsga2 import NSGA2
    from pymoo.core.problem import ElementwiseProblem
    from pymoo.optimize import minimize

    ev = constrained.QuantityEvaluator(pareto.bounded(problem, front, math.inf, 1.0))
    archive, tic = [], time.process_time()

    class Front(ElementwiseProblem):
        def __init__(self):
            super().__init__(n_var=problem.n, n_obj=2, xl=np.asarray(problem.lower), xu=np.asarray(problem.upper))

        def _evaluate(self, x, out, *args, **kwargs):
            values = pareto.measure(ev, problem, front, x)
            archive.append({"design_SI": [float(v) for v in x], **values, "cpu_seconds": time.process_time() - tic})
            f = [values["objective"], values["second"]]
            ok = values["feasible"] and all(map(math.isfinite, f))
            out["F"] = f if ok else [1e12, 1e12]
            print(f"nsga2 {len(archive)}: {f[0]:.5g}, {f[1]:.5g}", flush=True)

    minimize(Front(), NSGA2(pop_size=population), ("n_gen", generations), seed=1, verbose=False)
    return archive


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--grid", type=int, default=5, help="grid designs per variable (N x N)")
    ap.add_argument("--generations", type=int, default=3, help="NSGA-II generations")
    ap.add_argument("--population", type=int, default=8, help="NSGA-II population")
    ap.add_argument("--points", type=int, default=5, help="points on the gradient front, anchors included")
    ap.add_argument("--iterations", type=int, default=8, help="Adam iterations per round, per point")
    ap.add_argument("--rounds", type=int, default=1, help="augmented-Lagrangian rounds per point")
    ap.add_argument("--learning-rate", type=float, default=0.3, help="Adam's step, a fraction of the box")
    ap.add_argument("--settle", type=int, default=10, help="revolutions from rest before the steady-state search")
    ap.add_argument("--out", type=Path, default=ROOT / "results" / "pareto.json")
    args = ap.parse_args()

    problem, tables = spec.load(PROBLEM)
    problem = problem.with_objective(
        dataclasses.replace(
            problem.objective, options=dataclasses.replace(problem.objective.options, settle_revolutions=args.settle)
        )
    )
    tables["optimizer"] = {
        **tables["optimizer"],
        "max_iterations": args.iterations,
        "rounds": args.rounds,
        "learning_rate": args.learning_rate,
    }
    tables["pareto"] = {**tables["pareto"], "points": args.points}
    front = pareto.front_settings(problem, tables["pareto"])
    wall = time.perf_counter()

    fresh()
    folder = Path(tempfile.mkdtemp(prefix="bench_pareto_"))
    cpu = time.process_time()
    state = pareto.run_front(problem, tables, folder, progress=False)
    gradient_cpu = time.process_time() - cpu
    shutil.copyfile(folder / "pareto.png", args.out.with_suffix(".png"))
    gradient = state["points"]

    fresh()
    axes = [np.linspace(lo, hi, args.grid) for lo, hi in zip(problem.lower, problem.upper)]
    designs = [np.array([a, b]) for i, a in enumerate(axes[0]) for b in (axes[1] if i % 2 == 0 else axes[1][::-1])]
    grid = evaluate(problem, front, designs, "grid")

    fresh()
    archive = nsga2(problem, front, args.population, args.generations)

    fronts = {"gradient": front_of(gradient), "grid": front_of(grid), "nsga2": front_of(archive)}
    union = np.concatenate([objectives(f) for f in fronts.values() if f])
    reference = pareto.reference_point(union)
    hv = {k: pareto.hypervolume(objectives(f), reference) if f else 0.0 for k, f in fronts.items()}
    curve = [
        [p["cpu_seconds"], pareto.hypervolume(objectives(archive[: i + 1]), reference)] for i, p in enumerate(archive)
    ]
    reached = next((c for c, h in curve if h >= hv["gradient"]), None)
    cpu = {"gradient": gradient_cpu, "grid": grid[-1]["cpu_seconds"], "nsga2": archive[-1]["cpu_seconds"]}
    result = {
        "problem": problem.description,
        "problem_file": PROBLEM.name,
        "names": list(problem.names),
        "objectives": [problem.terms[0][0], front.quantity],
        "budgets": {
            "grid": args.grid,
            "generations": args.generations,
            "population": args.population,
            "points": args.points,
            "iterations": args.iterations,
            "rounds": args.rounds,
            "learning_rate": args.learning_rate,
            "settle_revolutions": args.settle,
        },
        "reference": reference.tolist(),
        "hypervolume": hv,
        "cpu_seconds": cpu,
        "evaluations": {"grid": len(grid), "nsga2": len(archive)},
        "gradient_iterations": sum(p["iterations"] for p in gradient),
        "gradient_over_grid_hypervolume": hv["gradient"] / hv["grid"] if hv["grid"] else None,
        "nsga2_cpu_seconds_to_gradient_hypervolume": reached,
        "nsga2_over_gradient_cpu": reached / gradient_cpu if reached is not None else None,
        "target": TARGET,
        "target_met": bool(
            hv["grid"]
            and abs(hv["gradient"] / hv["grid"] - 1.0) <= TARGET["hypervolume_of_grid_within"]
            and reached is not None
            and reached >= TARGET["cpu_faster_than_nsga2"] * gradient_cpu
        ),
        "fronts": {k: [{c: p[c] for c in (SHOWN)} for p in v] for k, v in fronts.items()},
        "gradient_points": gradient,
        "grid_points": grid,
        "nsga2_points": archive,
        "nsga2_hypervolume_curve": curve,
        "wall_seconds": time.perf_counter() - wall,
        "machine": machine(),
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(pareto._plain(result), indent=1))
    plot(fronts, grid, archive, reference, problem, front, args.out.with_name("pareto_methods.png"))
    keys = ("hypervolume", "cpu_seconds", "nsga2_cpu_seconds_to_gradient_hypervolume")
    print(json.dumps({k: result[k] for k in keys}))


def plot(fronts, grid, archive, reference, problem, front, png: Path) -> None:
    """The three fronts in the (q2, f1) plane, every grid and NSGA-II design faint behind them."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.6))
    for pts, style in ((grid, "C1."), (archive, "C2.")):
        ok = [p for p in pts if p["feasible"]]
        ax.plot([p["quantity"] for p in ok], [p["objective"] for p in ok], style, alpha=0.3)
    for (name, pts), style in zip(fronts.items(), ("C0o-", "C1s--", "C2^:")):
        pts = sorted(pts, key=lambda p: p["objective"])
        ax.plot([p["quantity"] for p in pts], [p["objective"] for p in pts], style, label=name)
    ax.plot([reference[1] / front.weight], [reference[0]], "k+", ms=10, label="reference")
    ax.set_xlabel(f"{front.quantity} [{pareto.unit_of(front.quantity)}]")
    ax.set_ylabel(f"{problem.terms[0][0]} [{pareto.unit_of(problem.terms[0][0])}]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(png, dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    main()
