"""Problem files: a design problem as a TOML file, read into a [`optim.design.DesignProblem`][].

A file names any mechanism (a preset or a written-out linkage), any of its parameters as
variables, derived geometric variables (a link's length, [`optim.geometry.Length`][]; a derived
group, ``[derived]``, [`optim.geometry`][]), an objective that is a weighted sum of any
quantities by their ``summary.json`` names ([`optim.quantities`][]) with an optional statistic
over manufactured parts (``[scatter]``), and constraints that bound any quantity (held by the
augmented Lagrangian of [`optim.constrained`][], with their exact gradients) or combine the
variables linearly (held exactly by the projection). The preset problems are such files
([`optim.presets`][]). [`load`][optim.spec.load] reads one; the docs page "Design your own
mechanism" describes the format, with an example a test runs as printed.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from pathlib import Path

from jaxcrank import config as mech_config
from jaxcrank.physics.params import ParameterError
from jaxcrank.physics.presets import preset

from .design import DesignProblem
from .geometry import CrankRocker, Length, SliderCrankStroke
from .objective_config import objective_from_config
from .steady import STEADY_OBJECTIVE, Steady

#: the tables of a problem file
TABLES = (
    "title",
    "mechanism",
    "variables",
    "derived",
    "objective",
    "scatter",
    "constraints",
    "solver",
    "optimizer",
    "pareto",
    "life",
)


@dataclasses.dataclass(frozen=True)
class LifeSpec:
    """A problem file's ``[life]`` table: measure the quantities after ``cycles`` crank revolutions
    of wear ([`optim.life_design`][]).

    Attributes:
        cycles: crank revolutions of wear before the quantities are read, > 0.
        rtol: the life run's step error relative to the deepest wear, > 0
            ([`jaxcrank.analysis.life.LifeOptions`][]); the first design's steps serve every design.
        wear: joints made worn (new, the default Archard law) before the variables are read; a
            joint whose law is ``"worn"`` in the mechanism wears as it is given.
        average_revolutions: where a point's motion is not periodic, the revolutions its wear is
            averaged over, >= 2.
        start_from_new: design for a new clearance first (the steady state: cheap) and for life
            from that design ([`optim.life_design.solve_for_life`][]); False: for life from the start.

    Raises:
        ParameterError: naming the key, for a value out of its range.
    """

    cycles: float
    rtol: float = 0.05
    wear: tuple[str, ...] = ()
    average_revolutions: int = 10
    start_from_new: bool = True

    def __post_init__(self):
        if not (math.isfinite(self.cycles) and self.cycles > 0):
            raise ParameterError(f"[life] cycles = {self.cycles!r} must be a finite number > 0 (crank revolutions)")
        if not (math.isfinite(self.rtol) and self.rtol > 0):
            raise ParameterError(f"[life] rtol = {self.rtol!r} must be a finite number > 0")
        if not (isinstance(self.average_revolutions, int) and self.average_revolutions >= 2):
            raise ParameterError(f"[life] average_revolutions = {self.average_revolutions!r} must be an integer >= 2")
        if not isinstance(self.start_from_new, bool):
            raise ParameterError(f"[life] start_from_new = {self.start_from_new!r} must be true or false")


def _life(table) -> LifeSpec:
    """The ``[life]`` table as a [`LifeSpec`][optim.spec.LifeSpec]."""
    if not isinstance(table, dict):
        raise ParameterError("[life] must be a table with cycles (and rtol, wear, average_revolutions)")
    _keys("[life]", table, {"cycles", "rtol", "wear", "average_revolutions", "start_from_new"})
    if "cycles" not in table:
        raise ParameterError("[life]: cycles is missing (crank revolutions of wear)")
    wear = table.get("wear", [])
    if not (isinstance(wear, list) and all(isinstance(j, str) for j in wear)):
        raise ParameterError(f"[life] wear = {wear!r} must be a list of joint names")
    spec = LifeSpec(
        cycles=_number("[life]", "cycles", table["cycles"]),
        rtol=_number("[life]", "rtol", table.get("rtol", LifeSpec.rtol)),
        wear=tuple(wear),
        average_revolutions=table.get("average_revolutions", LifeSpec.average_revolutions),
        start_from_new=table.get("start_from_new", LifeSpec.start_from_new),
    )
    return spec


# ---------------------------------------------------------------------------------------- the file


def mechanism_section(section: dict, folder: Path, wear=()):
    """The ``[mechanism]`` table's mechanism (``preset = NAME``, ``file = PATH`` relative to
    ``folder``, or the mechanism written out; the table's other keys change the preset or file);
    the joints in ``wear`` made worn before the table's settings apply to the preset or file (so
    that they can set the wear law's values).

    Raises:
        ParameterError: both preset and file, an empty table, or a bad mechanism (the message
            names it)."""
    from jaxcrank.numerics.wear_run import with_wear

    section = dict(section)
    if "preset" in section and "file" in section:
        raise ParameterError("[mechanism]: give preset or file, not both")
    if "preset" in section or "file" in section:
        if "preset" in section:
            base = preset(section.pop("preset"))
        else:
            base = mech_config.load(folder / section.pop("file"))
        base = with_wear(base, wear, where="[life] wear")
        return mech_config.from_dict(section, base) if section else base
    if not section:
        raise ParameterError(
            '[mechanism]: name a preset (preset = "paper"), a file (file = "my_linkage.toml") or '
            "write the mechanism out in the table"
        )
    return with_wear(mech_config.from_dict(section), wear, where="[life] wear")


def _number(where: str, key: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ParameterError(f"{where}: {key} = {value!r} must be a finite number")
    return float(value)


def _keys(where: str, table: dict, valid: set) -> None:
    bad = set(table) - valid
    if bad:
        raise ParameterError(f"{where}: unknown keys {sorted(bad)}; valid: {sorted(valid)}")


def from_dict(data: dict, folder: Path = Path(".")) -> tuple[DesignProblem, dict]:
    """The problem of a problem file's tables, and its run's tables: ``optimizer`` (the file's
    ``[optimizer]``), ``pareto`` (its ``[pareto]``, None without one) and ``life`` (its
    ``[life]`` as a [`LifeSpec`][optim.spec.LifeSpec], None without one).

    Args:
        data: the file's tables (`TABLES`: ``title``, ``[mechanism]``, ``[variables]``,
            ``[derived]``, ``[objective]``, ``[scatter]``, ``[[constraints]]``, ``[solver]``,
            ``[optimizer]``, ``[pareto]``, ``[life]``).
        folder: where a ``[mechanism] file`` is looked for (the problem file's folder).

    Raises:
        ParameterError: naming the table and key, for anything missing, unknown or out of range.
    """
    _keys("problem file", data, set(TABLES))
    for need in ("mechanism", "variables", "objective"):
        if need not in data:
            raise ParameterError(f"problem file: the [{need}] table is missing")
    life = _life(data["life"]) if "life" in data else None
    base = mechanism_section(data["mechanism"], folder, life.wear if life is not None else ())
    if life is not None:
        from jaxcrank.numerics.wear_run import worn_joints

        if not worn_joints(base):
            raise ParameterError(
                '[life]: the mechanism has no worn joint: name clearance joints in [life] wear = ["B"], or give a '
                'joint law = "worn"'
            )
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
    limits, rows, bounds = [], [], []
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
        limits.append((str(c["quantity"]), lo, hi, scale))
    solver = {"method": "steady_state", **data.get("solver", {})}
    objective_kind = objective_from_config(solver) if data.get("solver") else Steady(options=STEADY_OBJECTIVE)
    scatter = dict(data.get("scatter", {}))
    _keys("[scatter]", scatter, {"parts", "samples", "seed", "statistic"})
    problem = DesignProblem(
        base=base,
        names=tuple(names),
        lower=tuple(lower),
        upper=tuple(upper),
        A=tuple(rows),
        b=tuple(bounds),
        start=None,
        objective=objective_kind,
        cost_weight=_number("[objective]", "cost_weight", objective.get("cost_weight", 0.0)),
        cost_reference=_number("[objective]", "cost_reference", objective.get("cost_reference", 5e-4)),
        title=str(data.get("title", "")),
        terms=tuple(terms),
        limits=tuple(limits),
        lengths=tuple(lengths),
        derived=derived_from_table(data["derived"]) if "derived" in data else None,
        scatter=tuple((str(n), float(t), str(d)) for n, t, d in scatter.get("parts", [])),
        samples=int(scatter.get("samples", 0)),
        seed=int(scatter.get("seed", 0)),
        statistic=str(scatter.get("statistic", "mean")),
    )
    if any(v is not None for v in start):  # the others at their defaults
        filled = [d if v is None else v for v, d in zip(start, problem.default_start())]
        problem = dataclasses.replace(problem, start=tuple(filled))
    if life is not None and (data.get("pareto") is not None or not isinstance(objective_kind, Steady)):
        raise ParameterError("[life] takes the steady-state objective and no [pareto] table")
    return problem, {"optimizer": dict(data.get("optimizer", {})), "pareto": data.get("pareto"), "life": life}


def load(path) -> tuple[DesignProblem, dict]:
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


#: the derived groups by the ``kind`` of a problem file's ``[derived]`` table
DERIVED = {SliderCrankStroke.kind: SliderCrankStroke, CrankRocker.kind: CrankRocker}


def derived_from_table(table: dict):
    """The derived group of a ``[derived]`` table (``kind`` and the group's fields).

    Raises:
        ParameterError: an unknown kind or key."""
    values = dict(table)
    kind = values.pop("kind", None)
    if kind not in DERIVED:
        raise ParameterError(f"[derived] kind = {kind!r} is unknown; valid: {', '.join(DERIVED)}")
    cls = DERIVED[kind]
    valid = {f.name for f in dataclasses.fields(cls)}
    bad = set(values) - valid
    if bad:
        raise ParameterError(f"[derived] unknown keys {sorted(bad)} for kind {kind!r}; valid: kind, {sorted(valid)}")
    return cls(**values)


def derived_table(group) -> dict:
    """The ``[derived]`` table of a group ([`derived_from_table`][optim.spec.derived_from_table] reads it)."""
    return {"kind": group.kind, **{f.name: getattr(group, f.name) for f in dataclasses.fields(group)}}
