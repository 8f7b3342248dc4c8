"""The paper's slider-crank after 10^6 and 10^7 cycles: ``jaxcrank life --mechanism paper-wear``
to 1e6 cycles, then resumed to 1e7, at ``RTOL``; its points, the figures of the docs (the worn
profiles at 0, 1e6 and 1e7 cycles; the first orbit's contact arcs) and
``bench/results/paper_wear.json``, where each point also gives the worn holes against the
contact's geometry (`hole_geometry`).

    python bench/paper_wear.py [--out runs/paper-wear]    # about an hour on 2 cores
"""

from __future__ import annotations

import argparse
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
#: the life's limit: the largest gap at B, m (the new clearance plus a fifth)
LIMIT = 6e-4


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--results-only", action="store_true", help="only write the JSON and figures of the run")
    parser.add_argument("--out", type=Path, default=Path("runs/paper-wear"), help="the run's directory")
    args = parser.parse_args(argv)
    for i, cycles in enumerate(() if args.results_only else STAGES):
        done = args.out / "checkpoint.json"
        if done.exists() and json.loads(done.read_text())["cycles"][-1] >= cycles:
            continue  # this stage is in the run already
        command = [sys.executable, "-m", "jaxcrank.runs.cli", "life", "--mechanism", "paper-wear", "--cycles",
                   f"{cycles:g}", "--rtol", f"{RTOL:g}", "--metric", "B_clearance_m", "--limit", f"{LIMIT:g}",
                   "--out", str(args.out)] + (["--resume"] if i or done.exists() else [])  # fmt: skip
        subprocess.run(command, check=True)
    write_results(args.out)
    _figures(args.out)
    return 0


def write_results(out: Path) -> None:
    """``bench/results/paper_wear.json`` and the docs' figures from the run in ``out`` (its
    checkpoint: a run stopped early gives its points so far)."""
    from jaxcrank.analysis.life import cycles_to_limit

    data = json.loads((out / "checkpoint.json").read_text())
    rows = data["rows"]
    keep = ("cycles", "regime", "B_hole_max_depth_m", "B_pin_max_depth_m", "B_hole_volume_m3", "B_clearance_m",
            "C_hole_max_depth_m", "C_pin_max_depth_m", "C_hole_volume_m3", "C_clearance_m",
            "rms_transmission_angle_error_deg", "rms_slider_x_deviation_m", "peak_contact_force_B_N",
            "peak_contact_force_C_N", "rms_contact_force_B_N")  # fmt: skip
    points = [{k: r[k] for k in keep if k in r} for r in rows]
    for point, profiles in zip(points, data["profiles"]):
        point.update(hole_geometry(profiles))
    reached = float(cycles_to_limit(data["cycles"], [r["B_clearance_m"] for r in rows], LIMIT))
    life = {"metric": "B_clearance_m", "limit": LIMIT, "cycles_to_limit": reached if reached < float("inf") else None}
    OUT.joinpath("paper_wear.json").write_text(
        json.dumps(
            {
                "command": "python bench/paper_wear.py",
                "rtol": RTOL,
                "stages": list(STAGES),
                "reached_cycles": data["cycles"][-1],
                "points": points,
                "life": life,
            },
            indent=2,
        )  # fmt: skip
    )
    _figures(out)


def hole_geometry(profiles: dict, grid: int = 3600) -> dict:
    """Where the worn holes stand against the contact's geometry (``Worn``'s docstring): per joint of
    ``profiles`` (``joint -> (hole, pin)`` Fourier coefficients, m), the steepest slope of the hole's
    wall against the radius, ``|w'| / R_h``; its least local radius of curvature ``R_h + w + w''``, m
    (negative: the wall is convex there, a ridge); the fraction of the circumference where that
    radius is below ``R_p + c / 10``, where the contact law is handed ``R_p + c / 10`` instead (the
    most conforming contact the model allows, whatever the wall's shape; the pin's own wear, under a
    micrometre here, is left out of this bound); and, over the dent's deepest half (where the wear
    exceeds half its deepest), the fractions where the wall is more sharply curved than the pin
    (``0 < radius < R_p``: a pin could not reach it) and where it is convex."""
    import jax.numpy as jnp

    import jaxcrank as jc
    from jaxcrank.physics.wear import CONFORMING_GAP, evaluate_profile

    joints = jc.preset("paper-wear").joints
    angles = jnp.linspace(0.0, 2.0 * jnp.pi, grid, endpoint=False)
    out = {}
    for j, (hole, _) in profiles.items():
        law = joints[j]
        s = evaluate_profile(jnp.asarray(hole), (jnp.cos(angles), jnp.sin(angles)))
        rho = law.hole_radius + s.depth + s.bend
        out[f"{j}_hole_max_slope"] = float(jnp.max(jnp.abs(s.slope)) / law.hole_radius)
        out[f"{j}_hole_min_curvature_radius_m"] = float(jnp.min(rho))
        out[f"{j}_hole_clamped_fraction"] = float(jnp.mean(rho < law.pin_radius + CONFORMING_GAP * law.clearance))
        deep = s.depth > 0.5 * jnp.max(s.depth)
        worn = bool(jnp.max(s.depth) > 0.0)
        for name, where in (("tighter", (rho > 0.0) & (rho < law.pin_radius)), ("convex", rho <= 0.0)):
            share = float(jnp.sum(where & deep) / jnp.sum(deep)) if worn else 0.0
            out[f"{j}_hole_deepest_half_{name}_fraction"] = share
    return out


def _figures(out: Path) -> None:
    import jax.numpy as jnp

    import jaxcrank as jc
    from jaxcrank.runs import plots_life

    data = json.loads((out / "checkpoint.json").read_text())
    profiles = [{j: (jnp.asarray(h), jnp.asarray(p)) for j, (h, p) in pr.items()} for pr in data["profiles"]]
    at = (0.0, *[c for c in STAGES if c <= data["cycles"][-1]], data["cycles"][-1])
    plots_life.profiles_figure(
        jc.preset("paper-wear"), data["cycles"], profiles, IMG / "paper-wear-profiles.png", at=at
    )
    shutil.copy(out / "figures" / "contact_arcs.png", IMG / "paper-wear-contact-arcs.png")


if __name__ == "__main__":
    sys.exit(main())
