"""A run's mechanism moving: the drawing of [`jaxcrank.views.drawing`][] placed at each
frame from the run's columns, the ideal mechanism ghosted beside it, and for each
clearance joint an inset with its pin's orbit in the hole (magnified to the clearance)
and its contact force as an arrow.

[`animate`][jaxcrank.views.animation.animate] returns a matplotlib ``FuncAnimation``
(shown inline by notebooks); [`save`][jaxcrank.views.animation.save] writes it as GIF,
MP4 (where ffmpeg is found) or a self-contained HTML page with play controls.
"""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.animation import FFMpegWriter, FuncAnimation

from .._private import mark_animation_started
from ..physics.params import ParameterError
from . import geometry as geo
from .drawing import CLEARANCE, Sketch, fit

#: the file types [`save`][jaxcrank.views.animation.save] writes, by suffix
FORMATS = (".gif", ".mp4", ".html")
INSETS = 3  # at most this many clearance joints get an inset (the largest peak forces)


def frame_indices(cols: dict, mech, revolutions: float | None = 1.0, per_revolution: int = 72) -> np.ndarray:
    """The samples shown: the last ``revolutions`` turns of the driven body (``None``: the
    whole run), one frame every ``360 / per_revolution`` degrees of its angle.

    Raises:
        ParameterError: ``revolutions`` or ``per_revolution`` that is not positive.
    """
    if revolutions is not None and not (math.isfinite(revolutions) and revolutions > 0):
        raise ParameterError(f"revolutions = {revolutions!r} must be a positive number (valid range: (0, inf))")
    if per_revolution < 2:
        raise ParameterError(f"per_revolution = {per_revolution!r} must be an integer >= 2")
    angle = np.asarray(cols[f"{mech.linkage().driver.body}_angle"], dtype=float)
    travelled = np.maximum.accumulate(np.abs(angle - angle[0]))
    end = float(travelled[-1])
    start = 0.0 if revolutions is None else max(end - 360.0 * revolutions, 0.0)
    step = 360.0 / per_revolution
    targets = np.arange(start, end + 1e-9, step)
    idx = np.unique(np.clip(np.searchsorted(travelled, targets), 0, len(angle) - 1))
    return idx if len(idx) > 1 else np.arange(len(angle))


def _force(cols, j, i):
    """Joint ``j``'s force on its pin at samples ``i`` (N, world frame), (k, 2)."""
    if f"force_{j}_x" in cols:
        return np.stack([np.asarray(cols[f"force_{j}_x"])[i], np.asarray(cols[f"force_{j}_y"])[i]], -1)
    e = np.stack([np.asarray(cols[f"ecc_{j}_x"])[i], np.asarray(cols[f"ecc_{j}_y"])[i]], -1)
    n = np.hypot(e[:, 0], e[:, 1])
    unit = np.where(n[:, None] > 0, e / np.where(n > 0, n, 1.0)[:, None], 0.0)
    return -np.asarray(cols[f"force_{j}_normal"])[i][:, None] * unit


def _force_text(newtons: float) -> str:
    return f"{newtons / 1e3:.3g} kN" if newtons >= 1e3 else f"{newtons:.3g} N"


