"""Head-to-head on the steady state, judged on held-out long runs.

``taskset -c 1 python bench/bench_design.py [--budget 500] [--seed 0] [--checkpoints ...] [--out FILE]``

(``taskset -c 1``: one core for the methods, the other free for other work, so that the wall
budgets are not shared with it.)

Problem: the nine-variable design problem (:func:`optim.design.design_problem`) with the
steady-state objective (:class:`optim.steady.Steady`: Eq. 19 and the design terms over one
period of the periodic orbit; outside the periodic regime the long-run statistical value).
Every method optimises that same objective over the scaled box [0, 1]^9 from the same start
design (the preset's, which is not periodic), with the same wall budget, one process each,
one after another:

- ``ours``: regime-classified start, then gradients. The start and scrambled Sobol points
  are classified by the steady-state solve (value only) until a periodic design is found
  (at most ``CLASSIFY`` designs); from it (the best periodic one), projected Adam on the
  exact steady-state gradient with the regime guard (a step that leaves the periodic regime
  is halved, then held: :class:`optim.steady.RegimeGuard`), until the budget is spent.
- ``cma`` (CMA-ES, ``cma``), ``tpe`` (optuna's TPE), ``nelder_mead`` (scipy, bounded),
  ``sobol`` (scrambled Sobol points): the objective's value only.

Every evaluation of every method is warm-started from the last periodic orbit its own
evaluator found (:class:`optim.steady.SteadyEvaluator`). Compilation is done before the first
method, untimed: the steady-state solve (``compile_s``, every method uses it) and our
value-and-gradient program (``gradient_compile_s``, at the periodic CMA-ES design of
``bench/results/design_study.json``, used only to compile it; the program is shared by
every evaluator of the problem).

**Held-out truth.** Each method's best-so-far design (by the objective it optimised) at
``CHECKPOINTS`` fractions of the budget, its returned design among them, is scored by a
held-out evaluation that no method optimised: a simulation from rest of ``HELDOUT
["revolutions"]`` revolutions at the library's default tolerances, the RMS metrics over the
last ``HELDOUT["last_revolutions"]``, the problem's weighted value, averaged over
``HELDOUT["realisations"]`` realisations whose initial crank angle differs by
``HELDOUT["perturbation_rad"]`` (far below any tolerance). ``time_to_1pct_s``: the first
checkpoint at which a method's held-out value is within 1 % of the best held-out value any
method reached; ``speedup_vs_best_gradient_free``: the best gradient-free method's time
over ours (None when either never gets there).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

#: the steady-state objective's settings in the bench (looser than the library's default
#: 1e-10 so that a cold steady-state solve takes seconds on the 2-core machine)
STEADY = dict(
    rtol=1e-8,
    atol=1e-8,
    newton_tol=1e-6,
    settle_revolutions=12,
    statistics_revolutions=4,
    batch_revolutions=2,
    samples_per_revolution=360,
    max_steps=300_000,
)
#: the held-out evaluation
HELDOUT = dict(revolutions=20, last_revolutions=5, realisations=4, perturbation_rad=1e-9, samples_per_revolution=360)
#: fractions of the budget at which best-so-far designs are scored (finer early, where they change most)
CHECKPOINTS = (1 / 64, 1 / 32, 1 / 16, 3 / 32, 1 / 8, 5 / 32, 3 / 16, 1 / 4, 3 / 8, 1 / 2, 3 / 4, 1.0)
CLASSIFY = 8  # ours: designs classified at most before the gradient phase
LEARNING_RATE = 0.05  # ours: Adam step, scaled design units
GRADIENT_FREE = ("cma", "tpe", "nelder_mead", "sobol")
METHODS = ("ours",) + GRADIENT_FREE


def build():
    """The nine-variable design problem with the bench's steady-state objective."""
    from optim.design import design_problem
    from optim.steady import Steady

    return design_problem(Steady(**STEADY))


def heldout_program(problem, heldout=HELDOUT):
    """Jitted ``x (SI) -> (value per realisation (R,), ok (R,))``: the held-out evaluation
    (module docstring), the problem's value in degrees (terms + cost)."""
    import equinox as eqx
    import jax
    import jax.numpy as jnp

    import jaxcrank as jc

    revs, last = heldout["revolutions"], heldout["last_revolutions"]

    def one(x, dphi):
        mech = problem.mechanism(x)
        mech = eqx.tree_at(lambda m: m.driver.initial_angle, mech, mech.driver.initial_angle + dphi)
        period = mech.period
        n = revs * heldout["samples_per_revolution"]
        ts = jnp.linspace(0.0, revs * period, n + 1)
        # between samples: no rounding decides which samples are in the statistics
        start = (revs - last) * period + 0.5 * period / heldout["samples_per_revolution"]
        sim = jc.simulate(mech, ts=ts, metrics_start=start, save_ts=ts[-1:], max_steps=5_000_000, throw=False)
        value = problem.loss(sim.metrics) + problem.cost(x)
        return jnp.where(sim.ok, value, jnp.nan), sim.ok

    dphis = heldout["perturbation_rad"] * jnp.arange(heldout["realisations"], dtype=float)
    return jax.jit(lambda x: jax.vmap(lambda d: one(x, d))(dphis))


