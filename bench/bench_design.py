"""Head-to-head on the steady state over a family of design problems, in CPU time, judged
on held-out long runs.

``python bench/bench_design.py --problem NAME --seed S`` runs one part (every method on one
problem and seed) into ``bench/results/design_parts/NAME_seedS.json``;
``python bench/bench_design.py --merge`` combines the parts into ``bench/results/design.json``
and ``design.png``. A part that exists is not run again (a killed run loses only the part in
progress). Run parts pinned to one core each (``taskset -c 0 ...``, ``taskset -c 1 ...``): the
budgets are CPU time of the method's process, so other load on the machine does not decide.

**Problems** (`PROBLEMS`): the nine-variable design problem (:func:`optim.presets.design_problem`)
at its preset stroke and crank speed, and variants of both. Every method optimises the same
steady-state objective (:class:`optim.steady.Steady` at `STEADY`: Eq. 19 and the design terms
over one period of the periodic orbit; outside the periodic regime the long-run statistical
value) over the scaled box [0, 1]^9 from the problem's start design, with the same CPU budget:

- ``ours_adam``: the library's way in and projected Adam (`LEARNING_RATE`). The start and then
  scrambled Sobol points are classified until one is periodic and the lowest value so far
  (:func:`optim.way_in.periodic_start`, at most `CLASSIFY`; else the lowest periodic one); from
  it, Adam on the exact steady-state gradient with the regime guard
  (:class:`optim.steady.RegimeGuard`), the classification's orbit carried in.
- ``ours_lbfgs``: the same with projected L-BFGS (:class:`optim.optimizers.ProjectedLBFGS`).
  The better of the two by time to 1 % is the library's default (`DEFAULT`), and the target
  is measured on it.
- ``cma`` (CMA-ES, ``cma``), ``tpe`` (optuna's TPE): the objective's value only.

Every evaluation of every method is warm-started from the last periodic orbit its own
evaluator found (:class:`optim.steady.SteadyEvaluator`). The steady-state solve is compiled
before the first method, untimed (``compile_s``); each of our methods compiles its own gradient
programs inside its budget (``gradient_compile_s``; none is inherited from the other). Every
evaluation a method makes (line-search trial points included) counts towards its best-so-far design.

**Held-out truth.** Each method's best-so-far design (by the objective it optimised) at
``CHECKPOINTS`` fractions of the budget is scored by an evaluation no method optimised: a
simulation from rest of ``HELDOUT["revolutions"]`` revolutions at the library's default
tolerances, the problem's weighted value over the last ``HELDOUT["last_revolutions"]``,
averaged over ``HELDOUT["realisations"]`` realisations, each with its own initial crank angle
(offset uniform in +-``HELDOUT["crank_angle_rad"]``) and its own pin start positions (each
position coordinate offset uniform in +-``HELDOUT["pin_offset_clearances"]`` clearances); the
draws (seed ``HELDOUT["seed"]``) are the same for every design. ``time_to_1pct_s``: the first
checkpoint at which a method's held-out value is within 1 % of the best held-out value any
method reached on that problem (both seeds); ``speedup_vs_best_gradient_free``: the best
gradient-free method's time over ours (a lower bound, budget over ours' time, where no
gradient-free method gets there).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

#: the steady-state objective's settings in the bench, for every method (looser than the
#: library's default 1e-10 so that a cold steady-state solve takes seconds on the 2-core machine)
STEADY = dict(
    rtol=1e-8,
    atol=1e-8,
    newton_tol=1e-6,
    settle_revolutions=12,
    statistics_revolutions=4,
    batch_revolutions=2,
    samples_per_revolution=360,
    max_steps=300_000,
)  # the [objective] keys (flat) of a method="steady_state" table
#: the family: name -> (target stroke, m; crank speed, rpm)
PROBLEMS = {
    "preset": (0.240, 600.0),
    "short_fast": (0.200, 750.0),
    "mid_slow": (0.220, 480.0),
    "long_fast": (0.240, 720.0),
    "long_slow": (0.260, 420.0),
    "longest_slowest": (0.280, 360.0),
}
#: the upper bound of the minimum transmission angle, deg, where the preset's 70 deg cannot
#: reach the stroke at the shortest rod (the problem's own check: 2 L2 cos(alpha) >= stroke)
MAX_TRANSMISSION_DEG = {"long_slow": 65.0, "longest_slowest": 65.0}
#: the held-out evaluation
HELDOUT = dict(
    revolutions=20,
    last_revolutions=5,
    realisations=3,
    crank_angle_rad=1e-3,
    pin_offset_clearances=0.25,
    seed=2026,
    samples_per_revolution=360,
)
#: fractions of the budget at which best-so-far designs are scored (finer early, where they change most)
CHECKPOINTS = (1 / 32, 1 / 16, 1 / 8, 3 / 16, 1 / 4, 3 / 8, 1 / 2, 3 / 4, 1.0)
#: a gradient-free method rerun with a longer budget than its part's (``--update --budget``) is
#: also scored at these multiples of the part's budget, so that a speedup bounded by the budget can
#: be bounded further out
EXTENSIONS = (1.5, 2.0, 2.5, 3.0, 4.0, 5.0)
CLASSIFY = 8  # ours: candidate starts classified at most
#: the way in of the parts that do not record theirs
EARLIER_WAY_IN = (
    "earlier: the first periodic candidate that is the lowest so far, else the lowest periodic one; a failed "
    "solve had no value and set no bar; the budget checked only in value and gradient calls"
)
#: the way in the parts of this version run (recorded in each part; parts without it ran the earlier one)
WAY_IN = (
    "by value: every design has a value (the long-run statistics where shooting fails), the start is the lowest "
    "value classified, 4 candidates around it where that one is not periodic; budgets checked in every phase"
)
LEARNING_RATE = 0.05  # ours_adam: Adam step, scaled design units
GRADIENT_FREE = ("cma", "tpe")
OURS = ("ours_adam", "ours_lbfgs")
METHODS = OURS + GRADIENT_FREE
#: our default optimiser of the steady-state objective, the one the target is measured on (chosen by this bench)
DEFAULT = "ours_adam"
PARTS = ROOT / "bench" / "results" / "design_parts"


def build(name: str):
    """The nine-variable design problem of the family member ``name`` with the bench's
    steady-state objective."""
    import dataclasses

    import equinox as eqx

    from optim.objective_config import objective_from_config
    from optim.presets import design_problem

    stroke, rpm = PROBLEMS[name]
    problem = design_problem(objective_from_config({"method": "steady_state", **STEADY}))
    base = eqx.tree_at(lambda m: m.driver.speed, problem.base, rpm * 2.0 * math.pi / 60.0)
    title = f"design: {problem.n} variables, stroke {stroke * 1e3:g} mm, {rpm:g} rpm"
    derived = dataclasses.replace(problem.derived, stroke=stroke)
    upper = list(problem.upper)
    if name in MAX_TRANSMISSION_DEG:
        upper[problem.names.index("min_transmission_angle")] = math.radians(MAX_TRANSMISSION_DEG[name])
    return dataclasses.replace(problem, base=base, derived=derived, upper=tuple(upper), title=title)


def heldout_program(problem, heldout=HELDOUT):
    """Jitted ``x (SI) -> (value per realisation (R,), ok (R,))``: the held-out evaluation
    (module docstring), the problem's value in degrees (terms + cost)."""
    import equinox as eqx
    import jax
    import jax.numpy as jnp

    import jaxcrank as jc
    from jaxcrank.physics.state import initial_state, state_names

    revs, last, per_rev = heldout["revolutions"], heldout["last_revolutions"], heldout["samples_per_revolution"]
    rng = np.random.default_rng(heldout["seed"])
    count = heldout["realisations"]
    n = sum(name.startswith("d/dt ") for name in state_names(problem.base))  # position coordinates, scaled
    dphis = jnp.asarray(rng.uniform(-1.0, 1.0, count) * heldout["crank_angle_rad"])
    dpos = jnp.asarray(rng.uniform(-1.0, 1.0, (count, n)) * heldout["pin_offset_clearances"])

    def one(x, dphi, dy):
        mech = problem.mechanism(x)
        mech = eqx.tree_at(lambda m: m.driver.initial_angle, mech, mech.driver.initial_angle + dphi)
        y0 = initial_state(mech).at[:n].add(dy)
        period = mech.period
        ts = jnp.linspace(0.0, revs * period, revs * per_rev + 1)
        # between samples: no rounding decides which samples are in the statistics
        start = (revs - last) * period + 0.5 * period / per_rev
        sim = jc.simulate(
            mech,
            ts=ts,
            y0=y0,
            metrics_start=start,
            save_ts=ts[-1:],
            options=jc.SolveOptions(max_steps=5_000_000),
            throw=False,
        )
        value = problem.loss(sim.metrics) + problem.cost(x)
        return jnp.where(sim.ok, value, jnp.nan), sim.ok

    return jax.jit(lambda x: jax.vmap(lambda d, dy: one(x, d, dy))(dphis, dpos))


