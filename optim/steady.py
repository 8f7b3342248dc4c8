"""The steady-state objective: the metrics over one period of the mechanism's periodic
orbit, with their exact gradient; the regime guard and the regime-classified starts of
the optimiser.

A machine runs for hours: its designer cares about the motion it settles into, not the
start-up from rest. [`Steady`][optim.steady.Steady] measures a design there
([`jaxcrank.steady_state`][jaxcrank.numerics.steady.steady_state]):

- **periodic regime** (an attracting periodic orbit of period k revolutions): the RMS
  metrics over one period of the orbit, Eq. 19 and the design terms among them, and
  their exact gradient by the implicit function theorem at the orbit,
  ``dy*/dp = (I - M)^-1 dPhi^k/dp`` on the dynamic subspace
  ([`jaxcrank.numerics.steady.orbit_start`][]), then forward mode through one
  period from y*. Each evaluation is warm-started from the previous design's orbit, so
  an optimiser's step costs a few one-revolution solves.
- **not periodic** (chaotic impacts): the long-run statistical value of the metrics
  (batch means over revolutions, with a 95 % confidence interval), reported as such;
  its gradient is the ensemble estimate of the objective's ``trend`` (an
  [`Ensemble`][optim.ensemble.Ensemble]), flagged as a trend estimate, or zero without one.

The steady state is found on the host (settle, period detection, Newton shooting), so
this objective is evaluated at concrete designs, outside ``jax.jit``: use
[`SteadyEvaluator`][optim.steady.SteadyEvaluator] (what [`optim.optimize.optimize`][] does) or
[`Steady.rms`][optim.steady.Steady.rms] with a concrete mechanism.
"""

from __future__ import annotations

import dataclasses
import math
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from jaxcrank.numerics import steady as S
from jaxcrank.numerics.estimators import straight_through
from jaxcrank.numerics.results import Regime
from jaxcrank.numerics.shooting import SteadyOptions, period_solve
from jaxcrank.physics.linkage import AbstractMechanism as Mechanism
from jaxcrank.physics.params import ParameterError
from jaxcrank.physics.signals import metric_definitions, rms_metrics

from .ensemble import Ensemble
from .objective import AbstractObjective, options_fields, value_and_grad
from .problem import problem_values, values_key, with_values
from .programs import FOLDED, PENDING, PROGRAMS, TRACE_ERRORS, compile_program, compiler

#: the steady-state objective's default settings: periods up to 2 revolutions, 720 samples per
#: revolution; where Newton shooting fails, the design's value is its long-run statistics (labelled
#: not periodic), never NaN
STEADY_OBJECTIVE = SteadyOptions(max_period=2, samples_per_revolution=720, statistics_on_failure=True)
#: the regimes, as [`jaxcrank.steady_state`][jaxcrank.numerics.steady.steady_state] names them
PERIODIC, NOT_PERIODIC, FAILED = Regime.PERIODIC, Regime.NOT_PERIODIC, Regime.FAILED


