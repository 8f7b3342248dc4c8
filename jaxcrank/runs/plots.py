"""Figures of a run in the style of the paper (Figs. 4-10) and its bearing loads, from
[`jaxcrank.analysis.outputs.trajectory`][] columns, drawn against the driven body's angle
or against time, in one style (`STYLE`); and figures of a
sweep's table ([`sweep_figures`][jaxcrank.runs.plots.sweep_figures])."""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from .plots_angle import Abscissa, abscissa, after_first_revolution, clip_startup
from .plots_loads import bearing_loads

#: matplotlib settings of every figure (applied by [`style`][jaxcrank.runs.plots.style]):
#: run figures are 8 in wide and saved at `DPI`, so 9-11 pt text stays legible when a
#: page shows them 700 px wide
STYLE = {
    "font.size": 10,
    "axes.titlesize": 11,
    "axes.labelsize": 10,
    "xtick.labelsize": 9,
    "ytick.labelsize": 9,
    "legend.fontsize": 9,
    "figure.titlesize": 12,
    "axes.grid": True,
    "grid.color": "0.9",
    "grid.linewidth": 0.6,
    "axes.spines.top": False,
    "axes.spines.right": False,
    "axes.xmargin": 0.0,
    "lines.linewidth": 0.9,
    "legend.frameon": False,
}
#: dots per inch of the saved PNG files
DPI = 150


def style():
    """A context manager in which matplotlib draws with `STYLE`."""
    return plt.rc_context(STYLE)


def _legend_above(ax, **kw):
    """The axes' legend above its top right corner, outside the data."""
    ax.legend(loc="lower right", bbox_to_anchor=(1.0, 1.0), ncol=2, borderaxespad=0.2, **kw)


#: per coordinate: the columns' suffixes of position, velocity and acceleration, their
#: labels, scales and units
_COORDINATE_ROWS = {
    "x": [("x", "x", 1e3, "mm"), ("vx", "velocity x", 1.0, "m/s"), ("ax", "acceleration x", 1.0, "m/s$^2$")],
    "y": [("y", "y", 1e3, "mm"), ("vy", "velocity y", 1.0, "m/s"), ("ay", "acceleration y", 1.0, "m/s$^2$")],
    "angle": [
        ("angle", "angle", 1.0, "deg"),
        ("omega", "angular velocity", 1.0, "rad/s"),
        ("alpha", "angular acceleration", 1.0, "rad/s$^2$"),
    ],
}
_IDEAL = {"ls": "--", "color": "k", "lw": 1.1}


def _ideal_vs_clearance(cols, body, coordinate, x: Abscissa, steady):
    """3x2 grid: position, velocity, acceleration; left ideal and clearance, right error.
    The acceleration rows are scaled to the motion of the ``steady`` samples (shaded
    before), the start-up peak annotated."""
    fig, axes = plt.subplots(3, 2, figsize=(8, 7), sharex=True, layout="constrained")
    for row, (suffix, label, scale, unit) in enumerate(_COORDINATE_ROWS[coordinate]):
        real, ideal = cols[f"{body}_{suffix}"] * scale, cols[f"ideal_{body}_{suffix}"] * scale
        ax = axes[row, 0]
        ax.plot(x.values, real, label="with clearance")
        ax.plot(x.values, ideal, label="ideal", **_IDEAL)
        ax.set_ylabel(f"{label} [{unit}]")
        axes[row, 1].plot(x.values, real - ideal, color="C3")
        axes[row, 1].set_ylabel(f"deviation [{unit}]")
        if row == 2:
            clip_startup(ax, x, [real, ideal], steady, unit.replace("$^2$", "²"))
            clip_startup(axes[row, 1], x, [real - ideal], steady, unit.replace("$^2$", "²"))
    what = f"{body} {coordinate}" + (" (centre of mass)" if coordinate != "angle" else "")
    axes[0, 0].set_title(what, loc="left")
    axes[0, 1].set_title("with clearance − ideal", loc="left")
    fig.legend(*axes[0, 0].get_legend_handles_labels(), loc="outside lower center", ncol=2)
    for ax in axes[-1]:
        ax.set_xlabel(x.label)
        x.ticks(ax)
    return fig


def _single(cols, x: Abscissa, steady, series, ylabel, title, unit):
    """One panel of ``series`` (column, label, style), scaled to the motion of the
    ``steady`` samples (start-up shaded, its peak annotated)."""
    fig, ax = plt.subplots(figsize=(8, 3.6), layout="constrained")
    for key, label, style_ in series:
        ax.plot(x.values, cols[key], label=label, **style_)
    clip_startup(ax, x, [cols[key] for key, _, _ in series], steady, unit)
    ax.set_xlabel(x.label)
    x.ticks(ax)
    ax.set_ylabel(ylabel)
    ax.set_title(title, loc="left")
    _legend_above(ax)
    return fig


