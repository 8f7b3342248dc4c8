"""Audit of the approach-speed memory over a paper run (docs/numerics.md).

At every contact onset the approach speed the damping uses (the memory, floored at
``memory.min_approach_speed``) is compared with the true normal speed just before
onset (:mod:`jaxcrank.analysis.validation.memory_audit`). Default tolerances, 0.4 s; the paper preset and the
issue's setting (Hunt-Crossley, Ambrosio's friction ramp). Then the cost: the solver's
accepted and rejected steps of the 0.4 s run (tsit5, default tolerances) of each setting,
and over an ensemble of runs with the restitution 0.9 +- 5e-3 in steps of 1e-4 (101 runs;
the step count of one run is chaotic: a 1e-4 change of restitution moves it by up to
20 %). Writes ``bench/results/audit_memory.json``.

    python bench/audit_memory.py [--t1 0.4] [--no-steps] [--before FILE] [--half 50] [--out FILE]

The "before" step counts are this script run with the jaxcrank of commit a11de35
(``git checkout a11de35 -- jaxcrank``; it has no ``jaxcrank.analysis.validation.memory_audit``: the step counts
only, ``--no-audit``), written to ``audit_memory_steps_a11de35.json``. ``--before FILE``
compares with such a file: the ratio of the ensemble medians (after / before) with a
95 % bootstrap interval (10 000 resamples of each ensemble).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from _common import machine, timed

import jaxcrank as jc
from jaxcrank import config

SETTINGS = {
    "paper": [],
    "hunt_crossley_ambrosio": ["contact.law=hunt_crossley", "friction.law=ambrosio"],
}


def steps(mech, t1: float, half: int = 50) -> dict:
    """Accepted and rejected tsit5 steps of ``mech`` over ``t1`` s (samples every 0.1 deg
    as in `jaxcrank simulate`), for its restitution and the ``2 half + 1`` restitutions
    0.9 + 1e-4 k, k = -half..half."""
    import jax.numpy as jnp

    def count(e):  # e traced (an array): one compilation for all of them
        m = jc.set_parameter(mech, "contact.restitution", e)
        sim = jc.simulate(m, t1)
        return int(sim.num_steps), int(sim.num_rejected)

    sim = jc.simulate(mech, t1)  # the preset itself, as `jaxcrank simulate` runs it
    own = int(sim.num_steps), int(sim.num_rejected)
    rs = [round(0.9 + 1e-4 * k, 4) for k in range(-half, half + 1)]
    counts = [count(jnp.asarray(e)) for e in rs]
    accepted = [c[0] for c in counts]
    return {
        "own": {"restitution": jc.get_parameter(mech, "contact.restitution"), "accepted": own[0], "rejected": own[1]},
        "restitutions": rs,
        "accepted": accepted,
        "rejected": [c[1] for c in counts],
        "summary": {
            "own_accepted": own[0],
            "median_accepted": float(np.median(accepted)),
            "min_accepted": min(accepted),
            "max_accepted": max(accepted),
            "median_rejected": float(np.median([c[1] for c in counts])),
        },
    }


def compare(before: dict, after: dict, resamples: int = 10_000) -> dict:
    """After / before: the preset run's accepted steps, and the ensemble medians with a
    95 % bootstrap interval (each ensemble resampled with replacement, seed 0)."""
    a, b = np.asarray(after["accepted"]), np.asarray(before["accepted"])
    rng = np.random.default_rng(0)
    ratios = np.median(rng.choice(a, (resamples, a.size)), axis=1) / np.median(
        rng.choice(b, (resamples, b.size)), axis=1
    )
    low, high = np.percentile(ratios, [2.5, 97.5])
    return {
        "own_ratio": after["own"]["accepted"] / before["own"]["accepted"],
        "median_ratio": float(np.median(a) / np.median(b)),
        "median_ratio_95pct_interval": [float(low), float(high)],
        "ensemble_sizes": [int(b.size), int(a.size)],
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--t1", type=float, default=0.4)
    parser.add_argument("--no-steps", action="store_true", help="skip the step counts")
    parser.add_argument("--no-audit", action="store_true", help="step counts only")
    parser.add_argument("--before", type=Path, help="step counts of the jaxcrank before, to compare with")
    parser.add_argument("--half", type=int, default=50, help="the ensemble's restitutions 0.9 + 1e-4 k, |k| <= half")
    parser.add_argument("--out", type=Path, help="where to write the JSON (default: bench/results/)")
    args = parser.parse_args()
    report = {"machine": machine(), "t1_s": args.t1, "runs": {}, "steps": {}}
    if not args.no_steps:
        for name, overrides in SETTINGS.items():
            report["steps"][name] = steps(config.apply_overrides(jc.paper(), overrides), args.t1, args.half)
            if args.before is not None:
                before = json.loads(args.before.read_text())["steps"][name]
                report["steps"][name]["versus_before"] = compare(before, report["steps"][name])
            print(name, json.dumps(report["steps"][name]["summary"]), flush=True)
    for name, overrides in ({} if args.no_audit else SETTINGS).items():
        mech = config.apply_overrides(jc.paper(), overrides)
        from jaxcrank import audit

        onsets, wall = timed(lambda mech=mech: audit.onsets(mech, args.t1, max_steps=400_000))
        vmin = jc.get_parameter(mech, "memory.min_approach_speed")
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
    out = args.out or Path(__file__).parent / "results" / (
        "audit_memory.json" if not args.no_audit else "steps_only.json"
    )
    out.write_text(json.dumps(report, indent=1) + "\n")


if __name__ == "__main__":
    main()
