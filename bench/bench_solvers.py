"""Benchmark: jaxcrank's solvers against scipy's on the same vector field.

    python bench/bench_solvers.py [--t1 0.4] [--window 0.02] [--out bench/results/solvers.json]

Measures, on this machine's CPU:
- the paper run (``--t1`` s, default 0.4) with the default solver and with the
  ``--implicit`` one (default rodas4): compile time, wall time after compile, steps,
  headline metrics;
- on a shorter ``--window`` (default 0.02 s, the slow baselines would take
  minutes on the full run): every diffrax solver and scipy's LSODA and Radau
  (with the jitted Jacobian) on the same jitted vector field at the same
  tolerances, wall time and steps, and the agreement of the window's metrics;
- reverse-mode gradient time of a window metric against the forward time, the
  same two-parameter gradient in forward mode (``jax.jacfwd``, ``diffrax.ForwardMode``),
  and reverse mode with every step stored instead of recomputed
  (``RecursiveCheckpointAdjoint(checkpoints=steps)``); compile split into tracing
  (Python: JAX and diffrax building the program) and XLA's compilation;
- the same reverse-mode machinery with a vector field that costs nothing (a 12-state
  linear ODE at the same number of constant tsit5 steps): diffrax's own share.
Writes one JSON file; nothing is asserted.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import scipy.integrate
from _common import machine, timed

import jaxcrank as jc
from jaxcrank import model, outputs, solve


def jax_run(mech, t1, solver, tol, n_samples):
    ts = jnp.linspace(0.0, t1, n_samples)
    # the first call compiles; the second is timed as the run
    sim, first = timed(
        lambda: solve.simulate(
            mech, ts=ts, options=jc.SolveOptions.from_text(solver, rtol=tol, atol=tol, max_steps=5_000_000)
        )
    )
    sim, wall = timed(
        lambda: solve.simulate(
            mech, ts=ts, options=jc.SolveOptions.from_text(solver, rtol=tol, atol=tol, max_steps=5_000_000)
        )
    )
    return {
        "solver": solver,
        "wall_s": wall,
        "compile_s": max(first - wall, 0.0),
        "steps": int(sim.num_steps),
        "rejected": int(sim.num_rejected),
        "metrics": outputs.sample_metrics(sim, 0.0),
    }


def scipy_run(mech, t1, method, tol, n_samples):
    f = jax.jit(lambda t, y: model.vector_field(t, y, mech))
    jac = jax.jit(jax.jacfwd(lambda t, y: model.vector_field(t, y, mech), argnums=1))
    y0 = np.asarray(model.initial_state(mech))
    f(0.0, y0).block_until_ready()
    jac(0.0, y0).block_until_ready()
    ts = np.linspace(0.0, t1, n_samples)
    kwargs = {"jac": lambda t, y: np.asarray(jac(t, y))} if method in ("Radau", "BDF", "LSODA") else {}
    start = time.perf_counter()
    sol = scipy.integrate.solve_ivp(
        lambda t, y: np.asarray(f(t, y)), (0.0, t1), y0, method=method, t_eval=ts, rtol=tol, atol=tol, **kwargs
    )
    wall = time.perf_counter() - start
    sim = solve.Simulation(mech, jnp.asarray(sol.t), jnp.asarray(sol.y.T), None, jnp.asarray(sol.nfev), jnp.asarray(0))
    return {
        "solver": f"scipy-{method}",
        "wall_s": wall,
        "compile_s": 0.0,
        "steps": None,
        "nfev": int(sol.nfev),
        "njev": int(getattr(sol, "njev", 0) or 0),
        "success": bool(sol.success),
        "metrics": outputs.sample_metrics(sim, 0.0),
    }


def _steps(mech, l1, l2, ts, tol):
    m = eqx.tree_at(lambda x: (x.crank_length, x.rod_length), mech, (l1, l2))
    sim = solve.simulate(m, ts=ts, options=jc.SolveOptions(rtol=tol, atol=tol, max_steps=1_000_000))
    return sim.num_steps + sim.num_rejected


def _compiled(fn, *args):
    """``fn`` jitted, traced and compiled for ``args``: (compiled, trace s, XLA compile s,
    wall s of the second call)."""
    start = time.perf_counter()
    lowered = jax.jit(fn).lower(*args)
    traced = time.perf_counter()
    compiled = lowered.compile()
    done = time.perf_counter()
    jax.block_until_ready(compiled(*args))
    _, wall = timed(lambda: compiled(*args))
    return compiled, traced - start, done - traced, wall


def gradient_timing(mech, t1, tol):
    ts = jnp.linspace(0.0, t1, 201)

    def objective(l1, l2, adjoint=None):
        m = eqx.tree_at(lambda x: (x.crank_length, x.rod_length), mech, (l1, l2))
        sim = solve.simulate(
            m, ts=ts, options=jc.SolveOptions(rtol=tol, atol=tol, max_steps=1_000_000), adjoint=adjoint
        )
        return outputs.rms_transmission_error(sim, t_start=0.0)

    args = (jnp.asarray(mech.crank_length), jnp.asarray(mech.rod_length))
    _, fwd_trace, fwd_xla, fwd_wall = _compiled(objective, *args)
    grad, grad_trace, grad_xla, grad_wall = _compiled(jax.grad(objective, argnums=(0, 1)), *args)
    g = grad(*args)
    # forward mode: one pass carrying both tangents (diffrax.ForwardMode; the default
    # adjoint's checkpointed loop is reverse-mode only)
    jac_fwd, fm_trace, fm_xla, fm_wall = _compiled(
        jax.jacfwd(lambda a, b: objective(a, b, diffrax.ForwardMode()), argnums=(0, 1)), *args
    )
    gf = jac_fwd(*args)
    # every step stored instead of recomputed: a checkpoint per step of the forward solve
    n_steps = int(jax.jit(lambda a, b: _steps(mech, a, b, ts, tol))(*args))
    stored = diffrax.RecursiveCheckpointAdjoint(checkpoints=n_steps)
    _, st_trace, st_xla, st_wall = _compiled(jax.grad(lambda a, b: objective(a, b, stored), argnums=(0, 1)), *args)
    return {
        "window_s": t1,
        "forward_wall_s": fwd_wall,
        "forward_trace_s": fwd_trace,
        "forward_compile_s": fwd_trace + fwd_xla,
        "gradient_wall_s": grad_wall,
        "gradient_trace_s": grad_trace,
        "gradient_xla_compile_s": grad_xla,
        "gradient_compile_s": grad_trace + grad_xla,
        "gradient_over_forward": grad_wall / fwd_wall,
        "gradient": [float(x) for x in g],
        "forward_mode_wall_s": fm_wall,
        "forward_mode_compile_s": fm_trace + fm_xla,
        "forward_mode_over_forward": fm_wall / fwd_wall,
        "forward_mode_gradient": [float(x) for x in gf],
        "gradient_every_step_stored_wall_s": st_wall,
        "gradient_every_step_stored_compile_s": st_trace + st_xla,
        "gradient_every_step_stored_over_forward": st_wall / fwd_wall,
        "checkpoints": n_steps,
        "adjoint_floor": adjoint_floor(n_steps, ts),
        "note": "compile = trace and lower + XLA compile. Over 20 ms both derivatives are the chaotic "
        "pathwise one (~1e27, docs/numerics.md 'Gradients beyond the first impacts'); this times the work, "
        "tests/test_gradients.py checks that the two modes agree on 1.2 ms",
    }


def adjoint_floor(n_steps, ts):
    """What diffrax's reverse mode costs with a vector field that costs nothing: a
    12-state linear ODE, tsit5 at ``n_steps`` constant steps, saved at ``ts``; the
    ratio of its gradient (two parameters, default checkpointed adjoint) to its forward
    solve. The machinery's own share of the ratio measured on the model."""
    t1 = float(ts[-1])

    def field(t, y, args):
        a, b = args
        return a * jnp.roll(y, 1) - b * y

    def objective(a, b):
        sol = diffrax.diffeqsolve(
            diffrax.ODETerm(field),
            diffrax.Tsit5(),
            0.0,
            t1,
            t1 / n_steps,
            jnp.full(12, 0.1),
            args=(a, b),
            saveat=diffrax.SaveAt(ts=ts),
            stepsize_controller=diffrax.ConstantStepSize(),
            max_steps=n_steps + 10,
        )
        return jnp.sqrt(jnp.mean(sol.ys**2))

    args = (jnp.asarray(1.0), jnp.asarray(2.0))
    _, _, _, fwd = _compiled(objective, *args)
    _, _, _, grad = _compiled(jax.grad(objective, argnums=(0, 1)), *args)
    return {
        "steps": n_steps,
        "forward_wall_s": fwd,
        "forward_us_per_step": fwd / n_steps * 1e6,
        "gradient_wall_s": grad,
        "gradient_over_forward": grad / fwd,
        "backward_us_per_step": (grad - fwd) / n_steps * 1e6,
    }


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--t1", type=float, default=0.4)
    p.add_argument("--window", type=float, default=0.02)
    p.add_argument("--tol", type=float, default=1e-6)
    p.add_argument("--solvers", default="tsit5,dopri5,rodas4,kvaerno5")
    p.add_argument("--implicit", default="rodas4", help="implicit solver also timed on the paper run")
    p.add_argument("--scipy", default="LSODA,Radau")
    p.add_argument("--out", type=Path, default=Path("bench/results/solvers.json"))
    args = p.parse_args()
    mech = jc.paper()
    report = {"machine": machine(), "tolerance": args.tol}
    print(f"paper run, {args.t1} s, default solver {solve.DEFAULTS.solver_name} ...", flush=True)
    report["paper_run"] = jax_run(mech, args.t1, solve.DEFAULTS.solver_name, args.tol, int(args.t1 * 36000) + 1)
    print(json.dumps(report["paper_run"], indent=1), flush=True)
    if args.implicit:
        print(f"paper run, {args.t1} s, {args.implicit} ...", flush=True)
        report["paper_run_implicit"] = jax_run(mech, args.t1, args.implicit, args.tol, int(args.t1 * 36000) + 1)
        print(json.dumps(report["paper_run_implicit"], indent=1), flush=True)
    window = []
    n = int(args.window * 36000) + 1
    for name in args.solvers.split(","):
        print(f"window {args.window} s: {name} ...", flush=True)
        window.append(jax_run(mech, args.window, name, args.tol, n))
        print(f"  {window[-1]['wall_s']:.3f} s", flush=True)
    for method in filter(None, args.scipy.split(",")):
        print(f"window {args.window} s: scipy {method} ...", flush=True)
        window.append(scipy_run(mech, args.window, method, args.tol, n))
        print(f"  {window[-1]['wall_s']:.3f} s", flush=True)
    base = next(r for r in window if r["solver"] == solve.DEFAULTS.solver_name)
    for r in window:
        r["speedup_of_default"] = r["wall_s"] / base["wall_s"]
        r["max_slider_dev_rel_diff_vs_default"] = (
            abs(r["metrics"]["max_abs_slider_x_deviation_m"] - base["metrics"]["max_abs_slider_x_deviation_m"])
            / base["metrics"]["max_abs_slider_x_deviation_m"]
        )
    report["window"] = {"t1_s": args.window, "runs": window}
    print("gradient timing ...", flush=True)
    report["gradient"] = gradient_timing(mech, args.window, args.tol)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(report, indent=2))
    print(json.dumps({k: v for k, v in report.items() if k != "window"}, indent=1))
    for r in window:
        print(f"{r['solver']:>14}: {r['wall_s']:8.3f} s  ({r['speedup_of_default']:.1f}x default)")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