def timed_evaluator(problem, budget: float):
    """A :class:`optim.steady.SteadyEvaluator` that records every evaluation
    (``trace``: CPU seconds since its creation, value, unit design, regime) under a CPU-time
    :class:`optim.budget.Budget` of ``budget`` s, which every phase checks before its next solve
    or compilation (the regime guard's and the line search's trial points included): it raises
    :class:`optim.budget.BudgetSpent` there."""
    from optim.budget import Budget, BudgetSpent
    from optim.steady import SteadyEvaluator

    class Timed(SteadyEvaluator):
        def __init__(self):
            super().__init__(problem)
            self.budget, self.trace = Budget(budget, clock=time.process_time), []

        def elapsed(self):
            return self.budget.elapsed()

        def _record(self, x, value, info):
            regime = info.get("regime", "failed") if info.get("ok", False) else "failed"
            value = value if math.isfinite(value) else math.inf
            unit = np.clip(np.asarray(problem.to_unit(np.asarray(x, float))), 0.0, 1.0).tolist()
            self.trace.append((self.elapsed(), value, unit, regime))

        def value(self, x):
            try:
                value, info = super().value(x)
            except BudgetSpent:
                raise
            except Exception:  # noqa: BLE001 - a solver error: a failed design
                value, info = math.nan, {"ok": False}
            self._record(x, value, info)
            return value, info

        def value_and_grad(self, x):
            value, grad, info = super().value_and_grad(x)
            self._record(x, value, info)
            if self.first_gradient is not None and getattr(self, "first_gradient_cpu", None) is None:
                self.first_gradient_cpu = self.elapsed()  # CPU s from the evaluator's making (the way in included)
            return value, grad, info

        def unit_value(self, u):
            """The value at scaled design ``u`` (clipped to the box), for the gradient-free methods."""
            u = np.clip(np.asarray(u, float), 0.0, 1.0)
            value = self.value(np.asarray(problem.from_unit(u)))[0]
            return min(value, 1e6) if math.isfinite(value) else 1e6  # a failed design: a large finite value

    return Timed()


