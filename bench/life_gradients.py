"""Exact life gradients against central differences of whole life runs.

The four-bar at 300 rpm whose pin B wears (Archard coefficients 3e-4 for the bushing and 3e-5
for the pin, scaled up so that the hole wears visibly within a few hundred revolutions).
Design variables: relative changes u of the coupler's mass and of the clearance at B. At each
of ``DESIGNS``:

- a life run to ``CYCLES`` cycles in the steps ``STEPS`` (``jaxcrank.analysis.life.life``);
- the exact gradient (``jaxcrank.analysis.life_gradient.life_value_and_grad``) of two values:
  the RMS rocker-angle deviation after ``CYCLES`` cycles, and the life, the cycles at which
  that deviation first reaches the middle of its range over the run;
- central differences (step ``H`` in u) of whole life runs at the same steps in cycles
  (``schedule``), each warm-started from the centre's first steady state. Every point and
  predictor of those runs must be periodic, as the centre's are: a difference across a change
  of regime is not a derivative (``difference_runs_periodic`` says whether they all were).

Each point's leading Floquet multiplier is recorded: near 1 the orbit is close to a change
of regime, its derivative is large and differences of a finite step are not yet in their
linear range. With the 1000-fold coefficients of ``bench/life_validation.py`` at B and C the
run is that close (a 0.1 % larger clearance is not periodic after 150 cycles), and the exact
gradient and the differences disagreed there.

    python bench/life_gradients.py           # about 20 minutes on 2 cores
writes bench/results/life_gradients.json.
"""

from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path

import equinox as eqx
import jax.numpy as jnp
import numpy as np

import jaxcrank as jc
from jaxcrank.analysis.life import LifeOptions, crossing_index, cycles_to_limit, life
from jaxcrank.analysis.life_gradient import life_value_and_grad
from jaxcrank.physics.wear import Archard, from_clearance

sys.path.insert(0, str(Path(__file__).resolve().parent))
from life_validation import SAMPLES  # noqa: E402

WEAR = Archard(hole_coefficient=3e-4, pin_coefficient=3e-5)


def mechanism():
    """The four-bar at 300 rpm, its pin B worn with ``WEAR`` (new)."""
    mech = jc.set_parameter(jc.four_bar(), "driver.speed", 300.0 * 2.0 * math.pi / 60.0)
    return eqx.tree_at(lambda m: m.joints["B"], mech, from_clearance(mech.joints["B"], WEAR))


OUT = Path(__file__).resolve().parent / "results"
NAMES = ("coupler_mass", "clearance_B")
DESIGNS = ((0.0, 0.0), (0.05, 0.0), (0.0, -0.1))
CYCLES = 150.0
#: the steps in cycles, fixed (error control takes the whole run in one step at these wear rates),
#: so that the chain over several steps of the slow map is what is checked
STEPS = (50.0, 50.0, 50.0)
H = 1e-4
METRIC = "rms_rocker_angle_deviation_deg"
OPTIONS = LifeOptions(rtol=0.05, steady=jc.SteadyOptions(statistics_on_failure=True, samples_per_revolution=SAMPLES))


def build(u):
    base = mechanism()
    p0 = jnp.asarray([jc.get_parameter(base, n) for n in NAMES])
    return jc.set_parameters(base, NAMES, p0 * (1.0 + u))


def main() -> int:
    OUT.mkdir(exist_ok=True)
    rows = []
    for design in DESIGNS:
        t0 = time.perf_counter()
        u0 = jnp.asarray(design)
        run = life(build(u0), CYCLES, OPTIONS, schedule=STEPS)
        values = [p.metrics[METRIC] for p in run.points]
        limit = 0.5 * (min(values) + max(values))
        index = crossing_index(values, limit)
        primal_s = time.perf_counter() - t0
        t1 = time.perf_counter()

        def both(tr, limit=limit, index=index):
            return jnp.stack(
                [tr.metrics[METRIC][-1], cycles_to_limit(tr.cycles, tr.metrics[METRIC], limit, index=index)]
            )

        (final, to_limit), jac = life_value_and_grad(both, build, u0, run)
        g_final, g_life = jac[0], jac[1]
        grad_s = time.perf_counter() - t1
        t2 = time.perf_counter()
        fd_final, fd_life, fd_periodic = [], [], True
        for k in range(len(NAMES)):
            pair = []
            for sign in (1.0, -1.0):
                u = u0.at[k].add(sign * H)
                r = life(build(u), CYCLES, OPTIONS, schedule=run.schedule, warm_start=run.points[0].steady)
                v = [p.metrics[METRIC] for p in r.points]
                fd_periodic = fd_periodic and all(p.steady.periodic for p in r.points + r.predictors)
                pair.append((v[-1], float(cycles_to_limit(r.cycles, v, limit, index=index))))
            fd_final.append((pair[0][0] - pair[1][0]) / (2 * H))
            fd_life.append((pair[0][1] - pair[1][1]) / (2 * H))
        fd_s = time.perf_counter() - t2
        g_final, g_life = np.asarray(g_final), np.asarray(g_life)

        def rel(g, fd):
            fd = np.asarray(fd)
            return float(np.linalg.norm(g - fd) / np.linalg.norm(fd))

        rows.append({
            "design_u": list(design), "points": len(run.cycles), "regimes": sorted({p.regime for p in run.points}),
            "steps_cycles": list(run.schedule),
            "leading_multipliers": [float(np.max(p.steady.multiplier_moduli)) for p in run.points],
            "metric_after_cycles": float(final), "limit": limit, "cycles_to_limit": float(to_limit),
            "gradient_metric": g_final.tolist(), "central_difference_metric": fd_final,
            "relative_error_metric": rel(g_final, fd_final),
            "gradient_life_cycles": g_life.tolist(), "central_difference_life_cycles": fd_life,
            "relative_error_life": rel(g_life, fd_life), "difference_runs_periodic": fd_periodic,
            "seconds": {"life": round(primal_s, 1), "gradients": round(grad_s, 1), "differences": round(fd_s, 1)},
        })  # fmt: skip
        print(json.dumps(rows[-1]), file=sys.stderr)
    result = {
        "mechanism": "four-bar at 300 rpm, pin B worn (Archard 3e-4 bushing, 3e-5 pin)",
        "variables": [f"relative change of {n}" for n in NAMES],
        "cycles": CYCLES,
        "metric": METRIC,
        "life": "cycles at which the metric first reaches the middle of its range over the centre's run",
        "step": H,
        "rtol": OPTIONS.rtol,
        "designs": rows,
        "target_relative_error": 0.02,
    }
    (OUT / "life_gradients.json").write_text(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
