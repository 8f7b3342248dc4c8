"""Cycle averaging against brute force: the four-bar at 300 rpm whose pins B and C wear with
Archard coefficients scaled up (1e-3 hole, 1e-4 pin) so that the holes wear visibly within
a few hundred revolutions.

- Brute force: one transient run of ``REVOLUTIONS`` from the new joint's steady orbit, the
  contact acting against the profiles as they wear at every step
  (``jaxcrank.numerics.wear_run.wear_solve(feedback=True)``), the profiles saved every revolution;
  its metrics at a revolution are those of the next revolution run from the brute-force
  state with the profiles of that revolution.
- Time-scale separation: cycle averaging assumes the motion settles on its orbit much faster
  than the wear changes it. At the revolutions ``LAG_AT`` the brute force's next revolution
  (its wear and metrics, profiles held) is compared with the steady orbit at the same profiles,
  with the orbit's leading Floquet multiplier, then ``HELD`` more revolutions with the profiles
  held (does the brute force's state settle onto that orbit?). Where they differ, the brute force
  lags its geometry and stops being a reference for the averaging.
- Cycle averaging: ``jaxcrank.analysis.life.life`` to ``HORIZON`` cycles (where the brute force
  is still settled) at several ``rtol`` (steps in cycles shrinking).

At the same worn volume of the hole at B (the brute-force profiles interpolated between
revolutions), each hole's profile is compared (largest difference over the angle, relative
to the brute force's deepest wear) and so are the metrics (relative differences); each run's
profiles are also compared with the finest run's (convergence in the step).

    python bench/life_validation.py            # about 30 minutes on 2 cores
writes bench/results/life_validation.json and life_validation.png
(``LIFE_BRUTE_CACHE=file.npz`` keeps the brute force between runs).
"""

from __future__ import annotations

import json
import math
import os
import sys
import time
from pathlib import Path

import equinox as eqx
import jax.numpy as jnp
import numpy as np

import jaxcrank as jc
from jaxcrank.analysis.life import LifeOptions, life, wear_per_cycle
from jaxcrank.numerics import wear_run as nw
from jaxcrank.numerics.shooting import STEADY_DEFAULTS, period_solve
from jaxcrank.physics.wear import Archard, from_clearance, profile_on_grid

OUT = Path(__file__).resolve().parent / "results"
REVOLUTIONS = 300
HORIZON = 150
LAG_AT = (50, 100, 150, 200, 250, 300)
HELD = 8  # revolutions run on from each with the profiles held
RTOLS = (0.05, 0.0125, 0.004)
SAMPLES = 360
METRICS = ("rms_rocker_angle_deviation_deg", "rms_contact_force_B_N", "rms_contact_force_C_N", "peak_contact_force_B_N")
WEAR = Archard(hole_coefficient=1e-3, pin_coefficient=1e-4)


def mechanism():
    """The four-bar at 300 rpm, its pins B and C worn with ``WEAR`` (new)."""
    mech = jc.set_parameter(jc.four_bar(), "driver.speed", 300.0 * 2.0 * math.pi / 60.0)
    for j in ("B", "C"):
        mech = eqx.tree_at(lambda m, j=j: m.joints[j], mech, from_clearance(mech.joints[j], WEAR))
    return mech


def _interp(brute, rev):
    """The brute-force wear entries at a fractional revolution (linear between saves)."""
    i = min(int(math.floor(rev)), brute.shape[0] - 2)
    f = rev - i
    return (1 - f) * brute[i] + f * brute[i + 1]


def _relative(a: float, b: float) -> dict:
    return {"life": a, "brute_force": b, "relative_difference": abs(a - b) / abs(b)}


def _max_error(a, b, angles) -> float:
    """Largest difference of two profiles over the angle, relative to the second's deepest value."""
    d_a, d_b = np.asarray(profile_on_grid(a, angles)), np.asarray(profile_on_grid(b, angles))
    return float(np.max(np.abs(d_a - d_b)) / np.max(np.abs(d_b)))


