"""Drawn designs for the property-based tests (tests/test_fuzz.py) and the fuzz report
(bench/fuzz_report.py): hypothesis strategies over the ranges below and the check of
one design.

Ranges (SI; log-uniform where marked), of the offset slider-crank
([`jaxcrank.SliderCrank`][]):

- crank_length 0.05..0.3 m; offset -0.1..0.1 m; rod_length (crank_length + |offset|)
  times 1.02..4 (from near the assembly limit to a long rod);
- crank, rod and slider masses 0.1..10 kg (log); rod_inertia 1e-5..0.1 kg m^2 (log);
- crank speed 10..3000 rpm (log); initial crank angle 0..2 pi rad;
- hole radii 4..20 mm; radial clearances at B and C 1 um..1 mm (log);
- restitution 0.3..1; friction off (coefficient 0) or on (0.01..0.3), the same at B and C;
- structure (one compiled solve each): the six contact laws times three joint layouts
  (clearance at B and C, B ideal, C ideal; with both ideal the loop would have no
  clearance joint, which is no mechanism).

Each design is simulated for ``T1`` from the pins-centred start with a step budget of
``MAX_STEPS``. Numeric parameters are passed as arrays (traced), so one compiled solve
serves every design of a structure.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
from hypothesis import strategies as st

import jaxcrank as jc
from jaxcrank import outputs

T1 = 4e-3  #: simulated time of each drawn design, s (the start-up impacts at 600 rpm)
N_SAMPLES = 41  #: output samples, every 0.1 ms
MAX_STEPS = 20_000  #: step budget; a design that needs more reports max_steps
#: work-energy residual tolerance, as a fraction of the run's energy scale (largest
#: kinetic energy + |driver work| + dissipated work): the 0.5 % the paper-run test uses
ENERGY_RTOL = 5e-3
#: layout name -> (B ideal, C ideal); the name lists the joints with clearance
LAYOUTS = {"BC": (False, False), "C": (True, False), "B": (False, True)}
#: (contact law, layout) pairs
STRUCTURES = [(law, layout) for law in jc.CONTACT_LAWS for layout in LAYOUTS]
PINS = ("B", "C")


def _log(lo, hi):
    return st.floats(math.log10(lo), math.log10(hi)).map(lambda e: 10.0**e)


@st.composite
def designs(draw, structures=STRUCTURES):
    """A valid [`jaxcrank.SliderCrank`][] (concrete floats) of one of ``structures``."""
    law, layout = draw(st.sampled_from(structures))
    l1 = draw(st.floats(0.05, 0.3))
    e = draw(st.floats(-0.1, 0.1))
    l2 = (l1 + abs(e)) * draw(st.floats(1.02, 4.0))
    contact = jc.Contact(law=jc.CONTACT_LAWS[law](), restitution=draw(st.floats(0.3, 1.0)))
    friction = jc.Friction(coefficient=draw(st.one_of(st.just(0.0), st.floats(0.01, 0.3))))
    joints = {"A": jc.Ideal(), "guide": jc.Ideal()}
    for j, ideal in zip(PINS, LAYOUTS[layout]):
        hole = draw(st.floats(4e-3, 20e-3))
        clearance = draw(_log(1e-6, 1e-3))
        joints[j] = (
            jc.Ideal()
            if ideal
            else jc.Clearance(hole_radius=hole, pin_radius=hole - clearance, contact=contact, friction=friction)
        )
    return jc.SliderCrank(
        crank_length=l1,
        rod_length=l2,
        offset=e,
        crank_mass=draw(_log(0.1, 10.0)),
        rod_mass=draw(_log(0.1, 10.0)),
        slider_mass=draw(_log(0.1, 10.0)),
        rod_inertia=draw(_log(1e-5, 0.1)),
        driver=jc.ConstantSpeed(
            body="crank",
            speed=2.0 * math.pi * draw(_log(10.0, 3000.0)) / 60.0,
            initial_angle=draw(st.floats(0.0, 2.0 * math.pi)),
        ),
        joints=joints,
    )


def traced(mech):
    """``mech`` with every numeric leaf an array: traced by ``filter_jit``, so designs of
    one structure share a compiled solve (Python floats would be compile-time constants)."""
    return jax.tree.map(lambda x: jnp.asarray(x, dtype=float), mech)


def _clearance_pins(mech) -> list[str]:
    return [j for j in PINS if not mech.joints[j].ideal]


def outcome(mech) -> dict:
    """Simulate ``mech`` and check it. Returns a dict: ``status`` (``ok`` or the failure
    named by [`jaxcrank.simulate`][]'s [`SimulationError`][jaxcrank.SimulationError]: ``max_steps``,
    ``solver_failed``, ``non_finite``), ``message``, ``steps``; for ``ok``: whether every
    output column is finite, the energy residual / energy scale, and the largest
    deviation / geometric bound ratios ([`SliderCrank.deviation_bounds`][jaxcrank.SliderCrank.deviation_bounds])
    of slider x, rod x and the pin eccentricities (<= 1 inside the bound)."""
    ts = jnp.linspace(0.0, T1, N_SAMPLES)
    try:
        sim = jc.simulate(traced(mech), ts=ts, options=jc.SolveOptions(max_steps=MAX_STEPS))
    except jc.SimulationError as err:
        msg = str(err)
        status = "max_steps" if "max_steps" in msg else "non_finite" if "non-finite" in msg else "solver_failed"
        return {"status": status, "message": msg}
    cols = outputs.trajectory(sim)
    finite = all(bool(np.all(np.isfinite(v))) for v in cols.values())
    bal = outputs.energy_balance(cols)
    scale = float(np.max(cols["kinetic_energy"])) + abs(bal["driver_work_J"]) + abs(bal["dissipated_work_J"])
    pen = float(max(np.max(cols["penetration_B"]), np.max(cols["penetration_C"]), 0.0))
    bounds = mech.deviation_bounds(pen)

    def ratio(dev, bound):  # both joints ideal: the bound is 0 and the motion the closed form, exactly
        return dev / bound if bound > 0 else (0.0 if dev == 0.0 else math.inf)

    ratios = {
        "slider_x": ratio(float(np.max(np.abs(cols["slider_x"] - cols["ideal_slider_x"]))), bounds["slider_x_m"]),
        "rod_x": ratio(float(np.max(np.abs(cols["rod_x"] - cols["ideal_rod_x"]))), bounds["rod_x_m"]),
    }
    for j in _clearance_pins(mech):
        ecc = np.hypot(cols[f"ecc_{j}_x"], cols[f"ecc_{j}_y"])
        clearance = float(mech.joints[j].clearance)
        ratios[f"ecc_{j}"] = float(np.max(ecc / (clearance + np.max(cols[f"penetration_{j}"]))))
    return {
        "status": "ok",
        "message": "",
        "steps": int(sim.num_steps),
        "finite": finite,
        "energy_residual_over_scale": abs(bal["residual_J"]) / scale if scale > 0 else abs(bal["residual_J"]),
        "energy_scale_J": scale,
        "bound_ratios": ratios,
    }


def assert_outcome(res: dict) -> None:
    """The property: a named failure with a message, or finite outputs that balance
    energy within ``ENERGY_RTOL`` and stay inside the geometric bounds."""
    if res["status"] != "ok":
        assert res["status"] in ("max_steps", "solver_failed", "non_finite") and res["message"], res
        assert "nan" not in res["message"].lower().replace("nan/inf", ""), res["message"]
        return
    assert res["finite"], res
    assert res["energy_residual_over_scale"] <= ENERGY_RTOL, res
    for k, r in res["bound_ratios"].items():
        assert r <= 1.0 + 1e-12, (k, res)


def structure(mech) -> tuple[str, str]:
    """(contact law name, layout: the joints with clearance)."""
    pins = _clearance_pins(mech)
    return mech.joints[pins[0]].contact.law.name, "".join(pins)


def describe(mech) -> dict:
    """The drawn numbers of a design, for the report (SI; speed in rpm; an ideal joint's
    clearance None)."""
    law, layout = structure(mech)
    some = mech.joints[_clearance_pins(mech)[0]]
    return {
        "law": law,
        "clearance joints": layout,
        "rpm": float(mech.driver.speed) * 60.0 / (2.0 * math.pi),
        "clearance_B_m": None if mech.joints["B"].ideal else float(mech.joints["B"].clearance),
        "clearance_C_m": None if mech.joints["C"].ideal else float(mech.joints["C"].clearance),
        "friction": float(some.friction.coefficient),
        "rod_over_min": float(mech.rod_length) / (float(mech.crank_length) + abs(float(mech.offset))),
    }


__all__ = ["designs", "outcome", "assert_outcome", "describe", "structure", "traced", "STRUCTURES"]
