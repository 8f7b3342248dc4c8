"""The preset problems: problem files in the package (``optim/problems/*.toml``, the format of
[`optim.spec`][]), by name. The registry is the files: ``jaxcrank optimize --problem NAME`` and
[`problem`][optim.presets.problem] read ``NAME.toml``. The functions below load a preset with the
keyword changes the library's callers use (another objective, start, weights, variables).

| name | the file |
|---|---|
| ``paper`` | the paper's Eq. 19 over L1 and L2 with ``L2 >= L1 + e``, the ensemble-gradient objective |
| ``tolerance`` | the clearances at B and C, Eq. 19 plus the reciprocal clearance cost |
| ``robust`` | the paper's problem, the mean of Eq. 19 over 8 manufactured parts |
| ``design`` | nine variables on the slider-crank, the stroke held by its derived group, steady state |
| ``four-bar`` | the four-bar's link lengths under Grashof's condition and the transmission bound |
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from importlib import resources

from jaxcrank import reference
from jaxcrank.physics.parameters import set_parameters
from jaxcrank.physics.params import ParameterError

from .design import TERMS, DesignProblem
from .objective import EQ19, AbstractObjective
from .spec import from_dict

#: the paper's optimum of Eq. 19 (deg) and its reduction from the start design (%)
PAPER_OPTIMUM_DEG = reference.value("optimisation", "optimum_deg")
PAPER_REDUCTION_PCT = reference.value("optimisation", "reduction_percent")

#: the preset problems: name -> the problem file in the package
PROBLEMS = {name: f"{name}.toml" for name in ("paper", "tolerance", "robust", "design", "four-bar")}


def problem(name: str) -> DesignProblem:
    """The preset problem ``name`` (`PROBLEMS`), read from its file in the package.

    Raises:
        ParameterError: an unknown name (the message lists the presets)."""
    import tomllib

    if name not in PROBLEMS:
        raise ParameterError(f"problem {name!r} is unknown; valid: {', '.join(PROBLEMS)}, or a problem file (.toml)")
    text = resources.files("optim").joinpath("problems", PROBLEMS[name]).read_text()
    return from_dict(tomllib.loads(text))[0]


def problem_text(name: str) -> str:
    """The problem file of the preset ``name``, as text."""
    problem(name)  # checks the name
    return resources.files("optim").joinpath("problems", PROBLEMS[name]).read_text()


def _with(p: DesignProblem, objective=None, start=None, **changes) -> DesignProblem:
    if objective is not None:
        changes["objective"] = objective
    if start is not None:
        changes["start"] = tuple(start)
    return dataclasses.replace(p, **changes) if changes else p


def paper_problem(objective: AbstractObjective | None = None, start: Sequence[float] | None = None) -> DesignProblem:
    """The ``paper`` preset: Eq. 19 over L1 in [110, 130] mm and L2 in [390, 410] mm with
    ``L2 >= L1 + e`` (e the preset's 50 mm), from the box centre; ``objective`` default the
    file's (the ensemble gradient over the paper's window)."""
    return _with(problem("paper"), objective, start)


def tolerance_problem(
    objective: AbstractObjective | None = None, cost_weight: float = 0.005, start: Sequence[float] | None = None
) -> DesignProblem:
    """The ``tolerance`` preset: the clearances at B and C in [0.1, 0.5] mm, Eq. 19 + the
    reciprocal clearance cost (``cost_weight``, deg; reference 0.5 mm), from 0.4 mm at both."""
    return _with(problem("tolerance"), objective, start, cost_weight=cost_weight)


#: the robust problem's default manufacturing scatter: lengths +-0.05 mm (normal, +-3 sigma),
#: clearances +-0.05 mm (uniform) about the preset's 0.5 mm
ROBUST_SCATTER = (
    ("crank_length", 5e-5, "normal"),
    ("rod_length", 5e-5, "normal"),
    ("clearance_B", 5e-5, "uniform"),
    ("clearance_C", 5e-5, "uniform"),
)


def robust_problem(
    objective: AbstractObjective | None = None, samples: int = 8, seed: int = 0, start: Sequence[float] | None = None
) -> DesignProblem:
    """The ``robust`` preset: the paper's problem, minimising the mean Eq. 19 over ``samples``
    manufactured parts drawn from `ROBUST_SCATTER` (the same draws at every design)."""
    return _with(problem("robust"), objective, start, samples=samples, seed=seed)


def _variables(p: DesignProblem) -> tuple:
    start = p.start if p.start is not None else p.default_start()
    return tuple(zip(p.names, p.lower, p.upper, start))


#: the design preset's term weights besides Eq. 19, degrees per unit of each term
DESIGN_WEIGHTS = (
    ("rms_slider_x_deviation_m", 10.0),
    ("rms_driving_moment_deviation_N_m", 2e-3),
    ("rms_contact_force_N", 2e-5),
)


def design_problem(
    objective: AbstractObjective | None = None,
    cost_weight: float = 0.005,
    start: Sequence[float] | None = None,
    variables: Sequence[str] | None = None,
    weights=DESIGN_WEIGHTS,
) -> DesignProblem:
    """The ``design`` preset (nine variables, `design_variables`) with changes: ``objective``
    (default the file's, the steady state), ``cost_weight`` (deg; 0 without a clearance variable),
    ``start`` (SI, in the variables' order), ``variables`` (a subset of the names: the others stay
    at their start values, folded into the base mechanism) and ``weights`` (``(term, weight)``
    pairs of `optim.design.TERMS` besides Eq. 19, degrees per unit of the term)."""
    p = problem("design")
    every = _variables(p)
    unknown = set(variables or ()) - set(p.names)
    if unknown:
        raise ParameterError(f"unknown design variables {sorted(unknown)}; valid: {list(p.names)}")
    chosen = [v for v in every if variables is None or v[0] in variables]
    fixed = [v for v in every if v not in chosen]
    base = p.base
    direct = [(nm, x0) for nm, _, _, x0 in fixed if nm not in ("min_transmission_angle", "rod_inertia_ratio")]
    if direct:
        base = set_parameters(base, [d[0] for d in direct], [d[1] for d in direct])
    if "rod_inertia_ratio" not in [v[0] for v in chosen]:
        ratio = next(v[3] for v in every if v[0] == "rod_inertia_ratio")
        l2 = next(v[3] for v in every if v[0] == "rod_length")
        base = set_parameters(base, ["rod_inertia"], [ratio * float(base.rod_mass) * l2**2])
    weights = dict(weights)
    bad = [k for k in weights if k not in TERMS or k == EQ19]
    if bad:
        raise ParameterError(f"weights of {bad}: valid terms are {list(TERMS)[1:]}")
    terms = ((EQ19, 1.0),) + tuple((k, float(weights[k])) for k in TERMS if weights.get(k, 0.0))
    has_clearance = any(v[0].startswith("clearance_") for v in chosen)
    return _with(
        p,
        objective,
        tuple(v[3] for v in chosen) if start is None else start,
        base=base,
        names=tuple(v[0] for v in chosen),
        lower=tuple(v[1] for v in chosen),
        upper=tuple(v[2] for v in chosen),
        cost_weight=cost_weight if has_clearance else 0.0,
        terms=terms,
    )


def design_variables() -> tuple:
    """The design preset's variables: ``(name, lower, upper, start)``, SI."""
    return _variables(problem("design"))


def four_bar_problem(
    objective: AbstractObjective | None = None,
    start: Sequence[float] | None = None,
    min_transmission_deg: float = 40.0,
) -> DesignProblem:
    """The ``four-bar`` preset (its link lengths under Grashof's condition and the transmission
    bound, steady state settling 40 revolutions) with changes: ``objective``, ``start`` and the
    transmission bound ``min_transmission_deg`` (deg; the title follows)."""
    p = problem("four-bar")
    changes = {}
    if min_transmission_deg != p.derived.min_transmission_deg:
        changes["derived"] = dataclasses.replace(p.derived, min_transmission_deg=min_transmission_deg)
        changes["title"] = (
            f"four-bar: RMS transmission-angle error over the link lengths, transmission in "
            f"[{min_transmission_deg:g}, {180 - min_transmission_deg:g}] deg"
        )
    return _with(p, objective, start, **changes)


#: Reference designs of the nine-variable design problem (``design_problem``), SI values in
#: its variable order (``design_problem().names``): the final designs of three projected-Adam
#: runs (seeds 0, 1, 2) on the earlier start-up-window objective. Their steady states are
#: periodic: period 1 revolution for seeds 0 and 1, period 3 for seed 2.
ADAM_RUNS_SI = (
    (
        0.44,
        0.6981317007977318,
        0.0002463181816534627,
        0.00028640401237716974,
        1.0,
        0.057529002886706475,
        1.0,
        0.15,
        1e11,
    ),
    (
        0.44,
        0.6981317007977318,
        0.0002389972117927395,
        0.00026944582032075115,
        1.0,
        0.053166234876019486,
        1.0,
        0.15,
        2.1e11,
    ),
    (
        0.3973044990972775,
        0.9934458521962443,
        0.000256183637493091,
        0.00027235670697709624,
        1.6340041244359393,
        0.08041450740284659,
        1.0,
        0.10443039777904214,
        158357758934.72577,
    ),
)

#: A design of the nine-variable problem (SI, same order) whose motion from rest is still not
#: periodic after 20 revolutions: a reference for regime maps that mix regimes.
NOT_PERIODIC_SI = (
    0.3833234480768442,
    0.7132069223869358,
    0.000346804565563798,
    0.0004574124407023192,
    1.7902927123941481,
    0.08251968631520867,
    2.3336053458042443,
    0.13980346222408116,
    167591445464.64087,
)


def paper_reference() -> dict:
    """``jaxcrank optimize``'s result.json ``paper`` entry (the paper and robust problems): the
    paper's numbers and why ours differ."""
    return {
        "optimum_deg": PAPER_OPTIMUM_DEG,
        "reduction_percent": PAPER_REDUCTION_PCT,
        "why_ours_differs": (
            "The paper's ADAMS model is not fully specified (offset e, restitution, friction, "
            "materials, contact smoothing, evaluation window and sample count are not given; "
            "model.md lists our readings) and its start design L1 = 150 mm lies outside its own "
            "box. Our start is the box centre and our window (t_start, t_end]; the objective "
            "itself is Eq. 19 in degrees."
        ),
    }
