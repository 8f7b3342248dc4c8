"""Design for life against design for a new clearance, and the life evaluator's gradients.

The problem ``docs/problems/four-bar-life.toml``: the four-bar at 300 rpm whose bushing at B
wears fast (Archard coefficients scaled up 600-fold), the bushing's hardness and the coupler's
mass as variables, the RMS contact force at B as the objective and the RMS rocker-angle
deviation bounded. Designs from the same start, with the same optimiser:

- **for a new clearance**: the problem without ``[life]``: the force on the new mechanism's
  steady state (the bushing's hardness does not enter it);
- **for life**: the problem as written, the force after the ``[life]`` table's cycles of
  wear (``optim.life_design.solve_for_life``: from the new-clearance design, exact gradients
  through the life run);
- **for life from the start**: the same without the new-clearance run first
  (``start_from_new = false``), to show what that way in is for;
- **for a new clearance with twice the iterations**: as many steps as the design for life's two
  runs together, so that the gain is not that of a longer run.

All are scored on the same held-out truth, which none optimised: a fresh life run of each
final design to the same cycles, from rest, with error-controlled steps at a quarter of the
file's ``rtol`` (the optimiser's runs take the first design's steps). The start is scored too.

The evaluator's exact gradients of the force and the deviation after the cycles are checked
against central differences (relative step ``H``, the evaluator's steps in cycles) at three
designs: the start and the new-clearance and life designs.

    python bench/life_design.py          # about 20 minutes on 2 cores
writes bench/results/life_design.json.
"""

from __future__ import annotations

import dataclasses
import json
import sys
import time
from pathlib import Path

import numpy as np

from jaxcrank.analysis.life import life
from optim import constrained, spec
from optim.life_design import LifeEvaluator, all_periodic, life_options, solve_for_life

ROOT = Path(__file__).resolve().parents[1]
FILE = ROOT / "docs" / "problems" / "four-bar-life.toml"
OUT = Path(__file__).resolve().parent / "results"
METRIC = "rms_contact_force_B_N"
H = 1e-4


def held_out(problem, life_spec, x) -> dict:
    """The metric after the cycles at SI design ``x`` by a fresh life run (from rest, steps by
    error control at a quarter of the file's rtol)."""
    t = time.perf_counter()
    options = life_options(life_spec, problem.objective.options).replace(rtol=life_spec.rtol / 4)
    run = life(problem.mechanism(np.asarray(x)), life_spec.cycles, options)
    first, last = run.points[0], run.points[-1]
    read = lambda p, q: p.metrics[q] if p.steady.periodic else p.steady.statistics[q]["value"]  # noqa: E731
    return {
        "design_SI": [float(v) for v in x],
        "after_cycles": {q: float(read(last, q)) for q in problem.quantities},
        "new": {q: float(read(first, q)) for q in problem.quantities},
        "regimes": [p.regime for p in run.points],
        "steps_cycles": [float(s) for s in run.schedule],
        "seconds": round(time.perf_counter() - t, 1),
    }


def gradient_check(ev: LifeEvaluator, x) -> dict:
    """The evaluator's gradients of the objective's and the constraints' quantities against
    central differences of whole runs (the evaluator's steps in cycles)."""
    t = time.perf_counter()
    problem = ev.problem
    out, jac, info = ev.outputs_and_jacobian(x)
    rows = [i for i in range(len(problem.terms))] + [len(problem.terms) + 1 + j for j in range(len(problem.limits))]
    fd, periodic = np.zeros((len(rows), len(x))), True
    for k in range(len(x)):
        h = H * abs(x[k])
        pair = []
        for sign in (1.0, -1.0):
            xx = np.array(x, dtype=float)
            xx[k] += sign * h
            pair.append(ev.outputs_at(xx)[rows])
            periodic = periodic and ev.regime_at(xx) == "periodic"
        fd[:, k] = (pair[0] - pair[1]) / (2 * h)
    scaled = np.abs(np.asarray(x))  # per relative change of each variable
    quantities = {}
    for i, (row, q) in enumerate(zip(rows, problem.quantities)):
        g = np.asarray(jac[row])
        quantities[q] = {
            "value": float(out[row]),
            "gradient_per_SI": g.tolist(),
            "central_difference_per_SI": fd[i].tolist(),
            "relative_error": float(np.linalg.norm((g - fd[i]) * scaled) / np.linalg.norm(fd[i] * scaled)),
        }
    return {
        "design_SI": [float(v) for v in x],
        "regime": info["regime"],
        "quantities": quantities,
        "difference_runs_periodic": periodic,
        "seconds": round(time.perf_counter() - t, 1),
    }


