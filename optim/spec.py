"""A design problem as data: a TOML problem file, and the same problem as a Python object.

A [`FileProblem`][optim.spec.FileProblem] is any mechanism (a preset or a written-out
linkage), any of its parameters as variables, derived geometric variables (a link's
length, `Length`), an objective that is a weighted sum of any quantities by their
``summary.json`` names ([`optim.quantities`][]), and constraints that bound any quantity
(held by the augmented Lagrangian of [`optim.constrained`][], with their exact gradients)
or combine the variables linearly (held exactly by the projection). It is measured over
one period of the steady-state orbit ([`optim.steady.Steady`][]).

[`load`][optim.spec.load] reads a problem file; the docs page "Design your own mechanism"
describes the format, with an example a test runs as printed.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from pathlib import Path

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from jaxcrank import config as mech_config
from jaxcrank.physics.linkage import GROUND, Linkage
from jaxcrank.physics.parameters import get_parameter, set_parameters
from jaxcrank.physics.params import ParameterError
from jaxcrank.physics.presets import preset

from . import quantities as Q
from .objective_config import objective_from_config
from .problem import AbstractProblem, known_parameter
from .steady import STEADY_OBJECTIVE, Steady

#: how a length variable carries its body's mass properties along
CARRY = {
    "keep": "mass, centre of mass and inertia unchanged",
    "scale": "a bar of constant section: the centre of mass moves with the length, mass x r, inertia x r^3",
    "uniform_bar": "the centre of mass at the middle of the two points, inertia = mass x length^2 / 12",
}


@dataclasses.dataclass(frozen=True)
class Length:
    """A derived variable: the distance between two points of one body, m. Setting it moves
    ``to`` along the line from ``start`` (the attachment point slides along the body) and
    carries the body's mass properties by the rule ``carry`` (`CARRY`).

    Attributes:
        name: the variable's name.
        body: the body (``"ground"`` for two ground points: the frame's length, ``carry`` ignored).
        start: the point that stays, a point name of the body.
        to: the point that moves.
        carry: ``"keep"``, ``"scale"`` or ``"uniform_bar"``.
    """

    name: str
    body: str
    start: str
    to: str
    carry: str = "keep"

    def points(self, lk: Linkage) -> dict:
        return lk.ground if self.body == GROUND else lk.bodies[self.body].points

    def check(self, base) -> None:
        if not isinstance(base, Linkage):
            raise ParameterError(
                f"variable {self.name!r}: a length variable needs a written-out linkage (mechanism = "
                f'"linkage"); a preset has its lengths as parameters (<link>_length)'
            )
        if self.body != GROUND and self.body not in base.bodies:
            raise ParameterError(f"variable {self.name!r}: unknown body {self.body!r}; bodies: {sorted(base.bodies)}")
        pts = self.points(base)
        for p in (self.start, self.to):
            if p not in pts:
                raise ParameterError(
                    f"variable {self.name!r}: body {self.body!r} has no point {p!r}; its points: {sorted(pts)}"
                )
        if self.carry not in CARRY:
            raise ParameterError(f"variable {self.name!r}: carry = {self.carry!r} is unknown; valid: {list(CARRY)}")
        if self.base_length(base) <= 0.0:
            raise ParameterError(f"variable {self.name!r}: points {self.start} and {self.to} coincide")

    def base_length(self, base: Linkage) -> float:
        pts = self.points(base)
        a, b = pts[self.start], pts[self.to]
        return math.hypot(float(b.x) - float(a.x), float(b.y) - float(a.y))

    def apply(self, base: Linkage, mech: Linkage, length) -> tuple[list[str], list]:
        """The parameter names and values (traceable) that set this length on ``mech``."""
        prefix = GROUND if self.body == GROUND else f"bodies.{self.body}"
        pts = self.points(mech)
        a, b = pts[self.start], pts[self.to]
        r = length / self.base_length(base)
        names = [f"{prefix}.points.{self.to}.x", f"{prefix}.points.{self.to}.y"]
        if self.body == GROUND:
            names = [f"{GROUND}.{self.to}.x", f"{GROUND}.{self.to}.y"]
        bx, by = a.x + (b.x - a.x) * r, a.y + (b.y - a.y) * r
        values = [bx, by]
        if self.body == GROUND or self.carry == "keep":
            return names, values
        body = mech.bodies[self.body]
        com = body.centre_of_mass
        names += [f"{prefix}.centre_of_mass.x", f"{prefix}.centre_of_mass.y", f"{prefix}.inertia"]
        if self.carry == "scale":
            names.append(f"{prefix}.mass")
            com_x, com_y = a.x + (com.x - a.x) * r, a.y + (com.y - a.y) * r
            return names, values + [com_x, com_y, body.inertia * r**3, body.mass * r]
        return names, values + [0.5 * (a.x + bx), 0.5 * (a.y + by), body.mass * length**2 / 12.0]


@dataclasses.dataclass(frozen=True)
class FileProblem(AbstractProblem):
    """A design problem described as data (module docstring).

    Attributes (besides [`AbstractProblem`][optim.problem.AbstractProblem]'s):
        lengths: the derived length variables ([`Length`][optim.spec.Length]), named among ``names``.
        terms: the objective, ``(quantity, weight)`` pairs: minimise ``sum weight x value``
            (the weight in objective units per unit of the quantity; negative to maximise).
        constraints: ``(quantity, lower, upper, scale)``: ``lower <= value <= upper`` (None: no
            bound) in the quantity's unit; ``scale`` its typical size, by which violations are
            measured (None: the largest |bound|).
        kinematic_samples: driver angles per revolution of the kinematic quantities.

    Raises:
        ParameterError: on construction, for an unknown quantity, an empty objective, bounds
            in the wrong order, a bad length variable or an objective that is not the steady state.
    """

    lengths: tuple[Length, ...] = ()
    terms: tuple[tuple[str, float], ...] = ()
    constraints: tuple[tuple[str, float | None, float | None, float | None], ...] = ()
    kinematic_samples: int = 720

    def check_variable(self, name: str) -> None:
        if name not in {v.name for v in self.lengths}:
            known_parameter(self.base, name)

    def check(self) -> None:
        if not isinstance(self.objective, Steady):
            raise ParameterError(
                "a problem file's solver must be the steady state (method = 'steady_state'): its constraints and "
                "terms are measured over the periodic orbit"
            )
        for v in self.lengths:
            v.check(self.base)
            if v.name not in self.names:
                raise ParameterError(f"length variable {v.name!r} is not among the variables {list(self.names)}")
        if not self.terms:
            raise ParameterError("[objective] needs at least one term: terms = [{quantity = ..., weight = ...}]")
        for q, w in self.terms:
            Q.check_quantity(self.base, q, "[objective] term")
            if not math.isfinite(w) or w == 0.0:
                raise ParameterError(f"[objective] term {q!r}: weight = {w!r} must be a finite nonzero number")
        for q, lo, hi, scale in self.constraints:
            Q.check_quantity(self.base, q, "[[constraints]]")
            if lo is None and hi is None:
                raise ParameterError(f"constraint on {q!r}: give lower, upper or both")
            if lo is not None and hi is not None and not lo < hi:
                raise ParameterError(f"constraint on {q!r}: lower = {lo:g} must be below upper = {hi:g}")
            if scale is not None and not scale > 0:
                raise ParameterError(f"constraint on {q!r}: scale = {scale:g} must be > 0")

    @property
    def description(self) -> str:
        """``title``, or the objective's terms and the number of constraints."""
        return self.title or (
            "minimise " + " + ".join(f"{w:g} x {q}" for q, w in self.terms) + f" ({len(self.constraints)} constraints)"
        )

    def feasible(self, x, tol=1e-12):
        """Bounds and linear constraints (the constraints on quantities are the evaluator's)."""
        return self.box_feasible(x, tol)

    def physical(self, x) -> tuple[tuple[str, ...], Float[Array, " p"]]:
        """Mechanism parameter names and their values (SI, traceable) at design ``x``: the
        direct variables, then what each length variable sets."""
        x = jnp.asarray(x, dtype=float)
        derived = {v.name: v for v in self.lengths}
        names = [nm for nm in self.names if nm not in derived]
        values = [x[self.names.index(nm)] for nm in names]
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
        return [lengths[nm] if nm in lengths else float(get_parameter(self.base, nm)) for nm in self.names]

    @property
    def quantities(self) -> tuple[str, ...]:
        """The quantities the problem reads: the terms', then the constraints' (in file order)."""
        return tuple(q for q, _ in self.terms) + tuple(c[0] for c in self.constraints)

    def outputs(self, metrics: dict, x: Float[ArrayLike, " n"]) -> Float[Array, " k"]:
        """The problem's outputs at SI design ``x`` given the headline ``metrics`` of its steady
        state (traceable): the terms' quantities, the cost term, then the constraints'
        quantities (order of [`quantities`][optim.spec.FileProblem.quantities], the cost after the terms)."""
        kin = Q.kinematic_values(
            self.mechanism(x), sorted({q for q in self.quantities if q in Q.KINEMATICS}), self.kinematic_samples
        )
        pick = lambda q: kin[q] if q in kin else jnp.asarray(metrics[q], dtype=float)
        terms = [pick(q) for q, _ in self.terms]
        return jnp.stack(terms + [self.cost(jnp.asarray(x, dtype=float))] + [pick(c[0]) for c in self.constraints])

    def split(self, outputs) -> tuple[np.ndarray, float, np.ndarray]:
        """(terms' values, cost, constraints' values) of an ``outputs`` vector (numpy)."""
        v = np.asarray(outputs, dtype=float)
        n = len(self.terms)
        return v[:n], float(v[n]), v[n + 1 :]

    def loss(self, rms: dict) -> Float[Array, ""]:
        return sum(w * rms[q] for q, w in self.terms)

    def objective_value(self, x) -> Float[Array, ""]:
        """The weighted terms + cost at a concrete SI design (a steady-state solve; constraints not included)."""
        out = self.outputs(self.objective.rms_at(self.mechanism(x), self.objective.solve(self.mechanism(x)), True), x)
        w = jnp.asarray([w for _, w in self.terms])
        return jnp.dot(w, out[: len(self.terms)]) + out[len(self.terms)]


# ---------------------------------------------------------------------------------------- the file


def _mechanism(section: dict, folder: Path):
    section = dict(section)
    if "preset" in section and "file" in section:
        raise ParameterError("[mechanism]: give preset or file, not both")
    if "preset" in section:
        base = preset(section.pop("preset"))
        return mech_config.from_dict(section, base) if section else base
    if "file" in section:
        base = mech_config.load(folder / section.pop("file"))
        return mech_config.from_dict(section, base) if section else base
    if not section:
        raise ParameterError(
            '[mechanism]: name a preset (preset = "paper"), a file (file = "my_linkage.toml") or '
            "write the mechanism out in the table"
        )
    return mech_config.from_dict(section)


def _number(where: str, key: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ParameterError(f"{where}: {key} = {value!r} must be a finite number")
    return float(value)


def _keys(where: str, table: dict, valid: set) -> None:
    bad = set(table) - valid
    if bad:
        raise ParameterError(f"{where}: unknown keys {sorted(bad)}; valid: {sorted(valid)}")


def from_dict(data: dict, folder: Path = Path(".")) -> tuple[FileProblem, dict]:
    """The problem of a problem file's tables, and its run's tables (plain values): ``optimizer``
    (the file's ``[optimizer]``) and ``pareto`` (its ``[pareto]``, None without one).

    Args:
        data: the file's tables (``title``, ``[mechanism]``, ``[variables]``, ``[objective]``,
            ``[[constraints]]``, ``[solver]``, ``[optimizer]``, ``[pareto]``).
        folder: where a ``[mechanism] file`` is looked for (the problem file's folder).

    Raises:
        ParameterError: naming the table and key, for anything missing, unknown or out of range.
    """
    _keys(
        "problem file",
        data,
        {"title", "mechanism", "variables", "objective", "constraints", "solver", "optimizer", "pareto"},
    )
    for need in ("mechanism", "variables", "objective"):
        if need not in data:
            raise ParameterError(f"problem file: the [{need}] table is missing")
    base = _mechanism(data["mechanism"], folder)
    names, lower, upper, start, lengths = [], [], [], [], []
    for name, table in data["variables"].items():
        where = f"[variables.{name}]"
        if not isinstance(table, dict):
            raise ParameterError(f"{where}: must be a table with lower and upper")
        _keys(where, table, {"lower", "upper", "start", "kind", "body", "from", "to", "carry"})
        for key in ("lower", "upper"):
            if key not in table:
                raise ParameterError(f"{where}: {key} is missing")
        kind = table.get("kind", "parameter")
        if kind == "length":
            for key in ("body", "from", "to"):
                if key not in table:
                    raise ParameterError(f"{where}: a length variable needs body, from and to")
            lengths.append(Length(name, table["body"], table["from"], table["to"], table.get("carry", "keep")))
        elif kind != "parameter":
            raise ParameterError(f"{where}: kind = {kind!r} is unknown; valid: 'parameter', 'length'")
        names.append(name)
        lower.append(_number(where, "lower", table["lower"]))
        upper.append(_number(where, "upper", table["upper"]))
        start.append(_number(where, "start", table["start"]) if "start" in table else None)
    objective = dict(data["objective"])
    _keys("[objective]", objective, {"terms", "cost_weight", "cost_reference"})
    terms = []
    for i, term in enumerate(objective.get("terms", [])):
        where = f"[objective] terms[{i}]"
        if not isinstance(term, dict) or "quantity" not in term:
            raise ParameterError(f"{where}: must be a table {{quantity = ..., weight = ...}}")
        _keys(where, term, {"quantity", "weight"})
        terms.append((str(term["quantity"]), _number(where, "weight", term.get("weight", 1.0))))
    constraints, rows, bounds = [], [], []
    for i, c in enumerate(data.get("constraints", [])):
        where = f"[[constraints]] {i + 1}"
        _keys(where, c, {"quantity", "linear", "lower", "upper", "scale"})
        lo = _number(where, "lower", c["lower"]) if "lower" in c else None
        hi = _number(where, "upper", c["upper"]) if "upper" in c else None
        if ("quantity" in c) == ("linear" in c):
            raise ParameterError(f"{where}: give quantity (a bound on a quantity) or linear (on the variables)")
        if "linear" in c:
            coef = c["linear"]
            bad = set(coef) - set(names)
            if bad:
                raise ParameterError(f"{where}: linear names {sorted(bad)}, not variables; variables: {names}")
            row = [_number(where, f"linear.{n}", coef.get(n, 0.0)) for n in names]
            if hi is not None:
                rows.append(tuple(row)), bounds.append(hi)
            if lo is not None:
                rows.append(tuple(-v for v in row)), bounds.append(-lo)
            if lo is None and hi is None:
                raise ParameterError(f"{where}: give lower, upper or both")
            continue
        scale = _number(where, "scale", c["scale"]) if "scale" in c else None
        constraints.append((str(c["quantity"]), lo, hi, scale))
    solver = {"method": "steady_state", **data.get("solver", {})}
    objective_kind = objective_from_config(solver) if data.get("solver") else Steady(options=STEADY_OBJECTIVE)
    if any(s is None for s in start):
        defaults = FileProblem(
            base=base,
            names=tuple(names),
            lower=tuple(lower),
            upper=tuple(upper),
            lengths=tuple(lengths),
            terms=tuple(terms),
            objective=objective_kind,
        ).default_start()
        start = [d if s is None else s for s, d in zip(start, defaults)]
    problem = FileProblem(
        base=base,
        names=tuple(names),
        lower=tuple(lower),
        upper=tuple(upper),
        A=tuple(rows),
        b=tuple(bounds),
        start=tuple(start),
        objective=objective_kind,
        cost_weight=_number("[objective]", "cost_weight", objective.get("cost_weight", 0.0)),
        cost_reference=_number("[objective]", "cost_reference", objective.get("cost_reference", 5e-4)),
        title=str(data.get("title", "")),
        lengths=tuple(lengths),
        terms=tuple(terms),
        constraints=tuple(constraints),
    )
    return problem, {"optimizer": dict(data.get("optimizer", {})), "pareto": data.get("pareto")}


def load(path) -> tuple[FileProblem, dict]:
    """Read a problem file (TOML): the problem and its run's tables (``optimizer``, ``pareto``).

    Raises:
        ParameterError: naming the file: malformed TOML or a bad problem (from [`from_dict`][optim.spec.from_dict])."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as err:
        raise ParameterError(f"{path}: malformed TOML: {err}") from None
    except OSError as err:
        raise ParameterError(f"problem file {path}: {err.strerror}") from None
    try:
        return from_dict(data, path.parent)
    except ParameterError as err:
        raise ParameterError(f"{path}: {err}") from None
