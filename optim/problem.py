"""Design problems: which parameters vary, within which bounds and linear
constraints, and what is minimised.

Variables are scaled to the unit box, ``u = (x - lower) / (upper - lower)``, so
millimetres and metres (or clearances and lengths) weigh the same for the
optimiser. Feasibility is kept by Euclidean projection onto the scaled feasible
set (box intersected with the half-spaces ``A x <= b``), computed with
``optax.projections`` (box and half-space projections combined by Dykstra's
algorithm, exact for one active constraint and convergent in general).
"""

from __future__ import annotations

import dataclasses
from typing import Sequence

import jax
import jax.numpy as jnp
import numpy as np
import optax

from jaxcrank.params import Mechanism, ParameterError, get_parameter, paper, set_parameters

from .objective import Objective, value


@dataclasses.dataclass(frozen=True)
class Problem:
    """A design problem ``min F(x) + cost(x)`` s.t. ``lower <= x <= upper``, ``A x <= b``.

    Attributes:
        base: the mechanism every design starts from (fixed parameters).
        names: design variable names (see :func:`set_parameter`).
        lower, upper: bounds, SI units of each variable.
        A, b: linear inequality constraints ``A x <= b`` (SI), shape (m, n) and (m,).
        start: start design, SI (default: ``base``'s values projected onto the set).
        objective: settings of the Eq. 19 objective.
        cost_weight: weight of the manufacturing-cost term, degrees (0: none).
        cost_reference: reference clearance of the cost term, m.
        title: a short description for plots and reports.
    """

    base: Mechanism
    names: tuple[str, ...]
    lower: tuple[float, ...]
    upper: tuple[float, ...]
    A: tuple[tuple[float, ...], ...] = ()
    b: tuple[float, ...] = ()
    start: tuple[float, ...] | None = None
    objective: Objective = Objective()
    cost_weight: float = 0.0
    cost_reference: float = 5e-4
    title: str = ""

    def __post_init__(self):
        n = len(self.names)
        if n == 0:
            raise ParameterError("a design problem needs at least one variable")
        if len(self.lower) != n or len(self.upper) != n:
            raise ParameterError(f"lower and upper need {n} values (one per variable {list(self.names)})")
        for name, lo, hi in zip(self.names, self.lower, self.upper):
            if not lo < hi:
                raise ParameterError(f"bounds of {name!r}: lower = {lo:g} must be below upper = {hi:g}")
            get_parameter(self.base, name)  # raises on unknown names
        if len(self.A) != len(self.b) or any(len(row) != n for row in self.A):
            raise ParameterError(f"constraints: A must be (m, {n}) and b (m,), got {len(self.A)} rows, {len(self.b)} bounds")
        if self.cost_weight < 0:
            raise ParameterError(f"cost_weight = {self.cost_weight:g} must be >= 0")
        if self.cost_weight > 0 and not any(nm.startswith("clearance_") for nm in self.names):
            raise ParameterError("cost_weight > 0 needs clearance_B or clearance_C among the variables")
        if self.start is not None and len(self.start) != n:
            raise ParameterError(f"start needs {n} values")

    # ------------------------------------------------------------------ scaling
    @property
    def n(self) -> int:
        return len(self.names)

    @property
    def span(self):
        return jnp.asarray(self.upper) - jnp.asarray(self.lower)

    def to_unit(self, x):
        return (jnp.asarray(x, dtype=float) - jnp.asarray(self.lower)) / self.span

    def from_unit(self, u):
        return jnp.asarray(self.lower) + jnp.asarray(u, dtype=float) * self.span

    def feasible(self, x, tol=1e-12):
        """Whether the SI design ``x`` satisfies bounds and constraints (numpy bool, batched)."""
        x = np.asarray(x, dtype=float)
        ok = np.all((x >= np.asarray(self.lower) - tol) & (x <= np.asarray(self.upper) + tol), axis=-1)
        for row, bound in zip(self.A, self.b):
            ok &= x @ np.asarray(row) <= bound + tol
        return ok

    def project(self, u, iterations: int = 100):
        """Euclidean projection of the scaled design ``u`` onto the scaled feasible set."""
        u = jnp.asarray(u, dtype=float)
        box = lambda v: optax.projections.projection_box(v, 0.0, 1.0)  # noqa: E731
        if not self.A:
            return box(u)
        lo, span = jnp.asarray(self.lower), self.span
        rows = [(jnp.asarray(r) * span, bnd - jnp.dot(jnp.asarray(r), lo)) for r, bnd in zip(self.A, self.b)]
        sets = [box] + [lambda v, a=a, c=c: optax.projections.projection_halfspace(v, a, c) for a, c in rows]

        def sweep(carry, _):  # Dykstra's alternating projections with corrections
            v, corr = carry
            new = []
            for proj, p in zip(sets, corr):
                w = proj(v + p)
                new.append(v + p - w)
                v = w
            return (v, tuple(new)), None

        (v, _), _ = jax.lax.scan(sweep, (u, tuple(jnp.zeros_like(u) for _ in sets)), None, length=iterations)
        return v

    def start_unit(self):
        """Scaled, projected start design."""
        x0 = self.start if self.start is not None else [get_parameter(self.base, nm) for nm in self.names]
        return self.project(self.to_unit(x0))

    # ------------------------------------------------------------------ model
    def mechanism(self, x) -> Mechanism:
        """The mechanism at SI design ``x`` (traceable)."""
        return set_parameters(self.base, self.names, x)

    def cost(self, x):
        """Manufacturing cost term, degrees: ``cost_weight * sum_j cost_reference / c_j``
        over the clearance variables (reciprocal cost-tolerance model: halving a
        clearance doubles its machining cost)."""
        terms = [self.cost_reference / x[i] for i, nm in enumerate(self.names) if nm.startswith("clearance_")]
        return self.cost_weight * sum(terms) if terms else jnp.zeros(())

    def objective_value(self, x, method: str | None = None):
        """Total objective at SI design ``x``: Eq. 19 (degrees) + cost."""
        obj = self.objective if method is None else dataclasses.replace(self.objective, method=method)
        return value(self.mechanism(x), obj) + self.cost(x)


