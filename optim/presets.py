"""The problem presets by name, for the TOML/CLI boundary (``jaxcrank optimize --problem``,
``python -m optim.scans``): name -> a function returning the problem, taking the
objective instance as its ``objective`` keyword."""

from __future__ import annotations

from .design import design_problem
from .problem import paper_problem, robust_problem, tolerance_problem

PROBLEMS = {"paper": paper_problem, "tolerance": tolerance_problem, "robust": robust_problem, "design": design_problem}


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
