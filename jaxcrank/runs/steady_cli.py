"""``jaxcrank steady [--mechanism NAME | --config FILE | --design RESULT_JSON] [--set KEY=VALUE ...]
--out DIR``: the steady state of a mechanism ([`jaxcrank.numerics.steady.steady_state`][]) with its summary, one
period of the orbit, its figures and a Poincare-section plot."""

from __future__ import annotations

import csv
import json
import time
from pathlib import Path

from ..numerics.shooting import STEADY_DEFAULTS, SteadyOptions
from ..numerics.solve import SOLVERS, solver_from_name
from ..physics.params import ParameterError
from . import config


def add_arguments(p):
    """Add ``steady``'s options to its parser ``p``."""
    p.description = (
        "Settle from rest, then shoot for the periodic orbit of the once-per-revolution Poincare map. "
        "Writes summary.json (regime, period_revolutions, floquet_multipliers, the steady-state metrics), "
        "orbit.csv (one period), config.toml, figures/ and poincare_section.png into --out."
    )
    config.add_mechanism_arguments(p, "find the steady state of")
    p.add_argument("--out", type=Path, default=Path("runs/steady"), help="run directory (default: runs/steady)")
    p.add_argument("--settle-revolutions", type=int, default=20, help="revolutions from rest before shooting (20)")
    p.add_argument("--max-period", type=int, default=4, help="longest period looked for, revolutions (4)")
    p.add_argument("--newton-tol", type=float, default=1e-7, help="shooting tolerance, scaled units (1e-7)")
    p.add_argument(
        "--statistics-revolutions", type=int, default=10, help="not periodic: revolutions of the statistics run (10)"
    )
    p.add_argument("--batch-revolutions", type=int, default=2, help="revolutions per batch of the batch means (2)")
    p.add_argument(
        "--samples-per-revolution", type=int, default=3600, help="samples per revolution of the orbit (3600)"
    )
    p.add_argument("--solver", choices=sorted(SOLVERS), default=STEADY_DEFAULTS.solver_name, help="ODE solver")
    p.add_argument("--rtol", type=float, default=STEADY_DEFAULTS.rtol, help="relative tolerance (1e-10)")
    p.add_argument("--atol", type=float, default=STEADY_DEFAULTS.atol, help="absolute tolerance (1e-10)")
    p.add_argument("--max-steps", type=int, default=STEADY_DEFAULTS.max_steps, help="step budget per solve (2000000)")
    p.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    p.add_argument("--quiet", action="store_true", help="no progress on standard error")
    from . import cache

    cache.arguments(p)
    return p


def _section_eccentricities(steady):
    """Pin eccentricities at the settle's section points and at y*, in clearances:
    joint -> (points (n, 2), orbit point (2,))."""
    import numpy as np

    from ..physics import model

    mech = steady.mechanism
    compiled = model.compile_model(mech)
    lk, tree = compiled.linkage, compiled.tree
    out = {}
    for i, joint in enumerate(tree.cut):
        c = float(lk.joints[joint].clearance)
        pts = []
        for n, y in enumerate(np.asarray(steady.section_points)):
            d, _ = model.joint_eccentricities(mech, n * float(mech.period), y)
            pts.append(np.asarray(d[i]) / c)
        d, _ = model.joint_eccentricities(mech, 0.0, steady.section_state)
        out[joint] = (np.array(pts), np.asarray(d[i]) / c)
    return out


#: half the width of a joint's panel of the Poincare plot, clearances
_EXTENT = 1.15


def _zoom(ax, pts, star, cmap, norm):
    """An inset of ``ax`` (in the corner away from them) zoomed on the section points
    after the start from rest and on ``star``, where they gather within 0.3 clearances."""
    import numpy as np

    near = np.vstack([pts[1:], star[None, :]])
    lo, hi = near.min(axis=0), near.max(axis=0)
    if len(pts) < 3 or np.max(hi - lo) > 0.3:
        return
    centre, half = (lo + hi) / 2, max(0.6 * float(np.max(hi - lo)), 0.01)
    inset = ax.inset_axes([0.03 if centre[0] > 0 else 0.55, 0.03 if centre[1] > 0 else 0.55, 0.42, 0.42])
    theta = np.linspace(0, 2 * np.pi, 2000)
    inset.plot(np.cos(theta), np.sin(theta), color="0.6", lw=0.8)
    inset.scatter(*pts.T, c=np.arange(len(pts)), cmap=cmap, norm=norm, s=22, edgecolors="k", linewidths=0.4, zorder=3)
    inset.plot(star[0], star[1], "*", ms=16, mfc="none", mec="C3", mew=1.5, zorder=2)
    inset.set_xlim(centre[0] - half, centre[0] + half)
    inset.set_ylim(centre[1] - half, centre[1] + half)
    inset.set_aspect("equal")
    inset.tick_params(labelleft=False, labelbottom=False, length=0)
    inset.grid(False)
    inset.spines[:].set_visible(True)
    note = f"zoom ×{0.42 * 2 * _EXTENT / (2 * half):.0f}"  # on the inset's side away from the axes' edge
    if centre[1] > 0:
        inset.set_title(note, fontsize="small", pad=2)
    else:
        inset.set_xlabel(note, fontsize="small")
    _, connectors = ax.indicate_inset_zoom(inset, edgecolor="0.4")
    for line in connectors:
        line.set_visible(False)


