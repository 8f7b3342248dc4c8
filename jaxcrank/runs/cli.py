"""Command line: ``jaxcrank simulate [--config FILE | --design RESULT_JSON] [--out DIR]
[--set KEY=VALUE ...]``, ``jaxcrank sweep --spec FILE [--out DIR] [--resume]``, ``jaxcrank steady``
([`jaxcrank.runs.steady_cli`][]), ``jaxcrank regimes`` ([`jaxcrank.runs.regimes_cli`][]) and
``jaxcrank optimize`` ([`optim.cli`][]).

A command's options are added, and JAX imported, only once the command is named:
``jaxcrank --help`` lists the commands without loading JAX."""

from __future__ import annotations

import argparse
import csv
import json
import platform
import sys
import time
from pathlib import Path

from .. import __version__

#: the commands and their one-line help (``jaxcrank --help`` lists them without importing JAX)
COMMANDS = {
    "simulate": "simulate the clearance mechanism and write data, summary and figures",
    "sweep": "simulate many designs (grid, LHS, random, one-at-a-time, Monte Carlo), alone or in vmap batches",
    "steady": "find the steady state: periodic orbit and its Floquet multipliers, or chaos and long-run statistics",
    "regimes": "classify the steady-state regime (periodic and its period, or not) of every design of a sweep spec",
    "optimize": "minimise the RMS transmission-angle error (paper Eq. 19) or a design objective with optax",
    "assemble": "assemble a linkage at a driver angle: the poses, each dyad's branch, the lines that keep it",
}


def _simulate_parser(p):
    """Add ``simulate``'s options to its parser ``p``."""
    from ..numerics.solve import DEFAULTS, SOLVERS
    from . import config

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
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    return p