def run_cma(ev, n, start, seed):
    import cma

    es = cma.CMAEvolutionStrategy(list(start), 0.25, {"bounds": [0.0, 1.0], "seed": seed + 1, "verbose": -9})
    while not es.stop():
        xs = es.ask()
        es.tell(xs, [ev.unit_value(x) for x in xs])


def run_tpe(ev, n, start, seed):
    import optuna

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    study = optuna.create_study(sampler=optuna.samplers.TPESampler(seed=seed))
    study.enqueue_trial({f"u{j}": float(v) for j, v in enumerate(start)})
    while True:
        trial = study.ask()
        u = [trial.suggest_float(f"u{j}", 0.0, 1.0) for j in range(n)]
        study.tell(trial, ev.unit_value(u))


def run_ours(ev, problem, seed, info, adam: bool):
    """The library's way in (periodic_start) and then projected L-BFGS (or Adam) with the
    regime guard, the classification's orbit carried in (module docstring)."""
    from optim.optimize import Settings, optimize
    from optim.optimizers import ProjectedLBFGS
    from optim.optimizers import adam as make_adam
    from optim.starts import periodic_start
    from optim.steady import RegimeGuard

    search = periodic_start(problem, count=CLASSIFY, seed=seed, evaluator=ev, progress=False)
    info["start_search"] = search.describe()
    info["classification_cpu_s"] = ev.elapsed()
    if search.stopped:
        return
    if not search.periodic:
        info["note"] = "the lowest value classified is not periodic: no gradient there"
    settings = Settings(
        optimizer=make_adam(LEARNING_RATE) if adam else ProjectedLBFGS(),
        max_iterations=10_000,
        gtol=1e-4,
        xtol=1e-4,
        patience=5,
        guard=RegimeGuard(max_halvings=3),
    )
    res = optimize(search.problem, settings, progress=False, evaluator=ev)
    first = getattr(ev, "first_gradient_cpu", None)
    info.update(gradient_compile_s=ev.compile_seconds, finished_cpu_s=ev.elapsed(), first_gradient_cpu_s=first)
    info.update(
        iterations=len(res["history"]),
        converged=res["converged"],
        stop_reason=res["stop_reason"],
        halvings=int(sum(h["halvings"] for h in res["history"])),
        regimes=[h["regime"] for h in res["history"]],
        seconds=res["seconds"],
    )


