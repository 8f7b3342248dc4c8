"""The problem presets by name, for the TOML/CLI boundary (``jaxcrank optimize --problem``,
``python -m optim.scans``): name -> a function returning the problem, taking the
objective instance as its ``objective`` keyword."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

from jaxcrank import reference
from jaxcrank.physics.presets import paper

from .design import design_problem
from .ensemble import Ensemble
from .four_bar import four_bar_problem
from .objective import AbstractObjective
from .problem import ParameterProblem

#: the paper's optimum of Eq. 19 (deg) and its reduction from the start design (%)
PAPER_OPTIMUM_DEG = reference.value("optimisation", "optimum_deg")
PAPER_REDUCTION_PCT = reference.value("optimisation", "reduction_percent")


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


PROBLEMS = {
    "paper": paper_problem,
    "tolerance": tolerance_problem,
    "robust": robust_problem,
    "design": design_problem,
    "four-bar": four_bar_problem,
}


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