def _clearance_joints(mech) -> list[str]:
    return sorted(j for j, law in mech.joints.items() if not law.ideal)


def _contact_forces(cols, mech, x: Abscissa | None = None, steady=None):
    """The normal force of each joint with clearance at the samples, one panel each, scaled
    to the motion of the ``steady`` samples (default: after the first revolution; start-up
    shaded, its peak annotated: the largest stored sample; ``summary.json``'s peaks are
    over every solver step, so they can be larger)."""
    x = abscissa(cols, mech) if x is None else x
    steady = after_first_revolution(cols, mech) if steady is None else steady
    joints = _clearance_joints(mech)
    fig, axes = plt.subplots(len(joints), 1, figsize=(8, 0.6 + 2.6 * len(joints)), sharex=True, squeeze=False,
                             layout="constrained")  # fmt: skip
    for k, (ax, joint) in enumerate(zip(axes[:, 0], joints)):
        f = cols[f"force_{joint}_normal"]
        ax.plot(x.values, f, lw=0.7, color=f"C{k}")
        clip_startup(ax, x, [f], steady, "N")
        ax.set_ylabel("normal force [N]")
        ax.set_title(f"contact force at joint {joint}", loc="left")
    axes[-1, 0].set_xlabel(x.label)
    x.ticks(axes[-1, 0])
    return fig


def _pin_trajectories(cols, mech):
    """Each clearance joint's pin centre relative to its hole (a guide's slider: lateral
    offset and tilt times half its length) with the clearance drawn (and a worn hole's outline
    at the run's end); two panels to a row."""
    from ..views import geometry as geo

    joints = _clearance_joints(mech)
    sketches = {j.name: j for j in geo.layout(mech).joints}
    columns = min(len(joints), 2)
    rows = -(-len(joints) // columns)
    fig, axes = plt.subplots(rows, columns, figsize=(8 if columns > 1 else 4.6, 4.4 * rows), squeeze=False,
                             layout="constrained")  # fmt: skip
    circle = np.linspace(0, 2 * np.pi, 361)
    for ax, joint in zip(axes.flat, joints):
        c = float(mech.joints[joint].clearance) * 1e3
        ex, ey = cols[f"ecc_{joint}_x"] * 1e3, cols[f"ecc_{joint}_y"] * 1e3
        ax.plot(ex, ey, lw=0.5)
        ax.plot(ex[:1], ey[:1], "o", color="C2", ms=5, label="start", zorder=5)
        if "revolute" in mech.joints[joint].kinds:
            ax.plot(c * np.cos(circle), c * np.sin(circle), "k--", lw=1.0, label=f"clearance {c:.3g} mm")
            sketch = sketches[joint]
            if sketch.worn:  # the worn hole turns with its body: drawn where the run left it
                turn = [float(geo.body_angle(cols, side[0], -1)) for side in (sketch.hole, sketch.pin)]
                r = 1e3 * geo.gap(sketch, circle, *turn)
                ax.plot(r * np.cos(circle), r * np.sin(circle), "k-", lw=1.0, label="worn, at the end")
            ax.set_aspect("equal")
            ax.set_title(f"joint {joint}: pin centre in its bearing", loc="left")
        else:
            for sign in (-1, 1):
                ax.axhline(sign * c, color="k", ls="--", lw=1.0, label=f"clearance {c:.3g} mm" if sign > 0 else None)
            ax.set_title(f"joint {joint}: slider in its guide", loc="left")
        ax.set_xlabel("x [mm]")
        ax.set_ylabel("y [mm]")
        ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=2)
    for ax in axes.flat[len(joints) :]:
        ax.set_visible(False)
    return fig


def _transmission(cols, x: Abscissa):
    fig, axes = plt.subplots(2, 1, figsize=(8, 5), sharex=True, layout="constrained")
    axes[0].plot(x.values, cols["transmission_angle"], label="with clearance")
    axes[0].plot(x.values, cols["ideal_transmission_angle"], label="ideal", **_IDEAL)
    axes[0].set_ylabel("transmission angle [deg]")
    axes[0].set_title("transmission angle", loc="left")
    _legend_above(axes[0])
    axes[1].plot(x.values, cols["transmission_angle"] - cols["ideal_transmission_angle"], color="C3")
    axes[1].set_ylabel("deviation [deg]")
    axes[1].set_xlabel(x.label)
    x.ticks(axes[1])
    return fig


