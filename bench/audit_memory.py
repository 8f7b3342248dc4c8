"""Audit of the approach-speed memory over a paper run (docs/numerics.md).

At every contact onset the approach speed the damping uses (the memory, floored at
``contact.min_approach_speed``) is compared with the true normal speed just before
onset (:mod:`jaxcrank.audit`). Default tolerances, 0.4 s; the paper preset and the
issue's setting (Hunt-Crossley, Ambrosio's friction ramp). Writes
``bench/results/audit_memory.json``.

    python bench/audit_memory.py [--t1 0.4]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from _common import machine, timed

import jaxcrank as jc
from jaxcrank import audit, config

SETTINGS = {
    "paper": [],
    "hunt_crossley_ambrosio": ["contact.law=hunt_crossley", "friction.law=ambrosio"],
}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--t1", type=float, default=0.4)
    args = parser.parse_args()
    report = {"machine": machine(), "t1_s": args.t1, "runs": {}}
    for name, overrides in SETTINGS.items():
        mech = config.apply_overrides(jc.paper(), overrides)
        onsets, wall = timed(lambda mech=mech: audit.onsets(mech, args.t1, max_steps=400_000))
        vmin = float(mech.contact.min_approach_speed)
        err = onsets.relative_error
        report["runs"][name] = {
            "overrides": overrides,
            "wall_s": wall,
            "whole_run": onsets.summary(min_speed=vmin),
            "after_first_revolution": onsets.summary(t_min=float(mech.period), min_speed=vmin),
            "reimpacts_within_50us": int(np.sum(onsets.since_separation < 50e-6)),
            "largest_errors": [
                {
                    "joint": str(onsets.joint[i]),
                    "t_s": float(onsets.t[i]),
                    "used_m_s": float(onsets.used[i]),
                    "true_m_s": float(onsets.true[i]),
                    "relative_error": float(err[i]),
                    "since_separation_s": float(onsets.since_separation[i]),
                }
                for i in np.argsort(-np.abs(err))[:5]
            ],
        }
        print(name, json.dumps(report["runs"][name]["whole_run"]), flush=True)
    out = Path(__file__).parent / "results" / "audit_memory.json"
    out.write_text(json.dumps(report, indent=1) + "\n")


if __name__ == "__main__":
    main()
