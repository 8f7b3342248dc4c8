"""The nine-variable design study: optimum, an interior check around it, and the
accuracy / manufacturing-cost Pareto front.

``python bench/design_study.py [--out bench/results/design_study.json] [--iterations 60]``

1. Projected Adam (:func:`optim.optimize.optimize`) on :func:`optim.presets.design_problem`
   with the benchmark's evaluation window (:data:`_window_design.OBJECTIVE`), and CMA-ES
   from the same start on the common evaluator; the better of the two is the optimum.
2. Interior check: the common forward evaluator of ``_window_design`` at the best
   design, at ``+-delta`` along every scaled coordinate (clipped to the box) and at
   random points within ``delta`` (max norm) of it; records which variables sit
   on a bound and how many neighbours are lower.
3. Pareto front, accuracy against manufacturing cost, by a weighted-sum
   scalarisation sweep: for each weight ``lambda`` of the cost term, minimise
   ``accuracy + lambda * cost_index`` (accuracy: Eq. 19 + the weighted terms, deg;
   ``cost_index = sum_j 0.5 mm / c_j`` over the two clearances, the reciprocal
   machining-cost model) by projected Adam, warm-started from the previous
   weight's optimum, on step 1's compiled value-and-gradient with the analytic
   cost term's weight changed (no recompilation per weight), then CMA-ES from
   there; the best point of both by the common evaluator is kept (``found_by``);
   dominated points are flagged.
   Writes the points to a CSV and plots them (PNG beside the JSON).
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

import _window_design as B  # noqa: E402

LAMBDAS = (0.0005, 0.001, 0.002, 0.005, 0.01, 0.02, 0.05)  # deg per unit of cost_index


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "design_study.json")
    ap.add_argument("--iterations", type=int, default=60)
    ap.add_argument("--pareto-iterations", type=int, default=25)
    ap.add_argument("--cma-evaluations", type=int, default=3000)
    ap.add_argument("--pareto-cma-evaluations", type=int, default=600)
    ap.add_argument("--delta", type=float, default=0.05, help="neighbourhood radius, scaled units")
    ap.add_argument("--random", type=int, default=32, help="random neighbours")
    ap.add_argument("--tiny", action="store_true")
    ap.add_argument("--note", default="")
    args = ap.parse_args(argv)
    objective = B.TINY if args.tiny else B.OBJECTIVE
    import jax
    import jax.numpy as jnp

    jax.config.update("jax_enable_x64", True)
    from optim.optimize import Settings, optimize
    from optim.optimizers import adam

    tic = time.perf_counter()
    prob = B.build("design_9var", objective)
    f = B.evaluator(prob)

    def score(p, x):
        v, ok = f(jnp.asarray(x))
        return float(v) if bool(ok) else float("inf")

    res = optimize(prob, Settings(optimizer=adam(0.1), max_iterations=args.iterations), progress=False)
    hist = res["history"]
    xs = np.array([[h[f"{n}_SI"] for n in prob.names] for h in hist])
    scores = np.array([score(prob, x) for x in xs])
    k = int(np.argmin(scores))
    x_adam = xs[k]

    # CMA-ES from the same start on the same evaluator (serial), for a second opinion on the optimum
    import cma

    fu = lambda u: score(prob, np.asarray(prob.from_unit(np.clip(u, 0.0, 1.0))))  # noqa: E731
    es = cma.CMAEvolutionStrategy(
        list(np.asarray(prob.start_unit())),
        0.25,
        {"bounds": [0.0, 1.0], "seed": 1, "verbose": -9, "maxfevals": args.cma_evaluations},
    )
    es.optimize(lambda u: min(fu(u), 1e6))
    u_cma = np.clip(np.asarray(es.result.xbest), 0.0, 1.0)
    x_cma = np.asarray(prob.from_unit(u_cma))
    candidates = {"adam": (x_adam, float(scores[k])), "cma": (x_cma, score(prob, x_cma))}
    found_by = min(candidates, key=lambda m: candidates[m][1])
    x_best = candidates[found_by][0]
    u_best = np.asarray(prob.to_unit(x_best))
    print(
        f"adam {candidates['adam'][1]:.6g}, cma {candidates['cma'][1]:.6g} ({es.result.evaluations} evaluations)",
        flush=True,
    )

    # ---- the gradient's trend against secant slopes of the evaluator at Adam's best design:
    # scaled units, d objective / d u, secants over +-delta (clipped) along each axis
    from optim.optimize import programs

    vg = programs(dataclasses.replace(prob, start=None), 10.0)[0]
    u_a = np.asarray(prob.to_unit(x_adam))
    f_a = fu(u_a)
    grad_a = np.asarray(vg(jnp.asarray(u_a), f_a)[1]) * f_a
    secant = []
    for j in range(prob.n):
        lo_u, hi_u = u_a.copy(), u_a.copy()
        lo_u[j], hi_u[j] = max(u_a[j] - args.delta, 0.0), min(u_a[j] + args.delta, 1.0)
        secant.append((fu(hi_u) - fu(lo_u)) / (hi_u[j] - lo_u[j]))
    trend = {
        "design_unit": u_a.tolist(),
        "objective_deg": f_a,
        "ensemble_gradient_deg_per_unit": grad_a.tolist(),
        "secant_slope_deg_per_unit": secant,
        "delta_scaled": args.delta,
        "sign_agreement": [bool(np.sign(a) == np.sign(b)) for a, b in zip(grad_a, secant)],
    }
    print("trend vs secant:", np.round(grad_a, 4), np.round(secant, 4), flush=True)

    # ---- interior check
    rng = np.random.default_rng(0)
    nbrs = []
    for j in range(prob.n):
        for s in (-1.0, 1.0):
            u = u_best.copy()
            u[j] = np.clip(u[j] + s * args.delta, 0.0, 1.0)
            nbrs.append(("axis", prob.names[j], s, u))
    for _ in range(args.random):
        nbrs.append(("random", "", 0.0, np.clip(u_best + rng.uniform(-args.delta, args.delta, prob.n), 0.0, 1.0)))
    f_best = score(prob, x_best)
    rows = []
    for kind, name, s, u in nbrs:
        v = score(prob, np.asarray(prob.from_unit(u)))
        rows.append({"kind": kind, "variable": name, "sign": s, "u": u.tolist(), "objective_deg": v})
    vals = np.array([r["objective_deg"] for r in rows])
    on_bound = [n for n, u in zip(prob.names, u_best) if u < 1e-3 or u > 1 - 1e-3]
    interior = {
        "delta_scaled": args.delta,
        "best_objective_deg": f_best,
        "neighbours": len(rows),
        "neighbours_lower": int(np.sum(vals < f_best)),
        "neighbours_lower_by_more_than_1pct": int(np.sum(vals < 0.99 * f_best)),
        "largest_relative_drop": float(np.max((f_best - vals) / f_best)),
        "variables_on_a_bound": on_bound,
        "best_unit": u_best.tolist(),
        "rows": rows,
        "constraints_at_best": {k2: float(v) for k2, v in prob.constraints(x_best).items()},
    }
    print(
        f"optimum {f_best:.6g} deg at u = {np.round(u_best, 3)}; on bounds: {on_bound}; "
        f"{interior['neighbours_lower']} of {len(rows)} neighbours lower",
        flush=True,
    )

    # ---- Pareto sweep: projected Adam (as optimize's) on the same compiled value-and-gradient,
    # the cost weight changed in closed form (the cost term is analytic), so one compilation
    import optax

    w0 = prob.cost_weight
    cost_index = jax.jit(lambda u: prob.cost(prob.from_unit(u)) / w0)
    cost_grad = jax.jit(jax.grad(lambda u: prob.cost(prob.from_unit(u)) / w0))
    front = []
    u = jnp.asarray(u_best)
    for lam in LAMBDAS:
        f0 = float(f(prob.from_unit(u))[0]) + (lam - w0) * float(cost_index(u))
        opt = optax.adam(0.05)
        state = opt.init(u)
        path = []
        for _ in range(args.pareto_iterations):
            _, g = vg(u, f0)
            g = g + (lam - w0) * cost_grad(u) / f0
            upd, state = opt.update(g, state, u)
            u = prob.project(optax.apply_updates(u, upd))
            path.append(np.asarray(u))
        total = lambda v, lam=lam: fu(v) + (lam - w0) * float(cost_index(jnp.asarray(v)))  # noqa: E731
        sc = [total(v) for v in path]
        i = int(np.argmin(sc))
        es = cma.CMAEvolutionStrategy(
            list(np.asarray(u)),
            0.1,
            {"bounds": [0.0, 1.0], "seed": 1, "verbose": -9, "maxfevals": args.pareto_cma_evaluations},
        )
        es.optimize(lambda v, total=total: min(total(np.clip(v, 0.0, 1.0)), 1e6))
        u_c = np.clip(np.asarray(es.result.xbest), 0.0, 1.0)
        by, best_u, best_v = ("adam", path[i], sc[i]) if sc[i] <= total(u_c) else ("cma", u_c, total(u_c))
        u = jnp.asarray(best_u)
        ci = float(cost_index(u))
        front.append(
            {
                "lambda_deg": lam,
                "objective_deg": best_v,
                "cost_index": ci,
                "found_by": by,
                "adam_objective_deg": sc[i],
                "cma_objective_deg": total(u_c),
                "accuracy_deg": best_v - lam * ci,
                "design_SI": np.asarray(prob.from_unit(u)).tolist(),
            }
        )
        print(f"lambda {lam}: accuracy {front[-1]['accuracy_deg']:.6g} deg, cost index {ci:.4g}", flush=True)
    for a in front:
        a["dominated"] = any(
            b["accuracy_deg"] <= a["accuracy_deg"]
            and b["cost_index"] <= a["cost_index"]
            and (b["accuracy_deg"], b["cost_index"]) != (a["accuracy_deg"], a["cost_index"])
            for b in front
        )

    out = args.out
    out.parent.mkdir(parents=True, exist_ok=True)
    with open(out.with_name("design_pareto.csv"), "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(
            ["lambda_deg", "accuracy_deg", "cost_index", "objective_deg", "dominated"] + [f"{n}_SI" for n in prob.names]
        )
        for a in front:
            w.writerow(
                [a["lambda_deg"], a["accuracy_deg"], a["cost_index"], a["objective_deg"], a["dominated"]]
                + a["design_SI"]
            )
    result = {
        "command": "python bench/design_study.py " + " ".join(argv if argv is not None else sys.argv[1:]),
        "objective": objective,
        "problem": prob.description,
        "names": list(prob.names),
        "note": args.note,
        "load_average": os.getloadavg(),
        "optimum": {
            "design_SI": x_best.tolist(),
            "objective_deg": f_best,
            "iterations": len(hist),
            "start_objective_deg": float(scores[0]),
            "found_by": found_by,
            "adam_objective_deg": candidates["adam"][1],
            "cma_objective_deg": candidates["cma"][1],
            "adam_design_SI": x_adam.tolist(),
            "cma_design_SI": x_cma.tolist(),
        },
        "interior": interior,
        "gradient_vs_secants_at_adam_best": trend,
        "pareto": {
            "lambdas_deg": list(LAMBDAS),
            "points": front,
            "scalarisation": "weighted sum: accuracy + lambda * cost_index",
        },
        "wall_s": time.perf_counter() - tic,
    }
    out.write_text(json.dumps(result, indent=1))
    plot(front, out.with_name("design_pareto.png"))
    print(f"wrote {out}")


def plot(front, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5, 4))
    ok = [a for a in front if not a["dominated"]]
    bad = [a for a in front if a["dominated"]]
    ax.plot([a["cost_index"] for a in ok], [a["accuracy_deg"] for a in ok], "o-", label="non-dominated")
    if bad:
        ax.plot([a["cost_index"] for a in bad], [a["accuracy_deg"] for a in bad], "x", color="grey", label="dominated")
    for a in front:
        ax.annotate(f"{a['lambda_deg']:g}", (a["cost_index"], a["accuracy_deg"]), fontsize=7)
    ax.set_xlabel("manufacturing cost index  sum 0.5 mm / c_j")
    ax.set_ylabel("accuracy objective, deg (Eq. 19 + weighted terms)")
    ax.set_title("Pareto front, weighted-sum sweep (labels: lambda, deg)", fontsize=9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    main()
