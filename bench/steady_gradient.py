"""Exact steady-state gradients against finite differences, and warm-start cost.

For periodic designs of the nine-variable design problem (``optim.presets.design_problem``):
the implicit-function-theorem gradient of Eq. 19 over one period of the orbit
(:func:`jaxcrank.numerics.steady.steady_value_and_grad`, in unit-box variables) against
central differences of three references, none of which uses the gradient code:

- ``from_rest``: long simulation from rest at every design, without shooting
  (``--revolutions`` revolutions, Eq. 19 over the next one; rtol = atol = 1e-10),
  step ``--h-rest`` of the box. The start-up selects the frozen approach-speed memories
  (continuous contact) differently at every design, which these differences divide by
  the step;
- ``continued``: long simulation from rest at the centre design, then ``--continue``
  revolutions at each perturbed design from that state (the memories carried over, as
  the gradient holds them), step ``--h`` of the box;
- ``shooting``: the steady state by shooting, warm-started from the centre's orbit, step
  ``--h``.

Also the cost of the warm-started solves at ``--h-rest`` from the centre (revolution-solves
and wall time per call, compiled). Writes ``bench/results/steady_gradient.json``.
Usage: ``python bench/steady_gradient.py``.
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
from jaxcrank.numerics.steady import carry_state, steady_value_and_grad
from optim.presets import ADAM_RUNS_SI, design_problem

KEY = "rms_transmission_angle_error_deg"
ROOT = Path(__file__).resolve().parent


def designs():
    """name -> design (SI): the best designs recorded in bench/results."""
    study = json.loads((ROOT / "results" / "design_study.json").read_text())
    out = {"cma_best": study["optimum"]["cma_design_SI"], "adam_best": study["optimum"]["adam_design_SI"]}
    # projected-Adam runs of the nine-variable problem on the earlier start-up-window objective
    for seed, x in enumerate(ADAM_RUNS_SI):
        out[f"ours_seed{seed}"] = x
    for label, unit in (("cma_best_slider_mass_mid_box", 0.5), ("cma_best_slider_mass_upper", 1.0)):
        x = list(out["cma_best"])
        x[6] = 1.0 + unit * 1.5  # slider_mass, box 1-2.5 kg
        out[label] = x
    return out


def _tracked(mech, revolutions, y0=None, k=1):
    """Eq. 19 over the ``k`` revolutions after ``revolutions`` of a plain simulation
    (rtol = atol = 1e-10)."""
    period = float(mech.period)
    sim = jc.simulate(
        mech,
        t1=(revolutions + k) * period,
        n_samples=(revolutions + k) * 3600 + 1,
        y0=y0,
        metrics_start=revolutions * period,
        save_samples=False,
        options=jc.SolveOptions(rtol=1e-10, atol=1e-10, max_steps=10_000_000),
    )
    return float(sim.metrics[KEY])


def _differences(fn, u0, h):
    out = []
    for i in range(len(u0)):
        e = np.zeros(len(u0))
        e[i] = h
        out.append((fn(u0 + e) - fn(u0 - e)) / (2 * h))
    return np.array(out)


def _compare(grad, fd):
    norm = np.linalg.norm(fd)
    big = np.abs(fd) > 0.05 * norm
    return {
        "gradient_fd": fd.tolist(),
        "rel_error_norm": float(np.linalg.norm(grad - fd) / norm),
        "signs_agree_above_5pct_of_norm": bool(np.all(np.sign(grad[big]) == np.sign(fd[big]))),
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--h", type=float, default=1e-3, help="step of the continued and shooting differences, box")
    parser.add_argument("--h-rest", type=float, default=0.01, help="step of the from-rest differences, box")
    parser.add_argument("--revolutions", type=int, default=30, help="revolutions from rest before the period")
    parser.add_argument("--continue", dest="cont", type=int, default=10, help="revolutions of a continued run")
    parser.add_argument("--only", nargs="*", help="design names to run (default all)")
    parser.add_argument("--out", type=Path, default=ROOT / "results" / "steady_gradient.json")
    args = parser.parse_args()
    prob = design_problem()
    lo, hi = np.array(prob.lower), np.array(prob.upper)

    def build(u):
        return prob.mechanism(jnp.asarray(lo) + u * jnp.asarray(hi - lo))

    rows = []
    if args.only and args.out.exists():  # rerun some designs, keep the others' rows
        rows = [r for r in json.loads(args.out.read_text())["designs"] if r["design"] not in args.only]
    for name, x in designs().items():
        if args.only and name not in args.only:
            continue
        u0 = (np.asarray(x) - lo) / (hi - lo)
        start = time.perf_counter()
        steady = jc.steady_state(build(jnp.asarray(u0)), throw=False)
        row = {"design": name, "design_SI": list(map(float, x)), "regime": steady.regime}
        row["multipliers_abs"] = [float(v) for v in steady.multiplier_moduli[:4]]
        row["neutral"] = list(steady.neutral)
        print(name, steady.regime, row["multipliers_abs"], flush=True)
        if not steady.periodic:
            rows.append(row)
            continue
        value, grad = steady_value_and_grad(lambda sim: sim.metrics[KEY], build, jnp.asarray(u0), steady)
        grad = np.asarray(grad)
        row.update(value_deg=float(value), gradient_ift=grad.tolist(), first_call_s=time.perf_counter() - start)
        centre_mech = build(jnp.asarray(u0))
        settled = jc.simulate(
            centre_mech,
            ts=jnp.arange(args.revolutions + 1) * float(centre_mech.period),
            options=jc.SolveOptions(rtol=1e-10, atol=1e-10, max_steps=10_000_000),
        ).ys[-1]

        k = steady.period_revolutions

        def continued(u, centre=centre_mech, y=settled, k=k):
            mech = build(jnp.asarray(u))
            return _tracked(mech, args.cont, carry_state(centre, y, mech).at[-2:].set(0.0), k)

        def shooting(u, previous=steady):
            return float(jc.steady_state(build(jnp.asarray(u)), warm_start=previous).metrics[KEY])

        row["from_rest"] = _compare(
            grad, _differences(lambda u, k=k: _tracked(build(jnp.asarray(u)), args.revolutions, k=k), u0, args.h_rest)
        )
        row["continued"] = _compare(grad, _differences(continued, u0, args.h))
        row["shooting"] = _compare(grad, _differences(shooting, u0, args.h))
        row["long_run_value_deg"] = _tracked(centre_mech, args.revolutions, k=k)
        warm = []
        for sign in (1, -1):
            t0 = time.perf_counter()
            nxt = jc.steady_state(build(jnp.asarray(u0 + sign * args.h_rest)), warm_start=steady)
            warm.append((time.perf_counter() - t0, sum(nxt.revolutions.values()), nxt.newton_iterations))
        t0 = time.perf_counter()
        jc.steady_state(centre_mech)
        row.update(
            warm_start_wall_s=[w[0] for w in warm],
            warm_start_revolution_solves=[w[1] for w in warm],
            warm_start_newton_iterations=[w[2] for w in warm],
            cold_wall_s=time.perf_counter() - t0,
            cold_revolution_solves=sum(steady.revolutions.values()),
        )
        print(name, {k: row[k]["rel_error_norm"] for k in ("from_rest", "continued", "shooting")}, flush=True)
        rows.append(row)
        _write(args, rows)
    _write(args, rows)


def _write(args, rows):
    meta = {"h_box": args.h, "h_rest_box": args.h_rest, "revolutions": args.revolutions, "continued": args.cont}
    args.out.write_text(json.dumps({**meta, "designs": rows, "machine": machine()}, indent=1))


if __name__ == "__main__":
    main()
