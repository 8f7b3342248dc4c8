"""Design problems: which parameters vary, within which bounds and linear
constraints, and what is minimised.

[`AbstractProblem`][optim.problem.AbstractProblem] holds what every problem shares (variables, bounds, linear
constraints, the objective instance, the cost term, the scaling and the projection);
its final subclasses say how a design becomes a mechanism and how the objective's
metrics become the problem's value: [`ParameterProblem`][optim.problem.ParameterProblem] (mechanism parameters
directly, Eq. 19, optionally averaged over manufactured parts) here, and
[`optim.design.DesignProblem`][] (a reparametrised geometry with nonlinear
constraints held by its box, weighted terms).

Variables are scaled to the unit box, ``u = (x - lower) / (upper - lower)``, so
millimetres and metres (or clearances and lengths) weigh the same for the
optimiser. Feasibility is kept by Euclidean projection onto the scaled feasible
set (box intersected with the half-spaces ``A x <= b``), computed with
``optax.projections`` (box and half-space projections combined by Dykstra's
algorithm, exact for one active constraint and convergent in general).
"""

from __future__ import annotations

import abc
import dataclasses
from collections.abc import Sequence

import jax
import jax.numpy as jnp
import numpy as np
import optax
from jaxtyping import Array, ArrayLike, Bool, Float

from jaxcrank.physics.params import Mechanism, ParameterError, get_parameter, paper, parameter_value, set_parameters
from jaxcrank.runs.sampling import Tolerance, monte_carlo

from .objective import EQ19, AbstractObjective, Ensemble, value_and_grad


