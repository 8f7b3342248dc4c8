"""``jaxcrank regimes --spec FILE [--out DIR] [--resume]``: the steady-state regime of
every design of a sweep spec ([`jaxcrank.runs.regimes.classify`][]), with its table,
summary and, for a two-parameter grid, a regime map."""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from ..numerics.shooting import STEADY_DEFAULTS
from ..physics.params import ParameterError

#: the ``[simulation]`` keys of a sweep spec that a regime run uses (the others set a sweep's run length)
USED_SIMULATION_KEYS = ("solver", "rtol", "atol", "max_steps")

REGIMES_SPEC_HELP = """\
The spec is a `jaxcrank sweep` spec (see `jaxcrank sweep --help`): sampling, samples,
seed, chunk, [parameters.<name>] and mechanism (a preset's name, mechanism = "four-bar",
or a [mechanism] table) as there; --mechanism, --config or --design give the mechanism
instead, --set and --rpm change it. From [simulation] only
solver, rtol, atol and max_steps are used (max_steps: the step budget of a design's
whole settle); unset, they are the steady-state defaults (tsit5, 1e-10, 1e-10,
2000000), and the command-line options below override them. revolutions,
samples_per_revolution and metrics_from_revolution set a sweep's run and are ignored:
the settle is --settle-revolutions long.

Writes table.csv (index, parameters, status, message, regime, period_revolutions,
recurrence_distance_scaled, steps), summary.json (counts per status, regime and
period, engine, settings, wall time) and, for a two-parameter grid, regime_map.png.
"""


def add_arguments(p):
    """Add ``regimes``' options to its parser ``p``."""
    import argparse

    p.description = (
        "Classify the steady-state regime of every design of a sweep spec: settle from rest, then "
        "look for the smallest period (revolutions) whose Poincare-section points recur."
    )
    p.epilog = REGIMES_SPEC_HELP
    p.formatter_class = argparse.RawDescriptionHelpFormatter
    from . import config

    p.add_argument("--spec", type=Path, required=True, help="sweep spec TOML (see below)")
    config.add_mechanism_arguments(p, "classify designs of")
    p.add_argument("--out", type=Path, default=Path("runs/regimes"), help="output directory (default runs/regimes)")
    p.add_argument("--resume", action="store_true", help="continue the run in --out where it stopped")
    p.add_argument("--settle-revolutions", type=int, default=20, help="revolutions from rest (20)")
    p.add_argument("--max-period", type=int, default=4, help="longest period looked for, revolutions (4)")
    p.add_argument(
        "--recurrence-tol", type=float, default=1e-3, help="recurrence tolerance, scaled units: clearances (1e-3)"
    )
    p.add_argument("--rtol", type=float, help="relative tolerance (default: the spec's, else 1e-10)")
    p.add_argument("--atol", type=float, help="absolute tolerance (default: the spec's, else 1e-10)")
    p.add_argument("--max-steps", type=int, help="step budget of a design's settle (default: the spec's, else 2000000)")
    p.add_argument(
        "--engine",
        choices=("kernel", "xla"),
        default=None,
        help="kernel: one design per CPU thread, tsit5 only (the default where a C compiler is available; "
        "--resume keeps the run's engine); xla: the JAX path",
    )
    p.add_argument("--threads", type=int, help="kernel threads (default: the CPUs this process may use)")
    p.add_argument("--no-figures", action="store_true", help="skip regime_map.png")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    from . import cache

    cache.arguments(p)
    return p


def load(path, arguments=None):
    """(spec, solve options) of a regime run from a sweep spec TOML file; ``arguments``:
    command-line options that choose or change its mechanism
    ([`jaxcrank.runs.spec.base_mechanism`][])."""
    from . import config
    from .spec import base_mechanism, spec_from_dict

    def build(d):
        sim = dict(d.get("simulation", {}))
        changes = {k: sim[k] for k in USED_SIMULATION_KEYS if k in sim}
        spec = spec_from_dict(d, base_mechanism(d, arguments))
        options = STEADY_DEFAULTS
        if "solver" in changes:
            from ..numerics.solve import solver_from_name

            options = options.replace(solver=solver_from_name(changes.pop("solver")))
        return spec, options.replace(**changes)

    return config.load_toml(path, build)