def figures(cols, mech, *, against: str = "angle", from_rest: bool = True) -> dict:
    """All figures of a run as ``{file name: matplotlib Figure}``, drawn in
    `STYLE`. ``cols``: the columns of
    [`jaxcrank.analysis.outputs.trajectory`][] of a run of ``mech``; ``against``: the
    time series' x axis, ``"angle"`` (the driven body's angle since the start, deg) or
    ``"time"`` (s) ([`abscissa`][jaxcrank.runs.plots_angle.abscissa]); ``from_rest``: the
    run starts from rest, so its first revolution is a start-up (``False`` for a periodic
    orbit, drawn whole).

    One figure per deviation the mechanism reports (``<body>_<coordinate>.png``: position,
    velocity, acceleration, ideal against clearance), the output link's acceleration, the
    contact force of every clearance joint, the driving moment, the pin trajectories in
    their bearings, the transmission angle, and the load on every joint's bearing
    (``bearing_loads.png``, [`jaxcrank.runs.plots_loads.bearing_loads`][]). Accelerations,
    contact forces and the driving moment are scaled to the motion after the first
    revolution (the start-up impacts would squash it): the first revolution is shaded and
    its peak written in the panel; the bearing loads leave it out. A run shorter than one
    revolution is drawn whole.

    Raises:
        ValueError: if ``against`` is neither ``"angle"`` nor ``"time"``.
    """
    x = abscissa(cols, mech, against)
    steady = after_first_revolution(cols, mech) if from_rest else np.ones(len(cols["t"]), dtype=bool)
    outputs = mech.linkage().outputs
    out = {}
    with style():
        for body, coordinate in outputs.deviations:
            out[f"{body}_{coordinate}.png"] = _ideal_vs_clearance(cols, body, coordinate, x, steady)
        if outputs.acceleration is not None:
            body, coordinate = outputs.acceleration
            suffix, label, _, unit = _COORDINATE_ROWS[coordinate][2]
            series = [(f"{body}_{suffix}", "with clearance", {}), (f"ideal_{body}_{suffix}", "ideal", _IDEAL)]
            out[f"{body}_acceleration.png"] = _single(
                cols, x, steady, series, f"{label} [{unit}]", f"{body} {label}", unit.replace("$^2$", "²")
            )
        if _clearance_joints(mech):
            out["contact_force.png"] = _contact_forces(cols, mech, x, steady)
        series = [("driving_moment", "with clearance", {}), ("ideal_driving_moment", "ideal", _IDEAL)]
        out["driving_moment.png"] = _single(cols, x, steady, series, "moment [N m]", "driving moment", "N m")
        if _clearance_joints(mech):
            out["pin_trajectories.png"] = _pin_trajectories(cols, mech)
        if "transmission_angle" in cols:
            out["transmission_angle.png"] = _transmission(cols, x)
        out["bearing_loads.png"] = bearing_loads(cols, mech, steady)
    return out


def save_figures(cols, mech, directory, *, against: str = "angle", from_rest: bool = True) -> list[Path]:
    """Write [`figures`][jaxcrank.runs.plots.figures] (``against``, ``from_rest`` as there) as PNG files
    into ``directory`` at `DPI`; returns their paths.

    Raises:
        ValueError: if ``against`` is neither ``"angle"`` nor ``"time"``.
    """
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, fig in figures(cols, mech, against=against, from_rest=from_rest).items():
        path = directory / name
        fig.savefig(path, dpi=DPI)
        plt.close(fig)
        paths.append(path)
    return paths


_UNIT_LABELS = {
    "_m_s2": "m/s^2",
    "_kg_m2": "kg m^2",
    "_rad_s": "rad/s",
    "_N_m": "N m",
    "_m_s": "m/s",
    "_deg": "deg",
    "_Pa": "Pa",
    "_rad": "rad",
    "_kg": "kg",
    "_m": "m",
    "_N": "N",
    "_s": "s",
    "_1": "-",
}


def _label(col: str) -> str:
    """``rod_length_m`` -> ``rod_length [m]`` (units from the column-name suffix)."""
    for suf, unit in _UNIT_LABELS.items():
        if col.endswith(suf):
            return f"{col[: -len(suf)]} [{unit}]"
    return col


def _shown(col: str) -> tuple[str, float]:
    """(axis label, factor from the column's SI values) of a table column: lengths (m) in mm,
    everything else in its SI unit."""
    label = _label(col)
    if label.endswith(" [m]"):
        return label[: -len(" [m]")] + " [mm]", 1e3
    return label, 1.0


def _edges(levels: np.ndarray) -> np.ndarray:
    """Cell edges around sorted grid ``levels``: halfway between neighbours, the ends half a
    gap out; a single level gets a cell 10 % of its value wide (1 wide at zero)."""
    if len(levels) == 1:
        half = 0.05 * abs(levels[0]) or 0.5
        return np.array([levels[0] - half, levels[0] + half])
    mid = (levels[1:] + levels[:-1]) / 2
    return np.concatenate([[2 * levels[0] - mid[0]], mid, [2 * levels[-1] - mid[-1]]])


