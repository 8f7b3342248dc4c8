"""Design problems: which parameters vary, within which bounds and linear
constraints, and what is minimised.

[`AbstractProblem`][optim.problem.AbstractProblem] holds what every problem shares (variables, bounds, linear
constraints, the objective instance, the cost term, the scaling and the projection);
its one final subclass, [`optim.design.DesignProblem`][], says how a design becomes a
mechanism and how the objective's metrics become the problem's value.

Variables are scaled to the unit box, ``u = (x - lower) / (upper - lower)``, so
millimetres and metres (or clearances and lengths) weigh the same for the
optimiser. Feasibility is kept by Euclidean projection onto the scaled feasible
set (box intersected with the half-spaces ``A x <= b``), computed with
``optax.projections`` (box and half-space projections combined by Dykstra's
algorithm, exact for one active constraint and convergent in general).
"""

from __future__ import annotations

import abc
import copy
import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import optax
from jaxtyping import Array, ArrayLike, Bool, Float

from jaxcrank.physics.linkage import AbstractMechanism as Mechanism
from jaxcrank.physics.parameters import get_parameter
from jaxcrank.physics.params import ParameterError

from .ensemble import Ensemble
from .objective import AbstractObjective, value_and_grad


@dataclasses.dataclass(frozen=True)
class AbstractProblem(abc.ABC):
    """A design problem ``min F(x) + cost(x)`` s.t. ``lower <= x <= upper``, ``A x <= b``.

    Attributes:
        base: the mechanism every design starts from (fixed parameters).
        names: design variable names.
        lower: lower bounds, SI units of each variable, shape (n,).
        upper: upper bounds, SI units of each variable, shape (n,).
        A: matrix of the linear inequality constraints ``A x <= b`` (SI), shape (m, n).
        b: right-hand side of ``A x <= b`` (SI), shape (m,).
        start: start design, SI (default: the subclass's default start projected onto the set).
        objective: how the mechanism is measured (an [`optim.objective.AbstractObjective`][]).
        cost_weight: weight of the manufacturing-cost term, degrees (0: none).
        cost_reference: reference clearance of the cost term, m.
        title: a short description for plots and reports (see [`description`][optim.problem.AbstractProblem.description]
            ).
        base_key: ``base`` as a hashable value ([`mechanism_key`][optim.problem.mechanism_key]; a mechanism's
            joints are a dict), set on construction; problems compare and hash by it.

    Raises:
        ParameterError: on construction, for inconsistent sizes, empty bounds, a start outside
            its bounds, an unknown variable, a negative cost weight or one without clearance
            variables.
    """

    base: Mechanism = dataclasses.field(compare=False)
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
    base_key: tuple = dataclasses.field(default=(), init=False, repr=False)

    def __post_init__(self):
        object.__setattr__(self, "base_key", mechanism_key(self.base))
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
            raise ParameterError("cost_weight > 0 needs a clearance variable (clearance_<joint>) among the variables")
        if self.start is not None and len(self.start) != n:
            raise ParameterError(f"start needs {n} values")
        for name, lo, hi, s in zip(self.names, self.lower, self.upper, self.start or [None] * n):
            if s is not None and not lo <= s <= hi:
                raise ParameterError(
                    f"start of {name!r}: {s:g} is outside its bounds [lower, upper] = [{lo:g}, {hi:g}]"
                )
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

    def scaled_constraints(self) -> tuple[np.ndarray, np.ndarray]:
        """The linear constraints on the scaled design, ``A_u u <= b_u``: (m, n) and (m,),
        dimensionless (``A_u = A diag(upper - lower)``, ``b_u = b - A lower``)."""
        a = np.asarray(self.A, dtype=float).reshape(len(self.A), self.n)
        lo = np.asarray(self.lower, dtype=float)
        return a * (np.asarray(self.upper, dtype=float) - lo), np.asarray(self.b, dtype=float) - a @ lo

    def feasible_set(self) -> FeasibleSet:
        """The scaled feasible set, ``[0, 1]^n`` intersected with ``A_u u <= b_u``."""
        return FeasibleSet(*self.scaled_constraints())

    def project(self, u: Float[ArrayLike, " n"], iterations: int = 100) -> Float[Array, " n"]:
        """Euclidean projection of the scaled design ``u`` onto the scaled feasible set."""
        u = jnp.asarray(u, dtype=float)
        if not self.A:
            return optax.projections.projection_box(u, 0.0, 1.0)
        lo, span = jnp.asarray(self.lower), self.span
        rows = [(jnp.asarray(r) * span, bnd - jnp.dot(jnp.asarray(r), lo)) for r, bnd in zip(self.A, self.b)]
        return project_polyhedron(u, rows, iterations)

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


def mechanism_key(mech: Mechanism) -> tuple:
    """A hashable, picklable value that identifies a mechanism: its tree structure (as text:
    kinds, laws, names) and its leaves' dtypes, shapes and bytes."""
    leaves, treedef = jax.tree.flatten(mech)
    return str(treedef), tuple((np.asarray(v).dtype.str, np.shape(v), np.asarray(v).tobytes()) for v in leaves)


def _base_leaves(problem) -> tuple[list, object]:
    """The leaves and tree structure of ``problem``'s base with its nonzero numbers as arrays
    ([`jaxcrank.numerics.solve.as_values`][])."""
    from jaxcrank.numerics.solve import as_values

    return jax.tree.flatten(as_values(problem.base))


