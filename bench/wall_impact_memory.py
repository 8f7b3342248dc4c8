"""Isolated impacts with the frozen and the forgetting approach-speed memory
(:mod:`jaxcrank.analysis.validation.wall_impact`): for every contact law, the achieved
restitution of a 1 kg pin on the paper's steel joint (8 / 7.5 mm, frictionless) at approach
speeds from 3 mm/s to 1 m/s and restitutions 0.3 to 0.9, against the exact relation
``chi (1 + e) = ln((1 + chi) / (1 - chi e))``; and the impact durations at 3 mm/s (the
slowest, longest impacts), which the forgetting memory's ``t_dwell`` must exceed.
Writes ``bench/results/wall_impact_memory.json``.

    python bench/wall_impact_memory.py
"""

from __future__ import annotations

import json
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from _common import machine

from jaxcrank.analysis.validation import wall_impact
from jaxcrank.physics import laws, memory
from jaxcrank.physics.joints import Clearance
from jaxcrank.physics.params import Contact, Friction

SPEEDS = np.geomspace(3e-3, 1.0, 6)  # m/s
RESTITUTIONS = (0.3, 0.5, 0.7, 0.9)
MEMORIES = {"frozen": memory.FrozenMemory(), "forgetting": memory.ForgettingMemory()}


def joint(law: str, memory_law, restitution: float) -> Clearance:
    contact = Contact(law=laws.CONTACT_LAWS[law](), restitution=restitution)
    return Clearance(
        hole_radius=8e-3, pin_radius=7.5e-3, contact=contact, friction=Friction(coefficient=0.0), memory=memory_law
    )


def deviations(law: str, memory_law) -> dict:
    """The worst relative and absolute deviation of the achieved restitution from the root."""
    speeds, ces = np.meshgrid(SPEEDS, RESTITUTIONS, indexing="ij")

    def ratio(v, ce):
        return wall_impact.rebound_ratio(joint(law, memory_law, ce), v)

    achieved = np.asarray(jax.vmap(ratio)(jnp.asarray(speeds.ravel()), jnp.asarray(ces.ravel())))
    achieved = achieved.reshape(speeds.shape)
    chi = [float(laws.CONTACT_LAWS[law]().hysteresis_factor(ce)) for ce in RESTITUTIONS]
    exact = np.array([laws.achieved_restitution(c) for c in chi])
    rel = achieved / exact - 1.0
    i = np.unravel_index(np.argmax(np.abs(rel)), rel.shape)
    return {
        "worst_relative_deviation": float(rel[i]),
        "at_approach_speed_m_s": float(SPEEDS[i[0]]),
        "at_restitution": RESTITUTIONS[i[1]],
        "worst_absolute_deviation": float(np.max(np.abs(achieved - exact))),
    }


def main():
    out = {"machine": machine(), "approach_speeds_m_s": SPEEDS.tolist(), "restitutions": list(RESTITUTIONS)}
    out["forgetting_defaults"] = {
        k: float(getattr(MEMORIES["forgetting"], k)) for k in ("v_ref", "tau", "t_dwell", "gate_width")
    }
    out["rebound"] = {m: {law: deviations(law, mem) for law in laws.CONTACT_LAWS} for m, mem in MEMORIES.items()}
    durations = {}
    for law in laws.CONTACT_LAWS:
        for ce in (0.3, 0.9):
            impact = wall_impact.single_impact(joint(law, MEMORIES["forgetting"], ce), 3e-3)
            durations[f"{law}, c_e = {ce}"] = impact.duration
    out["impact_duration_at_3_mm_s_s"] = durations
    path = Path(__file__).parent / "results" / "wall_impact_memory.json"
    path.write_text(json.dumps(out, indent=1) + "\n")
    worst = max(abs(d["worst_relative_deviation"]) for per in out["rebound"].values() for d in per.values())
    print(f"worst |e / e_exact - 1| = {worst:.2e}; longest impact at 3 mm/s {max(durations.values()) * 1e3:.3f} ms")


if __name__ == "__main__":
    main()
