"""Figures in the style of the paper (Figs. 4-10), from :func:`jaxcrank.outputs.trajectory` columns."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def _ideal_vs_clearance(cols, prefix, title):
    """3x2 grid: position, velocity, acceleration; left ideal and clearance, right error."""
    t = cols["t"]
    fig, axes = plt.subplots(3, 2, figsize=(11, 8), sharex=True)
    rows = [("x", "position", 1e3, "mm"), ("vx", "velocity", 1.0, "m/s"), ("ax", "acceleration", 1.0, "m/s$^2$")]
    for row, (suffix, label, scale, unit) in enumerate(rows):
        real, ideal = cols[f"{prefix}_{suffix}"] * scale, cols[f"ideal_{prefix}_{suffix}"] * scale
        ax = axes[row, 0]
        ax.plot(t, real, lw=0.7, label="with clearance")
        ax.plot(t, ideal, lw=1.2, ls="--", color="k", label="ideal")
        ax.set_ylabel(f"{label} x [{unit}]")
        axes[row, 1].plot(t, real - ideal, lw=0.7, color="C3")
        axes[row, 1].set_ylabel(f"error [{unit}]")
    axes[0, 0].legend(loc="upper right", fontsize=8)
    axes[0, 0].set_title(f"{title}: ideal vs clearance")
    axes[0, 1].set_title(f"{title}: deviation (clearance - ideal)")
    for ax in axes[-1]:
        ax.set_xlabel("t [s]")
    fig.tight_layout()
    return fig


def _single(cols, series, ylabel, title):
    fig, ax = plt.subplots(figsize=(9, 4))
    for key, label, style in series:
        ax.plot(cols["t"], cols[key], lw=style.get("lw", 0.7), ls=style.get("ls", "-"),
                color=style.get("color"), label=label)
    ax.set_xlabel("t [s]")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    return fig


def _pin_trajectories(cols, clearances):
    fig, axes = plt.subplots(1, 2, figsize=(10, 5))
    circle = np.linspace(0, 2 * np.pi, 361)
    for ax, joint in zip(axes, "BC"):
        c = clearances[joint] * 1e3
        ax.plot(cols[f"ecc_{joint}_x"] * 1e3, cols[f"ecc_{joint}_y"] * 1e3, lw=0.5)
        ax.plot(cols[f"ecc_{joint}_x"][:1] * 1e3, cols[f"ecc_{joint}_y"][:1] * 1e3, "go", ms=4, label="start")
        if c > 0:
            ax.plot(c * np.cos(circle), c * np.sin(circle), "k--", lw=1.0, label=f"clearance c = {c:.3g} mm")
        ax.set_aspect("equal")
        ax.set_xlabel("x [mm]")
        ax.set_ylabel("y [mm]")
        ax.set_title(f"pin centre relative to bearing centre, joint {joint}")
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
    axes[0].set_title("transmission angle (paper Fig. 10)")
    fig.tight_layout()
    return fig


def figures(cols, clearances) -> dict:
    """All figures as ``{file name: matplotlib Figure}``. ``clearances``: {"B": m, "C": m}."""
    return {
        "rod_x.png": _ideal_vs_clearance(cols, "rod", "rod centre (paper Fig. 4)"),
        "slider_x.png": _ideal_vs_clearance(cols, "slider", "slider (paper Fig. 5)"),
        "slider_acceleration.png": _single(cols, [("slider_ax", "with clearance", {}),
                                                  ("ideal_slider_ax", "ideal", {"ls": "--", "color": "k", "lw": 1.2})],
                                           "slider acceleration x [m/s$^2$]", "slider acceleration (paper Fig. 6)"),
        "contact_force.png": _single(cols, [("force_C_normal", "joint C", {}), ("force_B_normal", "joint B", {"lw": 0.5})],
                                     "normal contact force [N]", "contact forces (paper Fig. 7: joint C)"),
        "driving_moment.png": _single(cols, [("driving_moment", "with clearance", {}),
                                             ("ideal_driving_moment", "ideal", {"ls": "--", "color": "k", "lw": 1.2})],
                                      "driving moment [N m]", "driving moment (paper Fig. 8)"),
        "pin_trajectories.png": _pin_trajectories(cols, clearances),
        "transmission_angle.png": _transmission(cols),
    }


def save_figures(cols, clearances, directory) -> list[Path]:
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, fig in figures(cols, clearances).items():
        path = directory / name
        fig.savefig(path, dpi=120)
        plt.close(fig)
        paths.append(path)
    return paths