def _derived_values(problem) -> tuple[str, ...]:
    """The derived group's fields that are traceable numbers (its class's ``VALUES``; none by default)."""
    return tuple(getattr(getattr(problem, "derived", None), "VALUES", ()))


def problem_values(problem: AbstractProblem) -> tuple:
    """The numbers of ``problem`` that its compiled programs can take as inputs instead of
    constants: the base mechanism's nonzero numbers (in leaf order,
    [`jaxcrank.numerics.solve.as_values`][]) and its derived group's ``VALUES`` fields (float64
    arrays). Problems that differ only in them have the same [`values_key`][optim.problem.values_key]."""
    leaves, _ = _base_leaves(problem)
    derived = getattr(problem, "derived", None)
    return (
        [v for v in leaves if isinstance(v, jax.Array)],
        [jnp.asarray(getattr(derived, f), dtype=float) for f in _derived_values(problem)],
    )


def with_values(problem: AbstractProblem, values) -> AbstractProblem:
    """``problem`` with the numbers of [`problem_values`][optim.problem.problem_values] replaced by
    ``values`` (traceable: a compiled program's inputs), without the construction's checks."""
    base_values, derived_values = values
    leaves, treedef = _base_leaves(problem)
    it = iter(base_values)
    base = jax.tree.unflatten(treedef, [next(it) if isinstance(v, jax.Array) else v for v in leaves])
    out = copy.copy(problem)
    object.__setattr__(out, "base", base)
    names = _derived_values(problem)
    if names:
        derived = dataclasses.replace(problem.derived, **dict(zip(names, derived_values)))
        object.__setattr__(out, "derived", derived)
    return out


def values_key(problem: AbstractProblem) -> tuple:
    """A hashable, picklable value equal for problems that differ only in the numbers
    [`problem_values`][optim.problem.problem_values] lists: the problem without them (the base's
    tree structure, its values' shapes, its zeros and other leaves, the derived group without its ``VALUES``) and
    without its start, title and variables' bounds and linear constraints, which no traced method
    of a problem reads (a program takes the design itself)."""
    leaves, treedef = _base_leaves(problem)

    def leaf(v):  # a value's shape and dtype (the program's input), any other leaf itself
        return ("value", v.shape, str(v.dtype)) if isinstance(v, jax.Array) else (type(v).__name__, repr(v))

    base = (str(treedef), tuple(leaf(v) for v in leaves))
    skip = {"base", "base_key", "start", "derived", "title", "lower", "upper", "A", "b"}
    fields = tuple((f.name, getattr(problem, f.name)) for f in dataclasses.fields(problem) if f.name not in skip)
    derived = getattr(problem, "derived", None)
    if derived is not None:
        derived = dataclasses.replace(derived, **{f: None for f in _derived_values(problem)})
    return type(problem).__name__, base, fields, derived


def known_parameter(base: Mechanism, name: str) -> None:
    """Raise ParameterError (``unknown design variable ...``, with the reason) unless ``name``
    is a numeric parameter of ``base`` ([`jaxcrank.physics.parameters.get_parameter`][])."""
    try:
        get_parameter(base, name)
    except ParameterError as err:
        raise ParameterError(f"unknown design variable {name!r}: {err}") from None


def project_polyhedron(u: Float[ArrayLike, " n"], rows, iterations: int = 100) -> Float[Array, " n"]:
    """Euclidean projection of ``u`` (n,) onto the unit box intersected with the
    half-spaces ``a . u <= c`` of ``rows`` (a sequence of ``(a (n,), c)``): the box and
    half-space projections of ``optax.projections`` combined by Dykstra's alternating
    projections with corrections, ``iterations`` sweeps (the result is the last
    half-space's projection; exact for one active half-space). Traceable."""
    box = lambda v: optax.projections.projection_box(v, 0.0, 1.0)
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


@jax.jit
def _project_jit(u, a, c):
    return project_polyhedron(u, list(zip(a, c))) if a.shape[0] else optax.projections.projection_box(u, 0.0, 1.0)


@dataclasses.dataclass(frozen=True, eq=False)
class FeasibleSet:
    """A scaled feasible set: the unit box ``[0, 1]^n`` intersected with the half-spaces
    ``A u <= b`` (dimensionless), with its projection and its constraints as rows, for
    optimisers that need the constraints' normals ([`optim.quasi_newton`][]).

    Attributes:
        A: half-space normals, (m, n) (m = 0: the box alone).
        b: half-space bounds, (m,).
    """

    A: np.ndarray
    b: np.ndarray

    @property
    def n(self) -> int:
        """Number of variables."""
        return int(np.shape(self.A)[1])

    def project(self, u: Float[ArrayLike, " n"]) -> np.ndarray:
        """Euclidean projection of ``u`` onto the set ([`project_polyhedron`][optim.problem.project_polyhedron],
        compiled once per shape), numpy float64."""
        return np.asarray(_project_jit(jnp.asarray(u, dtype=float), jnp.asarray(self.A), jnp.asarray(self.b)))

    def rows(self) -> tuple[np.ndarray, np.ndarray]:
        """Every constraint as a row of ``G u <= h``: ``u_i <= 1``, then ``-u_i <= 0``, then ``A u <= b``;
        shapes (2n + m, n) and (2n + m,)."""
        eye = np.eye(self.n)
        g = np.concatenate([eye, -eye, np.asarray(self.A, dtype=float)])
        return g, np.concatenate([np.ones(self.n), np.zeros(self.n), np.asarray(self.b, dtype=float)])