@dataclasses.dataclass(frozen=True)
class AbstractProblem(abc.ABC):
    """A design problem ``min F(x) + cost(x)`` s.t. ``lower <= x <= upper``, ``A x <= b``.

    Attributes:
        base: the mechanism every design starts from (fixed parameters).
        names: design variable names.
        lower: bounds, SI units of each variable (the same for upper).
        upper: bounds, SI units of each variable (the same for lower).
        A: linear inequality constraints ``A x <= b`` (SI), shape (m, n) and (m,) (the same for b).
        b: linear inequality constraints ``A x <= b`` (SI), shape (m, n) and (m,) (the same for A).
        start: start design, SI (default: the subclass's default start projected onto the set).
        objective: how the mechanism is measured (an [`optim.objective.AbstractObjective`][]).
        cost_weight: weight of the manufacturing-cost term, degrees (0: none).
        cost_reference: reference clearance of the cost term, m.
        title: a short description for plots and reports (see [`description`][optim.problem.AbstractProblem.description]
            ).

    Raises:
        ParameterError: on construction, for inconsistent sizes, empty bounds, an
            unknown variable, a negative cost weight or one without clearance variables.
    """

    base: Mechanism
    names: tuple[str, ...]
    lower: tuple[float, ...]
    upper: tuple[float, ...]
    A: tuple[tuple[float, ...], ...] = ()
    b: tuple[float, ...] = ()
    start: tuple[float, ...] | None = None
    objective: AbstractObjective = Ensemble()
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
            self.check_variable(name)
        if len(self.A) != len(self.b) or any(len(row) != n for row in self.A):
            raise ParameterError(
                f"constraints: A must be (m, {n}) and b (m,), got {len(self.A)} rows, {len(self.b)} bounds"
            )
        if not isinstance(self.objective, AbstractObjective):
            raise ParameterError(
                f"objective = {self.objective!r} must be an optim.objective.AbstractObjective "
                "(Pathwise, Ensemble or optim.steady.Steady)"
            )
        if self.cost_weight < 0:
            raise ParameterError(f"cost_weight = {self.cost_weight:g} must be >= 0")
        if self.cost_weight > 0 and not any(nm.startswith("clearance_") for nm in self.names):
            raise ParameterError("cost_weight > 0 needs clearance_B or clearance_C among the variables")
        if self.start is not None and len(self.start) != n:
            raise ParameterError(f"start needs {n} values")
        self.check()

    # ------------------------------------------------------------------ what a subclass says
    @abc.abstractmethod
    def check_variable(self, name: str) -> None:
        """Raise ParameterError if ``name`` cannot be a variable of this problem."""

    @abc.abstractmethod
    def check(self) -> None:
        """The subclass's own checks of its fields (ParameterError naming the field)."""

    @abc.abstractmethod
    def mechanism(self, x: Float[ArrayLike, " n"]) -> Mechanism:
        """The mechanism at SI design ``x`` (traceable)."""

    @abc.abstractmethod
    def default_start(self) -> list[float]:
        """The SI start design when ``start`` is None."""

    @abc.abstractmethod
    def loss(self, rms: dict) -> Float[Array, ""]:
        """The problem's value (degrees, without the cost term) from the objective's RMS
        metrics ([`optim.objective.AbstractObjective.rms`][])."""

    @abc.abstractmethod
    def objective_value(self, x: Float[ArrayLike, " n"]) -> Float[Array, ""]:
        """Total objective at SI design ``x``, degrees: [`loss`][optim.problem.AbstractProblem.loss] +
        [`cost`][optim.problem.AbstractProblem.cost] .
        Differentiate it with [`value_and_grad`][optim.problem.AbstractProblem.value_and_grad]."""

    @property
    @abc.abstractmethod
    def description(self) -> str:
        """A description for reports and plots (from ``title``)."""

    @abc.abstractmethod
    def feasible(self, x: Float[ArrayLike, "*designs n"], tol=1e-12) -> Bool[ArrayLike, "*designs"]:
        """Whether the SI design(s) ``x`` satisfy every constraint of the problem (numpy bool, batched)."""

    # ------------------------------------------------------------------ shared

    @property
    def n(self) -> int:
        """Number of design variables."""
        return len(self.names)

    @property
    def span(self) -> Float[Array, " n"]:
        """``upper - lower``, SI."""
        return jnp.asarray(self.upper) - jnp.asarray(self.lower)

    def to_unit(self, x: Float[ArrayLike, " n"]) -> Float[Array, " n"]:
        """SI design -> scaled design in the unit box."""
        return (jnp.asarray(x, dtype=float) - jnp.asarray(self.lower)) / self.span

    def from_unit(self, u: Float[ArrayLike, " n"]) -> Float[Array, " n"]:
        """Scaled design -> SI design."""
        return jnp.asarray(self.lower) + jnp.asarray(u, dtype=float) * self.span

    def box_feasible(self, x: Float[ArrayLike, "*designs n"], tol=1e-12) -> Bool[ArrayLike, "*designs"]:
        """Whether the SI design ``x`` satisfies bounds and linear constraints (numpy bool, batched)."""
        x = np.asarray(x, dtype=float)
        ok = np.all((x >= np.asarray(self.lower) - tol) & (x <= np.asarray(self.upper) + tol), axis=-1)
        for row, bound in zip(self.A, self.b):
            ok &= x @ np.asarray(row) <= bound + tol
        return ok

    def project(self, u: Float[ArrayLike, " n"], iterations: int = 100) -> Float[Array, " n"]:
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

    def start_unit(self) -> Float[Array, " n"]:
        """Scaled, projected start design."""
        x0 = self.start if self.start is not None else self.default_start()
        return self.project(self.to_unit(x0))

    def cost(self, x: Float[ArrayLike, " n"]) -> Float[Array, ""]:
        """Manufacturing cost term, degrees: ``cost_weight * sum_j cost_reference / c_j``
        over the clearance variables (reciprocal cost-tolerance model: halving a
        clearance doubles its machining cost)."""
        terms = [self.cost_reference / x[i] for i, nm in enumerate(self.names) if nm.startswith("clearance_")]
        return self.cost_weight * sum(terms) if terms else jnp.zeros(())

    def value_and_grad(self, x: Float[ArrayLike, " n"]) -> tuple[Float[Array, ""], Float[Array, " n"]]:
        """The objective (degrees) at SI design ``x`` (n,) and its gradient (n,), degrees
        per SI unit, by forward or reverse mode as the objective says. Traceable; ``jax.jit`` it."""
        return value_and_grad(self.objective_value, self.objective.forward_mode())(x)

    def with_objective(self, objective: AbstractObjective) -> AbstractProblem:
        """The same problem measured by another objective."""
        return dataclasses.replace(self, objective=objective)