def animate(
    sim=None,
    *,
    cols: dict | None = None,
    mech=None,
    revolutions: float | None = 1.0,
    per_revolution: int = 72,
    magnify: float | None = None,
    fps: float = 24.0,
    insets: bool = True,
    ghost: bool = True,
    dpi: float = 100.0,
):
    """The mechanism of a run, moving.

    Args:
        sim: a [`Simulation`][jaxcrank.numerics.solve.Simulation]; or give ``cols`` (a
            run's [`trajectory`][jaxcrank.analysis.outputs.trajectory] columns, e.g. read
            from its ``trajectory.csv``) and ``mech``.
        revolutions: the last this many turns of the driven body (``None``: the whole run).
        per_revolution: frames per turn.
        magnify: the clearance joints' play drawn this many times its size (default: a
            fixed fraction of each hole).
        fps: frames per second of playback.
        insets: an inset per clearance joint (up to three, the largest peak forces) with
            its pin's orbit in the hole and its contact force on the pin as an arrow (an
            arrow as long as the clearance is the 95th percentile of the force shown).
        ghost: the ideal mechanism drawn beside, grey and dashed.
        dpi: the figure's resolution, dots per inch (it is 8 x 4.5 inches).

    Returns:
        A matplotlib ``FuncAnimation`` (its figure is ``.fig``; the frames' sample indices
        are ``.indices``).

    Raises:
        ParameterError: bad ``revolutions``, ``per_revolution``, ``fps`` or ``magnify``.
        KeyError: ``cols`` without the columns of ``mech``'s bodies.
    """
    if sim is not None:
        from ..analysis import outputs

        mech = sim.mechanism
        cols = outputs.trajectory(sim) if cols is None else cols
    if cols is None or mech is None:
        raise ParameterError("animate needs a Simulation, or both cols (a run's columns) and mech")
    if not (math.isfinite(fps) and fps > 0):
        raise ParameterError(f"fps = {fps!r} must be a positive number (valid range: (0, inf))")
    if magnify is not None and not (math.isfinite(magnify) and magnify > 0):
        raise ParameterError(f"magnify = {magnify!r} must be a positive number (valid range: (0, inf))")
    lay = geo.layout(mech)
    idx = frame_indices(cols, mech, revolutions, per_revolution)
    real = {b: p[idx] for b, p in geo.poses_from_columns(cols, mech).items()}
    ideal = {b: p[idx] for b, p in geo.poses_from_columns(cols, mech, "ideal_").items()}
    lo, hi = geo.extent(lay, real)
    lo2, hi2 = geo.extent(lay, ideal)
    lo, hi = np.minimum(lo, lo2), np.maximum(hi, hi2)

    clear = [j for j in lay.joints if j.kind == "revolute" and j.clearance is not None and j.clearance > 0]
    peak = {j.name: float(np.max(np.hypot(*_force(cols, j.name, idx).T))) for j in clear}
    shown = sorted(clear, key=lambda j: -peak[j.name])[:INSETS] if insets else []
    shown = sorted(shown, key=lambda j: j.name)
    fig = plt.figure(figsize=(8.0, 4.5), dpi=dpi)
    if shown:
        grid = fig.add_gridspec(
            len(shown), 2, width_ratios=(3.2, 1.0), left=0.07, right=0.98, bottom=0.1, top=0.9, wspace=0.25, hspace=0.45
        )
        ax = fig.add_subplot(grid[:, 0])
    else:
        ax = fig.add_axes((0.08, 0.1, 0.88, 0.8))
    travel = fit(ax, lay, (lo, hi), ideal)
    ax.set_xlabel("x [m]", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.grid(True, lw=0.3, alpha=0.5)
    sketches = [Sketch(ax, lay, (lo, hi), travel=travel, ghost=True)] if ghost else []
    main = Sketch(ax, lay, (lo, hi), travel=travel, magnify=magnify, labels="joints")
    sketches.append(main)
    t = np.asarray(cols["t"], dtype=float)[idx]
    driver = np.asarray(cols[f"{lay.driven}_angle"], dtype=float)[idx]
    ax.text(0.01, 0.98, f"t, {lay.driven} angle:", transform=ax.transAxes, va="top", fontsize=7)
    clock = ax.text(0.01, 0.93, "", transform=ax.transAxes, va="top", fontsize=8, family="monospace")
    note = main.note()
    ax.set_title(
        f"{lay.name}" + (" (ideal mechanism dashed)" if ghost else "") + (f"\n{note}" if note else ""), fontsize=8
    )

    panels = []
    for k, j in enumerate(shown):
        iax = fig.add_subplot(grid[k, 1])
        c = j.clearance * 1e3
        e = np.stack([np.asarray(cols[f"ecc_{j.name}_x"])[idx], np.asarray(cols[f"ecc_{j.name}_y"])[idx]], -1) * 1e3
        f = _force(cols, j.name, idx)
        th = np.linspace(0, 2 * np.pi, 181)
        iax.plot(c * np.cos(th), c * np.sin(th), "k--", lw=0.8)
        worn, outline = None, None
        if j.worn:  # a worn hole turns with its body
            turn = [geo.body_angle(cols, side[0], idx)[:, None] for side in (j.hole, j.pin)]
            worn = 1e3 * geo.gap(j, th[None, :], *turn)
            (outline,) = iax.plot([], [], "k-", lw=0.9)
        iax.plot(e[:, 0], e[:, 1], color="0.6", lw=0.6)
        (dot,) = iax.plot([], [], "o", color=CLEARANCE, ms=4)
        arrow = iax.quiver(
            [0.0], [0.0], [0.0], [0.0], angles="xy", scale_units="xy", scale=1.0, color=CLEARANCE, width=0.02
        )
        r = 1.35 * max(c, float(np.max(np.hypot(*e.T))), 0.0 if worn is None else float(np.max(worn)))
        iax.set_xlim(-r, r)
        iax.set_ylim(-r, r)
        iax.set_aspect("equal")
        iax.tick_params(labelsize=6)
        reach = max(float(np.percentile(np.hypot(*f.T), 95)), 1e-12)  # an arrow of length c: this force
        scale = c / reach
        what = "pin in worn hole (new: dashed)" if worn is not None else "pin in hole"
        iax.set_title(f"{j.name}: {what} [mm]\narrow: contact force, c = {_force_text(reach)}", fontsize=6.5)
        panels.append((e, f, dot, arrow, scale, worn, outline, th))

    def update(k):
        pose = {b: p[k] for b, p in real.items()}
        moved = []
        if ghost:
            moved += sketches[0].update({b: p[k] for b, p in ideal.items()})
        moved += main.update(pose)
        clock.set_text(f"{t[k]:.4f} s {driver[k] % 360.0:5.1f}\N{DEGREE SIGN}")
        moved.append(clock)
        for e, f, dot, arrow, scale, worn, outline, th in panels:
            dot.set_data([e[k, 0]], [e[k, 1]])
            arrow.set_offsets([e[k]])
            arrow.set_UVC([f[k, 0] * scale], [f[k, 1] * scale])
            moved += [dot, arrow]
            if outline is not None:
                outline.set_data(worn[k] * np.cos(th), worn[k] * np.sin(th))
                moved.append(outline)
        return moved

    return MechanismAnimation(fig, update, idx, fps)


class MechanismAnimation(FuncAnimation):
    """A ``FuncAnimation`` of a mechanism that renders its frames fast: the still parts
    (axes, ground, titles) drawn once, only the moving artists redrawn per frame
    ([`rgba_frames`][jaxcrank.views.animation.MechanismAnimation.rgba_frames]); a notebook
    shows it as the page [`html_page`][jaxcrank.views.animation.html_page] writes.

    Attributes:
        fig: the matplotlib Figure.
        update_frame: places every artist for frame k; returns those that moved.
        indices: the run's sample index of each frame.
        fps: frames per second of playback.
    """

    def __init__(self, fig, update, indices, fps):
        super().__init__(fig, update, frames=len(indices), interval=1000.0 / fps, blit=False)
        mark_animation_started(self)  # its frames are rendered by rgba_frames, not by matplotlib's event loop
        self.fig, self.update_frame, self.indices, self.fps = fig, update, indices, fps

    def rgba_frames(self):
        """Each frame as an RGBA image, a uint8 array (height, width, 4), in order."""
        fig = self.fig
        moving = self.update_frame(0)
        for art in moving:
            art.set_animated(True)
        fig.canvas.draw()
        still = fig.canvas.copy_from_bbox(fig.bbox)
        for k in range(len(self.indices)):
            moving = self.update_frame(k)
            fig.canvas.restore_region(still)
            for art in sorted(moving, key=lambda a: a.get_zorder()):
                fig.draw_artist(art)
            yield np.asarray(fig.canvas.buffer_rgba()).copy()
        for art in moving:
            art.set_animated(False)

    def _repr_html_(self):
        page = html_page(self, standalone=False)
        plt.close(self.fig)  # shown as the player: a notebook need not show the still figure too
        return page


def check_target(path) -> Path:
    """``path`` as a ``pathlib.Path`` where [`save`][jaxcrank.views.animation.save] can
    write it.

    Raises:
        ParameterError: a suffix not in ``FORMATS`` (.gif, .mp4, .html), or
            ``.mp4`` where ffmpeg is not found (with what to do instead).
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in FORMATS:
        raise ParameterError(f"{path.name}: the animation's file type must be one of {', '.join(FORMATS)}")
    if suffix == ".mp4" and not FFMpegWriter.isAvailable():
        raise ParameterError(
            f"{path.name}: writing MP4 needs ffmpeg, which is not found on PATH: install it (e.g. "
            "'apt-get install ffmpeg' or 'conda install ffmpeg'), or write .gif or .html instead"
        )
    return path


def save(anim: MechanismAnimation, path, *, fps: float | None = None) -> Path:
    """Write an animation from [`animate`][jaxcrank.views.animation.animate] by the suffix of
    ``path``: ``.gif`` (Pillow), ``.mp4`` (ffmpeg) or ``.html`` (one self-contained page,
    frames embedded, play controls, playing on load). Returns the path.

    Raises:
        ParameterError: another suffix, or ``.mp4`` where ffmpeg is not found (with what
            to do instead).
    """
    from PIL import Image

    path = check_target(path)
    suffix = path.suffix.lower()
    fps = float(fps if fps is not None else anim.fps)
    path.parent.mkdir(parents=True, exist_ok=True)
    if suffix == ".gif":
        frames = [Image.fromarray(f[..., :3]) for f in anim.rgba_frames()]
        palette = frames[0].quantize(colors=96, method=Image.Quantize.FASTOCTREE)
        frames = [palette] + [f.quantize(palette=palette, dither=Image.Dither.NONE) for f in frames[1:]]
        frames[0].save(path, save_all=True, append_images=frames[1:], duration=round(1000.0 / fps), loop=0)
    elif suffix == ".mp4":
        _write_mp4(anim, path, fps)
    else:
        path.write_text(html_page(anim, title=path.stem, fps=fps), encoding="utf-8")
    plt.close(anim.fig)
    return path


def _write_mp4(anim: MechanismAnimation, path: Path, fps: float) -> None:
    """The frames piped to ffmpeg as raw RGBA (H.264, yuv420p: plays in browsers)."""
    import subprocess

    import matplotlib

    frames = anim.rgba_frames()
    first = next(frames)
    h, w = first.shape[:2]
    cmd = [matplotlib.rcParams["animation.ffmpeg_path"], "-y", "-loglevel", "error", "-f", "rawvideo"]
    cmd += ["-pix_fmt", "rgba", "-s", f"{w}x{h}", "-r", f"{fps:g}", "-i", "-", "-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2"]
    cmd += ["-vcodec", "libx264", "-pix_fmt", "yuv420p", str(path)]
    with subprocess.Popen(cmd, stdin=subprocess.PIPE, stderr=subprocess.PIPE) as proc:
        try:
            proc.stdin.write(first.tobytes())
            for frame in frames:
                proc.stdin.write(frame.tobytes())
            proc.stdin.close()
        except BrokenPipeError:
            pass
        err = proc.stderr.read().decode(errors="replace").strip()
        if proc.wait() != 0:
            raise ParameterError(f"{path.name}: ffmpeg failed: {err.splitlines()[-1] if err else 'no message'}")


_PLAYER = """<div class="jaxcrank-player" id="{id}">
<img alt="{title}" style="max-width:100%;height:auto;display:block">
<div style="font:13px sans-serif;margin-top:4px">
<button type="button" data-do="play">pause</button>
<button type="button" data-do="step">step</button>
<input type="range" min="0" max="{last}" value="0" style="width:60%;vertical-align:middle">
<span>frame 1 / {count}</span></div></div>
<script>(function () {{
  var frames = [{frames}];
  var root = document.getElementById("{id}"), img = root.querySelector("img");
  var slider = root.querySelector("input"), label = root.querySelector("span");
  var play = root.querySelector("[data-do=play]"), step = root.querySelector("[data-do=step]");
  var k = 0, timer = null;
  function show(i) {{ k = (i + frames.length) % frames.length; img.src = "data:image/png;base64," + frames[k];
    slider.value = k; label.textContent = "frame " + (k + 1) + " / " + frames.length; }}
  function start() {{ timer = setInterval(function () {{ show(k + 1); }}, {interval}); play.textContent = "pause"; }}
  function stop() {{ clearInterval(timer); timer = null; play.textContent = "play"; }}
  play.onclick = function () {{ if (timer) stop(); else start(); }};
  step.onclick = function () {{ stop(); show(k + 1); }};
  slider.oninput = function () {{ stop(); show(parseInt(slider.value)); }};
  show(0); start();
}})();</script>"""


def html_page(
    anim: MechanismAnimation, title: str = "jaxcrank animation", fps: float | None = None, standalone: bool = True
) -> str:
    """The animation as HTML: its frames embedded as PNG images, a player (play/pause,
    step, a slider) that starts playing when shown; nothing is loaded from the network.
    ``standalone``: a whole page (else the player alone, for a notebook cell)."""
    import base64
    import io

    from PIL import Image

    encoded = []
    for f in anim.rgba_frames():
        buf = io.BytesIO()
        Image.fromarray(f[..., :3]).save(buf, format="png", optimize=False)
        encoded.append('"' + base64.b64encode(buf.getvalue()).decode("ascii") + '"')
    fps = float(fps if fps is not None else anim.fps)
    player = _PLAYER.format(
        id=f"jaxcrank-{id(anim):x}",
        title=title,
        last=len(encoded) - 1,
        count=len(encoded),
        frames=",".join(encoded),
        interval=round(1000.0 / fps),
    )
    if not standalone:
        return player
    return (
        f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8"><title>{title}</title></head>\n'
        f"<body>\n{player}\n</body></html>\n"
    )
