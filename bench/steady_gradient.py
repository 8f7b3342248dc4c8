"""Exact steady-state gradients against finite differences, and warm-start cost.

For periodic designs of the nine-variable design problem (``optim.design.design_problem``):
the implicit-function-theorem gradient of Eq. 19 over one period of the orbit
(:func:`jaxcrank.numerics.steady.steady_value_and_grad`, in unit-box variables) against
central differences (``--h`` of the box) of

- the steady state by long simulation from rest, without shooting (``--revolutions``
  revolutions, Eq. 19 over the next one; rtol = atol = 1e-10);
- the steady state by shooting, warm-started from the centre's orbit (the idle
  approach-speed memories held at the centre's values, as the gradient holds them).

Also the cost of the warm-started solves (revolution-solves per call). Writes
``bench/results/steady_gradient.json``. Usage: ``python bench/steady_gradient.py``.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import jax.numpy as jnp
import numpy as np
from _common import machine

import jaxcrank as jc
from jaxcrank.numerics.steady import steady_value_and_grad
from optim.design import design_problem

KEY = "rms_transmission_angle_error_deg"
ROOT = Path(__file__).resolve().parent


def designs():
    """name -> design (SI): the best designs recorded in bench/results."""
    study = json.loads((ROOT / "results" / "design_study.json").read_text())
    out = {"cma_best": study["optimum"]["cma_design_SI"], "adam_best": study["optimum"]["adam_design_SI"]}
    runs = json.loads((ROOT / "results" / "design.json").read_text())["problems"]
    nine = next(p for p in runs if p["n_variables"] == 9)
    for run in nine["methods"]["ours"]["runs"]:
        out[f"ours_seed{run['seed']}"] = run["final_SI"]
    return out


def long_run(mech, revolutions):
    period = float(mech.period)
    sim = jc.simulate(
        mech,
        t1=(revolutions + 1) * period,
        n_samples=(revolutions + 1) * 3600 + 1,
        metrics_start=revolutions * period,
        save_samples=False,
        rtol=1e-10,
        atol=1e-10,
        max_steps=10_000_000,
    )
    return float(sim.metrics[KEY])


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--h", type=float, default=0.01, help="central-difference step, fraction of the box")
    parser.add_argument("--revolutions", type=int, default=30, help="revolutions of the long run before the period")
    parser.add_argument("--only", nargs="*", help="design names to run (default all)")
    parser.add_argument("--out", type=Path, default=ROOT / "results" / "steady_gradient.json")
    args = parser.parse_args()
    prob = design_problem()
    lo, hi = np.array(prob.lower), np.array(prob.upper)

    def build(u):
        return prob.mechanism(jnp.asarray(lo) + u * jnp.asarray(hi - lo))

    rows = []
    for name, x in designs().items():
        if args.only and name not in args.only:
            continue
        u0 = (np.asarray(x) - lo) / (hi - lo)
        start = time.perf_counter()
        steady = jc.steady_state(build(jnp.asarray(u0)), throw=False)
        row = {"design": name, "design_SI": list(map(float, x)), "regime": steady.regime}
        row["multipliers_abs"] = [float(v) for v in steady.multiplier_moduli[:4]]
        print(name, steady.regime, row["multipliers_abs"], flush=True)
        if not steady.periodic:
            rows.append(row)
            continue
        value, grad = steady_value_and_grad(lambda sim: sim.metrics[KEY], build, jnp.asarray(u0), steady)
        row["ift_s"] = time.perf_counter() - start
        grad = np.asarray(grad)
        fd_long, fd_shoot, warm_revs = [], [], []
        for i in range(len(u0)):
            e = np.zeros(len(u0))
            e[i] = args.h
            lr = [long_run(build(jnp.asarray(u0 + s * e)), args.revolutions) for s in (1, -1)]
            sh = [jc.steady_state(build(jnp.asarray(u0 + s * e)), warm_start=steady) for s in (1, -1)]
            fd_long.append((lr[0] - lr[1]) / (2 * args.h))
            fd_shoot.append((float(sh[0].metrics[KEY]) - float(sh[1].metrics[KEY])) / (2 * args.h))
            warm_revs += [sum(s.revolutions.values()) for s in sh]
        fd_long, fd_shoot = np.array(fd_long), np.array(fd_shoot)
        norm = np.linalg.norm(fd_long)
        big = np.abs(fd_long) > 0.05 * norm
        row.update(
            value_deg=float(value),
            long_run_value_deg=long_run(build(jnp.asarray(u0)), args.revolutions),
            gradient_ift=grad.tolist(),
            gradient_fd_long_run=fd_long.tolist(),
            gradient_fd_shooting_warm=fd_shoot.tolist(),
            rel_error_vs_long_run=float(np.linalg.norm(grad - fd_long) / norm),
            rel_error_vs_shooting=float(np.linalg.norm(grad - fd_shoot) / np.linalg.norm(fd_shoot)),
            signs_agree_above_5pct=bool(np.all(np.sign(grad[big]) == np.sign(fd_long[big]))),
            warm_start_revolution_solves_mean=float(np.mean(warm_revs)),
            cold_revolution_solves=sum(steady.revolutions.values()),
        )
        print(name, {k: row[k] for k in ("rel_error_vs_long_run", "rel_error_vs_shooting")}, flush=True)
        rows.append(row)
        args.out.write_text(json.dumps({"h_box": args.h, "revolutions": args.revolutions, "designs": rows,
                                        "machine": machine()}, indent=1))  # fmt: skip
    args.out.write_text(
        json.dumps({"h_box": args.h, "revolutions": args.revolutions, "designs": rows, "machine": machine()}, indent=1)
    )


if __name__ == "__main__":
    main()
