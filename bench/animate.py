"""Time to write an animation of a run, against matplotlib's own writer in the same run.

    taskset -c 0 python bench/animate.py [--frames 200] [--out bench/results/animate.json]

A run of the paper's slider-crank (two revolutions from the command line, into a
temporary folder), then for each mechanism case (the paper preset and the crank-rocker
four-bar of the docs) the last revolution at ``--frames`` frames, written as GIF and as
HTML by [`jaxcrank.views.animation.save`][] (still parts drawn once, the moving artists
redrawn per frame), and as GIF by ``FuncAnimation.save`` with ``PillowWriter`` (the whole
figure drawn per frame), the baseline. Each time is wall-clock from the run's files on disk
to the written file (reading the run, building the figure, rendering, encoding); the
JSON gets the seconds, the frame count, the files' sizes and the machine.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

from _common import machine

ROOT = Path(__file__).resolve().parent.parent
CASES = {"paper": ["--mechanism", "paper"], "crank-rocker": ["--config", str(ROOT / "docs/linkages/crank-rocker.toml")]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=200, help="frames in one revolution (default 200)")
    ap.add_argument("--out", type=Path, default=ROOT / "bench/results/animate.json")
    args = ap.parse_args()

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.animation import FuncAnimation, PillowWriter

    import jaxcrank as jc
    from jaxcrank.runs import config, view_cli
    from jaxcrank.runs.cli import main as cli
    from jaxcrank.views import animation

    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, how in CASES.items():
            run = Path(tmp) / name
            mech = config.load(how[1]) if how[0] == "--config" else jc.preset(how[1])
            t1 = ["--t1", f"{2.0 * float(mech.period):.6g}"]
            if cli(["simulate", *how, *t1, "--out", str(run), "--no-figures", "--quiet"]) != 0:
                raise SystemExit(f"simulate failed for {name}")
            row = {}

            def ours(suffix, run=run, name=name):
                start = time.perf_counter()
                mech, cols = view_cli.read_run(run)
                anim = animation.animate(cols=cols, mech=mech, revolutions=1.0, per_revolution=args.frames)
                path = animation.save(anim, Path(tmp) / f"{name}{suffix}")
                return time.perf_counter() - start, len(anim.indices), os.path.getsize(path)

            def baseline(run=run, name=name):
                start = time.perf_counter()
                mech, cols = view_cli.read_run(run)
                anim = animation.animate(cols=cols, mech=mech, revolutions=1.0, per_revolution=args.frames)
                plain = FuncAnimation(anim.fig, anim.update_frame, frames=len(anim.indices), blit=False)
                path = Path(tmp) / f"{name}-baseline.gif"
                plain.save(path, writer=PillowWriter(fps=anim.fps))
                plt.close(anim.fig)
                return time.perf_counter() - start, len(anim.indices), os.path.getsize(path)

            for label, fn in (
                ("gif", lambda: ours(".gif")),
                ("html", lambda: ours(".html")),
                ("gif_matplotlib_writer", baseline),
            ):
                seconds, frames, size = fn()
                row[label] = {"seconds": seconds, "frames": frames, "bytes": size}
                print(f"{name} {label}: {frames} frames in {seconds:.2f} s ({size / 1e6:.2f} MB)", flush=True)
            row["speedup_gif_vs_matplotlib_writer"] = row["gif_matplotlib_writer"]["seconds"] / row["gif"]["seconds"]
            results[name] = row
    out = {
        "what": "seconds to write one revolution of a run as an animation, from the run folder to the file",
        "frames_requested": args.frames,
        "cases": results,
        "machine": machine(cpus_pinned=len(os.sched_getaffinity(0))),
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(out, indent=2) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
