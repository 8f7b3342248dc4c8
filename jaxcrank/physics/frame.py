"""The output frame: every physical quantity of the mechanism at one instant.

[`evaluate`][jaxcrank.physics.frame.evaluate] is a function of (t, y) alone, so every output is a function of the
solution; it adds to [`dynamics`][jaxcrank.physics.dynamics.dynamics] what only the
outputs need (ideal motion, energies, per-joint quantities for ideal joints).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import ArrayLike, Float

from . import ideal, laws
from .dynamics import dynamics
from .joints import JOINTS
from .params import Mechanism
from .state import unpack


class Frame(NamedTuple):
    """The mechanism at one instant; SI units, angles in rad."""

    t: jax.Array
    crank_angle: jax.Array
    q: jax.Array  # (x2, y2, theta2, x3)
    qd: jax.Array
    qdd: jax.Array
    ideal_q: jax.Array
    ideal_qd: jax.Array
    ideal_qdd: jax.Array
    eccentricity_B: jax.Array
    eccentricity_C: jax.Array
    penetration_B: jax.Array
    penetration_C: jax.Array
    normal_force_B: jax.Array  # contact force; for an ideal joint, the reaction magnitude
    normal_force_C: jax.Array
    friction_force_B: jax.Array
    friction_force_C: jax.Array
    slip_speed_B: jax.Array
    slip_speed_C: jax.Array
    driving_moment: jax.Array
    ideal_driving_moment: jax.Array
    kinetic_energy: jax.Array
    potential_energy: jax.Array
    contact_energy: jax.Array
    driver_work: jax.Array
    dissipated_work: jax.Array
    state_rate: jax.Array  # dy/dt of the scaled state


def evaluate(mech: Mechanism, t: Float[ArrayLike, ""], y: Float[ArrayLike, " state"]) -> Frame:
    """All physical quantities at time t (s) for scaled state y; also dy/dt."""
    t = jnp.asarray(t, dtype=float)
    dyn = dynamics(mech, t, y)
    q, qd, qdd, contacts = dyn.q, dyn.qd, dyn.qdd, dyn.contacts
    state = unpack(mech, y)
    mass = ideal.mass_matrix(mech)
    th1 = ideal.crank_angle(mech, t)

    qi, qdi, qddi = ideal.kinematics(mech, t)
    kinetic = 0.5 * jnp.sum(mass * qd**2)
    potential = mech.rod_mass * mech.gravity * q[
        1
    ] + mech.crank_mass * mech.gravity * 0.5 * mech.crank_length * jnp.sin(th1)

    # per joint: the contact of a clearance joint; zeros and the reaction magnitude for an ideal one
    zero2, zero = jnp.zeros(2), jnp.zeros(())
    reactions = dict(zip((site.name for site in JOINTS), (dyn.reaction_B, dyn.reaction_C)))
    per_joint = {}
    for site in JOINTS:
        cj = contacts.get(site.name)
        ideal_values = dict(
            eccentricity=zero2,
            penetration=zero,
            normal_force=laws.safe_norm(reactions[site.name]),
            friction_force=zero,
            slip_speed=zero,
        )
        for field, value in ideal_values.items():
            per_joint[f"{field}_{site.name}"] = value if cj is None else getattr(cj, field)

    return Frame(
        t=t,
        crank_angle=th1,
        q=q,
        qd=qd,
        qdd=qdd,
        ideal_q=qi,
        ideal_qd=qdi,
        ideal_qdd=qddi,
        **per_joint,
        driving_moment=dyn.driving_moment,
        ideal_driving_moment=ideal.driving_moment(mech, t),
        kinetic_energy=kinetic,
        potential_energy=potential,
        contact_energy=sum((cj.elastic_energy for cj in contacts.values()), jnp.zeros(())),
        driver_work=state.driver_work,
        dissipated_work=state.dissipated_work,
        state_rate=dyn.state_rate,
    )
