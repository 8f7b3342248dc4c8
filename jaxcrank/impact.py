"""A single impact of a free pin on a fixed bearing, through the same joint model
as the mechanism (:func:`jaxcrank.model.joint_contact` and its approach-speed
memory). Used to check each contact law's achieved restitution against the exact
relation ``chi (1 + e) = ln((1 + chi) / (1 - chi e))`` (model.md).
"""

from __future__ import annotations

import diffrax
import equinox as eqx
import jax.numpy as jnp

from . import model
from .params import Mechanism


@eqx.filter_jit
def rebound_ratio(mech: Mechanism, approach_speed=0.5, pin_mass=1.0, rtol=1e-10, atol=1e-12):
    """Radial rebound speed / approach speed of a pin (mass ``pin_mass``, kg) that
    reaches the wall of joint B's bearing at ``approach_speed`` (m/s), no
    gravity, no tangential motion. Contact law and restitution from ``mech``.
    """
    joint = mech.joint_B
    c = joint.clearance

    def field(t, y, args):
        x, v, memory = y
        contact = model.joint_contact(
            mech,
            joint,
            mech.crank_material,
            mech.rod_material,
            jnp.stack([x, 0.0]),
            jnp.stack([v, 0.0]),
            0.0,
            jnp.zeros(2),
            jnp.zeros(2),
            0.0,
            memory,
        )
        # free flight: d(delta_dot)/dt = 0, so only the relaxation term remains
        return jnp.stack([v, contact.force_on_pin[0] / pin_mass, contact.memory_rate])

    # start 1 um before the wall, memory already equal to the approach speed
    y0 = jnp.stack([c - 1e-6, approach_speed, approach_speed])
    # past the contact (~0.2 ms for 1 kg at 0.5 m/s) but before the pin can cross
    # the bearing (2c / (e v) >= 8 ms) to the opposite wall
    t1 = 1e-6 / approach_speed + 2e-3
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(field),
        diffrax.Dopri8(),
        0.0,
        t1,
        1e-8,
        y0,
        stepsize_controller=diffrax.PIDController(rtol=rtol, atol=atol),
        saveat=diffrax.SaveAt(t1=True),
        max_steps=200_000,
    )
    return -sol.ys[0, 1] / approach_speed
