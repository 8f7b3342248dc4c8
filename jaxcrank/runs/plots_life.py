"""Figures of a life run ([`jaxcrank.runs.life_cli`][]): the worn profiles over the new ones,
the metrics against cycles, and where the wear falls against the orbit's contact arcs."""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.ticker import MaxNLocator

from .plots import DPI, style

#: life.csv's columns drawn against cycles, when present (suffixes per worn joint, then metrics)
JOINT_COLUMNS = (("hole_max_depth_m", "deepest hole wear", 1e6, "um"), ("clearance_m", "largest gap", 1e3, "mm"))


def _chosen(n: int, most: int = 6) -> list[int]:
    """Up to ``most`` point indices spread over a run of ``n`` points, the last included."""
    if n <= most:
        return list(range(n))
    return sorted({int(round(i)) for i in np.linspace(0, n - 1, most)})


def profiles_figure(mech, cycles, profiles, path: Path, at=None) -> Path:
    """Per worn joint, the hole's radius (polar, the wear exaggerated to a tenth of the
    radius at the deepest point) and both depths against the angle in the surface's frame,
    over the new (round) surface: at up to six points spread over the run, or at the points
    nearest the cycles ``at``."""
    import jax.numpy as jnp

    from ..physics.wear import profile_on_grid

    joints = list(profiles[0])
    theta = np.linspace(0.0, 2.0 * math.pi, 361)
    if at is None:
        picks = _chosen(len(cycles))
    else:
        picks = sorted({int(np.argmin(np.abs(np.asarray(cycles, dtype=float) - c))) for c in at})
    colours = plt.cm.viridis(np.linspace(0.0, 0.9, len(picks)))
    with style():
        fig = plt.figure(figsize=(8, 3.6 * len(joints)))
        for row, j in enumerate(joints):
            law = mech.joints[j]
            depths = {
                i: [np.asarray(profile_on_grid(jnp.asarray(s), jnp.asarray(theta))) for s in profiles[i][j]]
                for i in picks
            }
            deepest = max(max(float(np.max(np.abs(d))) for d in pair) for pair in depths.values()) or 1.0
            gain = 0.1 * float(law.hole_radius) / deepest
            ax = fig.add_subplot(len(joints), 2, 2 * row + 1, projection="polar")
            ax.plot(theta, np.full_like(theta, float(law.hole_radius)) * 1e3, color="0.5", ls="--", label="new")
            for c, i in zip(colours, picks):
                ax.plot(theta, (float(law.hole_radius) + gain * depths[i][0]) * 1e3, color=c, label=f"{cycles[i]:.3g}")
            ax.set_title(f"{j}: hole radius, mm (wear x{gain:.3g})", fontsize=10)
            ax.set_rticks([])
            ax2 = fig.add_subplot(len(joints), 2, 2 * row + 2)
            for c, i in zip(colours, picks):
                ax2.plot(np.degrees(theta), depths[i][0] * 1e6, color=c, label=f"hole, {cycles[i]:.3g} cycles")
                ax2.plot(np.degrees(theta), depths[i][1] * 1e6, color=c, ls=":")
            ax2.axhline(0.0, color="0.5", ls="--", lw=0.8)
            ax2.set_xlabel("angle in the surface's frame, deg")
            ax2.set_ylabel("wear depth, um (dotted: pin)")
            ax2.set_title(f"{j}: worn profiles")
            ax2.legend(fontsize=7, loc="upper right")
        fig.tight_layout()
        fig.savefig(path, dpi=DPI)
        plt.close(fig)
    return path


