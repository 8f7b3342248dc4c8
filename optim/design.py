"""The design problem: one type for every problem, preset or user's ([`DesignProblem`][optim.design.DesignProblem]).

A problem is data: the base mechanism; the variables (any parameter by name, derived link
lengths [`optim.geometry.Length`][], and at most one derived group such as the slider-crank's
stroke-holding or the four-bar's crank-rocker reparametrisation, [`optim.geometry`][]); the
objective, a weighted sum of quantities by their ``summary.json`` names ([`optim.quantities`][]),
optionally a statistic over manufactured parts; bounds, linear constraints and bounds on
quantities (held by [`optim.constrained`][]). The preset problems are problem files
([`optim.presets`][]); a user's file is read by [`optim.spec`][].

Value: ``sum_i w_i q_i + cost``, in the unit of the terms (degrees for the preset problems,
whose first term is the paper's Eq. 19 with weight 1, and whose other weights are degrees per
unit of their term); the cost is the reciprocal clearance cost of
[`cost`][optim.problem.AbstractProblem.cost]. With ``samples > 0`` the value is a statistic over
manufactured parts (the same draws at every design: common random numbers).
"""

from __future__ import annotations

import dataclasses
import re

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from jaxcrank.physics.compiled import compile_model
from jaxcrank.physics.parameters import get_parameter, parameter_value, set_parameters
from jaxcrank.physics.params import ParameterError
from jaxcrank.physics.signals import rms_metrics
from jaxcrank.runs.sampling import Tolerance, monte_carlo

from . import quantities as Q
from .geometry import CrankRocker, Length, SliderCrankStroke
from .objective import EQ19, safe_sqrt
from .problem import AbstractProblem, known_parameter
from .steady import Steady

#: the composite term of the clearance joints' forces (a wear proxy), N
CONTACT_FORCE = "rms_contact_force_N"

#: the terms of the slider-crank design preset (name -> meaning); units in the suffix
TERMS = {
    EQ19: "RMS of actual - ideal transmission angle (paper Eq. 19), weight 1",
    "rms_rod_x_deviation_m": "RMS of rod-centre x - ideal",
    "rms_slider_x_deviation_m": "RMS of slider x - ideal (the slider's positioning accuracy)",
    "rms_driving_moment_deviation_N_m": "RMS of driving moment - ideal driving moment (clearance-induced fluctuation)",
    CONTACT_FORCE: "RMS normal contact force over the clearance joints (bearing wear proxy)",
}

#: statistics over manufactured parts: ``mean``, ``std`` (standard deviation) or ``pNN`` (a percentile)
STATISTICS = ("mean", "std", "p50", "p90", "p95", "p99")