def best_so_far(trace):
    """``(seconds, best value, unit design)`` after each evaluation of a trace."""
    out, best = [], (math.inf, None)
    for t, v, u, _ in sorted(trace, key=lambda e: e[0]):
        if v < best[0]:
            best = (v, u)
        out.append((t, best[0], best[1]))
    return out


def checkpoint_times(budget, fractions=CHECKPOINTS, base=None):
    """CPU times (s) at which a method with ``budget`` is scored: ``fractions`` of the part's
    ``base`` budget (default ``budget``), then, for a method run longer than the base (an
    extended gradient-free run), the `EXTENSIONS` multiples of the base below its budget and
    the budget itself."""
    base = budget if base is None else base
    times = [f * base for f in fractions if f * base <= budget]
    if budget > base:
        times += [k * base for k in EXTENSIONS if base < k * base < budget] + [budget]
    return times


def checkpoints(trace, budget, fractions=CHECKPOINTS, base=None):
    """The best-so-far value and design at each of `checkpoint_times` (None before the first)."""
    bsf = best_so_far(trace)
    out = []
    for t_s in checkpoint_times(budget, fractions, base):
        upto = [b for b in bsf if b[0] <= t_s]
        t, v, u = upto[-1] if upto else (None, math.inf, None)
        out.append({"t_s": t_s, "objective_deg": v, "unit_design": u})
    return out


