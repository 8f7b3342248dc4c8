"""Calibration against a measured trace: Levenberg-Marquardt with the exact Jacobian through
the steady orbit (optim.fit) against CMA-ES on the same misfit.

The paper's slider-crank (``jaxcrank.paper()``, clearances at B and C) at a design the fit is
not told: clearance_B = 0.3 mm, clearance_C = 0.4 mm, contact.restitution = 0.7 (the preset's
is 0.9). Its steady state is checked to be periodic; the synthetic measurement is the slider's
acceleration (``slider_ax_m_s2``) over one revolution of the steady orbit, one sample per degree
of crank angle, plus Gaussian noise of 5 % of the signal's RMS (fixed seed). Every method
minimises the same misfit, the sum of squared residuals (model - measured) / noise, over the
same bounds, from one of two starts:

- ``far``: 30 % off every parameter (clearance_B -30 %, clearance_C -30 %, restitution +30 %:
  a corner whose steady state is periodic, as the fit needs; ``start_corners`` records the
  regime of each of the eight corners 30 % off);
- ``near``: inside the basin of the true design (clearance_B +2 %, clearance_C -2 %,
  restitution +4 %).

Methods: ``lm_*``: optim.fit.fit (bounded Levenberg-Marquardt in ln(x / start), exact Jacobian by
forward mode through the orbit and the implicit function theorem); ``cma_*``: CMA-ES (``cma``
package) in the same scaled variables (sigma0 0.3 far, 0.03 near) until its best misfit is within
1 % of the best LM fit's or its CPU budget is spent (``--cma-budget-s``; each evaluation is a
steady-state solve, several CPU seconds on two cores); ``hybrid``: LM from CMA-ES's best far
design.

CPU seconds are ``time.process_time()`` of this process (XLA's CPU threads included),
compilation included: JAX's caches and the compiled model-trace programs are dropped before
each method, so each compiles its own. Finally a design that is not periodic (the preset's
0.5 mm clearances, restitution 0.9) is fitted for a few iterations to record what the fit
reports there. Writes ``bench/results/calibration.json``.

Usage: ``python bench/bench_calibration.py [--cma-budget-s 1200] [--skip-cma] [--skip-not-periodic]``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import sys
import time
from pathlib import Path

import jax
import numpy as np
from _common import machine

import jaxcrank as jc
from optim.calibrate import FIT_STEADY, Calibration, FitParameter, forget_programs, model_trace
from optim.fit import fit
from optim.least_squares import LMSettings

ROOT = Path(__file__).resolve().parent
NAMES = ("clearance_B", "clearance_C", "contact.restitution")
TRUE = np.array([3e-4, 4e-4, 0.7])
START_FACTORS = np.array([0.7, 0.7, 1.3])
NEAR_FACTORS = np.array([1.02, 0.98, 1.04])
LOWER, UPPER = np.array([1e-4, 1e-4, 0.3]), np.array([8e-4, 8e-4, 1.0])
SIGNAL = "slider_ax_m_s2"


def _params(start):
    return [FitParameter(n, float(s), float(lo), float(hi)) for n, s, lo, hi in zip(NAMES, start, LOWER, UPPER)]


def _inside(ci, value) -> bool | None:
    return None if None in ci else bool(ci[0] <= value <= ci[1])


def corners(base) -> list:
    """The steady-state regime at each of the eight designs 30 % off the true one."""
    import itertools

    out = []
    for signs in itertools.product((0.7, 1.3), repeat=3):
        x = TRUE * np.array(signs)
        st = jc.steady_state(jc.set_parameters(base, NAMES, x), FIT_STEADY, throw=False)
        why = None if st.ok else "the solve failed (a revolution needs more than max_steps steps)"
        out.append({"factors": list(signs), "regime": str(st.regime) if st.ok else "failed", "why": why})
        print(f"corner {signs}: {out[-1]['regime']}", file=sys.stderr, flush=True)
    return out


def _errors(x) -> dict:
    return {n: float(v / t - 1.0) for n, v, t in zip(NAMES, x, TRUE)}


def run_lm(base, trace, start, noise, max_iterations):
    jax.clear_caches()
    forget_programs()
    result = fit(
        base, _params(start), trace, noise=noise, settings=LMSettings(max_iterations=max_iterations), progress=True
    )
    return result


def run_cma(base, trace, start, noise, target, budget_s, seed, sigma0):
    import cma

    jax.clear_caches()
    forget_programs()
    tic = time.process_time()
    cal = Calibration(base, _params(start), trace, noise=noise)
    params = cal.parameters
    lower = [p.scaled(p.lower) for p in params]
    upper = [p.scaled(p.upper) for p in params]
    best = {"misfit": math.inf, "x": None}
    trail = []

    def f(u):
        x = np.array([p.si(v) for p, v in zip(params, u)])
        m = cal.misfit(x)
        if m < best["misfit"]:
            best.update(misfit=m, x=x.tolist())
        trail.append({"evaluation": cal.evaluations, "cpu_s": time.process_time() - tic, "best_misfit": best["misfit"]})
        return m if math.isfinite(m) else 1e300

    es = cma.CMAEvolutionStrategy([0.0] * len(params), sigma0, {"bounds": [lower, upper], "seed": seed, "verbose": -9})
    reason = "cma stopped on its own"
    while not es.stop():
        xs = es.ask()
        es.tell(xs, [f(u) for u in xs])
        elapsed = time.process_time() - tic
        print(
            f"cma: {cal.evaluations} evaluations, best misfit {best['misfit']:.6g} (target {target:.6g}), "
            f"{elapsed:.0f} s CPU",
            file=sys.stderr,
            flush=True,
        )
        if best["misfit"] <= target:
            reason = "reached the target misfit (the LM fit's + 1 %)"
            break
        if elapsed > budget_s:
            reason = f"CPU budget of {budget_s:g} s spent"
            break
    return {
        "stop_reason": reason,
        "reached_target": best["misfit"] <= target,
        "cpu_seconds": time.process_time() - tic,
        "evaluations": cal.evaluations,
        "best_misfit": best["misfit"],
        "best_x_SI": dict(zip(NAMES, best["x"])),
        "relative_errors": _errors(np.asarray(best["x"])),
        "start_SI": dict(zip(NAMES, np.asarray(start).tolist())),
        "sigma0_scaled": sigma0,
        "popsize": es.popsize,
        "best_misfit_trail": trail[:: max(1, len(trail) // 60)] + trail[-1:],
    }


def not_periodic_case(base, max_iterations):
    """The fit at a design without a periodic orbit (the preset's own clearances and restitution)."""
    jax.clear_caches()
    forget_programs()
    x = np.array([5e-4, 5e-4, 0.9])
    trace, ev = model_trace(base, NAMES, x, SIGNAL, angle_deg=np.arange(0.0, 360.0, 2.0))
    if ev.regime == "periodic":
        return {"skipped": "the preset's design was periodic here"}
    start = x * np.array([1.05, 0.95, 0.98])
    result = fit(base, _params(start), trace, settings=LMSettings(max_iterations=max_iterations), progress=True)
    s = result.summary()
    return {
        "design_SI": dict(zip(NAMES, x.tolist())),
        "trace_regime": ev.regime,
        "trace_source": ev.source,
        "start_SI": dict(zip(NAMES, start.tolist())),
        "fitted_SI": dict(zip(NAMES, result.fitted.tolist())),
        "regime": s["regime"],
        "model_trace": s["model_trace"],
        "identifiable": {n: p["identifiable"] for n, p in s["parameters"].items()},
        "why_not": {n: p["why_not"] for n, p in s["parameters"].items()},
        "misfit_start": s["misfit_start"],
        "misfit_final": s["misfit_final"],
        "condition_number": s["condition_number"],
        "iterations": s["iterations"],
        "stop_reason": s["stop_reason"],
        "notes": s["notes"],
        "cpu_seconds": s["cpu_seconds"],
    }


def _lm_record(result, start) -> dict:
    s = result.summary()
    return {
        "start_SI": dict(zip(NAMES, np.asarray(start).tolist())),
        "fitted_SI": dict(zip(NAMES, result.fitted.tolist())),
        "relative_errors": _errors(result.fitted),
        "ci95": {n: s["parameters"][n]["ci95"] for n in NAMES},
        "true_inside_ci95": {n: _inside(s["parameters"][n]["ci95"], t) for n, t in zip(NAMES, TRUE)},
        "identifiable": {n: s["parameters"][n]["identifiable"] for n in NAMES},
        "cpu_seconds": s["cpu_seconds"],
        "compile_seconds": s["compile_seconds"],
        "evaluations": s["evaluations"],
        "evaluation_kind": "steady state + residuals and exact Jacobian (a refused trial out of the periodic "
        "regime: the steady state only)",
        "iterations": s["iterations"],
        "misfit_start": s["misfit_start"],
        "misfit_final": s["misfit_final"],
        "rms_residual_final": s["rms_residual_final"],
        "residual_variance": s["residual_variance"],
        "singular_values": s["singular_values"],
        "condition_number": s["condition_number"],
        "correlation": s["correlation"],
        "regime": s["regime"],
        "converged": s["converged"],
        "stop_reason": s["stop_reason"],
        "notes": s["notes"],
    }


def _met(errors: dict) -> bool:
    e = [abs(errors[n]) for n in NAMES]
    return bool(e[0] <= 0.02 and e[1] <= 0.02 and e[2] <= 0.05)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cma-budget-s", type=float, default=1200.0, help="CMA-ES CPU budget per run, s (default 1200)")
    ap.add_argument("--samples", type=int, default=360, help="samples over the revolution (default 360)")
    ap.add_argument("--noise", type=float, default=0.05, help="noise, fraction of the signal's RMS (default 0.05)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--max-iterations", type=int, default=40)
    ap.add_argument("--skip-cma", action="store_true")
    ap.add_argument("--skip-not-periodic", action="store_true")
    ap.add_argument("--out", type=Path, default=ROOT / "results" / "calibration.json")
    args = ap.parse_args()

    base = jc.paper()
    tic = time.process_time()
    truth = jc.steady_state(jc.set_parameters(base, NAMES, TRUE), FIT_STEADY)
    angles = np.arange(args.samples) * (360.0 / args.samples)
    clean, ev = model_trace(base, NAMES, TRUE, SIGNAL, angle_deg=angles)
    rms = float(np.sqrt(np.mean(clean.values**2)))
    noise = args.noise * rms
    rng = np.random.default_rng(args.seed)
    trace = dataclasses.replace(clean, values=clean.values + noise * rng.standard_normal(clean.n))
    misfit_at_truth = Calibration(base, _params(TRUE), trace, noise=noise).misfit(TRUE)
    out = {
        "benchmark": "calibration",
        "machine": machine(load_average=list(os.getloadavg())),
        "mechanism": "jaxcrank.paper()",
        "signal": SIGNAL,
        "true_design": {
            "SI": dict(zip(NAMES, TRUE.tolist())),
            "regime": str(truth.regime),
            "period_revolutions": int(truth.period_revolutions),
            "leading_floquet_multiplier": float(truth.multiplier_moduli[0]),
        },
        "trace": {
            "samples": clean.n,
            "over": "one revolution of the steady orbit, equal steps of crank angle",
            "signal_rms": rms,
            "noise_fraction_of_rms": args.noise,
            "noise_sigma": noise,
            "seed": args.seed,
            "misfit_at_true_design": misfit_at_truth,
        },
        "steady_options": {
            "settle_revolutions": FIT_STEADY.settle_revolutions,
            "max_period": FIT_STEADY.max_period,
            "rtol": FIT_STEADY.solve.rtol,
            "newton_tol": FIT_STEADY.newton_tol,
        },
        "bounds": {n: [float(lo), float(hi)] for n, lo, hi in zip(NAMES, LOWER, UPPER)},
        "setup_cpu_seconds": time.process_time() - tic,
        "targets": {"clearances_relative_error": 0.02, "restitution_relative_error": 0.05},
        "methods": {},
    }
    methods = out["methods"]

    def save():
        args.out.write_text(json.dumps(out, indent=2))

    starts = {"near": TRUE * NEAR_FACTORS, "far": TRUE * START_FACTORS}
    for label, start in starts.items():
        result = run_lm(base, trace, start, noise, args.max_iterations)
        methods[f"lm_{label}"] = {**_lm_record(result, start), "targets_met": _met(_errors(result.fitted))}
        save()
    best = min(m["misfit_final"] for m in methods.values())
    if not args.skip_cma:
        target = 1.01 * best
        for label, sigma in (("far", 0.3), ("near", 0.03)):
            rec = run_cma(base, trace, starts[label], noise, target, args.cma_budget_s, args.seed + 1, sigma)
            methods[f"cma_{label}"] = {**rec, "target_misfit": target, "targets_met": _met(rec["relative_errors"])}
            save()
        far = methods["cma_far"]
        if far["best_x_SI"] is not None:
            x = np.clip([far["best_x_SI"][n] for n in NAMES], LOWER, UPPER)
            result = run_lm(base, trace, x, noise, args.max_iterations)
            methods["hybrid_far"] = {
                **_lm_record(result, x),
                "targets_met": _met(_errors(result.fitted)),
                "cpu_seconds_with_cma": result.cpu_seconds + far["cpu_seconds"],
            }
            save()
    if not args.skip_not_periodic:
        out["start_corners"] = corners(base)
        save()
        out["not_periodic"] = not_periodic_case(base, 3)
    save()
    print(json.dumps({k: {q: v.get(q) for q in ("relative_errors", "cpu_seconds", "misfit_final", "best_misfit")}
                      for k, v in methods.items()}, indent=1))  # fmt: skip


if __name__ == "__main__":
    main()
