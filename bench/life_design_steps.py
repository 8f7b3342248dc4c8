"""The life evaluator's derivative at the design for life against central differences of
several steps.

At the final design of ``bench/life_design.py`` (``bench/results/life_design.json``,
``designs.for_life``) the differences of relative step 1e-4 disagree with the exact gradient
of the RMS force at B after the cycles with respect to the coupler's mass. This measures the
differences at relative steps from 1e-3 to 1e-6 (the evaluator's steps in cycles), each pair
of runs periodic, and the exact derivative, to show how the differences depend on the step.

    python bench/life_design_steps.py    # about 5 minutes on 2 cores
writes bench/results/life_design_steps.json.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from optim import spec
from optim.life_design import LifeEvaluator

ROOT = Path(__file__).resolve().parents[1]
OUT = Path(__file__).resolve().parent / "results"
STEPS = (1e-3, 1e-4, 1e-5, 1e-6)
VARIABLE = 1  # the coupler's mass


def main() -> int:
    design = json.loads((OUT / "life_design.json").read_text())
    problem, tables = spec.load(ROOT / design["problem"])
    ev = LifeEvaluator(problem, tables["life"])
    ev.schedule = list(design["evaluator_steps_cycles"])
    x = np.asarray(design["designs"]["for_life"], dtype=float)
    out, jac, info = ev.outputs_and_jacobian(x)
    rows = [0, len(problem.terms) + 1]  # the objective's quantity and the constraint's
    run = ev.life_at(x)
    differences = []
    for h in STEPS:
        pair, periodic = [], True
        for sign in (1.0, -1.0):
            xx = x.copy()
            xx[VARIABLE] *= 1.0 + sign * h
            pair.append(ev.outputs_at(xx)[rows])
            periodic = periodic and ev.regime_at(xx) == "periodic"
        fd = (pair[0] - pair[1]) / (2.0 * h * x[VARIABLE])
        differences.append({"relative_step": h, "central_difference_per_SI": fd.tolist(), "periodic": periodic})
        print(json.dumps(differences[-1]), file=sys.stderr)
    result = {
        "design_SI": x.tolist(),
        "variable": problem.names[VARIABLE],
        "quantities": [problem.quantities[0], problem.quantities[1]],
        "exact_per_SI": [float(jac[r, VARIABLE]) for r in rows],
        "leading_multipliers": [float(np.max(p.steady.multiplier_moduli)) for p in run.points + run.predictors],
        "differences": differences,
    }
    (OUT / "life_design_steps.json").write_text(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