def run_simulate(args) -> int:
    import math

    import jax
    import numpy as np

    from ..analysis import outputs
    from ..numerics import solve
    from ..physics.params import ParameterError
    from . import config, plots

    mech = config.mechanism_from_arguments(args)
    if args.t1 <= 0:
        raise ParameterError(f"--t1 = {args.t1:g} s must be positive")
    degrees = math.degrees(float(mech.speed) * args.t1)
    n_samples = max(2, int(round(degrees * args.samples_per_degree)) + 1)

    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    config.save(mech, out / "config.toml")

    start = time.perf_counter()
    options = solve.SolveOptions.from_text(solver=args.solver, rtol=args.rtol, atol=args.atol, max_steps=args.max_steps)
    # Metrics after the first revolution (the start-up impacts left out); a run that
    # ends within it is summarised over its whole length, and says so.
    period = float(mech.period)
    after_first = args.t1 > period
    sim = solve.simulate(
        mech,
        args.t1,
        n_samples=n_samples,
        options=options,
        progress=not args.quiet,
        metrics_start=period if after_first else 0.0,
    )
    jax.block_until_ready(sim.ys)
    wall = time.perf_counter() - start
    cols = outputs.trajectory(sim)
    units = outputs.columns(mech)

    with open(out / "trajectory.csv", "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(list(units))
        for row in zip(*(cols[k] for k in units)):
            writer.writerow([f"{v:.10g}" for v in row])

    metrics = {**outputs.summary_metrics(sim), "window_end_s": float(cols["t"][-1])}
    window = _window_label(metrics, period)
    i0 = int(np.searchsorted(cols["t"], metrics["window_start_s"]))
    summary = {
        "jaxcrank_version": __version__,
        "versions": _versions(),
        "solver": {
            "name": args.solver,
            "rtol": args.rtol,
            "atol": args.atol,
            "steps": int(sim.num_steps),
            "rejected_steps": int(sim.num_rejected),
            "result": "successful",
        },
        "wall_time_s": wall,
        "wall_time_includes": "compilation, solve, progress bar",
        "simulated_time_s": args.t1,
        "samples": n_samples,
        "metrics_window": window,
        "metrics": metrics,
        "energy_balance": {
            "from_s": float(cols["t"][i0]),
            "to_s": float(cols["t"][-1]),
            **outputs.energy_balance(cols, i0=i0),
        },
        "closure_residual_max_m": outputs.closure_residual(sim),
        "mechanism": mech.linkage().name,
        "units": units,
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    if not args.no_figures:
        plots.save_figures(cols, mech, out / "figures")
    print(f"wrote {out}/ (trajectory.csv, config.toml, summary.json{'' if args.no_figures else ', figures/'})")
    print(f"  {int(sim.num_steps)} steps ({int(sim.num_rejected)} rejected) in {wall:.1f} s")
    print(f"  {window}: {_headline_text(summary['metrics'])}")
    return 0


def _headline_text(metrics: dict) -> str:
    """The largest deviations and the RMS transmission-angle error, in words."""
    parts = []
    for name, value in metrics.items():
        if name.startswith("max_abs_") and name.endswith("_deviation_m"):
            parts.append(f"max |{name[8:-12].replace('_', ' ')} dev| = {value * 1e3:.3f} mm")
        elif name.startswith("max_abs_") and name.endswith("_angle_deviation_deg"):
            parts.append(f"max |{name[8:-14].replace('_', ' ')} dev| = {value:.4f} deg")
    if "rms_transmission_angle_error_deg" in metrics:
        parts.append(f"RMS transmission-angle error = {metrics['rms_transmission_angle_error_deg']:.4f} deg")
    return ", ".join(parts)


def _window_label(metrics: dict, period: float) -> str:
    """What the metrics window of [`jaxcrank.analysis.outputs.summary_metrics`][] was, in words."""
    start, end = metrics["window_start_s"], metrics["window_end_s"]
    if start == 0.0:
        return f"over the whole run, 0 to {end:g} s (shorter than one revolution, {period:g} s)"
    return f"after the first revolution ({start:g} to {end:g} s)"


SWEEP_SPEC_HELP = """\
TOML spec (SI units; every key but [parameters] optional):

  sampling = "grid"    # grid | lhs | random | oat | monte_carlo
  samples = 64         # lhs, random, monte_carlo: number of designs
  points = 11          # oat: points per line
  seed = 0             # lhs, random, monte_carlo
  chunk = 16           # designs solved together (and per checkpoint); default by engine:
                       # kernel 16 per CPU thread; xla 1 per device on a CPU (each solved
                       # alone), on a GPU a vmap batch per device that fits in 80 % of its
                       # free memory (1024 per device where the backend reports none); a
                       # chunk needing more than the free memory is refused
  metrics = ["max_abs_slider_x_deviation_m", "peak_contact_force_C_N"]  # plotted (all are computed;
                       # the names are the mechanism's, e.g. max_abs_rocker_angle_deviation_deg)
  mechanism = "four-bar"  # the base mechanism: a preset (paper, four-bar, ...) or a [mechanism] table

  [parameters.clearance_B]          # any parameter: clearance_B, rod_length, contact.restitution, ...
  values = [1e-4, 2.5e-4, 5e-4]     # grid: explicit levels, or lower/upper/points
  # lower = 1e-4  upper = 5e-4  points = 5     (grid, lhs, random, oat)
  # nominal = 2.5e-4  tolerance = 5e-5  distribution = "uniform" | "normal" (+-3 sigma)  (monte_carlo)

  [simulation]         # revolutions = 4, samples_per_revolution = 3600, metrics_from_revolution = 1,
                       # solver = "tsit5", rtol = 1e-6, atol = 1e-6, max_steps = 500000
  [mechanism]          # or the base mechanism written out, as in `jaxcrank simulate`'s config.toml
                       # (its own mechanism = "four-bar" key, [mechanism.joints.B], ...)

--mechanism NAME, --config FILE or --design RESULT_JSON give the base mechanism instead
(the spec then has none); --set KEY=VALUE and --rpm change it.

Engines: --engine kernel (default where a C compiler is available: one design per CPU
thread, tsit5 only, chunk default 16 per thread) or --engine xla (every solver; several
CPU cores: --workers N local processes). --out records the engine (engine.txt) and
--resume keeps it. Several devices: every local
device is used (a GPU machine's GPUs). Several machines: see docs/sweeps.md, "On a cluster".
"""


def _sweep_parser(p):
    """Add ``sweep``'s options to its parser ``p``."""
    p.description = (
        "Run a sweep over mechanism parameters and write table.csv (one row per design: "
        "parameters, status, headline metrics), summary.json and figures/ into --out."
    )
    p.epilog = SWEEP_SPEC_HELP
    p.formatter_class = argparse.RawDescriptionHelpFormatter
    from . import config

    p.add_argument("--spec", type=Path, required=True, help="sweep spec TOML (see below)")
    config.add_mechanism_arguments(p, "sweep designs of")
    p.add_argument("--out", type=Path, default=Path("runs/sweep"), help="output directory (default runs/sweep)")
    p.add_argument("--resume", action="store_true", help="continue the sweep in --out where it stopped")
    p.add_argument(
        "--distributed",
        action="store_true",
        help="join a jax.distributed job first: under Slurm / Open MPI / Kubernetes the cluster "
        "is detected; otherwise give --coordinator, --num-processes and --process-id",
    )
    p.add_argument("--coordinator", metavar="HOST:PORT", help="address of process 0 (implies --distributed)")
    p.add_argument("--num-processes", type=int, help="processes in the job (with --coordinator)")
    p.add_argument("--process-id", type=int, help="this process's rank, 0 .. num-processes - 1 (with --coordinator)")
    p.add_argument(
        "--workers",
        type=int,
        default=1,
        help="local processes solving designs in parallel, e.g. one per CPU core (default 1)",
    )
    p.add_argument(
        "--engine",
        choices=("kernel", "xla"),
        default=None,
        help="kernel: each design's solve in one compiled C function, one design per CPU thread (tsit5; "
        "the default where a C compiler is available, for tsit5 without --workers or --distributed); "
        "xla: the compiled JAX solve (every solver)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    return p


def run_sweep(args) -> int:
    import jax

    from ..analysis import metrics
    from . import config, engines, plots, sweep
    from . import spec as spec_module

    if args.distributed or args.coordinator:
        jax.distributed.initialize(
            coordinator_address=args.coordinator, num_processes=args.num_processes, process_id=args.process_id
        )
    config.check_resume(args.out, args.resume)
    spec = spec_module.load_spec(args.spec, args)
    out = args.out
    if jax.process_index() == 0:
        out.mkdir(parents=True, exist_ok=True)
        (out / "spec.toml").write_text(args.spec.read_text())
    start = time.perf_counter()
    distributed = bool(args.distributed or args.coordinator)
    engine = engines.resolve(args.engine, spec.settings, args.workers, distributed, out, args.resume)
    # the chunk this sweep uses (on a GPU derived from its free memory), reported below
    chunk = spec.chunk if spec.chunk is not None or engine == "xla" else engines.default_chunk()
    chunk = sweep.resolve_chunk(spec.base, spec.names, spec.settings, chunk)
    table = sweep.run(
        spec.base,
        spec.names,
        spec.designs,
        spec.settings,
        out=out,
        resume=args.resume,
        chunk=chunk,
        workers=args.workers,
        progress=not args.quiet,
        engine=engine,
    )
    wall = time.perf_counter() - start
    if jax.process_index() != 0:
        return 0
    summary = sweep.summarize(table)
    summary.update(
        {
            "sampling": spec.sampling,
            "parameters": spec.names,
            "wall_time_s_this_call": wall,
            "devices": jax.device_count(),
            "processes": jax.process_count(),
            "workers": args.workers,
            "chunk": chunk,
            "engine": engine,
            "settings": spec.settings.to_text(),
            "versions": _versions(),
            "mechanism": spec.base.linkage().name,
            "metric_meanings": metrics.meanings(spec.base),
        }
    )
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    param_cols = sweep.parameter_columns(spec.base, spec.names)
    files = plots.sweep_figures(table, spec.sampling, param_cols, spec.metrics, out / "figures")
    counts = summary["status_counts"]
    print(
        f"wrote {out}/ (table.csv, summary.json, figures/: {len(files)} PNGs): {summary['designs']} designs, "
        + ", ".join(f"{k} {v}" for k, v in counts.items() if v)
    )
    return 0


def _versions():
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


def parser(command: str | None = None) -> argparse.ArgumentParser:
    """The ``jaxcrank`` argument parser; only ``command``'s options are added (the others'
    subparsers carry their one-line help), so that naming no command imports no JAX."""
    top = argparse.ArgumentParser(prog="jaxcrank", description="Differentiable planar linkages with joint clearances.")
    top.add_argument("--version", action="version", version=f"jaxcrank {__version__}")
    sub = top.add_subparsers(dest="command", required=True)
    for name, help_ in COMMANDS.items():
        p = sub.add_parser(name, help=help_)
        if name != command:
            continue
        if name == "simulate":
            _simulate_parser(p)
        elif name == "sweep":
            _sweep_parser(p)
        elif name == "steady":
            from . import steady_cli

            steady_cli.add_arguments(p)
        elif name == "regimes":
            from . import regimes_cli

            regimes_cli.add_arguments(p)
        elif name == "assemble":
            from . import assemble_cli

            assemble_cli.add_arguments(p)
        else:
            from optim import cli as optim_cli

            optim_cli.add_arguments(p)
    return top


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    command = next((a for a in argv if not a.startswith("-")), None)  # the first word names the command
    if command in COMMANDS and "jax" not in sys.modules and not {"-h", "--help", "--quiet"} & set(argv):
        # the first line within the first second: loading JAX, diffrax and optax takes one or two
        print(f"{command}: starting (loading JAX)", file=sys.stderr, flush=True)
    args = parser(command if command in COMMANDS else None).parse_args(argv)

    from ..errors import CorruptFileError
    from ..numerics.solve import SimulationError
    from ..numerics.steady import SteadyStateError
    from ..physics.params import ParameterError

    try:
        if args.command == "simulate":
            return run_simulate(args)
        if args.command == "sweep":
            return run_sweep(args)
        if args.command == "steady":
            from . import steady_cli

            return steady_cli.run(args)
        if args.command == "regimes":
            from . import regimes_cli

            return regimes_cli.run(args)
        if args.command == "optimize":
            from optim import cli as optim_cli

            return optim_cli.run(args)
        if args.command == "assemble":
            from . import assemble_cli

            return assemble_cli.run(args)
    except (ParameterError, SimulationError, SteadyStateError, CorruptFileError) as err:
        print(f"jaxcrank: error: {err}", file=sys.stderr)
        return 2
    except OSError as err:  # unwritable or full output directory, missing input file, ...
        where = f": {err.filename}" if err.filename else ""
        print(f"jaxcrank: error: {err.strerror or err}{where}", file=sys.stderr)
        return 2
    return 1


if __name__ == "__main__":
    sys.exit(main())