class Budget(Exception):
    """The method's wall budget is spent."""


class Clock:
    """Times and records every objective evaluation of one method run."""

    def __init__(self, problem, evaluator, budget):
        self.problem, self.evaluator, self.budget = problem, evaluator, budget
        self.t0 = time.perf_counter()
        self.trace = []  # (seconds, value, unit design, regime)

    def elapsed(self):
        return time.perf_counter() - self.t0

    def value(self, u):
        if self.elapsed() > self.budget:
            raise Budget
        u = np.clip(np.asarray(u, float), 0.0, 1.0)
        try:
            v, info = self.evaluator.value(np.asarray(self.problem.from_unit(u)))
            regime = info["regime"] if info["ok"] else "failed"
        except Exception:  # noqa: BLE001 - a solver error: a failed design
            v, regime = math.nan, "failed"
        v = v if math.isfinite(v) else math.inf
        self.trace.append((self.elapsed(), v, u.tolist(), regime))
        return v


def run_cma(clock, n, start, seed):
    import cma

    es = cma.CMAEvolutionStrategy(list(start), 0.25, {"bounds": [0.0, 1.0], "seed": seed + 1, "verbose": -9})
    while not es.stop():
        xs = es.ask()
        es.tell(xs, [min(clock.value(x), 1e6) for x in xs])


def run_nelder_mead(clock, n, start, seed):
    from scipy.optimize import minimize

    minimize(
        lambda u: min(clock.value(u), 1e6),
        np.asarray(start),
        method="Nelder-Mead",
        bounds=[(0.0, 1.0)] * n,
        options={"maxfev": 100000, "xatol": 1e-6, "fatol": 1e-9},
    )


def run_tpe(clock, n, start, seed):
    import optuna

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    study = optuna.create_study(sampler=optuna.samplers.TPESampler(seed=seed))
    study.enqueue_trial({f"u{j}": float(v) for j, v in enumerate(start)})
    while True:
        trial = study.ask()
        u = [trial.suggest_float(f"u{j}", 0.0, 1.0) for j in range(n)]
        study.tell(trial, min(clock.value(u), 1e6))


def run_sobol(clock, n, start, seed):
    from scipy.stats import qmc

    clock.value(start)
    sampler = qmc.Sobol(d=n, scramble=True, seed=seed)
    while True:
        for u in sampler.random(2):
            clock.value(u)


def run_ours(clock, problem, start, seed, info):
    """Regime-classified start, then projected Adam with the regime guard (module docstring)."""
    import dataclasses

    from optim.optimize import Settings, optimize, start_points
    from optim.optimizers import adam
    from optim.steady import RegimeGuard

    x0 = tuple(float(v) for v in np.asarray(problem.from_unit(np.asarray(start))))
    points = start_points(dataclasses.replace(problem, start=x0), CLASSIFY, seed)
    classified = info["classified"] = []
    for u in points:
        v = clock.value(u)
        classified.append({"unit_design": np.asarray(u).tolist(), "value": v, "regime": clock.trace[-1][3]})
        if any(c["regime"] == "periodic" for c in classified):
            break
    periodic = [c for c in classified if c["regime"] == "periodic"]
    if not periodic:
        info["note"] = "no periodic design among the classified ones: no gradient phase"
        return
    best = min(periodic, key=lambda c: c["value"])
    prob = dataclasses.replace(problem, start=tuple(np.asarray(problem.from_unit(np.asarray(best["unit_design"])))))
    settings = Settings(
        optimizer=adam(LEARNING_RATE),
        max_iterations=10_000,
        gtol=1e-4,
        xtol=1e-4,
        patience=5,
        guard=RegimeGuard(max_halvings=3),
        max_seconds=max(0.0, clock.budget - clock.elapsed()),
    )
    t_phase = clock.elapsed()
    res = optimize(prob, settings, progress=False)
    wall = clock.elapsed() - t_phase
    secs = np.array([h["seconds"] for h in res["history"]])
    ends = t_phase + (wall - secs.sum()) + np.cumsum(secs)
    for t, h in zip(ends, res["history"]):
        u = np.asarray(prob.to_unit(np.asarray([h[f"{nm}_SI"] for nm in prob.names])))
        clock.trace.append((float(t), h["objective_deg"], u.tolist(), h["regime"]))
    info.update(
        iterations=len(res["history"]),
        converged=res["converged"],
        halvings=int(sum(h["halvings"] for h in res["history"])),
        regimes=[h["regime"] for h in res["history"]],
        leading_multipliers=[h["leading_multiplier"] for h in res["history"]],
        seconds_per_iteration_median=float(np.median(secs)) if len(secs) else None,
    )


