"""How much the forgetting memory's time constant ``tau`` and dwell time ``t_dwell`` decide.

One setting at a time around the defaults of [`jaxcrank.physics.memory.ForgettingMemory`][]
(every other setting at its default, every clearance joint alike):

1. ``paper_run``: the paper run (0.4 s, the solve defaults, metrics over 0.1-0.4 s) over
   ``--starts`` starts (every entry of the start + k x 1e-15 scaled units, k = 0, 1, ...: the
   run amplifies rounding after its first impacts). Per setting and metric: the mean and
   standard deviation over the starts, and the change of the mean from the defaults' in
   units of the standard error of that difference.
2. ``steady``: [`jaxcrank.steady_state`][] with its defaults at designs of the nine-variable
   design problem that are periodic under the default memory: regime, period, Newton
   iterations, the largest Floquet multiplier's modulus, and the orbit's metrics, with the
   relative change of each metric from the defaults'.

    python bench/memory_sensitivity.py   # -> bench/results/memory_sensitivity.json
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import jax.numpy as jnp
import numpy as np
from _common import machine

import jaxcrank as jc
from jaxcrank.physics import memory
from jaxcrank.runs import config
from optim.presets import ADAM_RUNS_SI, design_problem

ROOT = Path(__file__).resolve().parent
PERTURBATION = 1e-15
#: parameter -> values (s), one at a time; each list holds the default
GRID = {
    "tau": [0.005, 0.01, 0.02, 0.04, 0.08],
    "t_dwell": [0.0005, 0.001, 0.002, 0.004, 0.008],
}
#: metrics reported (units in the names)
METRICS = (
    "rms_transmission_angle_error_deg",
    "max_abs_slider_x_deviation_m",
    "max_abs_rod_x_deviation_m",
    "peak_contact_force_B_N",
    "peak_contact_force_C_N",
    "peak_driving_moment_N_m",
    "rms_driving_moment_deviation_N_m",
)
#: designs of the nine-variable problem, periodic under the default memory (bench/results/memory_law.json)
DESIGNS = {"ADAM_RUNS_SI[0]": ADAM_RUNS_SI[0], "ADAM_RUNS_SI[1]": ADAM_RUNS_SI[1], "ADAM_RUNS_SI[2]": ADAM_RUNS_SI[2]}


def settings():
    """``(parameter, value)`` pairs: the defaults first, then each grid value that differs."""
    defaults = memory.ForgettingMemory()
    out = [("defaults", None)]
    for name, values in GRID.items():
        out += [(name, v) for v in values if v != getattr(defaults, name)]
    return out


def with_setting(mech, name, value):
    """``mech`` with the forgetting memory at every clearance joint and ``memory.name = value``."""
    overrides = ["memory.law=forgetting"] + ([] if name == "defaults" else [f"memory.{name}={value!r}"])
    return config.apply_overrides(mech, overrides)


def paper_run(starts):
    base = jc.paper()
    y0 = jc.model.initial_state(base)
    ts = jnp.linspace(0.0, 0.4, 14401)
    rows = []
    for name, value in settings():
        mech = with_setting(base, name, value)
        runs = []
        for k in range(starts):
            sim = jc.simulate(mech, ts=ts, y0=y0 + k * PERTURBATION, metrics_start=0.1)
            runs.append({m: float(sim.metrics[m]) for m in METRICS})
        rows.append({"parameter": name, "value_s": value, "runs": runs})
        print("paper", name, value, {m: round(np.mean([r[m] for r in runs]), 6) for m in METRICS[:1]}, flush=True)
    ref = np.array([[r[m] for m in METRICS] for r in rows[0]["runs"]])
    for row in rows:
        a = np.array([[r[m] for m in METRICS] for r in row["runs"]])
        se = np.sqrt(a.var(0, ddof=1) / len(a) + ref.var(0, ddof=1) / len(ref))
        row["metrics"] = {
            m: {
                "mean": a[:, i].mean(),
                "std": a[:, i].std(ddof=1),
                "relative_change": a[:, i].mean() / ref[:, i].mean() - 1.0,
                "difference_over_standard_error": (a[:, i].mean() - ref[:, i].mean()) / se[i] if se[i] > 0 else None,
            }
            for i, m in enumerate(METRICS)
        }
    return {"starts": starts, "perturbation_scaled": PERTURBATION, "rows": rows}


def steady():
    prob = design_problem()
    rows = []
    for design, x in DESIGNS.items():
        base = prob.mechanism(jnp.asarray(x))
        cells = []
        for name, value in settings():
            tic = time.perf_counter()
            st = jc.steady_state(with_setting(base, name, value), throw=False)
            cell = {
                "parameter": name,
                "value_s": value,
                "ok": st.ok,
                "regime": str(st.regime),
                "period_revolutions": int(st.period_revolutions),
                "newton_iterations": int(st.newton_iterations),
                "largest_multiplier_modulus": float(st.multiplier_moduli[0]) if st.ok else None,
                "metrics": {m: float(st.metrics[m]) for m in METRICS if m in st.metrics},
                "wall_s": time.perf_counter() - tic,
            }
            cells.append(cell)
            print(design, name, value, cell["regime"], cell["period_revolutions"],
                  round(cell["metrics"].get(METRICS[0], float("nan")), 6), flush=True)  # fmt: skip
        ref = cells[0]
        for cell in cells:
            if ref["regime"] == cell["regime"] == "periodic":
                cell["relative_change"] = {m: v / ref["metrics"][m] - 1.0 for m, v in cell["metrics"].items()}
        rows.append({"design": design, "design_SI": list(map(float, x)), "cells": cells})
    return {"designs": rows}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--starts", type=int, default=4, help="starts per setting of the paper run")
    parser.add_argument("--out", type=Path, default=ROOT / "results" / "memory_sensitivity.json")
    args = parser.parse_args()
    defaults = memory.ForgettingMemory()
    result = {
        "command": "python bench/memory_sensitivity.py",
        "forgetting_defaults": {k: float(getattr(defaults, k)) for k in ("v_ref", "tau", "t_dwell", "gate_width")},
        "grid_s": GRID,
        "paper_run": paper_run(args.starts),
        "steady": steady(),
        "machine": machine(),
    }
    args.out.write_text(json.dumps(result, indent=1))
    print("wrote", args.out)


if __name__ == "__main__":
    main()