class Steady(AbstractObjective):
    """The RMS metrics over one period of the steady periodic orbit (module docstring).

    Attributes:
        options: the steady-state settings ([`jaxcrank.SteadyOptions`][jaxcrank.numerics.shooting.SteadyOptions];
            default `STEADY_OBJECTIVE`: periods up to 2 revolutions, 720 samples per
            revolution). A design whose solve needs more than ``options.solve.max_steps``
            steps is a failed evaluation: NaN, or raises with ``throw``.
        trend: not periodic: the objective whose gradient serves as a trend estimate
            (an [`Ensemble`][optim.ensemble.Ensemble]; None: zero gradient there).
        throw: a failed steady-state solve raises (True) or gives NaN values (False).

    Raises:
        ParameterError: for options that are not a ``SteadyOptions`` or a trend that is not an ``Ensemble``.
    """

    options: SteadyOptions = eqx.field(static=True, default=STEADY_OBJECTIVE)
    trend: Ensemble | None = eqx.field(static=True, default=None)
    throw: bool = eqx.field(static=True, default=True)

    def __check_init__(self):
        if not isinstance(self.options, SteadyOptions):
            raise ParameterError(f"Steady.options = {self.options!r} must be a jaxcrank.SteadyOptions")
        if self.trend is not None and not isinstance(self.trend, Ensemble):
            raise ParameterError(f"Steady.trend = {self.trend!r} must be an Ensemble objective or None")

    def solve(self, mech: Mechanism, warm_start=None) -> S.SteadyState:
        """The steady state of the concrete ``mech`` ([`jaxcrank.steady_state`][jaxcrank.numerics.steady.steady_state]),
        warm
        started from a previous [`jaxcrank.SteadyState`][jaxcrank.numerics.steady.SteadyState] when given.

        Raises:
            jaxcrank.SteadyStateError: the solve failed and ``throw`` is True."""
        return S.steady_state(mech, self.options, warm_start=warm_start, throw=self.throw)

    def rms_at(self, mech: Mechanism, steady: S.SteadyState, every: bool = False) -> dict[str, Float[Array, ""]]:
        """The RMS metrics of ``mech`` (traceable; e.g. built from traced design
        variables) given ``steady``, the steady state of its concrete value: periodic, the
        metrics over one period from [`jaxcrank.numerics.steady.orbit_start`][] (exact
        forward-mode gradient); not periodic, the long-run statistics' values with the
        ``trend`` objective's gradient (or none); NaN when the solve failed. ``every``: all
        the headline metrics ([`jaxcrank.physics.signals.metric_definitions`][]: the peaks too;
        not periodic, the peaks' long-run values have no gradient)."""
        names = tuple(metric_definitions(mech)) if every else rms_metrics(mech)
        if not steady.ok:
            return {k: jnp.asarray(jnp.nan) for k in names}
        if steady.periodic:
            orbit = _light(steady)
            sim = period_solve(
                mech,
                S.orbit_start(mech, orbit),
                orbit.period_revolutions,
                options=orbit.options,
                samples_per_revolution=self.options.samples_per_revolution,
            )
            return {k: jnp.where(sim.ok, sim.metrics[k], jnp.nan) for k in names}
        values = {k: jnp.asarray(float(steady.statistics[k]["value"])) for k in names}
        if self.trend is None:
            return values
        _, starts = self.trend.reference(jax.lax.stop_gradient(mech))
        surrogate = self.trend.pooled(mech, starts)
        return {k: straight_through(values[k], surrogate[k]) if k in surrogate else values[k] for k in names}

    def rms(self, mech: Mechanism) -> dict[str, Float[Array, ""]]:
        """The RMS metrics of a concrete ``mech`` ([`solve`][optim.steady.Steady.solve] then
        [`rms_at`][optim.steady.Steady.rms_at] )."""
        return self.rms_at(mech, self.solve(mech))

    def forward_mode(self) -> bool:
        return True

    def describe(self) -> dict:
        o = self.options
        d = {f.name: getattr(o, f.name) for f in dataclasses.fields(o) if f.name != "solve"}
        d["trend"] = None if self.trend is None else self.trend.describe()
        return {"kind": "steady_state", **d, **options_fields(o.solve), "throw": self.throw}


def _light(steady: S.SteadyState) -> S.SteadyState:
    """``steady`` without what [`jaxcrank.numerics.steady.orbit_start`][] does not need
    (the orbit, metrics, statistics and the settle's points), hashable for ``jit``."""
    return dataclasses.replace(
        steady,
        mechanism=None,
        orbit=None,
        metrics={},
        statistics=None,
        section_points=steady.section_points[-1:],
        revolutions=(),
        newton_iterations=0,
    )


def report(steady: S.SteadyState) -> dict:
    """The regime of a steady state as plain values: ``regime``, ``period_revolutions``,
    ``leading_multiplier`` (the largest |Floquet multiplier|, per period),
    ``lyapunov_exponent_per_s``, ``ok`` and, not periodic, ``statistics`` (metric ->
    value and 95 % confidence interval, units in the names) and
    ``gradient = "trend estimate"``; ``note`` where shooting failed and the statistics stand in
    ([`jaxcrank.SteadyOptions`][jaxcrank.numerics.shooting.SteadyOptions] ``statistics_on_failure``)."""
    moduli = steady.multiplier_moduli
    out = {
        "ok": steady.ok,
        "regime": steady.regime,
        "period_revolutions": int(steady.period_revolutions),
        "leading_multiplier": float(moduli[0]) if moduli.size else math.nan,
        "lyapunov_exponent_per_s": float(steady.lyapunov_exponent_per_s),
        "revolutions": dict(steady.revolutions),
    }
    if steady.statistics is not None:
        out["statistics"] = {k: {q: float(v) for q, v in s.items()} for k, s in steady.statistics.items()}
        out["gradient"] = "trend estimate"
    if steady.note:
        out["note"] = steady.note
    return out


