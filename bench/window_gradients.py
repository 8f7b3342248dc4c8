"""Per-window gradients of the ensemble objective: how they are distributed with
an explicit and an implicit window solver, and whether the largest ones are real
(checked against central differences of that window at the same tolerance and
against reverse mode at rtol = atol = 1e-9).

    python bench/window_gradients.py                        # tsit5, rodas4 and kvaerno5, all 100 windows
    python bench/window_gradients.py --solvers rodas4 --merge   # one solver, keep the others' entries
    python bench/window_gradients.py --solvers tsit5 --window 5e-4

Writes bench/results/window_gradients.json: per solver the ensemble gradient
d F / d (L1, L2) in deg/m, quantiles of |d window / d L2| and the largest windows
with their checks.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from jaxcrank import SolveOptions, simulate
from jaxcrank.analysis.outputs import transmission_angle_error
from optim import ensemble as W
from optim.ensemble import Ensemble
from optim.objective import EQ19
from optim.presets import paper_problem


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--design", type=float, nargs=2, default=[0.12, 0.40], help="L1 L2, m")
    ap.add_argument("--window", type=float, default=2e-3, help="window length, s")
    ap.add_argument("--solvers", nargs="+", default=["tsit5", "rodas4", "kvaerno5"])
    ap.add_argument("--merge", action="store_true", help="keep the other solvers' entries of an existing --out file")
    ap.add_argument("--check", type=int, default=3, help="largest windows to check")
    ap.add_argument("--out", type=Path, default=Path("bench/results/window_gradients.json"))
    args = ap.parse_args(argv)
    x0 = jnp.asarray(args.design)
    report = {"design_m": args.design, "window_s": args.window, "solvers": {}}
    if args.merge and args.out.exists():
        old = json.loads(args.out.read_text())
        if old["design_m"] == args.design and old["window_s"] == args.window:
            report["solvers"] = old["solvers"]
    for solver in args.solvers:
        obj = Ensemble(window=args.window, windows=0, window_options=SolveOptions.from_text(solver, max_steps=50_000))
        prob = paper_problem(obj)
        mech = prob.mechanism(x0)
        exact, starts = obj.reference(mech)
        exact = exact[EQ19]
        _, _, n_window, dt = obj.grid(mech)

        def window(x, i, tol, solver=solver, prob=prob, starts=starts, dt=dt, n_window=n_window):
            m = prob.mechanism(x)
            ts = starts.t[i] + dt * jnp.arange(n_window + 1)
            sim = simulate(
                m,
                ts=ts,
                y0=W.start_state(m, starts, i),
                options=SolveOptions.from_text(solver, rtol=tol, atol=tol, max_steps=200_000),
                throw=False,
            )
            return jnp.sum(transmission_angle_error(m, sim.ts[1:], sim.ys[1:]) ** 2)

        tic = time.perf_counter()
        idx = jnp.arange(starts.t.shape[0])
        vals, grads = jax.jit(jax.vmap(jax.value_and_grad(window), in_axes=(None, 0, None)))(x0, idx, 1e-6)
        vals, grads = np.asarray(vals), np.asarray(grads)
        wall = time.perf_counter() - tic
        ok = np.isfinite(vals) & np.isfinite(grads).all(axis=1)
        # dF/dx = sum_k dS_k/dx / (n_window K) / (2 F)
        f = np.sqrt(vals[ok].sum() / (n_window * ok.sum()))
        g = grads[ok].sum(axis=0) / (n_window * ok.sum()) / (2 * f)
        a = np.abs(grads[:, 1])
        entry = {
            "windows": int(len(vals)),
            "finished": int(ok.sum()),
            "seconds_incl_compile": wall,
            "F_deg": float(exact),
            "ensemble_gradient_deg_per_m": g.tolist(),
            "abs_dS_dL2_quantiles": dict(
                zip(["50", "90", "99", "max"], np.nanquantile(a, [0.5, 0.9, 0.99, 1.0]).tolist())
            ),
            "largest": [],
        }
        f1 = jax.jit(lambda x, i: window(x, i, 1e-6))
        g9 = jax.jit(jax.grad(lambda x, i: window(x, i, 1e-9)))
        for i in np.argsort(np.nan_to_num(a, nan=np.inf))[::-1][: args.check]:
            h = jnp.array([0.0, 1e-6])
            fd = (float(f1(x0 + h, int(i))) - float(f1(x0 - h, int(i)))) / 2e-6
            entry["largest"].append(
                {
                    "window": int(i),
                    "t0_s": float(starts.t[i]),
                    "ad_dS_dL2_rtol_1e-6": float(grads[i, 1]),
                    "central_difference_rtol_1e-6": fd,
                    "ad_dS_dL2_rtol_1e-9": float(g9(x0, int(i))[1]),
                }
            )
        report["solvers"][solver] = entry
        print(solver, json.dumps(entry, indent=1), flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
