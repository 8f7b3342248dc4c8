"""Equations of motion with clearance joints (model.md, Eq. 14).

Lagrange's ``J^T M J s'' = J^T (F - M gamma)`` with ``J = dQ/ds`` and
``gamma = dJ/dt s'`` from [`coordinates`][jaxcrank.physics.kinematics.coordinates], so
ideal-joint reactions drop out and are recovered afterwards by
[`jaxcrank.physics.ideal.reactions`][]. Every clearance joint goes through the same
code: its contact force loads the rod end (and, at the slider pin, the slider).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ..numerics import linalg
from . import ideal
from .contact import approach_memory_rate, joint_contact
from .joints import CRANK_PIN, clearance_sites
from .kinematics import coordinates, full_positions
from .params import Mechanism
from .state import n_dof, state_scales


class Dynamics(NamedTuple):
    """What the equations of motion give at one instant (SI): full coordinates and
    their first two rates, the clearance joints' contacts (by joint name), ideal-joint
    reactions, the driving moment and dy/dt of the scaled state."""

    q: jax.Array
    qd: jax.Array
    qdd: jax.Array
    contacts: dict
    reaction_B: jax.Array  # force of an ideal joint's pin on the rod, N (zeros for a clearance joint)
    reaction_C: jax.Array
    driving_moment: jax.Array
    state_rate: jax.Array


def dynamics(mech: Mechanism, t: Float[ArrayLike, ""], y: Float[ArrayLike, " state"]) -> Dynamics:
    """The equations of motion at time t (s) for scaled state y: only what dy/dt
    needs ([`jaxcrank.physics.frame.evaluate`][] adds the output-only quantities)."""
    n = n_dof(mech)
    sites = clearance_sites(mech)
    k = len(sites)
    scale = state_scales(mech)
    phys = y * scale
    s, sd, memory = phys[:n], phys[n : 2 * n], phys[2 * n : 2 * n + k]
    t = jnp.asarray(t, dtype=float)
    q, qd, gamma = coordinates(mech, s, sd, t)
    mass = ideal.mass_matrix(mech)
    centre = q[:2]

    applied = ideal.rod_gravity(mech)
    contacts, velocities = {}, {}
    for i, site in enumerate(sites):
        motion = site.motion(mech, q, qd, t)
        cj = joint_contact(mech, site.joint(mech), site.pin_material(mech), mech.rod_material, motion, memory[i])
        f_hole = -cj.force_on_pin
        arm = cj.hole_point - centre
        torque = arm[0] * f_hole[1] - arm[1] * f_hole[0]
        applied = applied + jnp.stack([f_hole[0], f_hole[1], torque, site.slider_load(cj.force_on_pin)])
        contacts[site.name] = cj
        velocities[site.name] = motion.pin_velocity - motion.hole_velocity

    if n == 4:  # Q = Q_ideal + s: J is the identity, M is diagonal
        sdd = (applied - mass * gamma) / mass
        qdd = sdd + gamma
    elif n == 2:
        jac = jax.jacfwd(lambda a: full_positions(mech, a, t))(s)
        lhs = jac.T @ (mass[:, None] * jac)
        rhs = jac.T @ (applied - mass * gamma)
        sdd = linalg.solve_2x2(lhs, rhs)
        qdd = jac @ sdd + gamma
    else:
        sdd = jnp.zeros(0)
        qdd = gamma

    memory_rates = []
    for site in sites:
        pin_acc, hole_acc = site.accelerations(mech, q, qd, qdd, t)
        memory_rates.append(
            approach_memory_rate(
                contacts[site.name], velocities[site.name], pin_acc - hole_acc, site.joint(mech).clearance
            )
        )

    residual = mass * qdd - applied
    react_b, react_c = ideal.reactions(mech, q, residual, mech.joint_B.ideal, mech.joint_C.ideal)
    crank = contacts.get(CRANK_PIN.name)
    if crank is not None:  # the force of the crank pin on the rod drives the crank
        moment = ideal.driving_moment_from_pin_force(mech, t, -crank.force_on_pin, crank.pin_point)
    else:
        moment = ideal.driving_moment_from_pin_force(mech, t, react_b, ideal.crank_pin(mech, t))
    dissipation = sum((cj.dissipation for cj in contacts.values()), jnp.zeros(()))
    rate = (
        jnp.concatenate(
            [
                sd,
                sdd,
                jnp.stack(memory_rates) if k else jnp.zeros(0),
                jnp.stack([moment * mech.crank_speed, dissipation]),
            ]
        )
        / scale
    )
    return Dynamics(q, qd, qdd, contacts, react_b, react_c, moment, rate)


@jax.jit
def vector_field(t: Float[ArrayLike, ""], y: Float[ArrayLike, " state"], mech: Mechanism) -> Float[Array, " state"]:
    """dy/dt of the scaled state ``y`` (shape (state_size,)) at time ``t`` (s), for
    diffrax: ``diffrax.ODETerm(vector_field)`` with ``args=mech``.

    Jitted, so a solve holds one call of the field per solver stage, which JAX
    linearizes and transposes once (shorter compiles of gradients); XLA inlines it.
    """
    return dynamics(mech, t, y).state_rate