def main() -> int:
    OUT.mkdir(exist_ok=True)
    problem, tables = spec.load(FILE)
    life_spec = tables["life"]
    opt, rounds = constrained.settings(tables["optimizer"])
    t = time.perf_counter()
    both = solve_for_life(problem, life_spec, opt, rounds, progress=False)
    for_life, for_new, ev = both, both["new_clearance"], both["evaluator"]
    life_s = time.perf_counter() - t
    print(f"for a new clearance {for_new['final_design']}, for life {for_life['final_design']}", file=sys.stderr)
    t = time.perf_counter()
    alone = solve_for_life(problem, dataclasses.replace(life_spec, start_from_new=False), opt, rounds, progress=False)
    alone_s = time.perf_counter() - t
    print(f"for life from the start: {alone['final_design']} ({alone_s:.0f} s)", file=sys.stderr)
    t = time.perf_counter()  # the new-clearance design with both runs' iterations: the same budget of steps
    twice = dataclasses.replace(opt, max_iterations=2 * opt.max_iterations)
    for_new_twice = constrained.solve(problem, twice, rounds, progress=False)
    print(f"for a new clearance, twice the iterations: {for_new_twice['final_design']}", file=sys.stderr)
    designs = {
        "start": alone["start"]["design_SI"],
        "for_new_clearance": for_new["final_design"],
        "for_new_clearance_twice_the_iterations": for_new_twice["final_design"],
        "for_life": for_life["final_design"],
        "for_life_from_start": alone["final_design"],
    }
    checks = {}
    for name in ("start", "for_new_clearance", "for_life"):
        checks[name] = gradient_check(ev, np.asarray(designs[name], dtype=float))
        print(name, json.dumps(checks[name]), file=sys.stderr)
    scores = {}
    for name, x in designs.items():
        scores[name] = held_out(problem, life_spec, x)
        print(name, json.dumps(scores[name]), file=sys.stderr)
    after = {name: score["after_cycles"][METRIC] for name, score in scores.items()}
    result = {
        "problem": str(FILE.relative_to(ROOT)),
        "names": list(problem.names),
        "cycles": life_spec.cycles,
        "rtol": life_spec.rtol,
        "held_out_rtol": life_spec.rtol / 4,
        "metric": METRIC,
        "quantities": list(problem.quantities),
        "optimizer": tables["optimizer"],
        "designs": designs,
        "held_out": scores,
        "life_design_lower_by": 1.0 - after["for_life"] / after["for_new_clearance"],
        "life_alone_lower_by": 1.0 - after["for_life_from_start"] / after["for_new_clearance"],
        "life_design_lower_than_twice_the_iterations_by": 1.0
        - after["for_life"] / after["for_new_clearance_twice_the_iterations"],
        "optimiser_runs": {
            "for_new_clearance_then_life": {
                "iterations": len(for_new["history"]) + len(for_life["history"]),
                "seconds": round(life_s, 1),
            },
            "for_life_from_start": {"iterations": len(alone["history"]), "seconds": round(alone_s, 1)},
        },
        "gradient_checks": checks,
        "gradient_step_relative": H,
        "evaluator_steps_cycles": ev.schedule,
        "every_run_periodic": all(all_periodic(r) for r in ev.runs.values() if not isinstance(r, str)),
        "target_relative_error": 0.02,
    }
    (OUT / "life_design.json").write_text(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
