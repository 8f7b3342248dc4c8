"""Bearing-load diagrams of a run ([`bearing_loads`][jaxcrank.runs.plots_loads.bearing_loads]),
from [`jaxcrank.analysis.outputs.trajectory`][] columns; [`jaxcrank.runs.plots.figures`][]
draws them as ``bearing_loads.png``."""

from __future__ import annotations

import math

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.ticker import MaxNLocator

from ..physics.linkage import GROUND

#: from this peak on (N) a panel's forces are shown in kN
KILONEWTON_FROM = 1e3


def _unit(peak: float) -> tuple[str, float, str]:
    """(unit, factor from N, number format) of a panel whose largest force is ``peak`` N."""
    return ("kN", 1e-3, ".3g") if peak >= KILONEWTON_FROM else ("N", 1.0, ".0f")


def _angle(cols, body: str) -> np.ndarray:
    """A body's angle, rad (zero for the ground)."""
    return np.zeros_like(cols["t"]) if body == GROUND else np.deg2rad(cols[f"{body}_angle"])


def _point(cols, lk, site) -> tuple[np.ndarray, np.ndarray]:
    """World position of a joint's site (``body.point``) at every sample, m."""
    if site.body == GROUND:
        p = lk.ground[site.point]
        return np.full_like(cols["t"], float(p.x)), np.full_like(cols["t"], float(p.y))
    body = lk.bodies[site.body]
    p, com = body.points[site.point], body.centre_of_mass
    dx, dy = float(p.x) - float(com.x), float(p.y) - float(com.y)
    a = _angle(cols, site.body)
    return cols[f"{site.body}_x"] + np.cos(a) * dx - np.sin(a) * dy, cols[f"{site.body}_y"] + np.sin(a) * dx + np.cos(
        a
    ) * dy


def bearing_force(cols, mech, joint: str) -> tuple[np.ndarray, np.ndarray]:
    """The force on a joint's bearing (its hole side, or a prismatic joint's guide): minus
    the pin-side force ``force_<joint>_x``, ``force_<joint>_y``, rotated into the frame of
    the hole's (guide's) body (the world frame for the ground), N: ``(along the body's
    x axis, along its y axis)`` at every sample."""
    hole = mech.linkage().connections[joint].sites()[0]
    fx, fy = -np.asarray(cols[f"force_{joint}_x"]), -np.asarray(cols[f"force_{joint}_y"])
    a = _angle(cols, hole.body)
    c, s = np.cos(a), np.sin(a)
    return c * fx + s * fy, -s * fx + c * fy


def _where(body: str) -> str:
    return "the ground" if body == GROUND else body


def _polar_panel(ax, cols, mech, joint, steady):
    hole = mech.linkage().connections[joint].sites()[0]
    lx, ly = bearing_force(cols, mech, joint)
    r, phi = np.hypot(lx, ly)[steady], np.arctan2(ly, lx)[steady]
    i = int(np.argmax(r))
    unit, f, fmt = _unit(float(r[i]))
    ax.plot(phi, r * f, lw=0.8, color="C0")
    ax.plot([phi[i]], [r[i] * f], "o", ms=6, mfc="none", mec="C3", mew=1.5, zorder=5)
    ax.plot([0.0, phi[i]], [0.0, r[i] * f], color="C3", lw=0.8, zorder=4)
    ax.set_rlim(0.0, 1.08 * max(float(r[i]) * f, 1e-12))
    ax.set_rlabel_position(112.5)
    ax.yaxis.set_major_locator(MaxNLocator(3))
    ax.tick_params(axis="y", labelsize="small")
    direction = np.rad2deg(phi[i]) % 360.0
    ax.set_title(
        f"{joint}: force on the bearing in {_where(hole.body)} [{unit}]\n"
        f"peak {r[i] * f:{fmt}} {unit} at {direction:.0f}°",
        fontsize="medium",
    )


def _guide_panel(ax, cols, mech, joint, steady):
    """A prismatic joint: the force on its guide normal to it (and along it where it is not
    zero: friction) against the slider's position along it."""
    lk = mech.linkage()
    conn = lk.connections[joint]
    guide, slider = conn.sites()
    lx, ly = bearing_force(cols, mech, joint)
    d = float(conn.direction)  # the guide's axis in the guide body's frame
    along, normal = np.cos(d) * lx + np.sin(d) * ly, -np.sin(d) * lx + np.cos(d) * ly
    (gx, gy), (sx, sy) = _point(cols, lk, guide), _point(cols, lk, slider)
    a = _angle(cols, guide.body) + d
    s = ((sx - gx) * np.cos(a) + (sy - gy) * np.sin(a))[steady] * 1e3
    normal, along = normal[steady], along[steady]
    i = int(np.argmax(np.abs(normal)))
    unit, f, fmt = _unit(float(np.max(np.hypot(normal, along))))
    ax.plot(s, normal * f, lw=0.8, color="C0", label="normal to the guide")
    if np.max(np.abs(along)) > 1e-6 * max(float(np.max(np.abs(normal))), 1e-300):
        ax.plot(s, along * f, lw=0.8, color="C1", label="along the guide")
        ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.22), ncol=2, frameon=False, fontsize="small")
    ax.plot([s[i]], [normal[i] * f], "o", ms=6, mfc="none", mec="C3", mew=1.5, zorder=5)
    ax.axhline(0.0, color="0.5", lw=0.6)
    ax.set_xlabel(f"slider position along {joint} [mm]")
    ax.set_ylabel(f"force on the guide [{unit}]")
    ax.yaxis.set_major_locator(MaxNLocator(5))
    ax.set_title(
        f"{joint}: force on the guide in {_where(guide.body)} [{unit}]\n"
        f"peak {abs(normal[i]) * f:{fmt}} {unit} at {s[i]:.0f} mm",
        fontsize="medium",
    )


def _grid(n: int) -> tuple[int, int]:
    """(rows, columns) of ``n`` panels: two columns for up to four, else three."""
    columns = 1 if n == 1 else (2 if n <= 4 else 3)
    return math.ceil(n / columns), columns


def bearing_loads(cols, mech, steady) -> plt.Figure:
    """The bearing-load diagram of every joint over the samples ``steady`` (bool; the
    motion after the first revolution): a revolute joint's force on its bearing (the
    hole side: minus ``force_<joint>_x``, ``force_<joint>_y``) in the frame of the hole's
    body (the world frame for a bearing in the ground) as a polar curve, angle from the
    body's x axis, counter-clockwise, and magnitude (N, or kN from `KILONEWTON_FROM`);
    a prismatic joint's force on its guide normal to the guide (and along it when not
    zero) against the slider's position along the guide, mm. Each panel marks its peak
    (circle) and gives it in its title. One panel per joint, in sorted joint order, two
    or three to a row."""
    lk = mech.linkage()
    joints = sorted(lk.connections)
    rows, columns = _grid(len(joints))
    fig = plt.figure(figsize=(4.0 * columns, 4.0 * rows + 0.4), layout="constrained")
    for k, joint in enumerate(joints):
        polar = lk.connections[joint].kind == "revolute"
        ax = fig.add_subplot(rows, columns, k + 1, projection="polar" if polar else None)
        (_polar_panel if polar else _guide_panel)(ax, cols, mech, joint, steady)
    part = "after the first revolution" if not steady.all() else "whole run"
    fig.suptitle(f"Force on each bearing in its body's frame ({part})")
    return fig
