"""Cost of the friction ramp width on the paper run (README, "Friction ramp width").

    python bench/friction_width.py [--t1 0.4] [--out bench/results/friction_width.json]

For v1 in 1e-3, 1e-2, 5e-2 m/s (v0 = 1e-4 m/s): steps, rejected steps, wall time
after compile, and the max slider x deviation after the first revolution.
"""

import argparse
import json
import time
from pathlib import Path

import equinox as eqx
import jax
import numpy as np

import jaxcrank as jc
from jaxcrank import outputs


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--t1", type=float, default=0.4)
    p.add_argument("--out", type=Path, default=Path("bench/results/friction_width.json"))
    args = p.parse_args()
    rows = []
    for v1 in [1e-3, 1e-2, 5e-2]:
        mech = eqx.tree_at(lambda m: (m.friction.stick_speed, m.friction.slip_speed), jc.paper(), (1e-4, v1))
        run = lambda: jc.simulate(mech, args.t1, n_samples=int(args.t1 * 10000) + 1, max_steps=5_000_000)  # noqa: E731
        jax.block_until_ready(run().ys)
        start = time.perf_counter()
        sim = run()
        jax.block_until_ready(sim.ys)
        wall = time.perf_counter() - start
        m = outputs.metrics(outputs.trajectory(sim), mech)
        rows.append({"slip_speed_m_s": v1, "steps": int(sim.num_steps), "rejected": int(sim.num_rejected),
                     "wall_s": wall, "max_abs_slider_x_deviation_m": m["max_abs_slider_x_deviation_m"]})
        print(rows[-1], flush=True)
    ref = rows[1]["max_abs_slider_x_deviation_m"]
    for r in rows:
        r["slider_deviation_rel_change_vs_1e-2"] = float(np.abs(r["max_abs_slider_x_deviation_m"] - ref) / ref)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(rows, indent=2))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
