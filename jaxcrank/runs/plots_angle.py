"""The x axis of a run's time-series figures and their start-up: the driven body's angle
or time ([`abscissa`][jaxcrank.runs.plots_angle.abscissa]), the samples after the first
revolution ([`after_first_revolution`][jaxcrank.runs.plots_angle.after_first_revolution]),
and the shaded start-up with its off-scale peak written where it covers the fewest
samples ([`clip_startup`][jaxcrank.runs.plots_angle.clip_startup])."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from matplotlib.ticker import MultipleLocator

#: the abscissas of the time-series figures: the driven body's angle (deg) or time (s)
AGAINST = ("angle", "time")
#: a run must go on this far past its first revolution, deg, for the figures to treat
#: that revolution as its start-up
LEFT_AFTER = 3.6
#: the (shaded) start-up's note goes to the spot, of these (axes fraction and alignment),
#: where it covers the fewest samples
SPOTS = tuple((x, y, ha, va) for y, va in ((0.97, "top"), (0.03, "bottom")) for x, ha in ((0.02, "left"),
               (0.26, "center"), (0.5, "center"), (0.74, "center"), (0.98, "right")))  # fmt: skip
NOTE = {"fontsize": 9, "bbox": {"boxstyle": "round,pad=0.25", "fc": "white", "ec": "0.6", "lw": 0.5, "alpha": 0.9}}


class Abscissa(NamedTuple):
    """The x values of the time-series figures, their axis label and kind (``"angle"``, ``"time"``)."""

    values: np.ndarray
    label: str
    kind: str

    def at(self, i: int) -> str:
        """Where sample ``i`` lies, in words."""
        return f"{self.values[i]:,.0f}°" if self.kind == "angle" else f"t = {self.values[i]:.4f} s"

    def ticks(self, ax) -> None:
        """On the angle, ``ax``'s x ticks every 90 deg where that gives at most about 2
        ticks per inch of the axes, else every 360 deg (or a multiple of it) with minor
        ticks every 90 deg; spans under 180 deg keep matplotlib's ticks."""
        if self.kind != "angle":
            return
        span = float(np.max(self.values) - np.min(self.values))
        if span < 180.0:
            return
        most = max(3, int(2.0 * ax.get_position().width * ax.figure.get_figwidth()))
        step = 90.0 if int(span / 90.0 + 1e-6) + 1 <= most else 360.0 * max(1, int(np.ceil(span / 360.0 / (most - 1))))
        ax.xaxis.set_major_locator(MultipleLocator(step))
        if step > 90.0 and span / 90.0 <= 64:
            ax.xaxis.set_minor_locator(MultipleLocator(90.0))


def abscissa(cols, mech, against: str = "angle") -> Abscissa:
    """The x axis of the time-series figures: ``"angle"``, the driven body's angle turned
    since the run's start (``mech.linkage().driver.body``'s ``<body>_angle`` column less
    its first value, deg, cumulative: 0 to 1440 for four revolutions; counted clockwise
    for a body that turns clockwise), or ``"time"`` (the ``t`` column, s).

    Raises:
        ValueError: if ``against`` is neither.
    """
    if against not in AGAINST:
        raise ValueError(f"against = {against!r}: must be one of {', '.join(repr(a) for a in AGAINST)}")
    if against == "time":
        return Abscissa(np.asarray(cols["t"]), "t [s]", "time")
    body = mech.linkage().driver.body
    turned = np.asarray(cols[f"{body}_angle"], dtype=float)
    turned = turned - turned[0]
    clockwise = turned[-1] < 0.0
    label = f"{body} angle from the start{', clockwise' if clockwise else ''} [deg]"
    return Abscissa(-turned if clockwise else turned, label, "angle")


def after_first_revolution(cols, mech) -> np.ndarray:
    """Samples after the driven body's first revolution (the start-up impacts left out),
    bool; all samples for a run that ends within it or less than `LEFT_AFTER` deg after
    it (a steady-state orbit of one revolution has no start-up)."""
    angle = np.asarray(cols[f"{mech.linkage().driver.body}_angle"], dtype=float)
    turned = np.abs(angle - angle[0])
    after = turned >= 360.0
    return after if turned.max() >= 360.0 + LEFT_AFTER else np.ones_like(after)