def regime_map(table, mech, names, path: Path) -> Path:
    """A two-parameter grid's regime map: one cell per design, coloured by its period in
    crank revolutions (periodic), grey (not periodic) or white with a red cross (failed or
    invalid), the period written in the cell; the grid's levels (SI, units on the axes)
    label the cells, so uneven or logarithmic levels stay readable. ``mech``: the base
    mechanism (the parameters' units)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import ListedColormap

    from ..physics.parameters import parameter_unit
    from .plots import DPI, _label, style
    from .sweep_table import parameter_columns

    cols = parameter_columns(mech, names)
    a, b = (np.asarray(table[c]) for c in cols)
    ua, ub = np.unique(a), np.unique(b)
    ia, ib = np.searchsorted(ua, a), np.searchsorted(ub, b)
    regime = np.asarray(table["regime"])
    code = np.where(regime == "periodic", np.asarray(table["period_revolutions"]), np.where(regime == "", np.nan, 0.0))
    k_max = int(np.nanmax(code, initial=0.0))
    z = np.full((len(ua), len(ub)), np.nan)
    z[ia, ib] = code
    colours = ["0.75"] + [plt.get_cmap("viridis")(0.35 + 0.6 * i / max(k_max - 1, 1)) for i in range(k_max)]
    with style():
        fig, ax = plt.subplots(figsize=(6.4, 4.8), layout="constrained")
        im = ax.pcolormesh(np.arange(len(ub)), np.arange(len(ua)), z, shading="nearest", cmap=ListedColormap(colours),
                           vmin=-0.5, vmax=k_max + 0.5)  # fmt: skip
        ax.grid(False)
        ax.spines[:].set_visible(True)
        bar = fig.colorbar(im, ax=ax, ticks=range(k_max + 1))
        bar.ax.set_yticklabels(["not periodic"] + [f"period {k}" for k in range(1, k_max + 1)])
        bar.set_label("steady-state regime (period in crank revolutions)")
        for i, j, k in zip(ia, ib, code):
            ax.text(j, i, "x" if np.isnan(k) else ("-" if k == 0 else str(int(k))), ha="center", va="center",
                    color="red" if np.isnan(k) else "black", fontsize=9)  # fmt: skip
        ax.set_xticks(np.arange(len(ub)), [f"{v:.4g}" for v in ub], rotation=45 if len(ub) > 6 else 0)
        ax.set_yticks(np.arange(len(ua)), [f"{v:.4g}" for v in ua])
        ax.set_xlabel(_label(f"{names[1]}_{parameter_unit(mech, names[1])}"))
        ax.set_ylabel(_label(f"{names[0]}_{parameter_unit(mech, names[0])}"))
        title = f"Regime map, {mech.linkage().name}"
        ax.set_title(f"{title} (x: failed or invalid)" if np.isnan(code).any() else title, loc="left")
        fig.savefig(path, dpi=DPI)
    plt.close(fig)
    return path


def run(args) -> int:
    from . import cache, config, regimes

    cache.use(args, "regimes")

    config.check_resume(args.out, args.resume)
    spec, options = load(args.spec, args)
    options = options.replace(rtol=args.rtol, atol=args.atol, max_steps=args.max_steps)
    if args.threads is not None and args.threads < 1:
        raise ParameterError(f"--threads = {args.threads} must be >= 1")
    engine = regimes.resolve_engine(args.engine, options, args.out, args.resume, spec.base)
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    (out / "spec.toml").write_text(args.spec.read_text())
    start = time.perf_counter()
    table = regimes.classify(
        spec.base,
        spec.names,
        spec.designs,
        settle_revolutions=args.settle_revolutions,
        max_period=args.max_period,
        recurrence_tol=args.recurrence_tol,
        options=options,
        engine=engine,
        out=out,
        resume=args.resume,
        chunk=spec.chunk,
        threads=args.threads,
        progress=not args.quiet,
    )
    wall = time.perf_counter() - start
    summary = regimes.summarize(table)
    summary.update(
        {
            "sampling": spec.sampling,
            "parameters": spec.names,
            "mechanism": spec.base.linkage().name,
            "engine": engine,
            "settle_revolutions": args.settle_revolutions,
            "max_period_revolutions": args.max_period,
            "recurrence_tol_scaled": args.recurrence_tol,
            "solver": {
                "name": options.solver_name,
                "rtol": options.rtol,
                "atol": options.atol,
                "max_steps_per_settle": options.max_steps,
            },
            "wall_time_s_this_call": wall,
            "wall_time_includes": "kernel compilation or XLA compilation, and every solve of this call",
        }
    )
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    written = ["table.csv", "summary.json"]
    if spec.sampling == "grid" and len(spec.names) == 2 and not args.no_figures:
        regime_map(table, spec.base, spec.names, out / "regime_map.png")
        written.append("regime_map.png")
    counts = {**summary["regime_counts"], **{k: v for k, v in summary["status_counts"].items() if k != "ok"}}
    print(
        f"wrote {out}/ ({', '.join(written)}): {summary['designs']} designs, "
        + ", ".join(f"{k} {v}" for k, v in counts.items() if v)
        + f"; {engine} engine, {wall:.1f} s"
    )
    return 0
