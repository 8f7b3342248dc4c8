"""``jaxcrank draw`` (a linkage at a driver angle, as PNG, SVG or PDF) and ``jaxcrank
animate RUN_DIR`` (a run's mechanism moving, as GIF, MP4 or HTML), on
``jaxcrank.views`` ([`jaxcrank.views.drawing`][], [`jaxcrank.views.animation`][])."""

from __future__ import annotations

import sys
from pathlib import Path

#: what ``draw`` writes, by suffix
DRAWINGS = (".png", ".svg", ".pdf")
#: the tables ``animate`` reads from a run folder, the first found: a simulation's, a steady state's orbit
TABLES = ("trajectory.csv", "orbit.csv")


def add_draw_arguments(p) -> None:
    """Add ``draw``'s options to its parser ``p``."""
    from . import config

    p.description = (
        "Draw a linkage (its ideal mechanism) at its driver's initial angle or --angle: bodies, ground pivots, "
        "guides, joints named, clearance joints marked with their play magnified, each joint's path over a turn; "
        "and print its kinematic summary."
    )
    config.add_mechanism_arguments(p, "draw")
    p.add_argument("--angle", type=config.angle_deg, help="the driver's angle, deg (default: its initial angle)")
    p.add_argument(
        "--out", type=Path, default=Path("linkage.png"), help="the drawing: .png, .svg or .pdf (default linkage.png)"
    )
    p.add_argument(
        "--magnify",
        type=float,
        help="draw each clearance this many times its size (default: every play drawn at a fixed fraction of its hole)",
    )
    p.add_argument("--frames", action="store_true", help="draw each body's frame and centre of mass")
    p.add_argument("--no-paths", action="store_true", help="leave out the joints' paths over a turn")
    p.add_argument("--quiet", action="store_true", help="print only errors")


def run_draw(args) -> int:
    """``jaxcrank draw``: write the drawing, print where and the kinematic summary."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..physics.params import ParameterError
    from ..views.drawing import draw
    from . import config

    if args.out.suffix.lower() not in DRAWINGS:
        raise ParameterError(f"--out {args.out}: the drawing's file type must be one of {', '.join(DRAWINGS)}")
    mech = config.mechanism_from_arguments(args)
    fig = draw(mech, args.angle, magnify=args.magnify, frames=args.frames, paths=not args.no_paths)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with matplotlib.rc_context({"svg.fonttype": "none"}):  # an SVG's text stays text: smaller, searchable
        fig.savefig(args.out, dpi=150)
    plt.close(fig)
    if not args.quiet:
        print(f"wrote {args.out}")
        for line in _summary_lines(mech):
            print(f"  {line}")
    return 0


def _summary_lines(mech) -> list[str]:
    """The kinematic summary of the ideal mechanism, in words."""
    from ..analysis.kinematic_summary import format_summary, kinematic_summary

    return format_summary(kinematic_summary(mech))


def add_animate_arguments(p) -> None:
    """Add ``animate``'s options to its parser ``p``."""
    p.description = (
        "Animate a run of `jaxcrank simulate` (its folder: config.toml and trajectory.csv) or the orbit of "
        "`jaxcrank steady` (orbit.csv): the mechanism moving, "
        "the ideal mechanism dashed beside it, and each clearance joint's pin in its hole with the contact force."
    )
    p.add_argument(
        "run_dir",
        type=Path,
        metavar="RUN_DIR",
        help="a folder written by `jaxcrank simulate` (or `jaxcrank steady`: its orbit)",
    )
    p.add_argument(
        "--out", type=Path, help="the animation: .gif, .mp4 (needs ffmpeg) or .html (default RUN_DIR/animation.gif)"
    )
    p.add_argument(
        "--revolutions",
        type=float,
        default=1.0,
        help="the last this many turns of the driven body (default 1; 0: the whole run)",
    )
    p.add_argument("--frames-per-revolution", type=int, default=72, help="frames per turn (default 72)")
    p.add_argument("--fps", type=float, default=24.0, help="frames per second of playback (default 24)")
    p.add_argument("--magnify", type=float, help="draw each clearance this many times its size")
    p.add_argument("--dpi", type=float, default=100.0, help="resolution; the frame is 8 x 4.5 inches (default 100)")
    p.add_argument("--quiet", action="store_true", help="print only errors")


def read_run(run_dir: Path):
    """A run folder's mechanism (``config.toml``) and columns (``trajectory.csv``, or
    the ``orbit.csv`` of a steady-state run: the names in its header, SI units, angles
    in deg).

    Raises:
        ParameterError: a folder without those files, or a table that does not belong to
            the mechanism (names what is missing).
    """
    import numpy as np

    from ..physics.params import ParameterError
    from . import config

    run_dir = Path(run_dir)
    table_file = next((run_dir / n for n in TABLES if (run_dir / n).is_file()), None)
    missing = [n for n in ("config.toml",) if not (run_dir / n).is_file()]
    missing += ["trajectory.csv (or a steady run's orbit.csv)"] if table_file is None else []
    if missing:
        raise ParameterError(
            f"{run_dir}: no {' or '.join(missing)} there: give the folder a `jaxcrank simulate --out` "
            "(or `jaxcrank steady --out`) wrote"
        )
    mech = config.load(run_dir / "config.toml")
    with open(table_file) as fh:
        names = fh.readline().strip().split(",")
    table = np.loadtxt(table_file, delimiter=",", skiprows=1, ndmin=2)
    if table.shape[1] != len(names) or len(table) < 2:
        raise ParameterError(f"{table_file}: expected a header and at least two rows of {len(names)} numbers")
    return mech, {n: table[:, k] for k, n in enumerate(names)}


def run_animate(args) -> int:
    """``jaxcrank animate``: write the animation and say where."""
    import time

    import matplotlib

    matplotlib.use("Agg")

    from ..physics.params import ParameterError
    from ..views import animation

    out = animation.check_target(args.out if args.out is not None else args.run_dir / "animation.gif")
    if args.revolutions < 0:
        raise ParameterError(f"--revolutions {args.revolutions:g} must be >= 0 (0: the whole run)")
    start = time.perf_counter()
    mech, cols = read_run(args.run_dir)
    try:
        anim = animation.animate(
            cols=cols,
            mech=mech,
            revolutions=args.revolutions or None,
            per_revolution=args.frames_per_revolution,
            magnify=args.magnify,
            fps=args.fps,
            dpi=args.dpi,
        )
    except KeyError as err:
        raise ParameterError(f"{args.run_dir}: {err.args[0]}") from None
    if not args.quiet:
        print(f"animate: {len(anim.indices)} frames", file=sys.stderr, flush=True)
    animation.save(anim, out)
    if not args.quiet:
        print(f"wrote {out} ({len(anim.indices)} frames in {time.perf_counter() - start:.1f} s)")
    return 0