def metrics_figure(rows, joints, path: Path) -> Path:
    """The deepest wear and the largest gap per joint, and the headline metrics, against cycles."""
    cycles = np.array([r["cycles"] for r in rows])
    metric_cols = [
        k for k in rows[0]
        if (k.startswith("rms_") or k.startswith("peak_contact_force_")) and not k.endswith("_whole_run_N")
        and isinstance(rows[0][k], float)
    ]  # fmt: skip
    metric_cols = metric_cols[:6]
    panels = len(JOINT_COLUMNS) + len(metric_cols)
    ncol = 2
    nrow = math.ceil(panels / ncol)
    with style():
        fig, axes = plt.subplots(nrow, ncol, figsize=(8, 2.4 * nrow), squeeze=False)
        flat = axes.ravel()
        for ax, (suffix, title, gain, unit) in zip(flat, JOINT_COLUMNS):
            for j in joints:
                ax.plot(cycles, [gain * r[f"{j}_{suffix}"] for r in rows], marker="o", ms=3, label=j)
            ax.set_title(f"{title}, {unit}")
            ax.legend()
        for ax, col in zip(flat[len(JOINT_COLUMNS) :], metric_cols):
            ax.plot(cycles, [r[col] for r in rows], marker="o", ms=3, color="C2")
            ax.set_title(col, fontsize=9)
        for ax in flat[panels:]:
            ax.set_visible(False)
        for ax in flat[:panels]:
            ax.set_xlabel("cycles")
            ax.xaxis.set_major_locator(MaxNLocator(5))  # cycle counts are long numbers: few ticks, powers of ten
            ax.ticklabel_format(axis="x", style="sci", scilimits=(-3, 4))
        fig.tight_layout()
        fig.savefig(path, dpi=DPI)
        plt.close(fig)
    return path


def contact_arcs_figure(mech, steady, rate, path: Path) -> Path:
    """Where the wear falls: per worn joint, the orbit's wear power (normal force times
    slip, W) at the contact's angle in the hole's frame, summed over 5 degree bins per
    cycle (J per degree), beside the hole's wear depth per cycle (m) from Archard's law."""
    import jax.numpy as jnp

    from ..numerics import wear_run as nw
    from ..physics.wear import profile_on_grid

    orbit = steady.orbit
    samples = nw.contact_samples(mech, orbit.ts, orbit.ys)
    dt = float(orbit.ts[1] - orbit.ts[0])
    k = max(int(steady.period_revolutions), 1)
    edges = np.linspace(-180.0, 180.0, 73)
    theta = np.linspace(-math.pi, math.pi, 361)
    joints = list(samples)
    with style():
        fig, axes = plt.subplots(len(joints), 1, figsize=(8, 2.8 * len(joints)), squeeze=False)
        for ax, j in zip(axes[:, 0], joints):
            s = {n: np.asarray(v) for n, v in samples[j].items()}
            energy, _ = np.histogram(np.degrees(s["hole_angle_rad"]), bins=edges, weights=s["wear_power_W"] * dt / k)
            ax.bar(
                edges[:-1],
                energy / 5.0,
                width=5.0,
                align="edge",
                color="C0",
                alpha=0.5,
                label="F_n |v_slip| dt per cycle",
            )
            ax.set_ylabel("J per deg per cycle")
            ax.set_xlabel("angle in the hole's frame, deg")
            ax2 = ax.twinx()
            depth = np.asarray(profile_on_grid(jnp.asarray(rate[j][0]), jnp.asarray(theta)))
            ax2.plot(np.degrees(theta), depth, color="C3", label="wear depth per cycle (Archard)")
            ax2.set_ylabel("m per cycle", color="C3")
            ax.set_title(f"{j}: contact arcs of the orbit ({steady.regime}) and the wear they cause")
            ax.legend(loc="upper left", fontsize=8)
            ax2.legend(loc="upper right", fontsize=8)
        fig.tight_layout()
        fig.savefig(path, dpi=DPI)
        plt.close(fig)
    return path


def write_figures(out: Path, mech, rows, cycles, profiles, first_point=None) -> list[Path]:
    """Write a life run's figures into ``out/figures``: ``profiles.png``, ``metrics.png``
    and, given the first point ([`WearPoint`][jaxcrank.analysis.life.WearPoint]) with an orbit,
    ``contact_arcs.png``."""
    figs = out / "figures"
    figs.mkdir(parents=True, exist_ok=True)
    joints = list(profiles[0])
    paths = [
        profiles_figure(mech, cycles, profiles, figs / "profiles.png"),
        metrics_figure(rows, joints, figs / "metrics.png"),
    ]
    if first_point is not None and first_point.steady.orbit is not None:
        paths.append(contact_arcs_figure(mech, first_point.steady, first_point.rate, figs / "contact_arcs.png"))
    return paths
