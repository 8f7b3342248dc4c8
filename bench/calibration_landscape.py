"""The misfit landscape of the calibration benchmark: how far from the true design a local fit
can start.

The same synthetic measurement as ``bench/bench_calibration.py`` (the paper's slider-crank at
clearance_B = 0.3 mm, clearance_C = 0.4 mm, restitution 0.7; the slider's acceleration over one
revolution of the steady orbit, one sample per degree, 5 % Gaussian noise, seed 0). The misfit
(sum of squared residuals over the noise) is evaluated

- along the straight line, in ln(x), from the benchmark's far start (30 % off every parameter)
  to the true design, and
- one parameter at a time, at 0.7 ... 1.3 times its true value, the others true;

for the misfit itself and for the misfit of the residuals low-pass filtered (a circular Gaussian
of 5, 20 and 45 deg along the crank angle) and integrated once and twice over the crank angle
(velocity- and position-like residuals): transforms that widen a basin when the misfit's
ruggedness comes from the phase of narrow spikes. Each design's regime is recorded.

Usage: ``python bench/calibration_landscape.py``; writes ``bench/results/calibration_landscape.json``.
"""

from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path

import numpy as np
from _common import machine

import jaxcrank as jc
from optim.calibrate import Calibration, FitParameter, model_trace

ROOT = Path(__file__).resolve().parent
NAMES = ("clearance_B", "clearance_C", "contact.restitution")
TRUE = np.array([3e-4, 4e-4, 0.7])
FAR = TRUE * np.array([0.7, 0.7, 1.3])
LINE = (0.0, 0.2, 0.4, 0.6, 0.7, 0.8, 0.9, 0.95, 1.0)
FACTORS = (0.7, 0.85, 0.95, 1.05, 1.15, 1.3)
WIDTHS_DEG = (5, 20, 45)


def smooth(r: np.ndarray, width: int) -> np.ndarray:
    """Circular Gaussian filter of ``width`` samples (one sample per degree)."""
    k = np.arange(-3 * width, 3 * width + 1)
    g = np.exp(-0.5 * (k / width) ** 2)
    g /= g.sum()
    return np.array([np.sum(g * np.take(r, i + k, mode="wrap")) for i in range(r.size)])


def integrate(r: np.ndarray) -> np.ndarray:
    """The zero-mean running sum of a zero-mean copy of ``r`` (one integration over the crank angle)."""
    c = np.cumsum(r - r.mean())
    return c - c.mean()


def misfits(r: np.ndarray) -> dict:
    out = {"misfit": float(np.sum(r**2))}
    for w in WIDTHS_DEG:
        out[f"low_pass_{w}_deg"] = float(np.sum(smooth(r, w) ** 2))
    out["integrated_once"] = float(np.sum(integrate(r) ** 2))
    out["integrated_twice"] = float(np.sum(integrate(integrate(r)) ** 2))
    return out


def main() -> None:
    tic = time.process_time()
    base = jc.paper()
    clean, _ = model_trace(base, NAMES, TRUE, "slider_ax_m_s2", angle_deg=np.arange(360.0))
    noise = 0.05 * float(np.sqrt(np.mean(clean.values**2)))
    rng = np.random.default_rng(0)
    trace = dataclasses.replace(clean, values=clean.values + noise * rng.standard_normal(clean.n))
    params = [
        FitParameter(n, float(t), lo, hi) for n, t, lo, hi in zip(NAMES, TRUE, (1e-4, 1e-4, 0.3), (8e-4,) * 2 + (1.0,))
    ]
    cal = Calibration(base, params, trace, noise=noise)
    points = [("line", t, np.exp((1 - t) * np.log(FAR) + t * np.log(TRUE))) for t in LINE]
    for j, name in enumerate(NAMES):
        for f in FACTORS:
            x = TRUE.copy()
            x[j] = min(x[j] * f, 1.0) if name == "contact.restitution" else x[j] * f
            points.append((name, f, x))
    rows = []
    for kind, t, x in points:
        ev = cal.evaluate(x, jacobian=False)
        finite = bool(np.all(np.isfinite(ev.residuals)))
        row = {"along": kind, "t_or_factor": t, "design_SI": dict(zip(NAMES, x.tolist())), "regime": ev.regime}
        row.update(misfits(ev.residuals) if finite else {"misfit": None})
        rows.append(row)
        print(json.dumps({k: row[k] for k in ("along", "t_or_factor", "regime", "misfit")}), flush=True)
    out = {
        "benchmark": "calibration_landscape",
        "true_design_SI": dict(zip(NAMES, TRUE.tolist())),
        "far_start_SI": dict(zip(NAMES, FAR.tolist())),
        "signal": "slider_ax_m_s2",
        "samples": clean.n,
        "noise_sigma": noise,
        "transforms": ["misfit"] + [f"low_pass_{w}_deg" for w in WIDTHS_DEG] + ["integrated_once", "integrated_twice"],
        "points": rows,
        "cpu_seconds": time.process_time() - tic,
        "machine": machine(),
    }
    (ROOT / "results" / "calibration_landscape.json").write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
