"""Why the paper run needs ~1e5 explicit steps: step sizes against the explicit stability limit.

    python bench/stiffness.py [--t1 0.1] [--every 200] [--out bench/results/stiffness.json]

Solves the paper preset with the default explicit solver (tsit5, rtol = atol = 1e-6)
from 0 to ``--t1`` s, saving every accepted step, and reports:
- steps and simulated time per contact regime (both pins in contact, one, none),
  for tsit5 and for the L-stable rodas4;
- at every ``--every``-th accepted step: the spectral radius rho of the vector field's
  Jacobian (1/s), the largest eigenvalue's real and imaginary parts, and the step the
  solver took against tsit5's stability limit on the negative real axis, beta / rho
  (beta computed here from diffrax's tableau);
- the same spectral radius with friction off (mu = 0) and with the hysteresis damping
  off (restitution 1) at the same states, to name the source of the stiffness;
- the fastest oscillation (largest |imaginary part| of the Jacobian's eigenvalues, Hz)
  while both pins are in contact, and tsit5's step as a fraction of its period;
- accepted and rejected steps of tsit5, rodas4 (linearly implicit, L-stable) and
  kvaerno5 (diffrax's default chord Newton, and a full Newton) on the first
  ``--window`` s (``jaxcrank.simulate``'s defaults) with friction on and off: what
  limits the implicit solvers' steps.
Writes one JSON file; nothing is asserted.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import diffrax
import jax
import numpy as np
import optimistix as optx
from _common import machine  # bench/ is on sys.path (python bench/stiffness.py)

import jaxcrank as jc
from jaxcrank import model, solve
from jaxcrank.physics.parameters import set_parameter


def tsit5_real_stability_limit() -> float:
    """beta > 0 with |R(-beta)| = 1 for tsit5's stability function R(z) = 1 + z b^T (I - z A)^-1 1."""
    tab = diffrax.Tsit5.tableau
    s = len(tab.b_sol) - 1  # the last (FSAL) stage does not advance the solution
    a = np.zeros((s, s))
    for i, row in enumerate(tab.a_lower[: s - 1]):
        a[i + 1, : len(row)] = row
    b = np.asarray(tab.b_sol[:s])

    def r(z):
        return 1.0 + z * b @ np.linalg.solve(np.eye(s) - z * a, np.ones(s))

    xs = np.linspace(-0.01, -10.0, 100_000)
    bad = np.array([abs(r(x)) > 1.0 for x in xs])
    return float(-xs[np.argmax(bad)])


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--t1", type=float, default=0.1, help="simulated time, s")
    parser.add_argument("--every", type=int, default=200, help="analyse every n-th accepted step")
    parser.add_argument("--window", type=float, default=0.02, help="window of the solver comparison, s")
    parser.add_argument("--out", default="bench/results/stiffness.json")
    args = parser.parse_args(argv)

    mech = jc.paper()

    def steps_by_regime(solver):
        """Accepted steps from 0 to t1 at rtol = atol = 1e-6, classified by the contact
        state at their start: (ts, ys, steps, rejected, per-regime counts and sizes)."""
        sol = jax.jit(
            lambda: diffrax.diffeqsolve(
                diffrax.ODETerm(model.vector_field),
                solver,
                0.0,
                args.t1,
                1e-6,
                model.initial_state(mech),
                args=mech,
                saveat=diffrax.SaveAt(steps=True),
                stepsize_controller=diffrax.PIDController(rtol=1e-6, atol=1e-6, norm=optx.rms_norm),
                max_steps=2_000_000,
                throw=True,
            )
        )()
        n = int(sol.stats["num_accepted_steps"])
        ts, ys = np.asarray(sol.ts[: n + 1]), np.asarray(sol.ys[: n + 1])
        ts, ys = ts[np.isfinite(ts)], ys[np.isfinite(ts)]
        dt = np.diff(ts)  # step k goes from ts[k] to ts[k + 1]; classify it by its start
        frames = jax.jit(jax.vmap(lambda t, y: model.evaluate(mech, t, y)))(ts[:-1], ys[:-1])
        joints = model.compile_model(mech).tree.joints
        in_b = np.asarray(frames.penetration[:, joints.index("B")]) > 0.0
        in_c = np.asarray(frames.penetration[:, joints.index("C")]) > 0.0
        regimes = {}
        for name, mask in (
            ("both_in_contact", in_b & in_c),
            ("only_B_in_contact", in_b & ~in_c),
            ("only_C_in_contact", ~in_b & in_c),
            ("both_separated", ~in_b & ~in_c),
        ):
            regimes[name] = {
                "steps": int(mask.sum()),
                "simulated_ms": float(dt[mask].sum() * 1e3),
                "median_step_us": float(np.median(dt[mask]) * 1e6) if mask.any() else None,
            }
        return ts, ys, dt, n, int(sol.stats["num_rejected_steps"]), regimes, in_b, in_c

    ts, ys, dt, n, rejected, regimes, in_b, in_c = steps_by_regime(diffrax.Tsit5())
    *_, n_rodas, rejected_rodas, regimes_rodas, _, _ = steps_by_regime(solve.solver_from_name("rodas4"))

    beta = tsit5_real_stability_limit()
    idx = np.arange(0, len(dt), args.every)

    def spectrum(m):
        jac = jax.jit(jax.vmap(jax.jacfwd(lambda t, y: model.vector_field(t, y, m), argnums=1)))
        eig = np.linalg.eigvals(np.asarray(jac(ts[idx], ys[idx])))
        top = eig[np.arange(len(idx)), np.argmax(np.abs(eig), axis=1)]
        return np.abs(top), top, np.abs(eig.imag).max(axis=1)

    rho, top, omega = spectrum(mech)
    rho_nofric, _, _ = spectrum(set_parameter(mech, "friction.coefficient", 0.0))
    rho_nodamp, _, _ = spectrum(set_parameter(mech, "contact.restitution", 1.0))
    ratio = dt[idx] / (beta / rho)
    q = [0.1, 0.5, 0.9]

    def quant(x):
        return {f"q{int(p * 100)}": float(v) for p, v in zip(q, np.quantile(x, q))}

    contact = (in_b & in_c)[idx]
    out = {
        "machine": machine(),
        "t1_s": args.t1,
        "solver": "tsit5",
        "rtol": 1e-6,
        "atol": 1e-6,
        "accepted_steps": n,
        "rejected_steps": rejected,
        "mean_step_us": float(dt.mean() * 1e6),
        "regimes": regimes,
        "rodas4": {"accepted_steps": n_rodas, "rejected_steps": rejected_rodas, "regimes": regimes_rodas},
        "tsit5_real_axis_stability_limit": beta,
        "analysed_steps": len(idx),
        "spectral_radius_per_s": quant(rho),
        "largest_eigenvalue_abs_imag_over_abs_real": quant(np.abs(top.imag) / np.maximum(np.abs(top.real), 1e-300)),
        "step_over_stability_limit": quant(ratio),
        "step_over_stability_limit_both_in_contact": quant(ratio[contact]) if contact.any() else None,
        "fastest_oscillation_hz_both_in_contact": quant(omega[contact] / (2 * np.pi)) if contact.any() else None,
        "step_over_fastest_period_both_in_contact": (
            quant(dt[idx][contact] * omega[contact] / (2 * np.pi)) if contact.any() else None
        ),
        "spectral_radius_friction_off_per_s": quant(rho_nofric),
        "spectral_radius_damping_off_per_s": quant(rho_nodamp),
    }
    out["solver_steps"] = []
    for label, m in (("friction on", mech), ("friction off", set_parameter(mech, "friction.coefficient", 0.0))):
        for name, solver in (
            ("tsit5", solve.solver_from_name("tsit5")),
            ("rodas4", solve.solver_from_name("rodas4")),
            ("kvaerno5", solve.solver_from_name("kvaerno5")),
            (
                "kvaerno5, full Newton (Jacobian every iteration)",
                diffrax.Kvaerno5(root_finder=optx.Newton(rtol=1e-6, atol=1e-6)),
            ),
        ):
            sim = solve.simulate(
                m, args.window, n_samples=11, options=jc.SolveOptions(solver=solver, max_steps=1_000_000)
            )
            out["solver_steps"].append(
                {
                    "friction": label,
                    "solver": name,
                    "window_s": args.window,
                    "accepted": int(sim.num_steps),
                    "rejected": int(sim.num_rejected),
                }
            )
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=2))
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
