"""Optimisation of a problem ([`AbstractProblem`][optim.problem.AbstractProblem]) with an
optimiser Module ([`optim.optimizers`][]), with a checkpoint after every iteration.

The optimiser works on the scaled design ``u`` in the unit box and on the
objective divided by its value at the start, so step sizes mean the same for any
problem. Feasibility: every iterate is projected onto the feasible set
([`project`][optim.problem.AbstractProblem.project], optax projections); a line-search
optimiser ([`optim.optimizers.ProjectedLBFGS`][]) projects its trial points too. An optional
regime guard (``Settings.guard``, [`optim.steady.RegimeGuard`][]) halves a step
whose design it refuses (a step that leaves the periodic regime), or holds the iterate;
for a line-search optimiser a refused trial point fails its Armijo test.

Convergence: the projected-gradient step ``|P(u - g) - u|_inf`` (g the scaled gradient) below ``gtol``, or the
design moving less than ``xtol`` (scaled) for ``patience`` consecutive iterations, or (line-search optimisers) an
accepted step changing the value by at most the optimiser's ``ftol`` relative. The run also stops, not converged,
at ``max_iterations``, at ``max_seconds``, when a line search fails, and at a design outside the periodic regime
whose steady-state gradient is exactly zero (no trend estimate; not a stationary point): ``stop_reason`` says which.

Checkpoint: ``checkpoint.npz`` (iterate, optimiser state, history) and ``history.csv``
are replaced atomically (temporary file and rename) after every iteration;
``resume=True`` continues from the last finished iteration, so a killed run loses at
most the iteration in progress and, being deterministic, reproduces the uninterrupted
history (``tests/test_faults.py`` kills runs with SIGKILL). A truncated or corrupted
checkpoint raises [`jaxcrank.CorruptFileError`][jaxcrank.errors.CorruptFileError] naming the file; it is never
silently replaced by a fresh start ([`optim.checkpoint`][]).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import optax
from tqdm.auto import tqdm

from jaxcrank import cache
from jaxcrank.errors import CorruptFileError
from jaxcrank.numerics.solve import SimulationError
from jaxcrank.physics.params import ParameterError

from . import checkpoint
from . import quasi_newton as qn
from .budget import Budget, BudgetSpent
from .objective import value_and_grad
from .optimizers import LBFGS, AbstractLineSearchOptimizer, AbstractOptimizer, adam
from .problem import AbstractProblem
from .steady import NOT_PERIODIC, RegimeGuard, Steady, SteadyEvaluator, not_periodic_reason
from .way_in import periodic_start

#: Adam's step (scaled design units) in the steady-state objective's default settings, chosen by
#: the design head-to-head over a family of problems (docs/design-studies.md)
STEADY_LEARNING_RATE = 0.05


@dataclasses.dataclass(frozen=True)
class Settings:
    """Optimiser settings (scaled units: the design in [0, 1]^n, the objective / its start value).

    Attributes:
        optimizer: the optimiser ([`optim.optimizers`][]: ``adam(0.1)`` by default,
            ``Projected(any optax transformation)``, ``LBFGS()`` or ``ProjectedLBFGS()``).
        max_iterations: iteration budget, >= 1.
        gtol: stop when the projected-gradient step is below this.
        xtol: stop when the design moves less than this ``patience`` times in a row.
        patience: see ``xtol``.
        starts: designs to optimise from ([`multistart`][optim.starts.multistart]): the problem's start, then
            ``starts - 1`` scrambled Sobol points of the box; 1 runs [`optimize`][optim.optimize.optimize] alone.
        seed: seed of those Sobol points.
        max_seconds: wall-time budget of one [`optimize`][optim.optimize.optimize] call, s (None: none). The
            steady-state objective: every phase (the way in, each step, the regime guard's and the line
            search's trial points, compiling a gradient program) checks it before its next solve or
            compilation ([`optim.budget.Budget`][]), so the run overshoots it by at most one solve and
            returns the best design so far; a windowed objective stops after the iteration that passes it.
        guard: optional regime guard ([`optim.steady.RegimeGuard`][]): a step to a design it refuses is halved until
            accepted (at most ``guard.max_halvings`` times, then the iterate is held); for ``ProjectedLBFGS`` a
            refused trial point fails the Armijo test (within the line search's own budget).
    """

    optimizer: AbstractOptimizer = dataclasses.field(default_factory=adam)
    max_iterations: int = 30
    gtol: float = 1e-3
    xtol: float = 1e-3
    patience: int = 3
    starts: int = 1
    seed: int = 0
    max_seconds: float | None = None
    guard: object = None

    def __post_init__(self):
        if not isinstance(self.optimizer, AbstractOptimizer):
            raise ParameterError(
                f"optimizer = {self.optimizer!r} must be an optim.optimizers.AbstractOptimizer "
                "(adam(...), Projected(optax transformation), LBFGS() or ProjectedLBFGS())"
            )
        if self.max_iterations < 1 or self.gtol < 0 or self.xtol < 0:
            raise ParameterError("max_iterations must be >= 1, gtol and xtol >= 0")
        if not (isinstance(self.starts, int) and self.starts >= 1):
            raise ParameterError(f"starts = {self.starts!r} must be an integer >= 1")


def default_settings(problem: AbstractProblem) -> Settings:
    """The settings [`optimize`][optim.optimize.optimize] uses when given none: for the steady-state
    objective, Adam at `STEADY_LEARNING_RATE` with the regime guard (steps stay in the periodic
    regime, where the gradient is exact); ``Settings()`` otherwise."""
    if isinstance(problem.objective, Steady):
        return Settings(optimizer=adam(STEADY_LEARNING_RATE), guard=RegimeGuard())
    return Settings()


def steady_evaluator(problem: AbstractProblem, settings: Settings) -> SteadyEvaluator:
    """A [`SteadyEvaluator`][optim.steady.SteadyEvaluator] of ``problem`` whose budget is ``settings.max_seconds``
    from now (None: none): pass it to [`optim.way_in.periodic_start`][] and then to
    [`optimize`][optim.optimize.optimize], so the way in and the run share one budget."""
    evaluator = SteadyEvaluator(problem)
    if settings.max_seconds is not None:
        evaluator.budget = Budget(settings.max_seconds)
    return evaluator


@functools.lru_cache(maxsize=8)
def programs(problem: AbstractProblem, penalty: float = 10.0):
    """The optimiser's compiled programs of ``problem``, on the scaled design ``u``
    (n,) with the objective divided by ``f0`` (an argument, so a resumed or repeated
    run reuses them; pass 1.0 for degrees).

    Args:
        problem: the design problem; its ``start`` is not part of the programs
            (pass ``dataclasses.replace(problem, start=None)`` to share them between starts).
        penalty: weight of L-BFGS's out-of-set penalty.

    Returns ``(value_and_grad, extended)``: ``value_and_grad(u, f0) -> (value, grad (n,))``
    inside the feasible set (forward or reverse mode, as the objective says) and the
    same for L-BFGS's extension beyond it, ``extended(u, f0) -> (value, grad (n,))``. Each is traced and
    compiled at its first call, or loaded from [`jaxcrank.runs.cache`][] when that is
    enabled and an earlier process stored it. A failed evaluation is NaN
    (the objective with ``throw=False`` and [`jaxcrank.runs.cache.checks_as_nan`][]: no
    host callback in the programs, so they can be cached); [`optimize`][optim.optimize.optimize] checks.
    """
    problem = problem.with_objective(dataclasses.replace(problem.objective, throw=False))

    def inside(u, f0):
        return problem.objective_value(problem.from_unit(u)) / f0

    def outside(u, f0):
        p = problem.project(u)
        return inside(p, f0) + penalty * jnp.sum((u - p) ** 2)

    args = (jax.ShapeDtypeStruct((problem.n,), jnp.float64), jax.ShapeDtypeStruct((), jnp.float64))
    vg = value_and_grad(inside, problem.objective.forward_mode())
    vg_outside = value_and_grad(outside, problem.objective.forward_mode())
    return (
        _Lazy(lambda: cache.exported(vg, ("optim.value_and_grad", problem), *args)),
        _Lazy(lambda: cache.exported(vg_outside, ("optim.extended_value_and_grad", problem, penalty), *args)),
    )


class _Lazy:
    """A program made at its first use (L-BFGS's extension is not needed by Adam)."""

    def __init__(self, make):
        self._make, self._fun = make, None

    def _get(self):
        if self._fun is None:
            self._fun = self._make()
        return self._fun

    def __call__(self, *args):
        return self._get()(*_strong(args))

    def lower(self, *args):
        return self._get().lower(*_strong(args))


def _strong(args):
    # float64 arrays: a Python float or a weakly typed array would make jit compile the
    # same program a second time for the other argument type (tracers, e.g. inside the
    # L-BFGS line search, stay tracers)
    return [
        jnp.asarray(a, dtype=jnp.float64) if isinstance(a, jax.core.Tracer) else np.asarray(a, dtype=np.float64)
        for a in args
    ]


def _checked(problem: AbstractProblem, u, value, grad):
    """``value, grad``, or SimulationError naming the design where they are not finite."""
    if np.isfinite(float(value)) and np.all(np.isfinite(np.asarray(grad))):
        return value, grad
    x = ", ".join(f"{n} = {v:.6g}" for n, v in zip(problem.names, np.asarray(problem.from_unit(u))))
    raise SimulationError(
        f"the objective could not be evaluated at {x}: its solve did not reach t_end within the "
        "objective's options.max_steps, or more than half of the ensemble windows failed; raise the objective's "
        "options.max_steps or window_options.max_steps, loosen its rtol/atol, or shorten its window"
    )


def optimize(
    problem: AbstractProblem,
    settings: Settings | None = None,
    out: Path | None = None,
    resume: bool = False,
    progress: bool = True,
    stop_after: int | None = None,
    evaluator: SteadyEvaluator | None = None,
) -> dict:
    """Minimise ``problem`` from its start design.

    Args:
        settings: the optimiser settings (default [`default_settings`][optim.optimize.default_settings]).
            With none given, a steady-state objective, no ``evaluator`` and no ``resume``, the run first
            finds a periodic start ([`optim.way_in.periodic_start`][]: the problem's start, then Sobol
            points), since the gradient is exact only in the periodic regime.
        out: run directory for ``checkpoint.npz`` and ``history.csv`` (no checkpoints when None).
        resume: continue from ``out``'s checkpoint (error if there is none).
        stop_after: stop (as if killed) after this many iterations of this call (tests).
        evaluator: steady-state objective only: the evaluator to use, e.g. the one that classified
            the start ([`optim.way_in.periodic_start`][]), whose last orbit warm-starts the first
            evaluation (default: a new one).

    Returns a dict: ``history`` (one dict per iteration, columns of
    [`optim.checkpoint.history_columns`][]; ``evaluations``: value-and-gradient evaluations so far, the start's
    and this iteration's line search included; ``halvings``: the iteration's step shortenings), ``converged`` (the
    convergence test met, or None), ``stop_reason`` (why the run stopped, converged or not), ``evaluations`` (in
    all; a resumed line-search run re-evaluates its iterate once, not counted), ``f0`` (objective at the start,
    degrees), ``final`` (the best SI design of the history), ``final_objective`` (its objective, degrees),
    ``last`` (the last iterate, SI) and ``seconds`` (wall time, s: ``start``, the start's evaluation, and
    ``iterations``, the iterations of this call; steady-state objective: ``gradient_compile``, the part of
    both spent compiling gradient programs, and ``first_gradient``, from the evaluator's making (before
    the way in, where it ran) to its first exact gradient, None where there was none), and
    ``start_search`` when the run looked for a start ([`optim.way_in.StartSearch.describe`][]; its
    classification time in ``seconds["start_search"]``). A run whose budget was spent before its
    first iteration finished has no history: its start is ``final``.
    """
    found = None
    if settings is None:
        settings = default_settings(problem)
        if isinstance(problem.objective, Steady) and evaluator is None and not resume:
            found = periodic_start(problem, seed=settings.seed, progress=progress)
            problem, evaluator = found.problem, found.evaluator
    opt = settings.optimizer
    penalty = getattr(opt, "penalty", 10.0)
    # the start is not part of the compiled programs: runs from other starts share them
    if isinstance(problem.objective, Steady):
        # evaluated on the host, warm-started from the last orbit (not one compiled program)
        if isinstance(opt, LBFGS):
            raise ParameterError("the steady-state objective needs adam() or ProjectedLBFGS(), not LBFGS()")
        evaluator = SteadyEvaluator(problem) if evaluator is None else evaluator
        compiled_before = evaluator.compile_seconds
        vg, extended = _steady_programs(problem, evaluator), None
        owned = evaluator.budget is None and settings.max_seconds is not None  # else the caller's (way in included)
        if owned:
            evaluator.budget = Budget(settings.max_seconds)
        budget = evaluator.budget
    else:
        if settings.guard is not None:
            raise ParameterError(
                "Settings.guard (the regime guard) needs the steady-state objective (optim.steady.Steady)"
            )
        evaluator, compiled_before, owned = None, 0.0, False
        vg, extended = programs(dataclasses.replace(problem, start=None), penalty)
        budget = None if settings.max_seconds is None else Budget(settings.max_seconds)
    ckpt = None if out is None else Path(out) / "checkpoint.npz"
    if resume:
        if ckpt is None or not ckpt.exists():
            raise ParameterError(f"--resume: no checkpoint at {ckpt}; run without --resume first")
        u, leaves, meta = checkpoint.load(Path(out))
        if meta["names"] != list(problem.names) or meta["method"] != opt.label:
            raise ParameterError(
                f"--resume: the checkpoint in {out} is for {meta['names']} with "
                f"{meta['method']}, not {list(problem.names)} with {opt.label}: resume "
                "with the run's own settings (optimize.toml) or choose another --out"
            )
        f0, history = meta["f0"], meta["history"]
        try:
            state = checkpoint.unflatten(opt.init(u), leaves)
        except (KeyError, ValueError, TypeError) as err:
            raise CorruptFileError(
                f"{ckpt}: the optimiser state does not fit {opt.label} ({err}); the checkpoint is corrupted"
            ) from None
        quiet, converged, stop = meta["quiet"], meta["converged"], meta.get("stop_reason")
        start_seconds = 0.0  # the start was evaluated by the run that made the checkpoint
    else:
        start_tic = time.perf_counter()
        u = problem.start_unit()
        # the objective at the start (degrees) scales the rest; its evaluation is iteration 0's
        try:
            first = _checked(problem, u, *vg(u, 1.0))
        except BudgetSpent as err:  # the way in spent the budget: the start is the result
            if owned:
                evaluator.budget = None
            return _spent_at_start(problem, evaluator, u, str(err), found)
        f0 = float(first[0])
        first = (first[0] / f0, first[1] / f0)
        state, history, quiet, converged, stop = opt.init(u), [], 0, None, None
        start_seconds = time.perf_counter() - start_tic

    search = isinstance(opt, AbstractLineSearchOptimizer)
    trial = qn.trial_function(problem, vg, f0, settings.guard, evaluator)
    carried = None if resume else first  # value and gradient at u when already evaluated
    evaluations = history[-1].get("evaluations", len(history)) if history else 1
    done_here, started, interrupted = 0, time.perf_counter(), None
    start_it = len(history)
    bar = tqdm(total=settings.max_iterations, initial=start_it, desc=opt.label, unit="it", disable=not progress)
    while converged is None and stop is None and len(history) < settings.max_iterations:
        tic = time.perf_counter()
        try:
            if carried is not None:
                value, grad = carried
            else:
                value, grad = _checked(problem, u, *vg(u, f0))
                evaluations += not search  # a line-search optimiser's resume re-evaluates its iterate: not counted
            carried, halvings = None, 0
            x = problem.from_unit(u)
            proj_step = float(jnp.max(jnp.abs(problem.project(u - grad) - u)))
            regime = evaluator.last_report if evaluator is not None else {}
            previous = history[-1]["objective_deg"] / f0 if search and history else None
            changed = qn.value_change_converged(previous, float(value), opt.ftol) if previous is not None else None
            if regime.get("regime") == NOT_PERIODIC and not np.any(np.asarray(grad)):
                stop, u_new = not_periodic_reason(problem, x), u
            elif search and (proj_step < settings.gtol or changed):
                u_new = u  # converged (below): no line search
            elif search:
                res = opt.step(trial, problem.feasible_set(), np.asarray(u), float(value), np.asarray(grad), state)
                u_new, state, halvings = jnp.asarray(res.u), res.state, res.trials - int(res.ok)
                evaluations += res.evaluations
                carried = (res.value, res.grad) if res.ok else None
                stop = None if res.ok else qn.failure_reason(res)
            else:
                updates, state = opt.update(grad, state, u, value, f0, extended)
                u_new = problem.project(optax.apply_updates(u, updates))
                u_new, halvings = _guarded(problem, settings.guard, evaluator, u, u_new)
        except BudgetSpent as err:  # the iterate so far is kept; this iteration's step is not taken
            interrupted = str(err)
            break
        step = float(jnp.max(jnp.abs(u_new - u)))
        cost = float(problem.cost(x))
        grad_si = np.asarray(grad) * f0 / np.asarray(problem.span)
        rec = {
            "iteration": len(history),
            "objective_deg": float(value) * f0,
            "objective_without_cost_deg": float(value) * f0 - cost,
            "cost_deg": cost,
            **{f"grad_{n}_deg_per_SI": float(g) for n, g in zip(problem.names, grad_si)},
            **{f"{n}_SI": float(v) for n, v in zip(problem.names, np.asarray(x))},
            "projected_gradient": proj_step,
            "step": step,
            "halvings": halvings,
            "evaluations": evaluations,
            "regime": regime.get("regime", ""),
            "leading_multiplier": regime.get("leading_multiplier"),
            "seconds": time.perf_counter() - tic,
        }
        history.append(rec)
        quiet = quiet + 1 if step < settings.xtol else 0
        if stop is not None:
            pass
        elif proj_step < settings.gtol:
            converged = f"projected gradient {proj_step:.2e} < gtol {settings.gtol:g}"
        elif quiet >= settings.patience:
            converged = f"design moved < xtol {settings.xtol:g} for {settings.patience} iterations"
        elif changed:
            converged = changed
        else:
            u = u_new
        bar.update(1)
        bar.set_postfix(objective=f"{rec['objective_deg']:.5f}", step=f"{step:.3g}")
        if out is not None:
            checkpoint.save(Path(out), problem, settings, u, state, history, f0, quiet, converged, stop)
        done_here += 1
        if stop_after is not None and done_here >= stop_after:
            interrupted = f"stopped after {done_here} iterations of this call (stop_after)"
            break
        if budget is not None and budget.spent():
            interrupted = f"time limit: max_seconds = {budget.seconds:g}"
            break
    bar.close()
    if owned:
        evaluator.budget = None
    if not history:  # the budget was spent before the first iteration finished
        return _spent_at_start(problem, evaluator, u, interrupted, found, f0)
    best = min(history, key=lambda h: h["objective_deg"])
    limit = f"iteration limit: max_iterations = {settings.max_iterations}"
    return {
        "history": history,
        "converged": converged,
        "stop_reason": converged or stop or (limit if len(history) >= settings.max_iterations else interrupted),
        "evaluations": evaluations,
        "f0": f0,
        "final": [best[f"{n}_SI"] for n in problem.names],
        "final_objective": best["objective_deg"],
        "last": [history[-1][f"{n}_SI"] for n in problem.names],
        **_phases(start_seconds, time.perf_counter() - started, evaluator, compiled_before, found),
    }


def _spent_at_start(problem: AbstractProblem, evaluator, u, reason: str, found, f0=None) -> dict:
    """The result of a run whose budget was spent before its first iteration: no history, the
    start as the final design with its value where it was classified (else NaN)."""
    x = np.asarray(problem.from_unit(u), dtype=float).tolist()
    seen = found.classified[found.chosen]["value_deg"] if found is not None and found.classified else f0
    if seen is None and evaluator is not None:
        try:  # the start's steady state is kept from the way in: no new solve
            seen = evaluator.value(np.asarray(x))[0]
        except BudgetSpent:
            pass
    value = math.nan if seen is None else seen
    return {"history": [], "converged": None, "stop_reason": reason, "evaluations": 0, "f0": value, "final": x,
            "final_objective": value, "last": x, **_phases(0.0, 0.0, evaluator, 0.0, found)}  # fmt: skip


def _phases(start: float, iterations: float, evaluator, compiled_before: float, found) -> dict:
    """The result's ``seconds`` (by phase) and ``start_search``."""
    steady = {} if evaluator is None else {"gradient_compile": evaluator.compile_seconds - compiled_before}
    steady.update({} if evaluator is None else {"first_gradient": evaluator.first_gradient})
    search = {} if found is None else {"start_search": found.seconds}
    return {
        "seconds": {"start": start, "iterations": iterations, **steady, **search},
        **({"start_search": found.describe()} if found is not None else {}),
    }


def _steady_programs(problem: AbstractProblem, evaluator: SteadyEvaluator):
    """The steady-state objective's ``value_and_grad(u, f0)`` on the scaled design, as
    [`programs`][optim.optimize.programs] gives for the windowed objectives (NaN where the solve failed)."""

    def vg(u, f0):
        value, grad, _ = evaluator.value_and_grad(np.asarray(problem.from_unit(jnp.asarray(u))))
        return jnp.asarray(value / f0), jnp.asarray(grad * np.asarray(problem.span) / f0)

    return vg


def _guarded(problem: AbstractProblem, guard, evaluator, u, u_new):
    """``u_new``, or the step from ``u`` halved until ``guard`` accepts its design (at most ``guard.max_halvings``
    times; then ``u`` is held, its steady state kept past the trials': not solved again), and the halvings."""
    if guard is None:
        return u_new, 0
    evaluator.warm_from(np.asarray(problem.from_unit(u)))
    for k in range(guard.max_halvings + 1):
        if guard.accept(evaluator, np.asarray(problem.from_unit(u_new))):
            return u_new, k
        u_new = u + 0.5 * (u_new - u)
    return u, guard.max_halvings + 1
