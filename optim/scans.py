"""1-D scans of the Eq. 19 objective along each design variable, and the
gradients measured against them (the evidence behind the gradient formulation).

    python -m optim.scans --out runs/scans            # paper problem (minutes)
    python -m optim.scans --out runs/scans --quick    # short window, coarse

Per variable, through the start design (other variables fixed):
- ``coarse``: ``--points`` designs across the whole box;
- ``fine``: ``--fine-points`` designs over +-``--half-width`` (default +-2 mm), whose
  least-squares slope is the local trend;
- ``micro``: 11 designs 20 um apart, whose neighbour differences show the jitter
  a finite difference at that step would see.
At the start design: the ensemble gradient (the optimiser's) and, for contrast, the
pathwise reverse-mode gradient of the same objective.

Writes ``scans.csv`` (variable, kind, design, objective in degrees),
``scans.json`` (slopes and gradients, deg per SI unit) and ``scans.png``.
"""

from __future__ import annotations

import argparse
import csv
import json
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from . import search
from .ensemble import Ensemble
from .objective import AbstractObjective
from .presets import PROBLEMS
from .problem import AbstractProblem as Problem


def least_squares_slope(x, y):
    """Slope of the least-squares line through (x, y), ignoring NaNs."""
    x, y = np.asarray(x), np.asarray(y)
    keep = np.isfinite(y)
    return float(np.polyfit(x[keep], y[keep], 1)[0])


def line(x0, i, offsets):
    xs = np.repeat(np.asarray(x0, dtype=float)[None], len(offsets), axis=0)
    xs[:, i] += offsets
    return xs


def gradient(problem: Problem, x0, objective: AbstractObjective | None = None):
    """d objective / d x (deg per SI unit) at SI design x0 by ``objective`` (default the problem's)."""
    prob = problem if objective is None else problem.with_objective(objective)
    return np.asarray(jax.jit(prob.value_and_grad)(jnp.asarray(x0, dtype=float))[1])


def run(
    problem: Problem,
    out: Path,
    points=21,
    fine_points=41,
    half_width=2e-3,
    micro_step=2e-5,
    pathwise_gradient=True,
    progress=True,
):
    out.mkdir(parents=True, exist_ok=True)
    x0 = np.asarray(problem.from_unit(problem.start_unit()))
    rows, report = (
        [],
        {
            "problem": problem.description,
            "start": x0.tolist(),
            "names": list(problem.names),
            "objective": problem.objective.describe(),
            "variables": {},
        },
    )
    tic = time.perf_counter()
    for i, name in enumerate(problem.names):
        lo, hi = problem.lower[i], problem.upper[i]
        kinds = {
            "coarse": np.linspace(lo, hi, points) - x0[i],
            "fine": np.linspace(-half_width, half_width, fine_points),
            "micro": micro_step * np.arange(-5, 6),
        }
        entry = {}
        for kind, offsets in kinds.items():
            xs = line(x0, i, offsets)
            values, ok = search.evaluate(problem, xs, chunk=len(xs), progress=progress)
            rows += [(name, kind, *x, v) for x, v in zip(xs, values)]
            entry[f"{kind}_slope"] = least_squares_slope(xs[:, i], values)
            if kind == "micro":
                fd = np.diff(values) / micro_step
                entry["micro_fd_slopes"] = [float(v) for v in fd]
                entry["micro_relative_jitter"] = float(
                    np.nanstd(values - np.polyval(np.polyfit(xs[:, i], values, 1), xs[:, i])) / np.nanmean(values)
                )
        report["variables"][name] = entry
    report["scan_seconds"] = time.perf_counter() - tic

    tic = time.perf_counter()
    g = gradient(problem, x0)
    report["ensemble_gradient"] = g.tolist()
    report["ensemble_gradient_seconds"] = time.perf_counter() - tic
    if pathwise_gradient:
        tic = time.perf_counter()
        report["pathwise_gradient"] = gradient(problem, x0, search.pathwise_of(problem.objective)).tolist()
        report["pathwise_gradient_seconds"] = time.perf_counter() - tic
    for i, name in enumerate(problem.names):
        e = report["variables"][name]
        e["ensemble_gradient"] = float(g[i])
        e["ensemble_over_fine_slope"] = float(g[i] / e["fine_slope"])

    with open(out / "scans.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["variable", "kind", *[f"{n}_SI" for n in problem.names], "objective_deg"])
        w.writerows(rows)
    (out / "scans.json").write_text(json.dumps(report, indent=2))
    from .plots import plot_scans

    plot_scans(out / "scans.csv", report, out / "scans.png")
    return report


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m optim.scans", description=__doc__.split("\n\n")[0])
    ap.add_argument("--problem", choices=sorted(PROBLEMS), default="paper")
    ap.add_argument("--out", type=Path, default=Path("runs/scans"))
    ap.add_argument("--points", type=int, default=21)
    ap.add_argument("--fine-points", type=int, default=41)
    ap.add_argument("--half-width", type=float, default=2e-3, help="fine scan half width, SI (default 2 mm)")
    ap.add_argument("--quick", action="store_true", help="window (0.1, 0.12] s and fewer points (smoke run)")
    ap.add_argument("--no-pathwise", action="store_true", help="skip the (expensive, exploding) pathwise gradient")
    args = ap.parse_args(argv)
    obj = Ensemble(t_end=0.12) if args.quick else Ensemble()
    problem = PROBLEMS[args.problem](objective=obj)
    pts, fine = (7, 11) if args.quick else (args.points, args.fine_points)
    report = run(problem, args.out, pts, fine, args.half_width, pathwise_gradient=not args.no_pathwise)
    for name, e in report["variables"].items():
        print(
            f"{name}: fine LS slope {e['fine_slope']:+.4g}, ensemble gradient {e['ensemble_gradient']:+.4g} "
            f"(ratio {e['ensemble_over_fine_slope']:.3f}), coarse slope {e['coarse_slope']:+.4g}, "
            f"micro FD slopes {min(e['micro_fd_slopes']):+.3g} .. {max(e['micro_fd_slopes']):+.3g} deg/SI"
        )
    if "pathwise_gradient" in report:
        print("pathwise gradient:", report["pathwise_gradient"])


if __name__ == "__main__":
    main()