@dataclasses.dataclass(frozen=True)
class ParameterProblem(AbstractProblem):
    """Mechanism parameters as the variables (any name
    [`jaxcrank.physics.params.set_parameter`][] accepts), Eq. 19 as the value, and
    optionally the mean over manufactured parts (robust design).

    Attributes (besides [`AbstractProblem`][optim.problem.AbstractProblem]'s):
        scatter: manufacturing scatter for the robust objective, one
            ``(name, tolerance, distribution)`` per parameter: the part's value is the
            design's (or the base's) value plus a deviation within ``+-tolerance`` (SI),
            ``"uniform"`` over the band or ``"normal"`` with the band as +-3 sigma
            ([`jaxcrank.runs.sampling.Tolerance`][]).
        samples: number of manufactured parts the robust objective averages over
            (0: the nominal design alone). With ``samples > 0`` the Eq. 19 part of the
            objective is the Monte Carlo mean over ``samples`` parts, the same draws at
            every design (common random numbers, a sample-average approximation of the
            expected RMS error), and its gradient the mean of the parts' gradients.
        seed: seed of those draws.
    """

    scatter: tuple[tuple[str, float, str], ...] = ()
    samples: int = 0
    seed: int = 0

    def check_variable(self, name: str) -> None:
        get_parameter(self.base, name)  # raises on unknown names

    def check(self) -> None:
        if self.samples < 0:
            raise ParameterError(f"samples = {self.samples} must be >= 0 (0: no manufacturing scatter)")
        if self.samples and not self.scatter:
            raise ParameterError("samples > 0 needs a scatter: [(name, tolerance, distribution), ...]")
        for entry in self.scatter:
            if len(entry) != 3:
                raise ParameterError(f"scatter entry {entry!r} must be (name, tolerance, distribution)")
            name, tol, dist = entry
            get_parameter(self.base, name)  # raises on unknown names
            Tolerance(0.0, float(tol), dist)  # checks tolerance >= 0 and the distribution
            if name == "crank_speed":
                raise ParameterError(
                    "scatter of crank_speed is not supported: the objective's sample grid "
                    "(equal crank angles) needs one crank speed for all parts"
                )
        if len({e[0] for e in self.scatter}) != len(self.scatter):
            raise ParameterError("scatter names a parameter twice")
        if self.samples:
            dev = self.draws()
            for j, (name, tol, _) in enumerate(self.scatter):
                if name.startswith("clearance_"):
                    lowest = (
                        self.lower[self.names.index(name)]
                        if name in self.names
                        else float(get_parameter(self.base, name))
                    )
                    if lowest + dev[:, j].min() <= 0.0:
                        raise ParameterError(
                            f"scatter of {name}: +-{tol:g} m reaches a clearance <= 0 ({lowest:g} m "
                            f"{dev[:, j].min():+g} m in the draws); valid: tolerance below the smallest clearance"
                        )

    @property
    def description(self) -> str:
        """``title`` for reports and plots, naming the number of manufactured parts
        when the objective is a mean over them (``samples > 0``)."""
        return f"{self.title} (mean over {self.samples} manufactured parts)" if self.samples else self.title

    def feasible(self, x: Float[ArrayLike, "*designs n"], tol=1e-12) -> Bool[ArrayLike, "*designs"]:
        """Whether the SI design ``x`` satisfies bounds and constraints (numpy bool, batched)."""
        return self.box_feasible(x, tol)

    def mechanism(self, x: Float[ArrayLike, " n"]) -> Mechanism:
        return set_parameters(self.base, self.names, x)

    def default_start(self) -> list[float]:
        return [float(get_parameter(self.base, nm)) for nm in self.names]

    def draws(self) -> Float[np.ndarray, "samples scatter"]:
        """Deviations of the manufactured parts from the design, (samples, len(scatter)), SI:
        the Monte Carlo draws of [`jaxcrank.runs.sampling.monte_carlo`][] about a zero nominal."""
        if not self.scatter:
            return np.zeros((self.samples, 0))
        tolerances = {name: Tolerance(0.0, tol, dist) for name, tol, dist in self.scatter}
        return monte_carlo(tolerances, self.samples, seed=self.seed)[1]

    def part(self, x: Float[ArrayLike, " n"], deviation: Float[ArrayLike, " scatter"]) -> Mechanism:
        """The manufactured part of SI design ``x`` with ``deviation`` (one row of
        [`draws`][optim.problem.ParameterProblem.draws]): each scattered parameter at its design (or base) value plus
        its deviation (traceable)."""
        mech = self.mechanism(x)
        names = [nm for nm, _, _ in self.scatter]
        return set_parameters(mech, names, [parameter_value(mech, nm) + deviation[j] for j, nm in enumerate(names)])

    def loss(self, rms: dict) -> Float[Array, ""]:
        return rms[EQ19]

    def objective_value(self, x: Float[ArrayLike, " n"]) -> Float[Array, ""]:
        if not self.samples:
            return self.loss(self.objective.rms(self.mechanism(x))) + self.cost(x)
        parts = jax.vmap(lambda d: self.loss(self.objective.rms(self.part(x, d))))(jnp.asarray(self.draws()))
        return jnp.mean(parts) + self.cost(x)


