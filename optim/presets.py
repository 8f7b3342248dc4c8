"""The problem presets by name, for the TOML/CLI boundary (``jaxcrank optimize --problem``,
``python -m optim.scans``): name -> a function returning the problem, taking the
objective instance as its ``objective`` keyword."""

from __future__ import annotations

from .design import design_problem
from .problem import paper_problem, robust_problem, tolerance_problem

PROBLEMS = {"paper": paper_problem, "tolerance": tolerance_problem, "robust": robust_problem, "design": design_problem}