def warm_solve(solve, last, settle_revolutions: int, again: bool = True) -> S.SteadyState:
    """The steady state ``solve(warm_start)`` finds warm-started from ``last`` (the last periodic
    one, or None). When ``again``, a warm start is redone from rest (``solve(None)``) where it
    found no orbit without a full settle of ``settle_revolutions``, and where its solve failed
    even after one: that settle began at the warm start, not at rest, and the motion from rest
    can settle onto another attractor."""
    steady = solve(last)
    settled = steady.revolutions.get("settle", 0) >= settle_revolutions
    if again and last is not None and not steady.periodic and (not settled or not steady.ok):
        steady = solve(None)
    return steady


def _key(x) -> tuple[float, ...]:
    """A design as the key of the evaluator's cached steady states."""
    return tuple(float(v) for v in np.asarray(x, dtype=float))


class SteadyEvaluator:
    """Value and exact gradient of a problem measured by a [`Steady`][optim.steady.Steady] objective, at
    concrete designs, each steady state warm-started from the last periodic one. A design
    whose solve fails is data, not an error: its value is NaN and its regime ``"failed"``
    (the objective is used with ``throw=False``), so an optimiser's trial point there is refused.

    Args:
        problem: a problem ([`AbstractProblem`][optim.problem.AbstractProblem]) whose objective is
            a [`Steady`][optim.steady.Steady]; a parameter problem without manufacturing scatter.

    Raises:
        ParameterError: for another objective, or a problem with manufacturing scatter.
    """

    def __init__(self, problem):
        if not isinstance(problem.objective, Steady):
            raise ParameterError(f"SteadyEvaluator needs a Steady objective, not {type(problem.objective).__name__}")
        if getattr(problem, "samples", 0):
            raise ParameterError(
                f"samples = {problem.samples}: the steady-state objective does not average over manufactured parts "
                "(samples = 0)"
            )
        self.problem = problem.with_objective(dataclasses.replace(problem.objective, throw=False))
        self.objective = self.problem.objective
        self.last = None  # the last periodic steady state: the next warm start
        self._steady = {}
        self._kept = None  # (design key, steady state) of the last periodic design kept by warm_from
        self._held = None  # the same for the last design kept that is not periodic
        self._trend = None
        self.last_report = {}  # report() of the last evaluated design
        self.compile_seconds = 0.0  # wall time this evaluator spent compiling gradient programs, s
        self.budget = None  # a Budget checked before every new solve and compilation (None: none)
        self.made = time.perf_counter()
        self.first_gradient = None  # wall time from the evaluator's making to its first exact gradient, s

    def steady_at(self, x) -> S.SteadyState:
        """The steady state at SI design ``x`` (cached for the last few designs), warm-started
        from the last periodic one. A warm-started solve that finds no attracting orbit
        without a full settle (its shooting from the carried-over state met an unstable
        orbit) is classified again from rest: the regime is the motion's from rest."""
        key = _key(x)
        known = self._known(key)
        if known is not None:
            return known
        if self.budget is not None:
            self.budget.check("a steady-state solve")
        # the problem's numbers as arrays: one compiled solve serves problems that differ only in them
        mech = with_values(self.problem, problem_values(self.problem)).mechanism(jnp.asarray(key))
        steady = warm_solve(
            lambda warm: self.objective.solve(mech, warm_start=warm),
            self.last,
            self.objective.options.settle_revolutions,
        )
        if steady.periodic:
            self.last = steady
        if len(self._steady) >= 4:
            self._steady.pop(next(iter(self._steady)))
        self._steady[key] = steady
        return steady

    def _known(self, key):
        """The steady state of design ``key`` kept by ``warm_from`` or cached, else None (no solve)."""
        for kept in (self._kept, self._held):
            if kept is not None and key == kept[0]:
                return kept[1]
        return self._steady.get(key)

    def value(self, x) -> tuple[float, dict]:
        """``(value, regime)`` at SI design ``x`` without a gradient: the objective in
        degrees over the orbit the steady-state solve computed (periodic), or the long-run
        statistics' value (not periodic; NaN when the solve failed), and [`report`][optim.steady.report]."""
        steady = self.steady_at(x)
        info = self.last_report = report(steady)
        if not steady.ok:
            return math.nan, info
        names = rms_metrics(self.problem.base)
        if steady.periodic:
            rms = {k: steady.metrics[k] for k in names}
        else:
            rms = {k: jnp.asarray(float(steady.statistics[k]["value"])) for k in names}
        return float(self.problem.loss(rms) + self.problem.cost(jnp.asarray(x))), info

    def warm_from(self, x) -> None:
        """Keep the steady state at SI design ``x`` beyond the cache of the last few designs, until
        another design of its kind is kept: a later ``warm_from(x)`` or evaluation at ``x`` finds it
        without a solve. A periodic one is also the next warm start; one that is not periodic (the
        way in's start where the lowest value is not periodic) is held in a slot of its own and
        changes no warm start. ``x`` is solved (warm-started from the last periodic steady state)
        only when it is neither kept nor cached."""
        steady = self.steady_at(x)
        if steady.periodic:
            self.last = steady
            self._kept = (_key(x), steady)
        else:
            self._held = (_key(x), steady)

    def regime_at(self, x) -> Regime:
        """The [`Regime`][jaxcrank.numerics.results.Regime] at SI design ``x`` (``FAILED`` when the solve failed)."""
        steady = self.steady_at(x)
        return steady.regime if steady.ok else FAILED

    def _program_key(self, steady: S.SteadyState, folded: bool = False):
        """The store key of the value-and-gradient program for the orbits of ``steady``'s period and
        dynamic subspace: the problem without its start and its numbers (multistart runs and problems
        that differ only in numbers share it, [`values_key`][optim.problem.values_key]); ``folded``: with them."""
        problem = dataclasses.replace(self.problem, start=None) if folded else values_key(self.problem)
        return (problem, steady.period_revolutions, steady.active)

    def _program_fun(self, steady: S.SteadyState, folded: bool = False):
        """The function that program compiles, of (the design, the orbit's section state, its monodromy,
        the problem's numbers; ``folded``: those are ignored, the problem's own compiled in)."""
        problem, objective, template = dataclasses.replace(self.problem, start=None), self.objective, _light(steady)

        def f(x, section_state, monodromy, values):
            p = problem if folded else with_values(problem, values)
            light = dataclasses.replace(template, section_state=section_state, monodromy=monodromy)
            return p.loss(objective.rms_at(p.mechanism(x), light)) + p.cost(x)

        return value_and_grad(f, True)

    def _args(self, x, steady: S.SteadyState) -> tuple:
        """The program's arguments at SI design ``x``."""
        return (jnp.asarray(x, dtype=float), steady.section_state, steady.monodromy, problem_values(self.problem))

    def _keys(self, steady: S.SteadyState) -> tuple:
        """``(key, plain)``: the program's key and the key without the problem's numbers; they are the
        same unless the numbers cannot be inputs (``FOLDED``), when the key holds them."""
        plain = self._program_key(steady)
        return (self._program_key(steady, folded=True) if plain in FOLDED else plain), plain

    def _build(self, steady: S.SteadyState, args, plain) -> tuple:
        """``(program, seconds, key)``: compiled with the problem's numbers as inputs (under ``plain``,
        the key without them), or, where a number is read at trace time, as constants (a program per
        problem)."""
        if plain not in FOLDED:
            try:
                return (*compile_program(self._program_fun(steady), args, plain), plain)
            except TRACE_ERRORS:
                FOLDED.add(plain)
        key = self._program_key(steady, folded=True)
        return (*compile_program(self._program_fun(steady, folded=True), args, key), key)

    def _program(self, steady: S.SteadyState, args):
        """The compiled program of [`_program_fun`][optim.steady.SteadyEvaluator._program_fun] for
        ``args`` = (the design, the orbit's section state, its monodromy, the problem's numbers): one
        program serves every design of a regime, and every evaluator of the same problem (its start and
        numbers aside: multistart runs and variants share it). Compiled at its first use (the budget
        checked first), or taken from a compilation [`prepare`][optim.steady.SteadyEvaluator.prepare]
        started; timed into ``compile_seconds``."""
        key, plain = self._keys(steady)
        if key not in PROGRAMS:
            # a compilation prepare() started under the plain key may have fallen back to the folded one
            pending = PENDING.pop(key, None) or PENDING.pop(plain, None)
            if pending is None:
                if self.budget is not None:
                    self.budget.check("compiling the gradient program")
                program, seconds, key = self._build(steady, args, plain)
            else:
                program, seconds, key = pending.result()
            self.compile_seconds += seconds
            if len(PROGRAMS) >= 8:
                PROGRAMS.pop(next(iter(PROGRAMS)))
            PROGRAMS[key] = program
        return PROGRAMS[key]

    def prepare(self, x) -> bool:
        """Start compiling, in a background thread, the gradient program the periodic steady state at
        SI design ``x`` (cached: no new solve) will need, while the caller goes on (the way in
        classifying further candidates). Returns whether a compilation was started (False: ``x``
        is not periodic or not solved yet, or its program is compiled or being compiled)."""
        steady = self._known(_key(x))
        if steady is None or not steady.periodic:
            return False
        key, plain = self._keys(steady)
        if key in PROGRAMS or key in PENDING:
            return False
        PENDING[key] = compiler().submit(self._build, steady, self._args(x, steady), plain)
        return True

    def _gradient_done(self) -> None:
        """Record the time to the first gradient (``first_gradient``, s since the evaluator was made)."""
        if self.first_gradient is None:
            self.first_gradient = time.perf_counter() - self.made

    def value_and_grad(self, x) -> tuple[float, np.ndarray, dict]:
        """``(value, gradient, regime)`` at SI design ``x``: the objective in degrees, its
        gradient in degrees per SI unit of each variable, and [`report`][optim.steady.report] of the
        steady state. Not periodic: the long-run value and the trend estimate (or zero)."""
        x = np.asarray(x, dtype=float)
        steady = self.steady_at(x)
        info = self.last_report = report(steady)
        if not steady.ok:
            return math.nan, np.full(x.shape, np.nan), info
        if steady.periodic:
            args = self._args(x, steady)
            value, grad = self._program(steady, args)(*args)
            self._gradient_done()
            return float(value), np.asarray(grad), info
        rms = {k: jnp.asarray(float(steady.statistics[k]["value"])) for k in rms_metrics(self.problem.base)}
        value = float(self.problem.loss(rms) + self.problem.cost(jnp.asarray(x)))
        if self.objective.trend is None:
            return value, np.zeros(x.shape), info
        if self._trend is None:
            trend = self.problem.with_objective(self.objective.trend)
            self._trend = jax.jit(trend.value_and_grad)
        return value, np.asarray(self._trend(jnp.asarray(x))[1]), info