def _lag(mech, wear, brute_ys, r, options, angles):
    """At brute-force revolution ``r``: the next revolution from the brute force's state with its
    profiles held, against the steady orbit at the same profiles (wear per cycle, metrics; a
    metric's ``life`` is the steady orbit's value, the one cycle averaging uses there)."""
    at = nw.unpack_wear(mech, jnp.asarray(wear[r]))
    held = nw.with_profiles(mech, {j: (at[j].hole, at[j].pin) for j in ("B", "C")})
    opts = LifeOptions(steady=jc.SteadyOptions(statistics_on_failure=True, samples_per_revolution=SAMPLES))
    steady = wear_per_cycle(held, opts, warm_start=brute_ys[r])
    T = float(mech.period)
    nxt = nw.unpack_wear(mech, nw.wear_solve(held, brute_ys[r], jnp.array([0.0, T]), options=options).wear[-1])
    sim = period_solve(held, brute_ys[r], 1, options=options, samples_per_revolution=SAMPLES)
    mu = np.abs(np.asarray(steady.steady.floquet_multipliers))
    out = {"revolution": r, "regime": steady.regime, "leading_multiplier": float(mu[0]) if mu.size else None}
    for j in ("B", "C"):
        out[f"{j}_hole_wear_rate_error_of_max"] = _max_error(steady.rate[j][0], nxt[j].hole, angles)
    out["metrics"] = {m: _relative(steady.metrics[m], float(sim.metrics[m])) for m in METRICS}
    # then HELD more revolutions with the profiles held: does the brute force's state settle onto the steady orbit?
    y, settling = sim.ys[-1], []
    for _ in range(HELD):
        more = period_solve(held, y, 1, options=options, samples_per_revolution=SAMPLES)
        y = more.ys[-1]
        settling.append({m: abs(float(more.metrics[m]) - steady.metrics[m]) / abs(steady.metrics[m]) for m in METRICS})
    out["held_revolutions_relative_difference"] = settling
    return out


def main() -> int:
    OUT.mkdir(exist_ok=True)
    mech = mechanism()
    T = float(mech.period)
    angles = jnp.linspace(0.0, 2 * math.pi, 720, endpoint=False)
    t0 = time.perf_counter()
    steady = jc.steady_state(mech, jc.SteadyOptions(samples_per_revolution=SAMPLES))
    assert steady.periodic, steady.regime
    print(f"new joint: periodic, period {steady.period_revolutions}", file=sys.stderr)
    options = STEADY_DEFAULTS.replace(max_steps=20_000_000)
    cache = os.environ.get("LIFE_BRUTE_CACHE")  # an .npz file to keep the brute force between runs
    if cache and Path(cache).exists():
        kept = np.load(cache)
        wear, brute_ys, brute_s, steps = (
            kept["wear"],
            jnp.asarray(kept["ys"]),
            float(kept["seconds"]),
            int(kept["steps"]),
        )
    else:
        ts = jnp.arange(REVOLUTIONS + 1) * T
        brute = nw.wear_solve(mech, steady.section_state, ts, options=options, feedback=True)
        assert bool(brute.ok), brute.result
        brute_s, steps = time.perf_counter() - t0, int(brute.num_steps)
        wear, brute_ys = np.asarray(brute.wear), brute.ys
        if cache:
            np.savez(cache, wear=wear, ys=np.asarray(brute_ys), seconds=brute_s, steps=steps)
    print(f"brute force: {REVOLUTIONS} revolutions in {brute_s:.0f} s ({steps} steps)", file=sys.stderr)
    volume_b = np.asarray(nw.unpack_wear(mech, jnp.asarray(wear))["B"].hole_volume)

    lag = []
    for r in LAG_AT:
        lag.append(_lag(mech, wear, brute_ys, r, options, angles))
        print(json.dumps(lag[-1]), file=sys.stderr)

    runs, finals = [], []
    for rtol in RTOLS:
        t1 = time.perf_counter()
        opts = LifeOptions(
            rtol=rtol, steady=jc.SteadyOptions(statistics_on_failure=True, samples_per_revolution=SAMPLES)
        )
        run = life(mech, HORIZON, opts)
        seconds = time.perf_counter() - t1
        final = run.profiles[-1]
        finals.append(final)
        v_life = float(nw.volumes(run.mechanism_at(-1))["B"][0])
        rev = float(np.interp(v_life, volume_b, np.arange(REVOLUTIONS + 1)))
        matched = nw.unpack_wear(mech, jnp.asarray(_interp(wear, rev)))
        errors = {}
        for j in ("B", "C"):
            d_life = np.asarray(profile_on_grid(final[j][0], angles))
            d_brute = np.asarray(profile_on_grid(matched[j].hole, angles))
            errors[f"{j}_hole_profile_error_of_max_depth"] = _max_error(final[j][0], matched[j].hole, angles)
            errors[f"{j}_hole_max_depth_brute_m"] = float(np.max(d_brute))
            errors[f"{j}_hole_max_depth_life_m"] = float(np.max(d_life))
        # the brute force's metrics over the revolution after the matched one, at its profiles
        i = int(round(rev))
        profs = {j: (matched[j].hole, matched[j].pin) for j in ("B", "C")}
        at = nw.with_profiles(mech, profs)
        sim = period_solve(at, brute_ys[min(i, REVOLUTIONS)], 1, options=options, samples_per_revolution=SAMPLES)
        point = run.points[-1]
        metric_errors = {m: _relative(point.metrics[m], float(sim.metrics[m])) for m in METRICS}
        runs.append({
            "rtol": rtol, "points": len(run.cycles), "rejected": run.rejected, "seconds": round(seconds, 1),
            "regimes": sorted({p.regime for p in run.points}), "matched_revolution": rev, "hole_volume_B_m3": v_life,
            **errors, "metrics": metric_errors,
        })  # fmt: skip
        print(json.dumps(runs[-1]), file=sys.stderr)
    for r, final in zip(runs, finals):  # convergence in the step: against the finest run
        r["against_finest"] = {
            f"{j}_hole_profile": _max_error(final[j][0], finals[-1][j][0], angles) for j in ("B", "C")
        }

    result = {
        "mechanism": "four-bar preset at 300 rpm, pins B and C worn (24 modes)",
        "wear": {"hole_coefficient": WEAR.hole_coefficient, "pin_coefficient": WEAR.pin_coefficient,
                 "hole_hardness_Pa": WEAR.hole_hardness, "pin_hardness_Pa": WEAR.pin_hardness, "length_m": WEAR.length},
        "revolutions": REVOLUTIONS,
        "horizon_cycles": HORIZON,
        "brute_force": {"seconds": round(brute_s, 1), "steps": steps, "solve": "tsit5, 1e-10"},
        "time_scale_separation": lag,
        "cycle_averaged": runs,
        "targets": {"profile_error_of_max_depth": 0.02, "metric_relative_difference": 0.02},
    }  # fmt: skip
    (OUT / "life_validation.json").write_text(json.dumps(result, indent=2))
    _figure(mech, wear, runs, finals, angles, lag)
    return 0


