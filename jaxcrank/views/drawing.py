"""A linkage drawn: bodies as bars (two or more points on a line), plates (three or more
off a line) or blocks (one point); ground pivots hatched; prismatic guides as rails or
slots; ideal pins as open circles; clearance joints as a pin in a hole, the play
exaggerated and labelled; joints and bodies named.

[`draw`][jaxcrank.views.drawing.draw] makes a figure of the ideal mechanism at a driver
angle; [`Sketch`][jaxcrank.views.drawing.Sketch] holds the artists, so the animation
([`jaxcrank.views.animation`][]) moves the same drawing. Each joint's artist carries the
``gid`` ``"joint:<name>"`` (a circle centred on the hole, or a block centred on the
sliding point), so a drawing can be read back.
"""

from __future__ import annotations

import math

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.lines import Line2D
from matplotlib.patches import Circle, Polygon

from . import geometry as geo
from .geometry import GROUND

#: colours of the moving bodies, in name order (the driven body first)
PALETTE = ("#1f77b4", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#17becf", "#bcbd22", "#e377c2")
CLEARANCE = "#d62728"  # clearance joints
GHOST = "0.55"  # the ideal mechanism beside a run


def _unit(lo, hi) -> float:
    """The drawing's size unit, m: a thirtieth of the linkage's larger span."""
    return max(float(np.max(hi - lo)), 1e-9) / 30.0


def _rect(centre, angle, length, height) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    a, n = np.array([c, s]), np.array([-s, c])
    h, w = 0.5 * length, 0.5 * height
    return np.array([centre + h * a + w * n, centre - h * a + w * n, centre - h * a - w * n, centre + h * a - w * n])


class Sketch:
    """The artists of one linkage on one axes, made once and moved by
    [`update`][jaxcrank.views.drawing.Sketch.update].

    Args:
        ax: the matplotlib axes (equal aspect is set).
        lay: the linkage's [`Layout`][jaxcrank.views.geometry.Layout].
        span: ``(lower_left, upper_right)`` of everything to be shown, m (from
            [`extent`][jaxcrank.views.geometry.extent] over every instant drawn).
        travel: per prismatic joint, the range along its axis the sliding point covers, m
            (its rail or slot is drawn over it); missing joints get a rail about the point.
        magnify: the clearance joints' play drawn this many times its size; ``None``:
            each joint's play drawn as a fixed fraction of the hole, whatever its size.
        ghost: draw only the bodies' outlines, grey and dashed (the ideal mechanism
            beside a run).
        labels: name the joints and bodies (``"joints"``: the joints only).
        frames: draw each body's frame (x red, y green) and centre of mass.
    """

    def __init__(self, ax, lay, span, travel=None, magnify=None, ghost=False, labels=True, frames=False):
        self.ax, self.lay, self.ghost, self.labels, self.frames = ax, lay, ghost, labels, frames
        lo, hi = span
        self.u = u = _unit(lo, hi)
        self.centre = 0.5 * (lo + hi)
        self.travel = dict(travel or {})
        self.magnify = {}
        for j in lay.joints:
            if j.clearance is not None and j.clearance > 0:
                self.magnify[j.name] = magnify if magnify is not None else 0.3 * u / j.clearance
        self.colours = {b: PALETTE[k % len(PALETTE)] for k, b in enumerate(sorted(lay.parts, key=self._order))}
        self.artists: dict[str, object] = {}
        self._made = False

    def _order(self, b):
        return (b != self.lay.driven, b)

    # ------------------------------------------------------------------ building
    def _bar_width(self) -> float:
        """A bar's line width, points: 0.6 size units in data coordinates."""
        ax = self.ax
        ax.apply_aspect()
        px = ax.transData.transform([[0.0, 0.0], [self.u, 0.0]])
        return max(float(px[1, 0] - px[0, 0]) * 0.6 * 72.0 / ax.figure.dpi, 1.0)

    def _make(self, poses):
        ax = self.ax
        lw = self._bar_width()
        sliders = {j.pin[0] for j in self.lay.joints if j.kind == "prismatic"}
        for b, part in self.lay.parts.items():
            colour = GHOST if self.ghost else self.colours[b]
            if part.shape == "bar":
                style = dict(lw=1.2, ls="--", color=GHOST) if self.ghost else dict(lw=lw, color=colour, alpha=0.9)
                (self.artists[f"body:{b}"],) = ax.plot([], [], solid_capstyle="round", zorder=3, **style)
            elif part.shape == "plate":
                style = dict(fill=False, ls="--", ec=GHOST, lw=1.2) if self.ghost else dict(fc=colour, ec=colour)
                self.artists[f"body:{b}"] = ax.add_patch(
                    Polygon(np.zeros((3, 2)), closed=True, zorder=2, alpha=1.0 if self.ghost else 0.45, **style)
                )
            elif b not in sliders:  # a lone block: a square at its point
                style = dict(fill=False, ls="--", ec=GHOST) if self.ghost else dict(fc=colour, ec="k")
                self.artists[f"body:{b}"] = ax.add_patch(Polygon(np.zeros((4, 2)), closed=True, zorder=4, **style))
        for j in self.lay.joints:
            if j.kind == "prismatic":
                self._make_prismatic(j, poses)
            elif not self.ghost:
                self._make_revolute(j, poses)
        if self.labels and not self.ghost:
            text = dict(ha="center", va="center", zorder=7, clip_on=True)
            for j in self.lay.joints:
                colour = CLEARANCE if j.name in self.magnify else "k"
                self.artists[f"label:{j.name}"] = ax.text(0, 0, j.name, fontsize=9, weight="bold", color=colour, **text)
            for b in self.lay.parts if self.labels != "joints" else ():
                self.artists[f"name:{b}"] = ax.text(0, 0, b, fontsize=8, style="italic", color=self.colours[b], **text)
        if self.frames and not self.ghost:
            for b in self.lay.parts:
                self.artists[f"x:{b}"] = ax.plot([], [], color="#d62728", lw=1.0, zorder=8)[0]
                self.artists[f"y:{b}"] = ax.plot([], [], color="#2ca02c", lw=1.0, zorder=8)[0]
                self.artists[f"com:{b}"] = ax.plot([], [], "k+", ms=7, zorder=8)[0]
        self._made = True

    def _make_revolute(self, j, poses):
        ax, u = self.ax, self.u
        hole, _ = geo.joint_positions(self.lay, poses)[j.name]
        if GROUND in (j.hole[0], j.pin[0]):  # a fixed pivot: a hatched base on the side away from its body
            self._ground_base(j, hole, poses)
        if j.name in self.magnify:
            self.artists[f"joint:{j.name}"] = ax.add_patch(
                Circle(hole, 0.75 * u, fc="white", ec=CLEARANCE, lw=1.8, zorder=5, gid=f"joint:{j.name}")
            )
            pin_r = max(0.75 * u - self.magnify[j.name] * j.clearance, 0.15 * u)
            self.artists[f"pin:{j.name}"] = ax.add_patch(
                Circle(hole, pin_r, fc=CLEARANCE, ec="k", lw=0.6, alpha=0.8, zorder=6, gid=f"pin:{j.name}")
            )
        else:
            self.artists[f"joint:{j.name}"] = ax.add_patch(
                Circle(hole, 0.4 * u, fc="white", ec="k", lw=1.2, zorder=5, gid=f"joint:{j.name}")
            )

    def _ground_base(self, j, at, poses):
        """A fixed pivot's base at ``at``: a triangle and a hatched strip below it, or, where
        the body it carries lies below, turned to the side away from that body."""
        ax, u = self.ax, self.u
        body = j.pin[0] if j.hole[0] == GROUND else j.hole[0]
        part = self.lay.parts[body]
        centre = np.mean(geo.place(np.array(list(part.points.values())), poses[body]), axis=0) - at
        down = np.array([0.0, -1.0])
        if np.hypot(*centre) > 1e-12 and np.dot(centre, down) > 0.5 * np.hypot(*centre):  # the body hangs below
            down = -down
        side = np.array([-down[1], down[0]])

        def pts(*uv):
            return [at + u * (a * side + b * down) for a, b in uv]

        ax.add_patch(Polygon(pts((0, 0), (-0.8, 1.4), (0.8, 1.4)), fc="0.85", ec="k", lw=0.8, zorder=1))
        strip = pts((-1.2, 1.4), (1.2, 1.4), (1.2, 1.9), (-1.2, 1.9))
        ax.add_patch(Polygon(strip, fill=False, hatch="////", lw=0.0, ec="0.3", zorder=1))
        ends = np.array(pts((-1.2, 1.4), (1.2, 1.4)))
        ax.plot(ends[:, 0], ends[:, 1], color="k", lw=1.0, zorder=1)

    def _make_prismatic(self, j, poses):
        ax, u = self.ax, self.u
        if j.hole[0] == GROUND and not self.ghost:  # a fixed rail, hatched on one side
            lo, hi = self._travel(j, poses)
            a = np.array([math.cos(j.direction), math.sin(j.direction)])
            n = np.array([-a[1], a[0]])
            g = self.lay.ground[j.hole[1]]
            for side in (-1.0, 1.0):
                p0, p1 = g + lo * a + side * 0.6 * u * n, g + hi * a + side * 0.6 * u * n
                ax.plot([p0[0], p1[0]], [p0[1], p1[1]], color="k", lw=1.0, zorder=1)
            near, far = 0.6 * u * n, 1.1 * u * n
            strip = [g + lo * a - near, g + hi * a - near, g + hi * a - far, g + lo * a - far]
            ax.add_patch(Polygon(strip, fill=False, hatch="////", lw=0.0, ec="0.3", zorder=1))
        elif j.hole[0] != GROUND and not self.ghost:  # a slot along a moving body
            self.artists[f"slot:{j.name}"] = ax.plot([], [], color="k", lw=0.9, zorder=4)[0]
        if self.ghost:
            self.artists[f"joint:{j.name}"] = ax.add_patch(
                Polygon(np.zeros((4, 2)), closed=True, fill=False, ls="--", ec=GHOST, zorder=4)
            )
            return
        edge = CLEARANCE if j.name in self.magnify else "k"
        colour = self.colours.get(j.pin[0], "0.7")
        self.artists[f"joint:{j.name}"] = ax.add_patch(
            Polygon(np.zeros((4, 2)), closed=True, fc=colour, ec=edge, lw=1.5, zorder=4.5, gid=f"joint:{j.name}")
        )

    def _travel(self, j, poses):
        if j.name in self.travel:
            return self.travel[j.name]
        hole, pin = geo.joint_positions(self.lay, poses)[j.name]
        a = np.array([math.cos(j.direction), math.sin(j.direction)])
        s = float(np.dot(pin - hole, a))
        return s - 4.0 * self.u, s + 4.0 * self.u

    # ------------------------------------------------------------------ moving
    def update(self, poses: dict) -> list:
        """Place every artist for the body frame poses ``poses`` (per body (x, y, angle),
        m and rad); returns the artists that moved."""
        if not self._made:
            self._make(poses)
        u, moved = self.u, []
        positions = geo.joint_positions(self.lay, poses)
        for b, part in self.lay.parts.items():
            art = self.artists.get(f"body:{b}")
            if art is None:
                continue
            if part.shape == "bar":
                w = geo.place(part.outline, poses[b])
                art.set_data(w[:, 0], w[:, 1])
            elif part.shape == "plate":
                art.set_xy(geo.place(part.outline, poses[b]))
            else:
                art.set_xy(_rect(geo.place(part.outline, poses[b]), poses[b][2], 1.6 * u, 1.6 * u))
            moved.append(art)
        for j in self.lay.joints:
            hole, pin = positions[j.name]
            art = self.artists.get(f"joint:{j.name}")
            if j.kind == "revolute":
                if art is not None:
                    art.set_center(hole)
                    moved.append(art)
                if f"pin:{j.name}" in self.artists:
                    self.artists[f"pin:{j.name}"].set_center(hole + self.magnify[j.name] * (pin - hole))
                    moved.append(self.artists[f"pin:{j.name}"])
                continue
            axis = geo.angle_of(poses, j.hole[0]) + j.direction
            a = np.array([math.cos(axis), math.sin(axis)])
            n = np.array([-a[1], a[0]])
            off = float(np.dot(pin - hole, n))
            tilt = geo.angle_of(poses, j.pin[0]) - geo.angle_of(poses, j.hole[0])
            tilt = math.remainder(float(tilt) - j.angle, 2 * math.pi)
            k = self.magnify.get(j.name, 1.0)
            centre = pin + (k - 1.0) * off * n
            art.set_xy(_rect(centre, axis + k * tilt, 2.2 * u, 1.1 * u))
            moved.append(art)
            slot = self.artists.get(f"slot:{j.name}")
            if slot is not None:
                lo, hi = self._slot_span(j, poses, hole, a)
                xs, ys = [], []
                for side in (-1.0, 1.0):
                    p0, p1 = hole + lo * a + side * 0.6 * u * n, hole + hi * a + side * 0.6 * u * n
                    xs += [p0[0], p1[0], np.nan]
                    ys += [p0[1], p1[1], np.nan]
                slot.set_data(xs, ys)
                moved.append(slot)
        if self.labels and not self.ghost:
            self._place_labels(poses, positions, moved)
        if self.frames and not self.ghost:
            for b, part in self.lay.parts.items():
                o = geo.place(np.zeros(2), poses[b])
                ex, ey = geo.place(np.array([[1.5 * u, 0.0], [0.0, 1.5 * u]]), poses[b])
                self.artists[f"x:{b}"].set_data([o[0], ex[0]], [o[1], ex[1]])
                self.artists[f"y:{b}"].set_data([o[0], ey[0]], [o[1], ey[1]])
                c = geo.place(part.centre_of_mass, poses[b])
                self.artists[f"com:{b}"].set_data([c[0]], [c[1]])
        return moved

    def _slot_span(self, j, poses, hole, a):
        part = self.lay.parts[j.hole[0]]
        pts = geo.place(np.array(list(part.points.values())), poses[j.hole[0]])
        s = (pts - hole) @ a
        return float(np.min(s)) - 0.5 * self.u, float(np.max(s)) + 0.5 * self.u

    def _occupied(self, poses, positions) -> np.ndarray:
        """Points the drawing covers (bodies sampled along, joints), m, (k, 2)."""
        pts = [np.reshape(p, (-1, 2)) for pair in positions.values() for p in pair]
        for b, part in self.lay.parts.items():
            w = np.reshape(geo.place(part.outline, poses[b]), (-1, 2))
            if part.shape == "bar":
                w = w[0] + np.linspace(0.0, 1.0, 12)[:, None] * (w[1] - w[0])
            pts.append(w)
        return np.concatenate(pts)

    def _place_labels(self, poses, positions, moved):
        u = self.u
        if not hasattr(self, "_offsets"):  # chosen once: the emptiest of eight directions around each joint
            taken = self._occupied(poses, positions)
            self._offsets = {}
            for j in self.lay.joints:
                p = positions[j.name][0] if j.kind == "revolute" else positions[j.name][1]
                best = None
                for k in range(8):
                    d = np.array([math.cos(k * math.pi / 4 + math.pi / 8), math.sin(k * math.pi / 4 + math.pi / 8)])
                    at = p + 1.6 * u * d
                    room = float(np.min(np.hypot(*(taken - at).T)))
                    if best is None or room > best[0] + 1e-12:
                        best = (room, 1.6 * u * d)
                self._offsets[j.name] = best[1]
                taken = np.vstack([taken, p + best[1]])
        for j in self.lay.joints:
            p = positions[j.name][0] if j.kind == "revolute" else positions[j.name][1]
            lab = self.artists[f"label:{j.name}"]
            lab.set_position(p + self._offsets[j.name])
            moved.append(lab)
        for b, part in self.lay.parts.items() if self.labels != "joints" else ():
            w = geo.place(part.outline, poses[b]).reshape(-1, 2)
            mid = w.mean(axis=0)
            if part.shape == "bar":
                t = w[1] - w[0]
                n = np.array([-t[1], t[0]]) / max(float(np.hypot(*t)), 1e-12)
                mid = mid + 1.1 * u * (n if np.dot(n, mid - self.centre) >= 0 else -n)
            elif part.shape == "block":
                mid = mid + np.array([0.0, 1.6 * u])
            lab = self.artists[f"name:{b}"]
            lab.set_position(mid)
            moved.append(lab)

    def note(self) -> str:
        """A line naming each clearance joint, its clearance (mm) and how much its play is
        magnified; empty without clearance joints."""
        parts = [
            f"{j.name} {j.clearance * 1e3:.3g} mm (x{self.magnify[j.name]:.3g})"
            for j in self.lay.joints
            if j.name in self.magnify
        ]
        return ("clearance joints (red), play drawn magnified: " + ", ".join(parts)) if parts else ""


def fit(ax, lay, span, poses=None) -> dict:
    """Frame ``ax`` on ``span`` (``(lower_left, upper_right)``, m) with a margin, equal
    aspect; return each fixed rail's travel along its axis (m) over the instants of
    ``poses`` (per body (n, 3)), for [`Sketch`][jaxcrank.views.drawing.Sketch]."""
    lo, hi = span
    u = _unit(lo, hi)
    pad = 3.5 * u
    ax.set_xlim(lo[0] - pad, hi[0] + pad)
    ax.set_ylim(lo[1] - pad, hi[1] + pad)
    ax.set_aspect("equal")
    travel = {}
    for j in lay.joints if poses is not None else ():
        if j.kind == "prismatic" and j.hole[0] == GROUND:
            s = (geo.site(lay, poses, j.pin) - geo.site(lay, poses, j.hole)) @ np.array(
                [math.cos(j.direction), math.sin(j.direction)]
            )
            travel[j.name] = (float(s.min()) - 2.0 * u, float(s.max()) + 2.0 * u)
    return travel


def draw(
    mech,
    angle: float | None = None,
    *,
    ax=None,
    magnify: float | None = None,
    labels: bool = True,
    frames: bool = False,
    paths: bool = True,
):
    """Draw a mechanism's ideal assembly at a driver angle.

    Args:
        mech: a preset or written-out linkage.
        angle: the driver's angle, deg (default: its initial angle).
        ax: the axes to draw on (default: a new figure's).
        magnify: draw each clearance this many times its size (default: every play
            drawn at a fixed fraction of its hole, the factor written beside the joint).
        labels: name the joints (with their clearances) and bodies.
        frames: draw each body's frame (x red, y green) and centre of mass (+).
        paths: draw the path of each moving joint over a turn of the driver (dotted).

    Returns:
        The matplotlib Figure.

    Raises:
        ParameterError: a linkage that cannot be assembled, or ``magnify`` that is not
            positive.
    """
    from ..physics.params import ParameterError

    if magnify is not None and not (math.isfinite(magnify) and magnify > 0):
        raise ParameterError(f"magnify = {magnify!r} must be a positive number (valid range: (0, inf))")
    lay = geo.layout(mech)
    start = float(np.asarray(mech.linkage().driver.initial_angle, dtype=float))
    phi = start if angle is None else math.radians(angle)
    turn = geo.assembled_poses(mech, phi + np.linspace(0.0, 2.0 * np.pi, 181))  # one program: the first is phi
    poses = {b: p[0] for b, p in turn.items()}
    ok = np.all(np.isfinite(np.stack([p[:, 0] for p in turn.values()])), axis=0)
    turn = {b: p[ok] for b, p in turn.items()}
    lo, hi = geo.extent(lay, turn if ok.any() else poses)
    if ax is None:
        fig, ax = plt.subplots(figsize=(7.0, 5.0), layout="constrained")
    fig = ax.figure
    travel = fit(ax, lay, (lo, hi), turn if ok.any() else None)
    sketch = Sketch(ax, lay, (lo, hi), travel=travel, magnify=magnify, labels=labels, frames=frames)
    if paths and ok.any():
        for j in lay.joints:
            if GROUND in (j.hole[0], j.pin[0]):
                continue
            p = geo.site(lay, turn, j.hole if j.kind == "revolute" else j.pin)
            ax.add_line(Line2D(p[:, 0], p[:, 1], color="0.6", lw=0.8, ls=":", zorder=0))
    sketch.update(poses)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(True, lw=0.3, alpha=0.5)
    note = f"\n{sketch.note()}" if sketch.note() else ""
    ax.set_title(f"{lay.name}: {lay.driven} at {math.degrees(phi):.4g} deg{note}", fontsize=9)
    fig.sketch = sketch  # the artists, for a caller that moves them
    return fig
