"""Figures in the style of the paper (Figs. 4-10), from [`jaxcrank.analysis.outputs.trajectory`][] columns."""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np  # noqa: E402


def _steady(cols, mech) -> np.ndarray:
    """Samples after the driven body's first revolution (the start-up impacts left out),
    bool; all samples for a run that ends within it."""
    angle = np.asarray(cols[f"{mech.linkage().driver.body}_angle"])
    after = np.abs(angle - angle[0]) >= 360.0
    return after if after.any() else np.ones_like(after)


def _clip_startup(ax, t, curves, steady, unit):
    """Limit ``ax``'s y-range to the curves' values after the start-up (``steady`` samples)
    and shade the start-up; a peak outside that range is written in the axes and
    marked by an arrow at the edge it crosses, so the steady motion is legible."""
    if steady.all():
        return
    lo = min(float(np.min(c[steady])) for c in curves)
    hi = max(float(np.max(c[steady])) for c in curves)
    pad = 0.08 * (hi - lo if hi > lo else max(abs(hi), 1.0))
    lo, hi = lo - pad, hi + pad
    ax.set_ylim(lo, hi)
    ax.axvspan(t[0], t[np.argmax(steady)], color="0.9", zorder=0, lw=0)
    # the largest excursion of any curve beyond the range, written and pointed at
    worst = None
    for c in curves:
        outside = (c > hi) | (c < lo)
        if outside.any():
            i = int(np.argmax(np.where(outside, np.abs(c), -np.inf)))
            if worst is None or abs(c[i]) > abs(worst[1]):
                worst = (t[i], float(c[i]))
    if worst is not None:
        ti, vi = worst
        edge = hi if vi > hi else lo
        ax.annotate(
            f"start-up (shaded): peak {vi:,.0f} {unit} at t = {ti:.4f} s, off scale",
            xy=(ti, edge),
            xytext=(0.12, 0.9 if vi > hi else 0.1),
            textcoords="axes fraction",
            fontsize=7,
            va="center",
            bbox={"boxstyle": "round,pad=0.2", "fc": "white", "ec": "0.6", "lw": 0.5},
            arrowprops={"arrowstyle": "->", "lw": 0.7},
        )


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


def _ideal_vs_clearance(cols, mech, body, coordinate):
    """3x2 grid: position, velocity, acceleration; left ideal and clearance, right error.
    The acceleration rows are scaled to the motion after the first revolution (shaded
    before), the start-up peak annotated."""
    t = cols["t"]
    steady = _steady(cols, mech)
    fig, axes = plt.subplots(3, 2, figsize=(11, 8), sharex=True)
    for row, (suffix, label, scale, unit) in enumerate(_COORDINATE_ROWS[coordinate]):
        real, ideal = cols[f"{body}_{suffix}"] * scale, cols[f"ideal_{body}_{suffix}"] * scale
        ax = axes[row, 0]
        ax.plot(t, real, lw=0.7, label="with clearance")
        ax.plot(t, ideal, lw=1.2, ls="--", color="k", label="ideal")
        ax.set_ylabel(f"{label} [{unit}]")
        axes[row, 1].plot(t, real - ideal, lw=0.7, color="C3")
        axes[row, 1].set_ylabel(f"error [{unit}]")
        if row == 2:
            _clip_startup(ax, t, [real, ideal], steady, unit.replace("$^2$", "²"))
            _clip_startup(axes[row, 1], t, [real - ideal], steady, unit.replace("$^2$", "²"))
    what = f"{body} centre of mass" if coordinate != "angle" else body
    axes[0, 0].legend(loc="upper right", fontsize=8)
    axes[0, 0].set_title(f"{what}: ideal vs clearance")
    axes[0, 1].set_title(f"{what}: deviation (clearance - ideal)")
    for ax in axes[-1]:
        ax.set_xlabel("t [s]")
    fig.tight_layout()
    return fig


def _single(cols, mech, series, ylabel, title, unit):
    """One panel of ``series`` (column, label, style) against time, scaled to the motion
    after the first revolution (start-up shaded, its peak annotated)."""
    fig, ax = plt.subplots(figsize=(9, 4))
    for key, label, style in series:
        ax.plot(
            cols["t"],
            cols[key],
            lw=style.get("lw", 0.7),
            ls=style.get("ls", "-"),
            color=style.get("color"),
            label=label,
        )
    _clip_startup(ax, cols["t"], [cols[key] for key, _, _ in series], _steady(cols, mech), unit)
    ax.set_xlabel("t [s]")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    return fig


def _clearance_joints(mech) -> list[str]:
    return sorted(j for j, law in mech.joints.items() if not law.ideal)


def _contact_forces(cols, mech):
    """The normal force of each joint with clearance, one panel each, scaled to the motion
    after the first revolution (start-up shaded, its peak annotated). The annotated
    start-up peak is the largest stored sample; ``summary.json``'s peaks are over every
    solver step, so they can be larger."""
    joints = _clearance_joints(mech)
    fig, axes = plt.subplots(len(joints), 1, figsize=(9, 3 * len(joints)), sharex=True, squeeze=False)
    steady = _steady(cols, mech)
    for k, (ax, joint) in enumerate(zip(axes[:, 0], joints)):
        f = cols[f"force_{joint}_normal"]
        ax.plot(cols["t"], f, lw=0.6, color=f"C{k}")
        _clip_startup(ax, cols["t"], [f], steady, "N")
        ax.set_ylabel(f"normal force at {joint} [N]")
        ax.set_title(f"contact force, joint {joint} (samples; summary.json's peaks are over solver steps)")
    axes[-1, 0].set_xlabel("t [s]")
    fig.tight_layout()
    return fig


