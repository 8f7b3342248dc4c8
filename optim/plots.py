"""Figures of the optimisation: 1-D scans, the iteration history (paper Fig. 11)
and the objective landscape with the optimiser's path."""

from __future__ import annotations

import csv
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np  # noqa: E402


def _unit(name: str) -> tuple[str, float, str]:
    """(label, factor from SI, unit) of a design variable, by the kind of its name: lengths
    (``*_length``, ``offset``, ``clearance_<joint>``) in mm, angles of the problem's
    constraints (``*_transmission_angle``) in degrees, masses in kg, inertias in kg m^2, Young's
    moduli in GPa, viscosities in Pa s, ratios and coefficients without a unit (""), anything
    else in SI."""
    kinds = (
        (("_mass",), 1.0, "kg"),
        (("_inertia",), 1.0, "kg m^2"),
        (("youngs_modulus",), 1e-9, "GPa"),
        (("viscosity",), 1.0, "Pa s"),
        (("_ratio", "coefficient", "restitution"), 1.0, ""),
    )
    for suffixes, scale, unit in kinds:
        if name.endswith(suffixes):
            return name, scale, unit
    if name.startswith("clearance_"):
        return f"c_{name.removeprefix('clearance_')}", 1e3, "mm"
    if name.endswith("_length") or name == "offset":
        return name.removesuffix("_length").replace("_", " "), 1e3, "mm"
    if name.endswith("_transmission_angle"):
        return name.replace("_", " "), 180.0 / np.pi, "deg"
    return name, 1.0, "SI"


def label(name):
    short, _, unit = _unit(name)
    return f"{short} [{unit}]" if unit else short


def factor(name):
    return _unit(name)[1]


def value_text(name, value) -> str:
    """``name = value unit`` for a report, the SI ``value`` in the unit the variable is shown in."""
    return f"{name} = {value * factor(name):.6g} {unit(name)}".rstrip()


def unit(name):
    """The unit a design variable is shown in (``mm``, ``deg``, ``kg``, ...; ``""`` without one)."""
    return _unit(name)[2]


def plot_scans(csv_path: Path, report: dict, png: Path):
    with open(csv_path) as f:
        rows = list(csv.DictReader(f))
    names = report["names"]
    fig, axes = plt.subplots(len(names), 2, figsize=(11, 3.6 * len(names)), squeeze=False)
    for i, name in enumerate(names):
        e = report["variables"][name]
        k = factor(name)
        x0 = report["start"][i]
        f0 = None
        for j, kinds in enumerate((("coarse",), ("fine", "micro"))):
            ax = axes[i, j]
            for kind, style in zip(kinds, ("o-", "s")):
                sel = [r for r in rows if r["variable"] == name and r["kind"] == kind]
                x = np.array([float(r[f"{name}_SI"]) for r in sel])
                y = np.array([float(r["objective_deg"]) for r in sel])
                ax.plot(x * k, y, style, ms=3, lw=0.8, label=f"{kind} scan")
                if kind in ("fine", "micro") and f0 is None:
                    mid = np.argmin(np.abs(x - x0))
                    f0 = y[mid]
            xs = np.array(ax.get_xlim()) / k
            span = xs - x0
            ref = f0 if f0 is not None else np.nan
            ax.plot(
                xs * k,
                ref + e["fine_slope"] * span,
                "k--",
                lw=1,
                label=f"LS slope over fine scan {e['fine_slope']:+.3g} deg/SI",
            )
            ax.plot(
                xs * k,
                ref + e["ensemble_gradient"] * span,
                "r-",
                lw=1,
                label=f"ensemble gradient {e['ensemble_gradient']:+.3g} deg/SI",
            )
            ax.set_xlabel(label(name))
            ax.set_ylabel("RMS transmission-angle error [deg]")
            ax.legend(fontsize=7)
            ax.grid(alpha=0.3)
        axes[i, 0].set_title(f"{name}: across the box")
        axes[i, 1].set_title(f"{name}: near the start (micro: 20 um steps)")
    fig.suptitle(report["problem"])
    fig.tight_layout()
    fig.savefig(png, dpi=120)
    plt.close(fig)


def plot_history(history: list[dict], png: Path, title="", best: float | None = None):
    """Objective (deg) per iteration (the paper's Fig. 11), saved to ``png``; a red star marks
    the reported best iterate, the first iterate whose objective is ``best`` (default: the
    history's minimum)."""
    it = [h["iteration"] for h in history]
    f = [h["objective_deg"] for h in history]
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot(it, f, "o-", label="iterate")
    if f:
        i = int(np.argmin(f)) if best is None else int(np.argmin(np.abs(np.asarray(f) - best)))
        ax.plot(it[i], f[i], "r*", ms=14, zorder=3, label=f"reported best: iteration {it[i]}, {f[i]:.5g} deg")
        ax.legend(fontsize=8)
    ax.set_xlabel("iteration")
    ax.set_ylabel("objective [deg]")
    ax.set_title(title or "optimisation history")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(png, dpi=120)
    plt.close(fig)


def plot_landscape(grid, names, path_xs, png: Path, title="", final=None):
    """Objective over a two-variable grid with the optimiser's path on it; the star
    marks ``final`` (the optimiser's best design; default the last iterate)."""
    k0, k1 = factor(names[0]), factor(names[1])
    fig, ax = plt.subplots(figsize=(6.5, 5))
    X, Y = np.meshgrid(grid.axes[0] * k0, grid.axes[1] * k1, indexing="ij")
    cs = ax.contourf(X, Y, np.ma.masked_invalid(grid.values), levels=20, cmap="viridis")
    fig.colorbar(cs, ax=ax, label="objective [deg]")
    if path_xs is not None and len(path_xs):
        p = np.asarray(path_xs)
        ax.plot(p[:, 0] * k0, p[:, 1] * k1, "w.-", lw=1.2, label="optimiser path")
        ax.plot(p[0, 0] * k0, p[0, 1] * k1, "wo", ms=7, label="start")
        f = p[-1] if final is None else np.asarray(final)
        ax.plot(f[0] * k0, f[1] * k1, "r*", ms=12, label="final (best iterate)")
    ax.plot(grid.best[0] * k0, grid.best[1] * k1, "kx", ms=10, mew=2, label="grid best")
    ax.set_xlabel(label(names[0]))
    ax.set_ylabel(label(names[1]))
    ax.set_title(title or "objective landscape")
    ax.legend(fontsize=7, loc="best")
    fig.tight_layout()
    fig.savefig(png, dpi=120)
    plt.close(fig)


def plot_tornado(result: dict, path, title: str | None = None):
    """Tornado chart of [`optim.sensitivity.sensitivities`][]: per metric, the
    elasticities (% metric change per % parameter change), largest on top."""
    metrics = result["metrics"]
    fig, axes = plt.subplots(
        1, len(metrics), figsize=(4.2 * len(metrics), 0.35 * len(result["names"]) + 1.5), squeeze=False
    )
    for ax, m, el in zip(axes[0], metrics, result["elasticity"]):
        order = np.argsort(np.abs(el))
        ax.barh(np.arange(len(order)), el[order], color=np.where(el[order] >= 0, "C3", "C0"))
        ax.set_yticks(np.arange(len(order)), [result["names"][i] for i in order], fontsize=8)
        ax.axvline(0.0, color="k", lw=0.8)
        ax.set_xlabel("elasticity (dm/m) / (dp/p)")
        ax.set_title(m, fontsize=9)
    fig.suptitle(title or "local sensitivities (ensemble AD) at the design")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
