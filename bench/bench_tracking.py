"""Benchmark: metrics tracked during the solve (jaxcrank.numerics.tracking) against the
same solve with stored samples, on the paper run.

    python bench/bench_tracking.py [--t1 0.4] [--out bench/results/tracking.json] [--metrics-from S]
        [--sweep-samples 360,3600,36000,360000]

Records, in one run on this machine:
- the paper run (tsit5, default tolerances, 10 samples per degree) saving every
  sample, without and with tracking: compile and run time (second call), steps;
- the sweep's per-design program (metrics only, nothing stored per sample): XLA's
  memory plan (temporary + output bytes) at 360 ... 360 000 samples per revolution;
- the peaks of the contact forces and slider acceleration over the solve at 1, 10
  and 100 samples per degree, and over the stored samples at 10 per degree.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import jax
import jax.numpy as jnp
from _common import machine, timed

import jaxcrank as jc
from jaxcrank import outputs

PEAKS = ("peak_contact_force_B_N", "peak_contact_force_C_N", "max_abs_slider_ax_deviation_m_s2")


def paper_runs(t1, start=None):
    """The paper run stored and tracked; metrics from ``start`` (s, default one revolution)."""
    mech = jc.paper()
    start = float(mech.period) if start is None else start
    n10 = int(round(t1 / mech.period * 3600)) + 1
    rows = {}
    for label, kwargs in (("stored_samples", {}), ("stored_samples_and_tracked", {"metrics_start": start})):
        run = lambda kwargs=kwargs: jc.simulate(mech, t1, n_samples=n10, **kwargs)  # noqa: E731
        _, first = timed(run)
        sim, wall = timed(run)
        rows[label] = {
            "compile_s": max(first - wall, 0.0),
            "run_s": wall,
            "steps": int(sim.num_steps),
            "rejected": int(sim.num_rejected),
        }
        if kwargs:
            tracked = outputs.summary_metrics(sim)
        else:
            stored = outputs.sample_metrics(sim, start)
    peaks = {
        "over_samples_10_per_degree": {k: stored[k] for k in PEAKS},
        "over_solve_10_per_degree": {k: tracked[k] for k in PEAKS},
    }
    for per_degree in (1, 100):
        n = int(round(t1 / mech.period * 360 * per_degree)) + 1
        sim = jc.simulate(mech, t1, n_samples=n, metrics_start=start, save_samples=False)
        peaks[f"over_solve_{per_degree}_per_degree"] = {k: float(sim.metrics[k]) for k in PEAKS}
    return rows, peaks


def sweep_memory(samples=(360, 3600, 36_000, 360_000)):
    from jaxcrank import sweep

    base = jc.paper()
    out = {}
    for spr in samples:
        settings = sweep.Settings(revolutions=0.05, samples_per_revolution=spr, metrics_from_revolution=0.01)
        program = jax.jit(lambda x, s=settings: sweep.simulate_design(base, ("rod_length",), x, s))
        m = program.lower(jnp.array([0.403])).compile().memory_analysis()
        out[str(spr)] = {"temp_bytes": int(m.temp_size_in_bytes), "output_bytes": int(m.output_size_in_bytes)}
    return out


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--t1", type=float, default=0.4, help="simulated time, s")
    p.add_argument("--out", type=Path, default=Path("bench/results/tracking.json"))
    p.add_argument("--note", default="", help="free text stored in the JSON (e.g. machine load)")
    p.add_argument("--metrics-from", type=float, help="start of the metrics window, s (default: one revolution)")
    p.add_argument("--sweep-samples", default="360,3600,36000,360000", help="samples per revolution of the sweep")
    args = p.parse_args(argv)
    runs, peaks = paper_runs(args.t1, args.metrics_from)
    plain, tracked = runs["stored_samples"], runs["stored_samples_and_tracked"]
    result = {
        "t1_s": args.t1,
        "runs": runs,
        "tracking_run_time_ratio": tracked["run_s"] / plain["run_s"],
        "same_steps": plain["steps"] == tracked["steps"] and plain["rejected"] == tracked["rejected"],
        "peaks": peaks,
        "sweep_program_memory_by_samples_per_revolution": sweep_memory(
            tuple(int(n) for n in args.sweep_samples.split(","))
        ),
        "machine": machine(),
        "note": args.note,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2))
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
