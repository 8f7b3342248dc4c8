"""The paper's slider-crank after 10^6 and 10^7 cycles: ``jaxcrank life --mechanism paper-wear``
to 1e6 cycles, then resumed to 1e7, at ``RTOL``; its points, the figures of the docs (the worn
profiles at 0, 1e6 and 1e7 cycles; the first orbit's contact arcs) and
``bench/results/paper_wear.json``.

    python bench/paper_wear.py [--out runs/paper-wear]    # about an hour on 2 cores
"""

from __future__ import annotations

import argparse
import csv
import json
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "bench" / "results"
IMG = ROOT / "docs" / "img"
RTOL = 0.05
STAGES = (1e6, 1e7)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("runs/paper-wear"), help="the run's directory")
    args = parser.parse_args(argv)
    for i, cycles in enumerate(STAGES):
        done = args.out / "checkpoint.json"
        if done.exists() and json.loads(done.read_text())["cycles"][-1] >= cycles:
            continue  # this stage is in the run already
        command = [sys.executable, "-m", "jaxcrank.runs.cli", "life", "--mechanism", "paper-wear", "--cycles",
                   f"{cycles:g}", "--rtol", f"{RTOL:g}", "--metric", "B_clearance_m", "--limit", "6e-4",
                   "--out", str(args.out)] + (["--resume"] if i or done.exists() else [])  # fmt: skip
        subprocess.run(command, check=True)
    rows = list(csv.DictReader((args.out / "life.csv").open()))
    keep = ("cycles", "regime", "B_hole_max_depth_m", "B_pin_max_depth_m", "B_hole_volume_m3", "B_clearance_m",
            "C_hole_max_depth_m", "C_pin_max_depth_m", "C_hole_volume_m3", "C_clearance_m",
            "rms_transmission_angle_error_deg", "rms_slider_x_deviation_m", "peak_contact_force_B_N",
            "peak_contact_force_C_N", "rms_contact_force_B_N")  # fmt: skip
    points = [{k: (r[k] if k == "regime" else float(r[k])) for k in keep if k in r} for r in rows]
    summary = json.loads((args.out / "summary.json").read_text())
    OUT.joinpath("paper_wear.json").write_text(
        json.dumps(
            {
                "command": "python bench/paper_wear.py",
                "rtol": RTOL,
                "stages": list(STAGES),
                "points": points,
                "life": summary.get("life"),
                "worn_joints": summary["worn_joints"],
            },
            indent=2,
        )  # fmt: skip
    )
    _figures(args.out)
    return 0


def _figures(out: Path) -> None:
    import jax.numpy as jnp

    import jaxcrank as jc
    from jaxcrank.runs import plots_life

    data = json.loads((out / "checkpoint.json").read_text())
    profiles = [{j: (jnp.asarray(h), jnp.asarray(p)) for j, (h, p) in pr.items()} for pr in data["profiles"]]
    plots_life.profiles_figure(jc.preset("paper-wear"), data["cycles"], profiles, IMG / "paper-wear-profiles.png",
                               at=(0.0, *STAGES))  # fmt: skip
    shutil.copy(out / "figures" / "contact_arcs.png", IMG / "paper-wear-contact-arcs.png")


if __name__ == "__main__":
    sys.exit(main())
