"""Work-precision: wall time of the paper run against the error each solver and
tolerance actually makes, so solvers are compared at equal accuracy rather than at
equal nominal tolerance.

    python bench/work_precision.py [--out bench/results/work_precision.json] [--t1 0.4] [--tols 1e-6,1e-8]

Error: the largest difference from a reference solution (tsit5 at rtol = atol =
1e-10, checked against rodas4 at 1e-9) of the slider position (m) and of the
normal contact force at C (N) over the first ``--error-window`` s (default 10 ms:
the start-up impacts, before the motion is chaotic; later the trajectories of any
two solvers part, see docs/numerics.md). Work: wall time after compilation of the whole
paper run (``--t1``, default 0.4 s, one sample per 0.1 deg), and the compile time. Writes the JSON and a
work-precision plot beside it; nothing is asserted.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from _common import machine, timed  # bench/ is on sys.path (python bench/work_precision.py)

import jaxcrank as jc
from jaxcrank import outputs, solve

RUNS = {"tsit5": [1e-4, 1e-5, 1e-6, 1e-7, 1e-8], "rodas4": [1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8]}


def paper_run(mech, t1, solver, tol):
    """(trajectory columns, wall time after compilation, compile time, accepted, rejected)."""

    def go():
        return solve.simulate(
            mech, t1, options=jc.SolveOptions.from_text(solver, rtol=tol, atol=tol, max_steps=5_000_000)
        )

    _, first = timed(go)  # compiles
    sim, wall = timed(go)
    return outputs.trajectory(sim), wall, max(first - wall, 0.0), int(sim.num_steps), int(sim.num_rejected)


def errors(cols, ref, window):
    early = ref["t"] <= window
    return {
        "slider_x_m": float(np.abs(cols["slider_x"][early] - ref["slider_x"][early]).max()),
        "force_C_normal_N": float(np.abs(cols["force_C_normal"][early] - ref["force_C_normal"][early]).max()),
    }


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--t1", type=float, default=0.4, help="simulated time, s")
    ap.add_argument("--error-window", type=float, default=0.01, help="error measured over (0, window] s")
    ap.add_argument("--out", type=Path, default=Path("bench/results/work_precision.json"))
    ap.add_argument("--tols", help="comma-separated tolerances instead of each solver's list (a quick check)")
    args = ap.parse_args(argv)
    runs = RUNS if not args.tols else {solver: [float(t) for t in args.tols.split(",")] for solver in RUNS}
    mech = jc.paper()
    print("reference (tsit5, 1e-10) ...", flush=True)
    ref, ref_wall, _, ref_steps, _ = paper_run(mech, args.t1, "tsit5", 1e-10)
    check, *_ = paper_run(mech, args.t1, "rodas4", 1e-9)
    report = {
        "machine": machine(),
        "t1_s": args.t1,
        "error_window_s": args.error_window,
        "reference": {
            "solver": "tsit5",
            "tol": 1e-10,
            "wall_s": ref_wall,
            "steps": ref_steps,
            "error_of_rodas4_1e-9": errors(check, ref, args.error_window),
        },
        "runs": [],
    }
    for solver, tols in runs.items():
        for tol in tols:
            cols, wall, compile_s, steps, rejected = paper_run(mech, args.t1, solver, tol)
            row = {
                "solver": solver,
                "tol": tol,
                "wall_s": wall,
                "compile_s": compile_s,
                "steps": steps,
                "rejected": rejected,
                "error": errors(cols, ref, args.error_window),
            }
            report["runs"].append(row)
            print(
                f"{solver:7s} {tol:7.0e}  {wall:6.3f} s (compile {compile_s:4.1f} s)  {steps:7d} steps  slider error "
                f"{row['error']['slider_x_m']:.2e} m  force C error {row['error']['force_C_normal_N']:.2e} N",
                flush=True,
            )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(report, indent=2))

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4.5))
    for solver in RUNS:
        rows = [r for r in report["runs"] if r["solver"] == solver]
        ax.loglog([r["error"]["slider_x_m"] for r in rows], [r["wall_s"] for r in rows], "o-", label=solver)
        for r in rows:
            ax.annotate(
                f"{r['tol']:.0e}",
                (r["error"]["slider_x_m"], r["wall_s"]),
                fontsize=7,
                textcoords="offset points",
                xytext=(4, 4),
            )
    ax.set_xlabel(f"max |slider x error| over the first {args.error_window * 1e3:g} ms, m")
    ax.set_ylabel(f"wall time of the {args.t1:g} s paper run, s")
    ax.set_title("work-precision (labels: rtol = atol)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(args.out.with_suffix(".png"), dpi=120)
    print(f"wrote {args.out} and {args.out.with_suffix('.png')}")


if __name__ == "__main__":
    main()