def run_part(name: str, seed: int, budget: float, methods, path: Path, update: bool = False) -> dict:
    """Every method of ``methods`` on problem ``name`` with ``seed``, then the held-out
    scores of their checkpoint designs; written to ``path``. ``update``: ``path`` holds the
    part already; the methods run again and replace their entries (the others are kept)."""
    import jax

    jax.config.update("jax_enable_x64", True)
    from _common import machine

    from optim.budget import BudgetSpent
    from optim.programs import forget_programs
    from optim.steady import SteadyEvaluator

    tic_all = time.perf_counter()
    base = json.loads(path.read_text())["budget_cpu_s"] if update else budget  # the part's budget
    problem = build(name)
    start = np.asarray(problem.start_unit(), dtype=float)
    x_start = np.asarray(problem.from_unit(start))
    t = time.perf_counter()
    start_value, start_info = SteadyEvaluator(problem).value(x_start)  # compiles the steady-state solve
    compile_s = time.perf_counter() - t
    heldout = heldout_program(problem)
    print(f"{name} seed {seed}: start {start_value:.5f} deg ({start_info['regime']}), {compile_s:.0f} s", flush=True)

    runs = {}
    for method in methods:
        ev = timed_evaluator(problem, budget)
        info = {}
        try:
            if method in OURS:
                forget_programs()  # each of our methods pays its own compilation
                run_ours(ev, problem, seed, info, adam=method == "ours_adam")
            else:
                {"cma": run_cma, "tpe": run_tpe}[method](ev, problem.n, start, seed)
        except BudgetSpent:
            pass
        runs[method] = (ev.trace, info)
        best = min((v for _, v, _, _ in ev.trace), default=math.inf)
        print(f"  {method}: {len(ev.trace)} evaluations in {ev.elapsed():.0f} CPU-s, best {best:.5f} deg", flush=True)

    scored = {}

    def score(u):
        key = tuple(u)
        if key not in scored:
            v, ok = heldout(np.asarray(problem.from_unit(np.asarray(u))))
            v = np.asarray(v)
            scored[key] = (float(np.mean(v)), float(np.std(v)), bool(np.all(np.asarray(ok))))
        return scored[key]

    t = time.perf_counter()
    start_heldout = score(start.tolist())[0]
    out = {}
    for method, (trace, info) in runs.items():
        cps = checkpoints(trace, budget, base=base)
        for cp in cps:
            if cp["unit_design"] is None:
                cp.update(heldout_deg=start_heldout, heldout_std_deg=None, heldout_ok=True)
            else:
                m, s, ok = score(cp["unit_design"])
                cp.update(heldout_deg=m, heldout_std_deg=s, heldout_ok=ok)
        out[method] = {
            "budget_cpu_s": budget,
            "evaluations": len(trace),
            "periodic_evaluations": sum(e[3] == "periodic" for e in trace),
            "best_objective": min((v for _, v, _, _ in trace), default=math.inf),
            "checkpoints": cps,
            "returned_design_SI": None
            if cps[-1]["unit_design"] is None
            else np.asarray(problem.from_unit(np.asarray(cps[-1]["unit_design"]))).tolist(),
            "trace": [[t_, v, r] for t_, v, _, r in trace],
            **info,
        }
        print(f"  {method}: held-out {[round(c['heldout_deg'], 5) for c in cps]}", flush=True)
    stroke, rpm = PROBLEMS[name]
    part = {
        "problem": name,
        "stroke_m": stroke,
        "crank_speed_rpm": rpm,
        "seed": seed,
        "budget_cpu_s": base,
        "names": list(problem.names),
        "start_unit_design": start.tolist(),
        "start_objective_deg": start_value,
        "start_regime": start_info["regime"],
        "start_heldout_deg": start_heldout,
        "compile_s": compile_s,
        "way_in": WAY_IN,
        "heldout_s": time.perf_counter() - t,
        "heldout_designs": len(scored),
        "methods": out,
        "machine": machine(load_average=list(__import__("os").getloadavg())),
        "wall_s": time.perf_counter() - tic_all,
    }
    if update:  # the earlier part with these methods replaced (its start and held-out truth are the same)
        earlier = json.loads(path.read_text())
        earlier["methods"] = {**_renamed(earlier["methods"]), **out}
        earlier.setdefault("updated", []).append({"methods": list(out), "machine": part["machine"]})
        if any(m in OURS for m in out):  # ours ran again: with today's way in
            earlier["way_in"] = WAY_IN
        part = earlier
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(part, default=float))
    tmp.replace(path)
    return part


