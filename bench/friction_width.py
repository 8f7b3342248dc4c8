"""Cost of the friction ramp width on the paper run (docs/numerics.md, "Friction ramp width").

    python bench/friction_width.py [--t1 0.4] [--out bench/results/friction_width.json] [--metrics-from S]

For v1 in 1e-3, 1e-2, 5e-2 m/s (v0 = 1e-4 m/s): steps, rejected steps, wall time
after compile, and the max slider x deviation after the first revolution.
Then Ambrosio's typical v1 = 2e-4 m/s on a short ``--narrow-window`` with tsit5 and
kvaerno5 under a step budget: how far each gets, and the smallest accepted step.
"""

import argparse
import json
import time
from pathlib import Path

import diffrax
import jax
import numpy as np

import jaxcrank as jc
from jaxcrank import model, outputs, solve


def _ramp(v0, v1):
    """The paper preset with the friction ramp from v0 to v1 (m/s) in every joint."""
    return jc.set_parameters(jc.paper(), ["friction.stick_speed", "friction.slip_speed"], [v0, v1])


def narrow_ramp(window, budget):
    """Ambrosio's v1 = 2e-4 m/s: progress and smallest step within ``budget`` steps."""
    mech = _ramp(1e-4, 2e-4)
    rows = []
    for name in ["tsit5", "kvaerno5"]:
        solver = solve.solver_from_name(name)
        sol = diffrax.diffeqsolve(
            diffrax.ODETerm(model.vector_field),
            solver,
            0.0,
            window,
            1e-6,
            model.initial_state(mech),
            args=mech,
            saveat=diffrax.SaveAt(steps=True),
            stepsize_controller=solve.step_size_controller(solver, 1e-6, 1e-6),
            max_steps=budget,
            throw=False,
        )
        ts = np.asarray(sol.ts)
        ts = ts[np.isfinite(ts)]
        rows.append(
            {
                "solver": name,
                "window_s": window,
                "step_budget": budget,
                "finished": bool(sol.result == diffrax.RESULTS.successful),
                "reached_t_s": float(ts[-1]),
                "accepted_steps": int(sol.stats["num_accepted_steps"]),
                "rejected_steps": int(sol.stats["num_rejected_steps"]),
                "smallest_step_s": float(np.min(np.diff(ts))),
            }
        )
        print(rows[-1], flush=True)
    return rows


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--t1", type=float, default=0.4)
    p.add_argument("--narrow-window", type=float, default=0.03)
    p.add_argument("--narrow-budget", type=int, default=200_000)
    p.add_argument("--out", type=Path, default=Path("bench/results/friction_width.json"))
    p.add_argument("--metrics-from", type=float, help="start of the deviation's window, s (default: one revolution)")
    args = p.parse_args()
    rows = []
    for v1 in [1e-3, 1e-2, 5e-2]:
        mech = _ramp(1e-4, v1)
        run = lambda mech=mech: jc.simulate(
            mech, args.t1, n_samples=int(args.t1 * 10000) + 1, options=jc.SolveOptions(max_steps=5_000_000)
        )  # noqa: E731
        jax.block_until_ready(run().ys)
        start = time.perf_counter()
        sim = run()
        jax.block_until_ready(sim.ys)
        wall = time.perf_counter() - start
        start_s = float(mech.period) if args.metrics_from is None else args.metrics_from
        m = outputs.sample_metrics(sim, start_s)
        rows.append(
            {
                "slip_speed_m_s": v1,
                "steps": int(sim.num_steps),
                "rejected": int(sim.num_rejected),
                "wall_s": wall,
                "max_abs_slider_x_deviation_m": m["max_abs_slider_x_deviation_m"],
            }
        )
        print(rows[-1], flush=True)
    ref = rows[1]["max_abs_slider_x_deviation_m"]
    for r in rows:
        r["slider_deviation_rel_change_vs_1e-2"] = float(np.abs(r["max_abs_slider_x_deviation_m"] - ref) / ref)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    narrow = narrow_ramp(args.narrow_window, args.narrow_budget)
    args.out.write_text(json.dumps({"widths": rows, "ambrosio_typical_v1_2e-4": narrow}, indent=2))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
