"""How the paper reproduction's deviations depend on the assumptions the paper does not give.

    python bench/paper_assumptions.py [--t1 0.4] [--out bench/results/paper_assumptions.json]

The paper (ADAMS) states the rod-centre x deviation within +-0.5 mm and the slider x
deviation within +-1.0 mm, but gives neither the coefficient of restitution c_e, the
contact damping law, the friction coefficient mu nor the materials' Young's modulus E
(docs/model.md, "The `paper` preset and its assumptions"). This script simulates the
`paper` preset for ``--t1`` seconds (default 0.4 s, 4 revolutions at 600 rpm) and changes
one assumption at a time:

- ``contact.restitution`` c_e (preset 0.9);
- ``contact.law``, the damping model of the normal force (preset ``hybrid``, the paper's
  Eq. 6-8);
- ``friction.coefficient`` mu (preset 0.1);
- Young's modulus E of the pins' and holes' materials at B and C (preset 207 GPa, steel).

For each value it writes max |slider x deviation| and max |rod x deviation| after the
first revolution (m), the peak contact forces (N), the largest penetration (m), the
geometric bounds on both deviations that the clearances and that penetration allow
(``jaxcrank.SliderCrank.deviation_bounds``, m), steps and the wall time (s) into the
JSON file (``docs/gen_tables.py`` renders it in docs/validation.md).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import jax
from _common import machine

import jaxcrank as jc
from jaxcrank import config, outputs

#: (assumption, key, values): one-at-a-time changes of the paper preset (PRESET holds its values)
ASSUMPTIONS = (
    ("restitution c_e", "contact.restitution", [0.5, 0.7, 0.8, 0.9, 0.95, 1.0]),
    ("contact damping law", "contact.law", ["hybrid", "lankarani_nikravesh", "flores", "hunt_crossley"]),
    ("friction coefficient mu", "friction.coefficient", [0.0, 0.05, 0.1, 0.15, 0.2]),
    ("Young's modulus E (pins and holes), Pa", "youngs_modulus", [70e9, 100e9, 207e9, 300e9]),
)
PRESET = {"contact.restitution": 0.9, "contact.law": "hybrid", "friction.coefficient": 0.1, "youngs_modulus": 207e9}


def overrides(key: str, value) -> list[str]:
    """``--set`` lines for one assumption's value (E: the pins' and the holes' materials)."""
    if key == "youngs_modulus":
        return [f"{part}.youngs_modulus={value!r}" for part in ("pin_material", "hole_material")]
    return [f"{key}={value!r}" if not isinstance(value, str) else f"{key}={value}"]


def run_one(mech, t1: float) -> dict:
    start = time.perf_counter()
    sim = jc.simulate(mech, t1, n_samples=int(round(t1 * 36000)) + 1, metrics_start=float(mech.period))
    jax.block_until_ready(sim.ys)
    wall = time.perf_counter() - start
    m = outputs.summary_metrics(sim)
    pen = max(m["max_penetration_B_m"], m["max_penetration_C_m"])
    bound = mech.deviation_bounds(pen)
    return {
        "max_abs_slider_x_deviation_m": m["max_abs_slider_x_deviation_m"],
        "max_abs_rod_x_deviation_m": m["max_abs_rod_x_deviation_m"],
        "peak_contact_force_B_N": m["peak_contact_force_B_N"],
        "peak_contact_force_C_N": m["peak_contact_force_C_N"],
        "max_penetration_m": pen,
        "geometric_bound_slider_x_m": bound["slider_x_m"],
        "geometric_bound_rod_x_m": bound["rod_x_m"],
        "steps": int(sim.num_steps),
        "wall_s": wall,
    }


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--t1", type=float, default=0.4, help="simulated time, s (default 0.4)")
    p.add_argument("--out", type=Path, default=Path("bench/results/paper_assumptions.json"))
    p.add_argument("--values", type=int, help="only the first VALUES values of each assumption (a quick check)")
    args = p.parse_args()
    paper = jc.paper()
    rows = []
    for label, key, values in ASSUMPTIONS:
        for value in values[: args.values]:
            mech = config.apply_overrides(paper, overrides(key, value))
            row = {"assumption": label, "key": key, "value": value, "preset": value == PRESET[key]}
            row.update(run_one(mech, args.t1))
            rows.append(row)
            print(
                f"{key} = {value}: slider {row['max_abs_slider_x_deviation_m'] * 1e3:.3f} mm, "
                f"rod {row['max_abs_rod_x_deviation_m'] * 1e3:.3f} mm ({row['steps']} steps, {row['wall_s']:.1f} s)",
                flush=True,
            )
    from jaxcrank import reference

    result = {
        "description": "max |slider x dev| and max |rod x dev| after the first revolution of the paper preset, "
        "one unstated assumption changed at a time (all others at the preset)",
        "t1_s": args.t1,
        "metrics_window_start_s": float(paper.period),
        "paper_envelope_m": {
            "slider_x": reference.value("deviations", "slider_x_deviation_within_m"),
            "rod_x": reference.value("deviations", "rod_x_deviation_within_m"),
        },
        "rows": rows,
        "machine": machine(),
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
