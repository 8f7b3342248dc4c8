"""Benchmark: where a solver step's time goes on this machine's CPU.

    python bench/step_cost.py [--out bench/results/step_cost.json] [--t1 0.4] [--evals 200000]

Splits the paper run's wall time per solver step (accepted + rejected, tsit5 at
rtol = atol = 1e-6, as ``jaxcrank simulate``) into:

- the vector field alone, evaluated N times in a ``lax.fori_loop`` (us per
  evaluation), with the mechanism's parameters compiled in as constants (as
  ``simulate`` does) and with every parameter traced (as under ``vmap``/``grad``
  over a whole mechanism);
- diffrax's own loop: the same solver, saving and step count with a trivial vector
  field of the same size (constant step size, so the step count is fixed), i.e.
  the per-step cost no vector field can remove;
- one vector-jacobian product of the field (w.r.t. the state and every
  parameter), evaluated the same way: the unit of work of a reverse-mode step;
- the paper run itself.

Tsit5 evaluates the vector field 6 times a step (FSAL), so
``paper run ~ steps * (loop overhead + 6 * field)``. Writes one JSON file;
nothing is asserted.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import diffrax
import jax
import jax.numpy as jnp

jax.config.update("jax_enable_x64", True)

from _common import machine, timed  # noqa: E402

import jaxcrank as jc  # noqa: E402
from jaxcrank import model, solve  # noqa: E402


def field_cost(mech, traced: bool, n=200_000):
    """us per vector-field evaluation inside a compiled loop."""
    y0 = model.initial_state(mech) + 0.1  # pins off centre, both joints in contact range

    def loop(y, m):
        def body(i, carry):
            y, acc = carry
            return y, acc + model.vector_field(i * 1e-7, y + acc * 1e-12, m)  # a data dependence per step

        return jax.lax.fori_loop(0, n, body, (y, jnp.zeros_like(y)))[1]

    if traced:
        m = jax.tree_util.tree_map(lambda x: jnp.asarray(x) if isinstance(x, float) else x, mech)
        f = jax.jit(loop)
        _, wall = timed(lambda: f(y0, m), warmup=1)
    else:
        f = jax.jit(lambda y: loop(y, mech))
        _, wall = timed(lambda: f(y0), warmup=1)
    return wall / n * 1e6


def vjp_cost(mech, n=100_000):
    """us per vector-jacobian product of the vector field (cotangent to the state
    and to every float parameter) inside a compiled loop."""
    y0 = model.initial_state(mech) + 0.1
    m0 = jax.tree_util.tree_map(lambda x: jnp.asarray(x) if isinstance(x, float) else x, mech)

    def loop(y, m):
        def body(i, carry):
            y, acc = carry
            _, pullback = jax.vjp(lambda y, m: model.vector_field(i * 1e-7, y, m), y + acc * 1e-12, m)
            ct_y, ct_m = pullback(jnp.ones_like(y))
            return y, acc + ct_y + 1e-12 * ct_m.crank_length  # a data dependence per step

        return jax.lax.fori_loop(0, n, body, (y, jnp.zeros_like(y)))[1]

    f = jax.jit(loop)
    _, wall = timed(lambda: f(y0, m0), warmup=1)
    return wall / n * 1e6


def loop_overhead(size, t1, n_samples, steps):
    """us per diffrax step with a trivial vector field of ``size`` entries."""
    ts = jnp.linspace(0.0, t1, n_samples)

    @jax.jit
    def run(y0):
        term = diffrax.ODETerm(lambda t, y, args: jnp.cos(t) - 1e-3 * y)
        sol = diffrax.diffeqsolve(
            term,
            diffrax.Tsit5(),
            0.0,
            t1,
            t1 / steps,
            y0,
            saveat=diffrax.SaveAt(ts=ts),
            stepsize_controller=diffrax.ConstantStepSize(),
            max_steps=steps + 10,
        )
        return sol.ys, sol.stats["num_steps"]

    y0 = jnp.zeros(size)
    (_, n), wall = timed(lambda: run(y0), warmup=1)
    return wall / int(n) * 1e6


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, default=Path("bench/results/step_cost.json"))
    p.add_argument("--t1", type=float, help="the paper run's length, s (default: four revolutions)")
    p.add_argument("--evals", type=int, default=200_000, help="vector-field evaluations timed (VJPs: half)")
    a = p.parse_args(argv)
    mech = jc.paper()
    ts = solve.sample_times(mech, t1=a.t1)
    sim, wall = timed(lambda: solve.simulate(mech, ts=ts), warmup=1)
    attempts = int(sim.num_steps) + int(sim.num_rejected)
    field_static = field_cost(mech, traced=False, n=a.evals)
    field_traced = field_cost(mech, traced=True, n=a.evals)
    vjp = vjp_cost(mech, n=a.evals // 2)
    overhead = loop_overhead(model.state_size(mech), float(ts[-1]), len(ts), attempts)
    per_step = wall / attempts * 1e6
    report = {
        "machine": machine(),
        "paper_run": {
            "wall_s": wall,
            "accepted_steps": int(sim.num_steps),
            "rejected_steps": int(sim.num_rejected),
            "us_per_step": per_step,
        },
        "vector_field_us_per_eval": {"parameters_constant": field_static, "parameters_traced": field_traced},
        "vjp_us_per_eval": vjp,
        "vjp_over_field_traced": vjp / field_traced,
        "diffrax_loop_us_per_step_trivial_field": overhead,
        "model_us_per_step": overhead + 6 * field_static,
        "loop_floor_s_for_paper_run_steps": overhead * attempts * 1e-6,
        "note": "model = loop overhead + 6 vector-field evaluations (tsit5, FSAL); the floor is the paper "
        "run's step count at the trivial field's cost, before any physics",
    }
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps(report, indent=2))
    print(
        f"paper run: {wall:.2f} s, {attempts} steps, {per_step:.1f} us/step; vector field {field_static:.2f} us "
        f"(traced parameters {field_traced:.2f} us, its VJP {vjp:.2f} us); diffrax loop alone "
        f"{overhead:.1f} us/step -> "
        f"{overhead * attempts * 1e-6:.2f} s floor; wrote {a.out}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