def best_so_far(trace):
    """``(seconds, best value, unit design)`` after each evaluation of a trace."""
    out, best = [], (math.inf, None)
    for t, v, u, _ in sorted(trace, key=lambda e: e[0]):
        if v < best[0]:
            best = (v, u)
        out.append((t, best[0], best[1]))
    return out


def checkpoints(trace, budget, fractions=CHECKPOINTS):
    """The best-so-far value and design at each fraction of the budget (None before the first)."""
    bsf = best_so_far(trace)
    out = []
    for f in fractions:
        upto = [b for b in bsf if b[0] <= f * budget]
        t, v, u = upto[-1] if upto else (None, math.inf, None)
        out.append({"t_s": f * budget, "objective_deg": v, "unit_design": u})
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--budget", type=float, default=500.0, help="wall budget per method, s")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS)
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "design.json")
    ap.add_argument(
        "--checkpoints",
        type=float,
        nargs="+",
        default=list(CHECKPOINTS),
        help="fractions of the budget at which best-so-far designs are scored held-out (the last must be 1)",
    )
    args = ap.parse_args(argv)
    fractions = tuple(sorted(args.checkpoints))
    if not all(0.0 < f <= 1.0 for f in fractions) or fractions[-1] != 1.0:
        ap.error(f"--checkpoints: fractions in (0, 1] ending at 1, got {list(args.checkpoints)}")

    import jax

    jax.config.update("jax_enable_x64", True)
    from optim.steady import SteadyEvaluator

    tic_all = time.perf_counter()
    problem = build()
    start = np.asarray(problem.start_unit(), dtype=float)
    x_start = np.asarray(problem.from_unit(start))
    print(f"start design (unit box): {np.round(start, 4).tolist()}", flush=True)

    # compile the steady-state solve and the held-out program (untimed)
    t = time.perf_counter()
    start_value, start_info = SteadyEvaluator(problem).value(x_start)
    compile_s = time.perf_counter() - t
    study = json.loads((ROOT / "bench" / "results" / "design_study.json").read_text())
    t = time.perf_counter()
    SteadyEvaluator(problem).value_and_grad(np.asarray(study["optimum"]["cma_design_SI"]))
    gradient_compile_s = time.perf_counter() - t
    heldout = heldout_program(problem)
    t = time.perf_counter()
    vals, ok = heldout(x_start)
    start_heldout = float(np.mean(np.asarray(vals)))
    heldout_first_s = time.perf_counter() - t
    print(
        f"start: objective {start_value:.5f} deg ({start_info['regime']}), held-out {start_heldout:.5f} deg; "
        f"steady compile+solve {compile_s:.0f} s, held-out {heldout_first_s:.0f} s",
        flush=True,
    )

    runs = {}
    for name in args.methods:
        clock = Clock(problem, SteadyEvaluator(problem), args.budget)
        info = {}
        try:
            if name == "ours":
                run_ours(clock, problem, start, args.seed, info)
            else:
                {"cma": run_cma, "tpe": run_tpe, "nelder_mead": run_nelder_mead, "sobol": run_sobol}[name](
                    clock, problem.n, start, args.seed
                )
        except Budget:
            pass
        runs[name] = (clock.trace, info)
        best = min((v for _, v, _, _ in clock.trace), default=math.inf)
        print(f"{name}: {len(clock.trace)} evaluations, best objective {best:.5f} deg", flush=True)

    # held-out scores of the checkpoint designs (cached per design)
    scored = {}

    def score(u):
        key = tuple(u)
        if key not in scored:
            v, ok = heldout(np.asarray(problem.from_unit(np.asarray(u))))
            v = np.asarray(v)
            scored[key] = (float(np.mean(v)), float(np.std(v)), bool(np.all(np.asarray(ok))))
        return scored[key]

    methods = {}
    for name, (trace, info) in runs.items():
        cps = checkpoints(trace, args.budget, fractions)
        for cp in cps:
            if cp["unit_design"] is not None:
                m, s, ok = score(cp["unit_design"])
                cp.update(heldout_deg=m, heldout_std_deg=s, heldout_ok=ok)
            else:
                cp.update(heldout_deg=start_heldout, heldout_std_deg=None, heldout_ok=True)
        methods[name] = {
            "evaluations": len(trace),
            "periodic_evaluations": sum(e[3] == "periodic" for e in trace),
            "best_objective": min((v for _, v, _, _ in trace), default=math.inf),
            "checkpoints": cps,
            "best_heldout": cps[-1]["heldout_deg"],
            "returned_design_SI": None
            if cps[-1]["unit_design"] is None
            else np.asarray(problem.from_unit(np.asarray(cps[-1]["unit_design"]))).tolist(),
            "trace": [[t, v, r] for t, v, _, r in trace],
            **info,
        }
        print(f"{name}: held-out at checkpoints {[round(c['heldout_deg'], 5) for c in cps]}", flush=True)
    best_any = min(min(c["heldout_deg"] for c in m["checkpoints"]) for m in methods.values())
    target = 1.01 * best_any
    for m in methods.values():
        hit = [c["t_s"] for c in m["checkpoints"] if c["heldout_deg"] <= target]
        m["time_to_1pct_s"] = hit[0] if hit else None
    free = [methods[k]["time_to_1pct_s"] for k in GRADIENT_FREE if k in methods]
    free = [t for t in free if t is not None]
    ours_t = methods.get("ours", {}).get("time_to_1pct_s")
    speedup = (min(free) / ours_t) if free and ours_t else None
    # no gradient-free method within 1 % in its budget: it would get there after the budget at the soonest
    speedup_lower_bound = args.budget / ours_t if ours_t and not free else speedup

    data = {
        "objective": "steady_state",
        "command": _command(argv if argv is not None else sys.argv[1:]),
        "steady_objective": STEADY,
        "heldout": {**HELDOUT, "metric": "problem value: Eq. 19 + weighted terms + cost, deg"},
        "budget_s_per_method": args.budget,
        "checkpoint_fractions": list(fractions),
        "seeds": [args.seed],
        "learning_rate": LEARNING_RATE,
        "start_unit_design": start.tolist(),
        "start_objective_deg": start_value,
        "start_regime": start_info["regime"],
        "start_heldout_deg": start_heldout,
        "compile_s": compile_s,
        "gradient_compile_s": gradient_compile_s,
        "problems": [
            {
                "name": "design_9var",
                "n_variables": problem.n,
                "names": list(problem.names),
                "methods": methods,
                "best_heldout_any_method": best_any,
                "target_heldout_deg": target,
                "speedup_vs_best_gradient_free": speedup,
                "speedup_vs_best_gradient_free_lower_bound": speedup_lower_bound,
            }
        ],
        "machine": {
            "platform": platform.platform(),
            "cpus": os.cpu_count(),
            "cpus_usable": len(os.sched_getaffinity(0)),
            "load_average": os.getloadavg(),
        },
        "wall_s": time.perf_counter() - tic_all,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(data, indent=1, default=float))
    plot(data, args.out.with_suffix(".png"))
    print(f"speedup vs best gradient-free: {speedup} (lower bound {speedup_lower_bound}); wrote {args.out}", flush=True)
    return data