def paper_problem(objective: AbstractObjective = Ensemble(), start: Sequence[float] | None = None) -> ParameterProblem:
    """The paper's problem (Eq. 19): L1 in [110, 130] mm, L2 in [390, 410] mm,
    ``L2 >= L1 + e`` (written ``L1 - L2 <= -e``), offset e fixed at the preset's 50 mm.
    Start: the box centre (L1 = 120, L2 = 400 mm); the paper's own design (L1 = 150
    mm) lies outside its stated box."""
    base = paper()
    e = float(base.offset)
    return ParameterProblem(
        base=base,
        names=("crank_length", "rod_length"),
        lower=(0.110, 0.390),
        upper=(0.130, 0.410),
        A=((1.0, -1.0),),
        b=(-e,),
        start=(0.120, 0.400) if start is None else tuple(start),
        objective=objective,
        title="paper: RMS transmission-angle error over L1, L2",
    )


def tolerance_problem(
    objective: AbstractObjective = Ensemble(), cost_weight: float = 0.005, start: Sequence[float] | None = None
) -> ParameterProblem:
    """Tolerance allocation: radial clearances c_B, c_C in [0.1, 0.5] mm at the
    paper's geometry, minimising RMS transmission-angle error + manufacturing cost
    ([`AbstractProblem.cost`][optim.problem.AbstractProblem.cost], reference clearance 0.5 mm). Start: 0.4 mm at
    both."""
    return ParameterProblem(
        base=paper(),
        names=("clearance_B", "clearance_C"),
        lower=(1e-4, 1e-4),
        upper=(5e-4, 5e-4),
        start=(4e-4, 4e-4) if start is None else tuple(start),
        objective=objective,
        cost_weight=cost_weight,
        cost_reference=5e-4,
        title="tolerance allocation: RMS error + reciprocal clearance cost",
    )


#: the robust problem's default manufacturing scatter: lengths +-0.05 mm (normal, +-3 sigma),
#: clearances +-0.05 mm (uniform) about the preset's 0.5 mm
ROBUST_SCATTER = (
    ("crank_length", 5e-5, "normal"),
    ("rod_length", 5e-5, "normal"),
    ("clearance_B", 5e-5, "uniform"),
    ("clearance_C", 5e-5, "uniform"),
)


def robust_problem(
    objective: AbstractObjective = Ensemble(), samples: int = 8, seed: int = 0, start: Sequence[float] | None = None
) -> ParameterProblem:
    """The paper's L1, L2 problem under manufacturing tolerances: minimise the
    expected RMS transmission-angle error over ``samples`` parts drawn from
    `ROBUST_SCATTER` (Monte Carlo mean, the same draws at every design)."""
    p = paper_problem(objective, start)
    return dataclasses.replace(
        p, scatter=ROBUST_SCATTER, samples=samples, seed=seed, title="robust: expected RMS transmission-angle error"
    )
