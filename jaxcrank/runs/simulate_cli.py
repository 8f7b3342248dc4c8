"""``jaxcrank simulate``: one run of a mechanism (a preset, or a description in TOML with
``--set`` overrides) written to a run folder: ``trajectory.csv`` (every output at every
sample, units in ``summary.json``), ``config.toml`` (the resolved description), ``summary.json``
(solver statistics, phases, metrics after the first revolution, energy balance) and the
figures."""

from __future__ import annotations

import json
import platform
import sys
import time
from pathlib import Path

from .. import __version__


def add_arguments(p):
    """Add ``simulate``'s options to its parser ``p``."""
    from ..numerics.solve import DEFAULTS, SOLVERS
    from . import cache, config

    p.description = (
        "Simulate a planar linkage with clearance joints (a preset, your own linkage from --config, or an "
        "optimised design; the paper's offset slider-crank unless --mechanism/--config/--design say otherwise) "
        "and write trajectory.csv, config.toml, summary.json and figures/ into --out."
    )
    config.add_mechanism_arguments(p, "simulate")
    p.add_argument("--out", type=Path, default=Path("runs/paper"), help="run directory (default: runs/paper)")
    p.add_argument("--t1", type=float, default=0.4, help="simulated time, s (default 0.4 = 4 revolutions at 600 rpm)")
    p.add_argument(
        "--samples-per-degree", type=float, default=10.0, help="output samples per degree of crank angle (default 10)"
    )
    p.add_argument(
        "--solver",
        choices=sorted(SOLVERS),
        default=DEFAULTS.solver_name,
        help=f"ODE solver (default {DEFAULTS.solver_name})",
    )
    p.add_argument(
        "--rtol",
        type=float,
        default=DEFAULTS.rtol,
        help=f"relative tolerance on the scaled state (default {DEFAULTS.rtol:g})",
    )
    p.add_argument(
        "--atol",
        type=float,
        default=DEFAULTS.atol,
        help=f"absolute tolerance on the scaled state (default {DEFAULTS.atol:g})",
    )
    p.add_argument(
        "--max-steps", type=int, default=DEFAULTS.max_steps, help=f"solver step budget (default {DEFAULTS.max_steps})"
    )
    p.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    p.add_argument(
        "--against",
        choices=("angle", "time"),
        default="angle",
        help="the figures' x axis: the driven body's angle since the start, deg (default), or time, s",
    )
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.add_argument(
        "--fold-parameters",
        action="store_true",
        help="compile the mechanism's numbers into the solve as constants, which XLA can fold (for a long "
        "run of one design); every --set variant then compiles its own program",
    )
    p.add_argument(
        "--progress",
        action="store_true",
        help="a progress bar of the simulated time on a terminal (its program is compiled for this run, not kept in "
        "the cache)",
    )
    cache.arguments(p)
    return p