def merge(parts_dir: Path, out: Path) -> dict:
    """Combine the parts in ``parts_dir`` into ``out`` (module docstring): per problem the
    best held-out value of any method and seed, the 1 % target, each method's time to it and
    ours' speedup over the best gradient-free method; ``summary``: the worst and best case."""
    parts = [json.loads(p.read_text()) for p in sorted(parts_dir.glob("*.json"))]
    for p in parts:
        p["methods"] = _renamed(p["methods"])
    if not parts:
        raise SystemExit(f"no parts in {parts_dir}: run bench/bench_design.py --problem NAME --seed S first")
    problems, cases = [], []
    for name in PROBLEMS:
        mine = sorted((p for p in parts if p["problem"] == name), key=lambda p: p["seed"])
        if not mine:
            continue
        best = min(c["heldout_deg"] for p in mine for m in p["methods"].values() for c in m["checkpoints"])
        target = 1.01 * best
        for p in mine:
            for m in p["methods"].values():
                hit = [c["t_s"] for c in m["checkpoints"] if c["heldout_deg"] <= target]
                m["time_to_1pct_s"] = hit[0] if hit else None
            ran = [k for k in GRADIENT_FREE if k in p["methods"]]
            free = [(p["methods"][k]["time_to_1pct_s"], method_budget(p, k)) for k in ran]
            reached = [t for t, _ in free if t is not None]
            # a gradient-free method not within 1 % in its budget would get there after its budget at the soonest
            unreached = [b for t, b in free if t is None]
            ours = p["methods"].get(DEFAULT, {}).get("time_to_1pct_s")
            exact = bool(reached) and (not unreached or min(reached) <= min(unreached))
            p["speedup_vs_best_gradient_free"] = min(reached) / ours if exact and ours else None
            p["speedup_lower_bound"] = min(reached + unreached) / ours if ours and free and not exact else None
            speedup = p["speedup_vs_best_gradient_free"] or p["speedup_lower_bound"]
            cases.append(
                {
                    "problem": name,
                    "seed": p["seed"],
                    "ours_time_to_1pct_s": ours,
                    "default": DEFAULT,
                    **{f"{k}_time_to_1pct_s": p["methods"].get(k, {}).get("time_to_1pct_s") for k in OURS},
                    "best_gradient_free_time_to_1pct_s": min(reached) if reached else None,
                    "gradient_free_budgets_cpu_s": {k: b for k, (_, b) in zip(ran, free)},
                    "speedup": speedup,
                    "speedup_is_lower_bound": p["speedup_lower_bound"] is not None,
                    "ours_first_gradient_cpu_s": p["methods"].get(DEFAULT, {}).get("first_gradient_cpu_s"),
                    "ours_start": p["methods"].get(DEFAULT, {}).get("start_search", {}).get("chosen"),
                }
            )
        problems.append(
            {
                "name": name,
                "stroke_m": mine[0]["stroke_m"],
                "crank_speed_rpm": mine[0]["crank_speed_rpm"],
                "n_variables": len(mine[0]["names"]),
                "names": mine[0]["names"],
                "best_heldout_any_method": best,
                "target_heldout_deg": target,
                "way_in": mine[0].get("way_in", EARLIER_WAY_IN),
                "runs": mine,
            }
        )
    scored = [c for c in cases if c["speedup"] is not None]
    summary = {
        "cases": cases,
        "worst": min(scored, key=lambda c: c["speedup"]) if scored else None,
        "best": max(scored, key=lambda c: c["speedup"]) if scored else None,
        "ours_never_within_1pct": [c for c in cases if c["ours_time_to_1pct_s"] is None],
    }
    data = {
        "objective": "steady_state",
        "command": "python bench/bench_design.py --problem NAME --seed S (each part), then --merge",
        "steady_objective": STEADY,
        "heldout": {**HELDOUT, "metric": "problem value: Eq. 19 + weighted terms + cost, deg"},
        "budget_cpu_s_per_method": parts[0]["budget_cpu_s"],
        "checkpoint_fractions": list(CHECKPOINTS),
        "seeds": sorted({p["seed"] for p in parts}),
        "learning_rate_adam": LEARNING_RATE,
        "classify_at_most": CLASSIFY,
        "problems": problems,
        "summary": summary,
    }
    first = out.parent / "design_first_gradient.json"  # bench/design_first_gradient.py
    if first.exists():
        data["first_gradient"] = json.loads(first.read_text())
    out.write_text(json.dumps(data, indent=1, default=float))
    plot(data, out.with_suffix(".png"))
    return data