def _pin_trajectories(cols, mech):
    """Each clearance joint's pin centre relative to its hole (a guide's slider: lateral
    offset and tilt times half its length) with the clearance drawn."""
    joints = _clearance_joints(mech)
    fig, axes = plt.subplots(1, len(joints), figsize=(5 * len(joints), 5), squeeze=False)
    circle = np.linspace(0, 2 * np.pi, 361)
    for ax, joint in zip(axes[0], joints):
        c = float(mech.joints[joint].clearance) * 1e3
        ax.plot(cols[f"ecc_{joint}_x"] * 1e3, cols[f"ecc_{joint}_y"] * 1e3, lw=0.5)
        ax.plot(cols[f"ecc_{joint}_x"][:1] * 1e3, cols[f"ecc_{joint}_y"][:1] * 1e3, "go", ms=4, label="start")
        if "revolute" in mech.joints[joint].kinds:
            ax.plot(c * np.cos(circle), c * np.sin(circle), "k--", lw=1.0, label=f"clearance c = {c:.3g} mm")
            ax.set_aspect("equal")
            ax.set_title(f"pin centre relative to bearing centre, joint {joint}")
        else:
            for sign in (-1, 1):
                ax.axhline(sign * c, color="k", ls="--", lw=1.0)
            ax.set_title(f"slider in its guide, joint {joint} (dashed: clearance {c:.3g} mm)")
        ax.set_xlabel("x [mm]")
        ax.set_ylabel("y [mm]")
        ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    return fig


def _transmission(cols):
    fig, axes = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    axes[0].plot(cols["t"], cols["transmission_angle"], lw=0.7, label="with clearance")
    axes[0].plot(cols["t"], cols["ideal_transmission_angle"], lw=1.2, ls="--", color="k", label="ideal")
    axes[0].set_ylabel("transmission angle [deg]")
    axes[0].legend(loc="upper right", fontsize=8)
    axes[1].plot(cols["t"], cols["transmission_angle"] - cols["ideal_transmission_angle"], lw=0.7, color="C3")
    axes[1].set_ylabel("error [deg]")
    axes[1].set_xlabel("t [s]")
    axes[0].set_title("transmission angle")
    fig.tight_layout()
    return fig


def figures(cols, mech) -> dict:
    """All figures of a run as ``{file name: matplotlib Figure}``. ``cols``: the columns of
    [`jaxcrank.analysis.outputs.trajectory`][] of a run of ``mech``.

    One figure per deviation the mechanism reports (``<body>_<coordinate>.png``: position,
    velocity, acceleration, ideal against clearance), the output link's acceleration, the
    contact force of every clearance joint, the driving moment, the pin trajectories in
    their bearings and the transmission angle. Accelerations, contact forces and the
    driving moment are scaled to the motion after the first revolution (the start-up
    impacts would squash it): the first revolution is shaded and its peak written in the
    panel. A run shorter than one revolution is drawn whole."""
    outputs = mech.linkage().outputs
    out = {}
    for body, coordinate in outputs.deviations:
        out[f"{body}_{coordinate}.png"] = _ideal_vs_clearance(cols, mech, body, coordinate)
    if outputs.acceleration is not None:
        body, coordinate = outputs.acceleration
        suffix, label, _, unit = _COORDINATE_ROWS[coordinate][2]
        out[f"{body}_acceleration.png"] = _single(
            cols,
            mech,
            [
                (f"{body}_{suffix}", "with clearance", {}),
                (f"ideal_{body}_{suffix}", "ideal", {"ls": "--", "color": "k", "lw": 1.2}),
            ],
            f"{body} {label} [{unit}]",
            f"{body} {label}",
            unit.replace("$^2$", "²"),
        )
    if _clearance_joints(mech):
        out["contact_force.png"] = _contact_forces(cols, mech)
    out["driving_moment.png"] = _single(
        cols,
        mech,
        [
            ("driving_moment", "with clearance", {}),
            ("ideal_driving_moment", "ideal", {"ls": "--", "color": "k", "lw": 1.2}),
        ],
        "driving moment [N m]",
        "driving moment",
        "N m",
    )
    if _clearance_joints(mech):
        out["pin_trajectories.png"] = _pin_trajectories(cols, mech)
    if "transmission_angle" in cols:
        out["transmission_angle.png"] = _transmission(cols)
    return out


def save_figures(cols, mech, directory) -> list[Path]:
    """Write [`figures`][jaxcrank.runs.plots.figures] as PNG files into ``directory``; returns their paths."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, fig in figures(cols, mech).items():
        path = directory / name
        fig.savefig(path, dpi=120)
        plt.close(fig)
        paths.append(path)
    return paths


# ------------------------------------------------------------------ sweeps
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
    ok = np.asarray(table["status"]) == "ok"
    files = []

    def save(fig, name):
        fig.tight_layout()
        fig.savefig(out_dir / name, dpi=120)
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
            im = ax.pcolormesh(ub, ua, z, shading="nearest", cmap="viridis")
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
            ax.set_ylabel(lm, fontsize=7)
        axes[-1, 0].set_xlabel(lc)
        axes[0, 0].set_title(
            f"metrics vs {lc.split(' [')[0]}"
            + (" (bars: min-max over the other parameters)" if sampling == "grid" and len(param_cols) > 1 else "")
        )
        save(fig, f"lines_{_label(c).split(' [')[0]}.png")
    return files