def paper_problem(objective: Objective = Objective(), start: Sequence[float] | None = None) -> Problem:
    """The paper's problem (Eq. 19): L1 in [110, 130] mm, L2 in [390, 410] mm,
    ``L2 >= L1 + e`` (written ``L1 - L2 <= -e``), offset e fixed at the preset's 50 mm.
    Start: the box centre (L1 = 120, L2 = 400 mm); the paper's own design (L1 = 150
    mm) lies outside its stated box."""
    base = paper()
    e = float(base.offset)
    return Problem(base=base, names=("crank_length", "rod_length"), lower=(0.110, 0.390), upper=(0.130, 0.410),
                   A=((1.0, -1.0),), b=(-e,), start=(0.120, 0.400) if start is None else tuple(start),
                   objective=objective, title="paper: RMS transmission-angle error over L1, L2")


def tolerance_problem(objective: Objective = Objective(), cost_weight: float = 0.005,
                      start: Sequence[float] | None = None) -> Problem:
    """Tolerance allocation: radial clearances c_B, c_C in [0.1, 0.5] mm at the
    paper's geometry, minimising RMS transmission-angle error + manufacturing cost
    (:meth:`Problem.cost`, reference clearance 0.5 mm). Start: 0.4 mm at both."""
    return Problem(base=paper(), names=("clearance_B", "clearance_C"), lower=(1e-4, 1e-4), upper=(5e-4, 5e-4),
                   start=(4e-4, 4e-4) if start is None else tuple(start), objective=objective,
                   cost_weight=cost_weight, cost_reference=5e-4,
                   title="tolerance allocation: RMS error + reciprocal clearance cost")


PROBLEMS = {"paper": paper_problem, "tolerance": tolerance_problem}