def emptiest_spot(ax, text: str, edge: str | None = None) -> tuple[tuple, int, float]:
    """Where in ``ax`` (its limits set) a note of ``text`` covers the least data: of the
    spots `SPOTS` (along the ``edge`` ``"top"`` or ``"bottom"`` only, if given), the one
    whose box the fewest segments of the axes' lines cross (by their bounding boxes).

    Returns:
        ``((x, y, ha, va), segments crossing its box, the box's height in axes fraction)``.
    """
    ax.get_xlim(), ax.get_ylim()  # the limits autoscaled now: the data's place in the axes
    if ax.figure.get_layout_engine() is not None:  # the axes' size as drawn
        ax.figure.get_layout_engine().execute(ax.figure)
    renderer = ax.figure.canvas.get_renderer()
    probe = ax.text(0.0, 0.0, text, transform=ax.transAxes, **NOTE)
    box, frame = probe.get_window_extent(renderer), ax.get_window_extent(renderer)
    probe.remove()
    w, h = 1.1 * box.width / frame.width, 1.2 * box.height / frame.height
    to_axes = ax.transData + ax.transAxes.inverted()
    segments = []
    for line in ax.get_lines():
        p = to_axes.transform(np.column_stack(line.get_data()))
        segments.append(np.concatenate([np.minimum(p[:-1], p[1:]), np.maximum(p[:-1], p[1:])], axis=1))
    segments = np.concatenate(segments) if segments else np.zeros((0, 4))
    spots = [spot for spot in SPOTS if edge in (None, spot[3])]
    counts = []
    for x, y, ha, va in spots:
        x0 = x - {"left": 0.0, "center": w / 2, "right": w}[ha]
        y0 = y - (h if va == "top" else 0.0)
        crossing = (
            (segments[:, 2] >= x0) & (segments[:, 0] <= x0 + w) & (segments[:, 3] >= y0) & (segments[:, 1] <= y0 + h)
        )
        counts.append(int(np.sum(crossing)))
    k = int(np.argmin(counts))
    return spots[k], counts[k], h


def clip_startup(ax, x: Abscissa, curves, steady, unit):
    """Limit ``ax``'s y-range to the curves' values after the start-up (``steady`` samples,
    bool) and shade the start-up; the largest peak outside that range is written in the
    axes along the edge it crosses, where the note covers the least data (in a band
    added beyond the steady range where every spot would cover some), with an arrow to
    where it leaves the axes, so the steady motion is legible. ``x``: the
    abscissa the curves are drawn against; ``unit``: the curves' unit, for the note."""
    if steady.all():
        return
    t = x.values
    lo = min(float(np.min(c[steady])) for c in curves)
    hi = max(float(np.max(c[steady])) for c in curves)
    pad = 0.08 * (hi - lo if hi > lo else max(abs(hi), 1.0))
    lo, hi = lo - pad, hi + pad
    ax.set_ylim(lo, hi)
    ax.axvspan(t[0], t[np.argmax(steady)], color="0.92", zorder=0, lw=0)
    # the largest excursion of any curve beyond the range, written and pointed at
    worst = None
    for c in curves:
        outside = (c > hi) | (c < lo)
        if outside.any():
            i = int(np.argmax(np.where(outside, np.abs(c), -np.inf)))
            if worst is None or abs(c[i]) > abs(worst[1]):
                worst = (i, float(c[i]))
    if worst is not None:
        i, vi = worst
        text = f"start-up peak {vi:,.0f} {unit}\nat {x.at(i)}, off scale"
        edge = "top" if vi > hi else "bottom"
        (sx, sy, ha, va), covered, h = emptiest_spot(ax, text, edge)
        if covered:  # a band of the note's height beyond the steady motion's range, on that edge
            extra = (hi - lo) * h / (1.0 - h)
            lo, hi = (lo, hi + extra) if edge == "top" else (lo - extra, hi)
            ax.set_ylim(lo, hi)
            (sx, sy, ha, va), _, _ = emptiest_spot(ax, text, edge)
        ax.annotate(text, xy=(t[i], hi if edge == "top" else lo), xytext=(sx, sy), textcoords="axes fraction", ha=ha,
                    va=va, arrowprops={"arrowstyle": "->", "lw": 0.7, "color": "0.3"}, **NOTE)  # fmt: skip
