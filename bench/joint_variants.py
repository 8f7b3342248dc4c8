"""The paper run with other joints: dry against lubricated pins at B and C, and the slider's
play in its guide.

1. ``lubricated``: the paper run (0.4 s, the solve defaults, metrics over 0.1-0.4 s) of the
   ``paper`` and the ``paper-lubricated`` presets: the headline metrics of both, and a
   figure of the contact forces at B and C and the slider's acceleration deviation over
   the last revolution (``docs/img/dry_vs_lubricated.png``).
2. ``guide``: the ``paper-guide`` preset over the same run: the slider's lateral position
   (its centre's y, from the guide's line) and tilt over the last revolution against the
   crank angle, with the limits the guide's play allows (``docs/img/guide_play.png``).

    python bench/joint_variants.py     # -> bench/results/joint_variants.json and the two figures
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import jax.numpy as jnp
import numpy as np
from _common import machine

import jaxcrank as jc
from jaxcrank.analysis import outputs
from jaxcrank.physics import presets

ROOT = Path(__file__).resolve().parent
T_END, WINDOW = 0.4, 0.1  # s


def run(mech):
    """The paper run of ``mech``: its trajectory columns and metrics over 0.1-0.4 s."""
    sim = jc.simulate(mech, ts=jnp.linspace(0.0, T_END, 14401), metrics_start=WINDOW)
    return outputs.trajectory(sim), {k: float(v) for k, v in sim.metrics.items()}, int(sim.num_steps)


def last_revolution(cols, mech):
    t = np.asarray(cols["t"])
    return t >= T_END - float(mech.period) - 1e-12


def save(fig, axes, path):
    """Label the shared crank-angle axis, grid every panel and write ``fig`` to ``path``."""
    import matplotlib.pyplot as plt

    axes[-1].set_xlabel("crank angle, deg (last revolution of the 0.4 s run)")
    for ax in axes:
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def lubricated(figure):
    import matplotlib.pyplot as plt

    out, curves = {}, {}
    for name in ("paper", "paper-lubricated"):
        mech = presets.preset(name)
        cols, metrics, steps = run(mech)
        out[name] = {"metrics": metrics, "steps": steps}
        last = last_revolution(cols, mech)
        curves[name] = {
            "angle": np.degrees(np.unwrap(np.radians(np.asarray(cols["crank_angle"])[last]))) % 360.0,
            "B": np.asarray(cols["force_B_normal"])[last],
            "C": np.asarray(cols["force_C_normal"])[last],
            "dax": np.asarray(cols["slider_ax"])[last] - np.asarray(cols["ideal_slider_ax"])[last],
        }
    fig, axes = plt.subplots(3, 1, figsize=(8, 8), sharex=True)
    for name, style in (("paper", "-"), ("paper-lubricated", "--")):
        c = curves[name]
        order = np.argsort(c["angle"])
        label = "dry (paper)" if name == "paper" else "lubricated (paper-lubricated)"
        axes[0].plot(c["angle"][order], c["B"][order] / 1e3, style, lw=0.8, label=label)
        axes[1].plot(c["angle"][order], c["C"][order] / 1e3, style, lw=0.8, label=label)
        axes[2].plot(c["angle"][order], c["dax"][order], style, lw=0.8, label=label)
    axes[0].set_ylabel("normal force at B, kN")
    axes[1].set_ylabel("normal force at C, kN")
    axes[2].set_ylabel("slider acceleration\ndeviation, m/s^2")
    axes[0].legend(loc="upper right")
    save(fig, axes, figure)
    keys = [k for k in out["paper"]["metrics"] if k.startswith(("peak_contact_force", "max_abs_slider_ax", "rms_"))]
    out["relative_change"] = {
        k: (out["paper-lubricated"]["metrics"][k] - out["paper"]["metrics"][k]) / abs(out["paper"]["metrics"][k])
        for k in keys
        if out["paper"]["metrics"][k] != 0
    }
    return out


def guide(figure):
    import matplotlib.pyplot as plt

    mech = presets.preset("paper-guide")
    cols, metrics, steps = run(mech)
    last = last_revolution(cols, mech)
    angle = np.degrees(np.unwrap(np.radians(np.asarray(cols["crank_angle"])[last]))) % 360.0
    lateral = np.asarray(cols["slider_y"])[last] - np.asarray(cols["ideal_slider_y"])[last]  # m
    tilt = np.radians(np.asarray(cols["slider_angle"])[last] - np.asarray(cols["ideal_slider_angle"])[last])  # rad
    law = mech.joints["guide"]
    c, length = float(law.clearance), float(law.length)
    order = np.argsort(angle)
    fig, axes = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    axes[0].plot(angle[order], 1e3 * lateral[order], lw=0.8)
    axes[0].axhline(1e3 * c, color="k", ls=":", lw=0.8, label="play, each side")
    axes[0].axhline(-1e3 * c, color="k", ls=":", lw=0.8)
    axes[0].set_ylabel("lateral position of the\nslider's centre, mm")
    axes[0].legend(loc="upper right")
    axes[1].plot(angle[order], 1e3 * tilt[order], lw=0.8)
    limit = 2.0 * c / length  # both corners of a face against opposite faces
    axes[1].axhline(1e3 * limit, color="k", ls=":", lw=0.8, label="2 c / L")
    axes[1].axhline(-1e3 * limit, color="k", ls=":", lw=0.8)
    axes[1].set_ylabel("tilt, mrad")
    axes[1].legend(loc="upper right")
    save(fig, axes, figure)
    return {
        "metrics": metrics,
        "steps": steps,
        "play_each_side_m": c,
        "slider_length_m": length,
        "tilt_limit_rad": limit,
        "lateral_range_m": [float(lateral.min()), float(lateral.max())],
        "tilt_range_rad": [float(tilt.min()), float(tilt.max())],
        "crank_angle_at_extremes_deg": {
            "lateral_min": float(angle[np.argmin(lateral)]),
            "lateral_max": float(angle[np.argmax(lateral)]),
            "tilt_min": float(angle[np.argmin(tilt)]),
            "tilt_max": float(angle[np.argmax(tilt)]),
        },
    }


def main():
    import matplotlib

    matplotlib.use("Agg")
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "results" / "joint_variants.json")
    parser.add_argument("--figures", type=Path, default=ROOT.parent / "docs" / "img")
    args = parser.parse_args()
    result = {
        "run": {"t_end_s": T_END, "metrics_from_s": WINDOW, "samples": 14401},
        "lubricated": lubricated(args.figures / "dry_vs_lubricated.png"),
        "guide": guide(args.figures / "guide_play.png"),
        "machine": machine(),
    }
    args.out.write_text(json.dumps(result, indent=1, default=float))
    print(json.dumps({k: result["lubricated"]["relative_change"][k] for k in result["lubricated"]["relative_change"]},
                     indent=1))  # fmt: skip
    print("guide", {k: v for k, v in result["guide"].items() if k != "metrics"})


if __name__ == "__main__":
    main()