def poincare_plot(steady, path: Path) -> Path:
    """The Poincare section (crank at its initial angle, once per revolution): pin
    eccentricity in each clearance bearing, in units of its clearance, at the settle's
    section points (coloured by revolution, one colour bar for the panels; an inset
    zooms on them where they gather) and at the orbit's start state (an open star under
    them); and, by revolution, the distance of the section points to that state
    (periodic) or to the section point before (not periodic), scaled units. Drawn in
    `jaxcrank.runs.plots.STYLE`."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    from matplotlib.colors import BoundaryNorm
    from matplotlib.ticker import MaxNLocator

    from .plots import DPI, style

    ecc = _section_eccentricities(steady)
    m = np.asarray(steady.monodromy).shape[0]
    pts_all = np.asarray(steady.section_points)[:, :m]
    n = len(pts_all)
    norm = BoundaryNorm(np.arange(-0.5, n + 0.5), n)
    cmap = plt.get_cmap("viridis", n)
    with style():
        fig, axes = plt.subplots(1, len(ecc) + 1, figsize=(4.2 * (len(ecc) + 1) + 1.0, 4.6), squeeze=False,
                                 layout="constrained")  # fmt: skip
        ax = axes[0, -1]
        if steady.regime == "periodic":
            gap = np.max(np.abs(pts_all - np.asarray(steady.section_state)[:m]), axis=1)
            revs = np.arange(len(gap))
            ax.set_ylabel("max |y_n − y*| (scaled)")
            ax.set_title("distance to the orbit's start", loc="left")
        else:  # the last section point is the state shown: compare each point with the one before instead
            gap = np.max(np.abs(np.diff(pts_all, axis=0)), axis=1)
            revs = np.arange(1, len(gap) + 1)
            ax.set_ylabel("max |y_n − y_(n−1)| (scaled)")
            ax.set_title("distance between successive points", loc="left")
        gap = np.maximum(gap, 1e-16)
        ax.plot(revs, gap, "o-", ms=4, color="0.3")
        if gap.max() > 10.0 * gap.min():  # a log scale where the distances span a decade or more
            ax.set_yscale("log")
        ax.set_xlabel("revolution of the settle")
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        theta = np.linspace(0, 2 * np.pi, 200)
        label = "orbit start y*" if steady.regime == "periodic" else "last section point"
        for ax, (joint, (pts, star)) in zip(axes[0], ecc.items()):
            ax.plot(np.cos(theta), np.sin(theta), color="0.6", lw=0.8, label="clearance circle")
            ax.scatter(pts[:, 0], pts[:, 1], c=np.arange(len(pts)), cmap=cmap, norm=norm, s=22, edgecolors="k",
                       linewidths=0.4, zorder=3, label="section points")  # fmt: skip
            ax.plot(star[0], star[1], "*", ms=16, mfc="none", mec="C3", mew=1.5, zorder=2, label=label)
            ax.set_aspect("equal")
            ax.set_xlim(-_EXTENT, _EXTENT)
            ax.set_ylim(-_EXTENT, _EXTENT)
            ax.set_xlabel("e_x / clearance")
            ax.set_ylabel("e_y / clearance")
            ax.set_title(f"joint {joint}", loc="left")
            _zoom(ax, pts, star, cmap, norm)
        axes[0, 0].legend(loc="upper left", bbox_to_anchor=(0.0, -0.14), ncol=3, fontsize="small")
        bar = fig.colorbar(plt.cm.ScalarMappable(norm=norm, cmap=cmap), ax=list(axes[0, :-1]), shrink=0.85)
        bar.set_label("revolution of the settle")
        bar.ax.yaxis.set_major_locator(MaxNLocator(integer=True, nbins=min(n, 8)))
        k = steady.period_revolutions
        fig.suptitle(f"Poincare section: {steady.regime}" + (f", period {k} revolution(s)" if k else ""))
        fig.savefig(path, dpi=DPI)
    plt.close(fig)
    return path


def summary(steady, wall: float, args) -> dict:
    """summary.json's content (units in key names; scaled units are clearances)."""
    import numpy as np

    mult = np.asarray(steady.floquet_multipliers)
    return {
        "mechanism": steady.mechanism.linkage().name,
        "regime": steady.regime,
        "regime_within_revolutions": steady.revolutions["settle"] + steady.revolutions["statistics"],
        "regime_note": (
            f"period found after {steady.revolutions['settle']} revolution(s) from rest"
            if steady.regime == "periodic"
            else f"no period up to {args.max_period} revolution(s) within "
            f"{steady.revolutions['settle'] + steady.revolutions['statistics']} revolutions from rest: a design "
            "that settles later is periodic all the same (try more --settle-revolutions)"
        ),
        "period_revolutions": steady.period_revolutions,
        "floquet_multipliers": [float(v) for v in np.abs(mult)],
        "floquet_multipliers_complex": [[float(v.real), float(v.imag)] for v in mult],
        "floquet_multipliers_note": (
            "per period, on the dynamic subspace, largest modulus first"
            if steady.regime == "periodic"
            else "finite-time: the one-revolution map's at the last section point"
        ),
        "neutral_directions": list(steady.neutral),
        "newton_residual_scaled": float(steady.residual),
        "newton_iterations": steady.newton_iterations,
        "lyapunov_exponent_per_s": float(steady.lyapunov_exponent_per_s),
        "metrics_window": (
            f"one period of the orbit ({steady.period_revolutions} revolution(s))"
            if steady.regime == "periodic"
            else f"long-run statistics over {args.statistics_revolutions} revolutions: an RMS metric's long-run "
            "RMS, a peak the largest over those revolutions (statistics: the per-revolution mean with its "
            "batch-means 95 % CI, and that largest as max)"
        ),
        "metrics": {k: float((steady.statistics or {}).get(k, {}).get("max", v)) for k, v in steady.metrics.items()},
        "statistics": steady.statistics,
        "revolutions_solved": dict(steady.revolutions),
        "solver": {"name": args.solver, "rtol": args.rtol, "atol": args.atol, "max_steps": args.max_steps},
        "wall_time_s": wall,
        "wall_time_includes": "compilation and every solve",
    }