def sweep_figures(table, sampling, param_cols, metrics, out_dir) -> list[Path]:
    """Figures of a sweep table ([`jaxcrank.runs.sweep.read_table`][jaxcrank.runs.sweep_table.read_table]) into
    ``out_dir``:
    heat maps for two-parameter grids, metric-vs-parameter plots (the mean at each level
    with a bar from the minimum to the maximum over the other parameters; points, not
    joined, since a metric between two levels can be anything where the motion is chaotic)
    for grids and one-at-a-time lines, scatter plots for LHS / random samples, histograms
    for Monte Carlo. Lengths are shown in mm. Failed designs are drawn as crosses on heat
    maps and left out elsewhere."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    with style():
        return _sweep_figures(table, sampling, param_cols, metrics, out_dir)


def _sweep_figures(table, sampling, param_cols, metrics, out_dir) -> list[Path]:
    ok = np.asarray(table["status"]) == "ok"
    files = []

    def save(fig, name):
        fig.tight_layout()
        fig.savefig(out_dir / name, dpi=DPI)
        plt.close(fig)
        files.append(out_dir / name)

    if sampling == "grid" and len(param_cols) == 2:
        (la, fa), (lb, fb) = (_shown(c) for c in param_cols)
        a, b = (np.asarray(table[c]) * f for c, f in zip(param_cols, (fa, fb)))
        ua, ub = np.unique(a), np.unique(b)
        for m in metrics:
            lm, fm = _shown(m)
            z = np.full((len(ua), len(ub)), np.nan)
            z[np.searchsorted(ua, a[ok]), np.searchsorted(ub, b[ok])] = np.asarray(table[m])[ok] * fm
            fig, ax = plt.subplots(figsize=(6, 4.8))
            im = ax.pcolormesh(_edges(ub), _edges(ua), z, shading="flat", cmap="viridis")
            ax.grid(False)
            ax.spines[:].set_visible(True)
            fig.colorbar(im, ax=ax, label=lm)
            if (~ok).any():
                ax.plot(b[~ok], a[~ok], "rx", label="failed / invalid")
                ax.legend(fontsize=8)
            ax.set_xlabel(lb)
            ax.set_ylabel(la)
            ax.set_title(lm.split(" [")[0])
            save(fig, f"heatmap_{m}.png")
    if sampling == "monte_carlo":
        for m in metrics:
            v = np.asarray(table[m])[ok]
            fig, ax = plt.subplots(figsize=(6, 4))
            ax.hist(v, bins=max(5, int(np.sqrt(max(len(v), 1)))), color="C0", alpha=0.8)
            for q, ls in ((0.05, ":"), (0.5, "--"), (0.95, ":")):
                if len(v):
                    ax.axvline(np.quantile(v, q), color="k", ls=ls, lw=1)
            ax.set_xlabel(_label(m))
            ax.set_ylabel("parts")
            ax.set_title(f"{m}: {len(v)} parts (5/50/95 % quantiles dashed)")
            save(fig, f"histogram_{m}.png")
        return files
    for c in param_cols:
        lc, fc = _shown(c)
        x = np.asarray(table[c]) * fc
        fig, axes = plt.subplots(len(metrics), 1, figsize=(7, 2.2 * len(metrics)), sharex=True, squeeze=False)
        for ax, m in zip(axes[:, 0], metrics):
            lm, fm = _shown(m)
            y = np.asarray(table[m]) * fm
            if sampling in ("lhs", "random"):
                ax.plot(x[ok], y[ok], ".", ms=4)
            else:
                sel = ok
                if sampling == "oat":  # the line of this parameter: the others at their base value
                    others = [o for o in param_cols if o != c]
                    sel = (
                        ok & np.all([np.asarray(table[o]) == np.median(np.asarray(table[o])) for o in others], axis=0)
                        if others
                        else ok
                    )
                xs = np.unique(x[sel])
                stats = [y[sel & (x == v)] for v in xs]
                mean = np.array([s.mean() for s in stats])
                low, high = mean - [s.min() for s in stats], [s.max() for s in stats] - mean
                ax.errorbar(xs, mean, yerr=[low, high], fmt="o", ms=3, capsize=2, lw=0.8)
            ax.set_ylabel(lm, fontsize=8)
        axes[-1, 0].set_xlabel(lc)
        axes[0, 0].set_title(
            f"metrics vs {lc.split(' [')[0]}"
            + (" (bars: min-max over the other parameters)" if sampling == "grid" and len(param_cols) > 1 else "")
        )
        save(fig, f"lines_{_label(c).split(' [')[0]}.png")
    return files