def not_periodic_reason(problem, x) -> str:
    """Why an optimiser stops at SI design ``x`` of ``problem`` when it is not periodic and
    the steady-state gradient there is exactly zero (no trend estimate), and what to do."""
    design = ", ".join(f"{n} = {v:.6g}" for n, v in zip(problem.names, np.asarray(x)))
    return (
        f"not periodic at {design}: the steady-state gradient there is exactly zero (no trend estimate), which "
        "says nothing about optimality; start from a periodic design (optim.way_in.periodic_start finds one; "
        "optimize(problem) with no settings runs it first; jaxcrank optimize does with one start) or give Steady "
        "a trend objective (Steady(trend=Ensemble()))"
    )


@dataclasses.dataclass(frozen=True)
class RegimeGuard:
    """The optimiser's regime guard (``optim.optimize.Settings.guard``): a step to a design
    that is not in the periodic regime is halved, at most ``max_halvings`` times, then
    the iterate is held.

    Attributes:
        max_halvings: halvings of a refused step before the iterate is held, >= 0.
    """

    max_halvings: int = 3

    def accept(self, evaluator: SteadyEvaluator, x) -> bool:
        """Whether SI design ``x`` is in the periodic regime (its steady state is cached
        for the evaluation that follows)."""
        return evaluator.regime_at(x) == PERIODIC