def _command(args) -> str:
    """The command line that reproduces the results (``--out`` left out: it moves them only)."""
    kept, skip = [], False
    for a in args:
        if skip:
            skip = False
        elif a == "--out":
            skip = True
        elif not a.startswith("--out="):
            kept.append(a)
    return " ".join(["python bench/bench_design.py", *kept])


def plot(data, path):
    """Held-out value of each method's best-so-far design against wall time (solid, the
    checkpoints), and the objective it optimised (dotted)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    (p,) = data["problems"]
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for i, (name, m) in enumerate(p["methods"].items()):
        color = f"C{i}"
        ts = [0.0] + [c["t_s"] for c in m["checkpoints"]]
        hs = [data["start_heldout_deg"]] + [c["heldout_deg"] for c in m["checkpoints"]]
        ax.step(ts, hs, where="post", color=color, lw=2, label=f"{name} (held-out)")
        bsf = best_so_far([(t, v, None, r) for t, v, r in m["trace"]])
        if bsf:
            ax.step([b[0] for b in bsf], [b[1] for b in bsf], where="post", color=color, lw=0.8, ls=":")
    ax.axhline(p["target_heldout_deg"], color="k", lw=0.8, ls="--", label="within 1 % of the best held-out")
    ax.set_xlabel("wall time, s")
    ax.set_ylabel("value, deg (solid: held-out long run; dotted: steady-state objective)")
    ax.set_title(f"{p['name']}: steady-state objective, held-out long runs")
    ax.set_ylim(top=min(ax.get_ylim()[1], 1.3 * data["start_heldout_deg"]))
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    main()