def run(args) -> int:
    import math

    import jax
    import numpy as np

    from ..analysis import outputs
    from ..analysis.kinematic_summary import format_summary, kinematic_summary
    from ..numerics import solve
    from ..physics.params import ParameterError
    from . import cache, config, programs

    mech = config.mechanism_from_arguments(args)
    if args.t1 <= 0:
        raise ParameterError(f"--t1 = {args.t1:g} s must be positive")
    degrees = math.degrees(float(mech.speed) * args.t1)
    n_samples = max(2, int(round(degrees * args.samples_per_degree)) + 1)
    options = solve.SolveOptions.from_text(solver=args.solver, rtol=args.rtol, atol=args.atol, max_steps=args.max_steps)
    cache.use(args, "simulate")

    start = time.perf_counter()
    # Metrics after the first revolution (the start-up impacts left out); a run that
    # ends within it is summarised over its whole length, and says so. A torque-driven
    # body's first turn is found in the run and the metrics tracked again from there.
    period = float(mech.period)
    prescribed = mech.linkage().driver.prescribed
    metrics_start = period if args.t1 > period else 0.0

    def run(metrics_start, label=None):
        if args.progress and sys.stderr.isatty():  # elsewhere the phases' plain lines, as without it
            sim = solve.simulate(
                mech, args.t1, n_samples=n_samples, options=options, progress=True, metrics_start=metrics_start
            )
            jax.block_until_ready(sim.ys)
            return sim, {"loaded": False}
        return programs.simulate(
            mech, args.t1, n_samples, options, metrics_start, quiet=args.quiet, label=label, fold=args.fold_parameters
        )

    sim, phases = run(metrics_start)
    every, phases["outputs"] = programs.frames(sim, quiet=args.quiet)
    cols = outputs.trajectory(sim, every)
    if not prescribed:
        first_turn = _first_turn(cols, mech.linkage().driver.body)
        metrics_start = 0.0 if first_turn is None else first_turn
        # the same steps again; only the tracked window moves
        sim, again = run(metrics_start, "tracking the metrics from the driven body's first revolution")
        phases["window"] = again.get("solve", 0.0)
    wall = time.perf_counter() - start

    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    config.save(mech, out / "config.toml")
    units = outputs.columns(mech)

    table = np.stack([np.asarray(cols[k], dtype=float) for k in units], axis=1)
    with open(out / "trajectory.csv", "w", newline="") as fh:  # 10 significant digits, as csv.writer wrote them
        np.savetxt(fh, table, fmt="%.10g", delimiter=",", newline="\r\n", header=",".join(units), comments="")

    metrics = {**outputs.summary_metrics(sim), "window_end_s": float(cols["t"][-1])}
    try:
        kinematics = kinematic_summary(mech)
    except ParameterError as err:  # the run stands without it
        kinematics = {"unavailable": str(err)}
    window = _window_label(metrics, period, prescribed)
    i0 = int(np.searchsorted(cols["t"], metrics["window_start_s"]))
    summary = {
        "jaxcrank_version": __version__,
        "versions": versions(),
        "solver": {
            "name": args.solver,
            "rtol": args.rtol,
            "atol": args.atol,
            "steps": int(sim.num_steps),
            "rejected_steps": int(sim.num_rejected),
            "result": "successful",
        },
        "wall_time_s": wall,
        "wall_time_includes": "compilation (or loading it from the cache), solve",
        "phases_s": {k: v for k, v in phases.items() if k != "loaded"},
        "program_from_cache": phases.get("loaded", False),
        "simulated_time_s": args.t1,
        "samples": n_samples,
        "metrics_window": window,
        "metrics": metrics,
        "energy_balance": {
            "from_s": float(cols["t"][i0]),
            "to_s": float(cols["t"][-1]),
            **outputs.energy_balance(cols, i0=i0),
        },
        "closure_residual_max_m": float(np.max(every.closure_residual)) if every.closure_residual.size else 0.0,
        "mechanism": mech.linkage().name,
        "kinematics": kinematics,
        "units": units,
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    if not args.no_figures:
        from . import plots

        plots.save_figures(cols, mech, out / "figures", against=args.against)
        _save_drawing(mech, out / "figures" / "linkage.png")
    print(f"wrote {out}/ (trajectory.csv, config.toml, summary.json{'' if args.no_figures else ', figures/'})")
    print(f"  {int(sim.num_steps)} steps ({int(sim.num_rejected)} rejected) in {wall:.1f} s, compilation included")
    print(f"  {window}: {headline_text(summary['metrics'])}")
    print("  the ideal mechanism over a turn of the driver:")
    for line in [kinematics["unavailable"]] if "unavailable" in kinematics else format_summary(kinematics):
        print(f"    {line}")
    return 0


def _save_drawing(mech, path) -> None:
    """The linkage drawn at its driver's initial angle ([`jaxcrank.views.drawing.draw`][]) into ``path``."""
    import matplotlib.pyplot as plt

    from ..views.drawing import draw

    fig = draw(mech)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def headline_text(metrics: dict) -> str:
    """The largest deviations and the RMS transmission-angle error, in words; without those (a
    linkage without ``[outputs]``), the largest peak contact force and the peak driving moment."""
    parts = []
    for name, value in metrics.items():
        if name.startswith("max_abs_") and name.endswith("_deviation_m"):
            parts.append(f"max |{name[8:-12].replace('_', ' ')} dev| = {value * 1e3:.3f} mm")
        elif name.startswith("max_abs_") and name.endswith("_angle_deviation_deg"):
            parts.append(f"max |{name[8:-14].replace('_', ' ')} dev| = {value:.4f} deg")
    if "rms_transmission_angle_error_deg" in metrics:
        parts.append(f"RMS transmission-angle error = {metrics['rms_transmission_angle_error_deg']:.4f} deg")
    if parts:
        return ", ".join(parts)
    forces = {k: v for k, v in metrics.items() if k.startswith("peak_contact_force_") and "_whole_run" not in k}
    if forces:
        name = max(forces, key=forces.get)
        parts.append(f"peak contact force at {name[len('peak_contact_force_') : -2]} = {forces[name]:.4g} N")
    if "peak_driving_moment_N_m" in metrics:
        parts.append(f"peak driving moment = {metrics['peak_driving_moment_N_m']:.4g} N m")
    return ", ".join(parts)


def _first_turn(cols, body: str) -> float | None:
    """The time the driven ``body`` first completes one revolution from its start angle,
    s (linear between samples), or ``None`` where it never does in the run."""
    import numpy as np

    t = np.asarray(cols["t"], dtype=float)
    turned = np.abs(np.asarray(cols[f"{body}_angle"], dtype=float) - float(cols[f"{body}_angle"][0]))
    i = int(np.argmax(turned >= 360.0))
    if turned[i] < 360.0:
        return None
    if i == 0:
        return float(t[0])
    return float(t[i - 1] + (t[i] - t[i - 1]) * (360.0 - turned[i - 1]) / (turned[i] - turned[i - 1]))


def _window_label(metrics: dict, period: float, prescribed: bool = True) -> str:
    """What the metrics window of [`jaxcrank.analysis.outputs.summary_metrics`][] was, in words."""
    start, end = metrics["window_start_s"], metrics["window_end_s"]
    if start == 0.0:
        if prescribed:
            return f"over the whole run, 0 to {end:g} s (shorter than one revolution, {period:g} s)"
        return f"over the whole run, 0 to {end:g} s (the driven body did not complete a revolution)"
    return f"after the first revolution ({start:g} to {end:g} s)"


def versions() -> dict:
    """The versions of Python, JAX, diffrax, equinox, numpy and the XLA setting, for a run's summary."""
    import diffrax
    import equinox
    import jax
    import numpy

    from ..numerics import runtime

    return {
        "python": platform.python_version(),
        "jax": jax.__version__,
        "diffrax": diffrax.__version__,
        "equinox": equinox.__version__,
        "numpy": numpy.__version__,
        "xla": runtime.describe(),
    }