@dataclasses.dataclass(frozen=True)
class DesignProblem(AbstractProblem):
    """A design problem (module docstring).

    Attributes (besides [`AbstractProblem`][optim.problem.AbstractProblem]'s):
        terms: the objective, ``(quantity, weight)`` pairs (default: Eq. 19 alone).
        limits: bounds on quantities, ``(quantity, lower, upper, scale)`` (None: no bound;
            ``scale`` the size violations are measured by, None: the largest |bound|); the
            steady-state objective only ([`optim.constrained.solve`][] holds them).
        lengths: derived length variables ([`optim.geometry.Length`][]), named among ``names``.
        derived: a derived group ([`optim.geometry.SliderCrankStroke`][],
            [`optim.geometry.CrankRocker`][]) or None.
        scatter: manufacturing scatter, ``(name, tolerance, distribution)`` per parameter: the
            part's value is the design's (or base's) plus a deviation within ``+-tolerance``
            (SI), ``"uniform"`` or ``"normal"`` (the band as +-3 sigma).
        samples: manufactured parts the value is a statistic over (0: the design alone).
        seed: seed of the parts' draws.
        statistic: the statistic over parts, one of `STATISTICS`.
        kinematic_samples: driver angles per revolution of the kinematic quantities.

    Raises:
        ParameterError: on construction, naming the field: an unknown quantity or variable,
            an empty objective, bounds in the wrong order, a bad derived variable, limits or
            quantities the objective cannot measure, a bad scatter.
    """

    terms: tuple[tuple[str, float], ...] = ((EQ19, 1.0),)
    limits: tuple[tuple[str, float | None, float | None, float | None], ...] = ()
    lengths: tuple[Length, ...] = ()
    derived: SliderCrankStroke | CrankRocker | None = None
    scatter: tuple[tuple[str, float, str], ...] = ()
    samples: int = 0
    seed: int = 0
    statistic: str = "mean"
    kinematic_samples: int = 720

    # ------------------------------------------------------------------ checks
    def check_variable(self, name: str) -> None:
        if self.derived is not None:
            self.derived.check_variable(name)
            if name in self.derived.OWNED:
                return
        if name not in {v.name for v in self.lengths}:
            known_parameter(self.base, name)

    def check(self) -> None:
        for v in self.lengths:
            v.check(self.base)
            if v.name not in self.names:
                raise ParameterError(f"length variable {v.name!r} is not among the variables {list(self.names)}")
        if self.derived is not None:
            self.derived.check(self)
        if not self.terms:
            raise ParameterError("the objective needs at least one term: terms = [{quantity = ..., weight = ...}]")
        steady = isinstance(self.objective, Steady)
        measurable = set(rms_metrics(self.base)) | {CONTACT_FORCE}
        for q, w in self.terms:
            if q != CONTACT_FORCE:
                Q.check_quantity(self.base, q, "objective term")
            if not steady and q not in measurable:
                raise ParameterError(
                    f"objective term {q!r}: a windowed objective measures the RMS metrics only "
                    f"({', '.join(sorted(measurable))}); use the steady state (method = 'steady_state')"
                )
            if not np.isfinite(w) or w == 0.0:
                raise ParameterError(f"objective term {q!r}: weight = {w!r} must be a finite nonzero number")
        if len({q for q, _ in self.terms}) != len(self.terms):
            raise ParameterError("the objective names a term twice")
        if self.limits and not steady:
            raise ParameterError("bounds on quantities need the steady-state objective (method = 'steady_state')")
        for q, lo, hi, scale in self.limits:
            Q.check_quantity(self.base, q, "constraint")
            if lo is None and hi is None:
                raise ParameterError(f"constraint on {q!r}: give lower, upper or both")
            if lo is not None and hi is not None and not lo < hi:
                raise ParameterError(f"constraint on {q!r}: lower = {lo:g} must be below upper = {hi:g}")
            if scale is not None and not scale > 0:
                raise ParameterError(f"constraint on {q!r}: scale = {scale:g} must be > 0")
        self._check_scatter()

    def _check_scatter(self) -> None:
        if self.samples < 0:
            raise ParameterError(f"samples = {self.samples} must be >= 0 (0: no manufacturing scatter)")
        if self.samples and not self.scatter:
            raise ParameterError("samples > 0 needs a scatter: [(name, tolerance, distribution), ...]")
        if self.samples and isinstance(self.objective, Steady):
            raise ParameterError(
                f"[scatter] samples = {self.samples}: the steady-state objective does not average over manufactured "
                "parts; set samples = 0, or choose a windowed objective ([solver] method = 'ensemble')"
            )
        if self.statistic not in STATISTICS:
            raise ParameterError(f"statistic = {self.statistic!r} is unknown; valid: {', '.join(STATISTICS)}")
        for entry in self.scatter:
            if len(entry) != 3:
                raise ParameterError(f"scatter entry {entry!r} must be (name, tolerance, distribution)")
            name, tol, _ = entry
            known_parameter(self.base, name)
            Tolerance(0.0, float(tol), entry[2])  # checks tolerance >= 0 and the distribution
            if name.startswith("driver."):
                raise ParameterError(
                    f"scatter of {name} is not supported: the objective's sample grid (equal crank angles) "
                    "needs one driver for all parts"
                )
        if len({e[0] for e in self.scatter}) != len(self.scatter):
            raise ParameterError("scatter names a parameter twice")
        if self.samples:
            dev = self.draws()
            for j, (name, tol, _) in enumerate(self.scatter):
                if name.startswith("clearance_"):
                    low = self.lower[self.names.index(name)] if name in self.names else get_parameter(self.base, name)
                    if low + dev[:, j].min() <= 0.0:
                        raise ParameterError(
                            f"scatter of {name}: +-{tol:g} m reaches a clearance <= 0 ({low:g} m "
                            f"{dev[:, j].min():+g} m in the draws); valid: tolerance below the smallest clearance"
                        )

    # ------------------------------------------------------------------ the design
    @property
    def description(self) -> str:
        """``title`` (else the derived group's or the objective's description), naming the
        manufactured parts when the value is a statistic over them."""
        text = self.title or (
            self.derived.describe(self)
            if self.derived is not None
            else "minimise " + " + ".join(f"{w:g} x {q}" for q, w in self.terms)
        )
        if self.samples:
            what = "mean" if self.statistic == "mean" else self.statistic
            return f"{text} ({what} over {self.samples} manufactured parts)"
        return text

    def physical(self, x) -> tuple[tuple[str, ...], Float[Array, " p"]]:
        """Mechanism parameter names and their values (SI, traceable) at design ``x``: the
        direct variables, then what the derived group and each length variable set."""
        x = jnp.asarray(x, dtype=float)
        owned = set(self.derived.OWNED) if self.derived is not None else set()
        derived = {v.name for v in self.lengths} | owned
        names = [nm for nm in self.names if nm not in derived]
        values = [x[self.names.index(nm)] for nm in names]
        if self.derived is not None:
            more, vals = self.derived.physical(self, x)
            names, values = names + more, values + vals
        if self.lengths:
            mech = set_parameters(self.base, names, values)
            for v in self.lengths:
                more, vals = v.apply(self.base, mech, x[self.names.index(v.name)])
                mech = set_parameters(mech, more, vals)
                names, values = names + more, values + list(vals)
        return tuple(names), jnp.stack([jnp.asarray(v, dtype=float) for v in values])

    def mechanism(self, x):
        names, values = self.physical(x)
        return set_parameters(self.base, names, values)

    def default_start(self) -> list[float]:
        lengths = {v.name: v.base_length(self.base) for v in self.lengths}
        out = []
        for nm, lo, hi in zip(self.names, self.lower, self.upper):
            value = None
            if self.derived is not None and nm in self.derived.OWNED:
                value = self.derived.default_start(self, nm, lo, hi)
            if value is None:
                value = lengths[nm] if nm in lengths else float(get_parameter(self.base, nm))
            out.append(value)
        return out

    def constraints(self, x) -> dict:
        """The derived group's closed-form constraint values at SI design(s) ``x`` (..., n), numpy
        ([`optim.geometry.SliderCrankStroke.constraints`][],
        [`optim.geometry.CrankRocker.constraints`][]); empty without a group."""
        return {} if self.derived is None else self.derived.constraints(self, x)

    def feasible(self, x, tol=1e-12):
        """Bounds, linear constraints and the derived group's constraints (the bounds on
        quantities are the evaluator's, [`optim.constrained`][])."""
        ok = self.box_feasible(x, tol)
        return ok if self.derived is None else ok & self.derived.feasible(self, x, self.constraints(x))

    # ------------------------------------------------------------------ the value
    @property
    def clearance_joints(self) -> tuple[str, ...]:
        """The base's clearance joints, over which ``rms_contact_force_N`` is taken."""
        return compile_model(self.base).tree.cut

    def quantity(self, metrics: dict, name: str):
        """A term's value from a metrics dict: the metric, or the composite
        ``rms_contact_force_N = sqrt(mean_j rms_contact_force_<j>_N^2)`` over the clearance joints."""
        if name == CONTACT_FORCE:
            joints = self.clearance_joints
            return safe_sqrt(sum(metrics[f"rms_contact_force_{j}_N"] ** 2 for j in joints) / len(joints))
        return metrics[name]

    def loss(self, rms: dict) -> Float[Array, ""]:
        return sum(w * self.quantity(rms, q) for q, w in self.terms)

    def weight_of(self) -> dict[str, float]:
        """Each term's weight, per unit of the term: the problem's terms, and 0 for the other
        terms of the design preset (`TERMS`)."""
        return {**dict.fromkeys(TERMS, 0.0), **dict(self.terms)}

    def term_values(self, x) -> dict[str, Float[Array, ""]]:
        """Every term of the design preset (`TERMS`) and the problem's own terms at SI design
        ``x`` by the problem's objective (name -> value; a concrete ``x`` for the steady state)."""
        rms = self.objective.rms(self.mechanism(x))
        names = dict.fromkeys([k for k in TERMS if k == CONTACT_FORCE or k in rms] + [q for q, _ in self.terms])
        return {k: self.quantity(rms, k) for k in names}

    def draws(self) -> Float[np.ndarray, "samples scatter"]:
        """Deviations of the manufactured parts from the design, (samples, len(scatter)), SI."""
        if not self.scatter:
            return np.zeros((self.samples, 0))
        tolerances = {name: Tolerance(0.0, tol, dist) for name, tol, dist in self.scatter}
        return monte_carlo(tolerances, self.samples, seed=self.seed)[1]

    def part(self, x, deviation):
        """The manufactured part of SI design ``x`` with ``deviation`` (one row of
        [`draws`][optim.design.DesignProblem.draws]), traceable."""
        mech = self.mechanism(x)
        names = [nm for nm, _, _ in self.scatter]
        return set_parameters(mech, names, [parameter_value(mech, nm) + deviation[j] for j, nm in enumerate(names)])

    def objective_value(self, x) -> Float[Array, ""]:
        """The value at SI design ``x`` (module docstring; traceable for the windowed objectives,
        a concrete ``x`` for the steady state; the bounds on quantities not included)."""
        if not self.samples:
            return self.loss(self.objective.rms(self.mechanism(x))) + self.cost(x)
        parts = jax.vmap(lambda d: self.loss(self.objective.rms(self.part(x, d))))(jnp.asarray(self.draws()))
        return statistic_of(parts, self.statistic) + self.cost(x)

    # ------------------------------------------------------------------ outputs for the constrained solve
    @property
    def quantities(self) -> tuple[str, ...]:
        """The quantities the problem reads: the terms', then the limits' (in order)."""
        return tuple(q for q, _ in self.terms) + tuple(c[0] for c in self.limits)

    def outputs(self, metrics: dict, x: Float[ArrayLike, " n"]) -> Float[Array, " k"]:
        """The terms' quantities, the cost's sum ``sum_j cost_reference / c_j`` over the clearance
        variables (without ``cost_weight``: problems that differ in the weight share the program),
        then the limits' quantities at SI design ``x`` given the headline ``metrics`` of its steady
        state (traceable)."""
        x = jnp.asarray(x, dtype=float)
        kin = Q.kinematic_values(
            self.mechanism(x), sorted({q for q in self.quantities if q in Q.KINEMATICS}), self.kinematic_samples
        )
        pick = lambda q: kin[q] if q in kin else jnp.asarray(self.quantity(metrics, q), dtype=float)
        terms = [pick(q) for q, _ in self.terms]
        cost = [self.cost_reference / x[i] for i, nm in enumerate(self.names) if nm.startswith("clearance_")]
        cost_sum = sum(cost) if cost else jnp.zeros(())
        return jnp.stack(terms + [cost_sum] + [pick(c[0]) for c in self.limits])

    def split(self, outputs) -> tuple[np.ndarray, float, np.ndarray]:
        """(terms' values, cost (``cost_weight`` x the cost's sum), limits' values) of an ``outputs``
        vector (numpy)."""
        v = np.asarray(outputs, dtype=float)
        n = len(self.terms)
        return v[:n], float(self.cost_weight * v[n]), v[n + 1 :]


def statistic_of(values: Float[ArrayLike, " parts"], statistic: str) -> Float[Array, ""]:
    """The statistic (`STATISTICS`) of the parts' values, traceable: the mean, the standard deviation
    (population, finite gradient at zero spread) or the percentile ``pNN`` (linear interpolation)."""
    values = jnp.asarray(values)
    if statistic == "mean":
        return jnp.mean(values)
    if statistic == "std":
        return safe_sqrt(jnp.mean((values - jnp.mean(values)) ** 2))
    return jnp.percentile(values, float(re.sub("^p", "", statistic)))
