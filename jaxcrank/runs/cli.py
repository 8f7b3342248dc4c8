"""Command line: ``jaxcrank simulate [--config FILE | --design RESULT_JSON] [--out DIR]
[--set KEY=VALUE ...]``, ``jaxcrank sweep --spec FILE [--out DIR] [--resume]``, ``jaxcrank steady``
([`jaxcrank.runs.steady_cli`][]), ``jaxcrank regimes`` ([`jaxcrank.runs.regimes_cli`][]),
``jaxcrank life`` ([`jaxcrank.runs.life_cli`][]), ``jaxcrank optimize`` ([`optim.cli`][]),
``jaxcrank fit`` ([`optim.fit_cli`][]), ``jaxcrank assemble``, ``jaxcrank draw`` and
``jaxcrank animate`` ([`jaxcrank.runs.view_cli`][]).

A command's options are added, and JAX imported, only once the command is named:
``jaxcrank --help`` lists the commands without loading JAX."""

from __future__ import annotations

import argparse
import json
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
    "fit": "calibrate parameters (clearances, restitution, ...) against a measured trace, with confidence intervals",
    "assemble": "assemble a linkage at a driver angle: the poses, each dyad's branch, the lines that keep it",
    "draw": "draw a linkage at a driver angle (PNG, SVG, PDF) and print its kinematic summary",
    "life": "wear the mechanism's worn joints over many cycles: worn profiles, metrics and the life to a limit",
    "animate": "animate a run's mechanism (GIF, MP4, HTML), the ideal one beside it and the pins in their holes",
}


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
    from . import cache

    cache.arguments(p)
    return p


def run_sweep(args) -> int:
    import jax

    from ..analysis import metrics
    from . import cache, config, engines, plots, simulate_cli, sweep
    from . import spec as spec_module

    cache.use(args, "sweep")
    if args.distributed or args.coordinator:
        jax.distributed.initialize(
            coordinator_address=args.coordinator, num_processes=args.num_processes, process_id=args.process_id
        )
    config.check_resume(args.out, args.resume)
    spec = spec_module.load_spec(args.spec, args)
    out = args.out
    if jax.process_index() == 0:
        out.mkdir(parents=True, exist_ok=True)
        if not (args.resume and (out / "spec.toml").exists()):  # a resumed run keeps its record
            (out / "spec.toml").write_text(args.spec.read_text())
    start = time.perf_counter()
    distributed = bool(args.distributed or args.coordinator)
    engine = engines.resolve(args.engine, spec.settings, args.workers, distributed, out, args.resume, spec.base)
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
            "versions": simulate_cli.versions(),
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
            from . import simulate_cli

            simulate_cli.add_arguments(p)
        elif name == "sweep":
            _sweep_parser(p)
        elif name == "steady":
            from . import steady_cli

            steady_cli.add_arguments(p)
        elif name == "regimes":
            from . import regimes_cli

            regimes_cli.add_arguments(p)
        elif name == "life":
            from . import life_cli

            life_cli.add_arguments(p)
        elif name == "assemble":
            from . import assemble_cli

            assemble_cli.add_arguments(p)
        elif name in ("draw", "animate"):
            from . import view_cli

            (view_cli.add_draw_arguments if name == "draw" else view_cli.add_animate_arguments)(p)
        elif name == "fit":
            from optim import fit_cli

            fit_cli.add_arguments(p)
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

    from ..analysis.life import LifeError
    from ..errors import CorruptFileError
    from ..numerics.solve import SimulationError
    from ..numerics.steady import SteadyStateError
    from ..physics.params import ParameterError

    try:
        if args.command == "simulate":
            from . import simulate_cli

            return simulate_cli.run(args)
        if args.command == "sweep":
            return run_sweep(args)
        if args.command == "steady":
            from . import steady_cli

            return steady_cli.run(args)
        if args.command == "regimes":
            from . import regimes_cli

            return regimes_cli.run(args)
        if args.command == "life":
            from . import life_cli

            return life_cli.run(args)
        if args.command == "optimize":
            if (args.problem or "").endswith(".toml"):  # a problem file: optim.file_cli
                from optim import file_cli

                return file_cli.run(args)
            from optim import cli as optim_cli

            return optim_cli.run(args)
        if args.command == "fit":
            from optim import fit_cli

            return fit_cli.run(args)
        if args.command == "assemble":
            from . import assemble_cli

            return assemble_cli.run(args)
        if args.command in ("draw", "animate"):
            from . import view_cli

            return (view_cli.run_draw if args.command == "draw" else view_cli.run_animate)(args)
    except (ParameterError, SimulationError, SteadyStateError, LifeError, CorruptFileError) as err:
        print(f"jaxcrank: error: {err}", file=sys.stderr)
        return 2
    except OSError as err:  # unwritable or full output directory, missing input file, ...
        where = f": {err.filename}" if err.filename else ""
        print(f"jaxcrank: error: {err.strerror or err}{where}", file=sys.stderr)
        return 2
    return 1


if __name__ == "__main__":
    sys.exit(main())