def run(args) -> int:
    from ..analysis import outputs
    from ..numerics.steady import steady_state
    from . import cache, plots
    from .simulate_cli import headline_text

    cache.use(args, "steady")

    mech = config.mechanism_from_arguments(args)
    if not (args.newton_tol > 0):
        raise ParameterError(f"--newton-tol = {args.newton_tol:g} must be > 0")
    solve = STEADY_DEFAULTS.replace(
        solver=solver_from_name(args.solver), rtol=args.rtol, atol=args.atol, max_steps=args.max_steps
    )
    options = SteadyOptions(
        settle_revolutions=args.settle_revolutions,
        max_period=args.max_period,
        newton_tol=args.newton_tol,
        statistics_revolutions=args.statistics_revolutions,
        batch_revolutions=args.batch_revolutions,
        samples_per_revolution=args.samples_per_revolution,
        solve=solve,
    )
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    config.save(mech, out / "config.toml")
    start = time.perf_counter()
    steady = steady_state(mech, options, progress=not args.quiet)
    wall = time.perf_counter() - start
    data = summary(steady, wall, args)
    if steady.orbit is not None:
        data["units"] = outputs.columns(mech)  # of orbit.csv's columns, as simulate's summary.json gives them
    (out / "summary.json").write_text(json.dumps(data, indent=2))
    written = ["config.toml", "summary.json"]
    if steady.orbit is not None:
        cols = outputs.trajectory(steady.orbit)
        units = outputs.columns(mech)
        with open(out / "orbit.csv", "w", newline="") as fh:
            writer = csv.writer(fh)
            writer.writerow(list(units))
            for row in zip(*(cols[k] for k in units)):
                writer.writerow([f"{v:.10g}" for v in row])
        written.append("orbit.csv")
        if not args.no_figures:
            plots.save_figures(cols, mech, out / "figures", from_rest=False)  # an orbit: no start-up
            written.append("figures/")
    if not args.no_figures:
        poincare_plot(steady, out / "poincare_section.png")
        written.append("poincare_section.png")
    mods = ", ".join(f"{v:.3g}" for v in data["floquet_multipliers"][:3])
    print(f"wrote {out}/ ({', '.join(written)})")
    print(
        f"  {steady.regime}"
        + (f", period {steady.period_revolutions} revolution(s)" if steady.period_revolutions else "")
        + ("" if steady.periodic else f" within {data['regime_within_revolutions']} revolutions from rest")
        + f"; |Floquet multipliers| {mods}; Lyapunov exponent {data['lyapunov_exponent_per_s']:.3g} 1/s; "
        f"{wall:.1f} s"
    )
    headline = headline_text(data["metrics"])
    if headline:
        print(f"  {data['metrics_window']}: {headline}")
    return 0