def _figure(mech, wear, runs, finals, angles, lag):
    import matplotlib.pyplot as plt

    from jaxcrank.runs.plots import DPI, style

    deg = np.degrees(np.asarray(angles))
    with style():
        fig, axes = plt.subplots(1, 3, figsize=(12, 3.4))
        for ax, j in zip(axes, ("B", "C")):
            for k, (r, final) in enumerate(zip(runs, finals)):
                matched = nw.unpack_wear(mech, jnp.asarray(_interp(wear, r["matched_revolution"])))[j].hole
                if k == len(runs) - 1:
                    ax.plot(
                        deg, 1e6 * np.asarray(profile_on_grid(matched, angles)), color="k", lw=2.5, label="brute force"
                    )
                depth = 1e6 * np.asarray(profile_on_grid(final[j][0], angles))
                ax.plot(
                    deg, depth, lw=1.0, ls="--", label=f"cycle averaged, rtol {r['rtol']:g} ({r['points'] - 1} steps)"
                )
            ax.legend(fontsize=7)
            ax.set_title(f"hole {j} after {HORIZON} revolutions")
            ax.set_xlabel("angle in the hole's frame, deg")
            ax.set_ylabel("wear depth, um")
        ax = axes[2]
        revs = [p["revolution"] for p in lag]
        for j in ("B", "C"):
            ax.plot(revs, [100 * p[f"{j}_hole_wear_rate_error_of_max"] for p in lag], "o-", label=f"hole {j} wear rate")
        for m in ("rms_contact_force_B_N", "rms_contact_force_C_N"):
            ax.plot(revs, [100 * p["metrics"][m]["relative_difference"] for p in lag], "s--", label=m)
        ax.set_xlabel("brute-force revolution")
        ax.set_ylabel("brute force's next revolution vs steady orbit, %")
        ax.set_title("does the brute force stay settled?")
        twin = ax.twinx()
        twin.plot(revs, [p["leading_multiplier"] for p in lag], "k:", label="leading multiplier")
        twin.set_ylabel("leading Floquet multiplier")
        twin.set_ylim(0, 1)
        ax.axvline(HORIZON, color="0.6", lw=0.8)
        ax.legend(fontsize=7, loc="upper left")
        fig.tight_layout()
        fig.savefig(OUT / "life_validation.png", dpi=DPI)
        plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