def method_budget(part: dict, method: str) -> float:
    """The CPU budget (s) ``method`` ran with in ``part``: its own where it was rerun longer, else the part's."""
    return part["methods"][method].get("budget_cpu_s", part["budget_cpu_s"])


def _renamed(methods: dict) -> dict:
    """A part's methods with the first runs' name for projected L-BFGS (``ours``) spelled as now."""
    return {("ours_lbfgs" if k == "ours" else k): v for k, v in methods.items()}


def plot(data, path):
    """Per problem, the held-out value of each method's best-so-far design against CPU time
    (seed 0 solid, seed 1 dashed), and the 1 % target."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    problems = data["problems"]
    cols = 2 if len(problems) > 1 else 1
    rows = math.ceil(len(problems) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(6.5 * cols, 4.2 * rows), squeeze=False)
    for ax, prob in zip(axes.flat, problems):
        for run in prob["runs"]:
            for name, m in sorted(run["methods"].items(), key=lambda nm: METHODS.index(nm[0])):
                ts = [0.0] + [c["t_s"] for c in m["checkpoints"]]
                hs = [run["start_heldout_deg"]] + [c["heldout_deg"] for c in m["checkpoints"]]
                label = f"{name}" if run["seed"] == data["seeds"][0] else None
                color = f"C{METHODS.index(name)}"  # one colour per method in every panel
                ax.step(ts, hs, where="post", color=color, lw=1.6, ls="-" if run["seed"] == 0 else "--", label=label)
        ax.axhline(prob["target_heldout_deg"], color="k", lw=0.8, ls=":", label="within 1 % of the best")
        ax.set_xscale("symlog", linthresh=10.0)
        ax.set_xlim(0.0, max(method_budget(r, k) for r in prob["runs"] for k in r["methods"]))
        ax.set_xlabel("CPU time, s (one core)")
        ax.set_ylabel("held-out value, deg")
        ax.set_title(f"{prob['name']}: stroke {prob['stroke_m'] * 1e3:g} mm, {prob['crank_speed_rpm']:g} rpm")
        top = max(r["start_heldout_deg"] for r in prob["runs"])
        ax.set_ylim(0.9 * prob["best_heldout_any_method"], 1.15 * top)
        ax.legend(fontsize=7)
    for ax in list(axes.flat)[len(problems) :]:
        ax.axis("off")
    fig.suptitle("Held-out value of each method's best design so far (seed 0 solid, seed 1 dashed)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--problem", nargs="+", default=list(PROBLEMS), choices=list(PROBLEMS))
    ap.add_argument("--seed", type=int, nargs="+", default=[0, 1])
    ap.add_argument("--budget", type=float, default=240.0, help="CPU budget per method, s")
    ap.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS)
    ap.add_argument("--parts", type=Path, default=PARTS, help="folder of the per-problem, per-seed results")
    ap.add_argument("--merge", action="store_true", help="combine the parts into --out and its figure")
    ap.add_argument("--update", action="store_true", help="rerun --methods in existing parts, keeping the others")
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "design.json")
    args = ap.parse_args(argv)
    if args.merge:
        data = merge(args.parts, args.out)
        print(json.dumps({k: data["summary"][k] for k in ("worst", "best")}, indent=1, default=float))
        print(f"wrote {args.out}")
        return data
    for name in args.problem:
        for seed in args.seed:
            path = args.parts / f"{name}_seed{seed}.json"
            if path.exists() and not args.update:
                print(f"{path} exists: kept", flush=True)
                continue
            run_part(name, seed, args.budget, args.methods, path, update=args.update and path.exists())
    return None


if __name__ == "__main__":
    main()
