"""Contact in one clearance joint: penetration, normal and friction forces, and the
rate of the joint's approach-speed memory (model.md, paper Eq. 1-13).

The laws themselves live in [`jaxcrank.physics.laws`][] and
[`jaxcrank.physics.memory`][]; [`joint_contact`][jaxcrank.physics.contact.joint_contact] composes them for one joint
from where its pin and hole are ([`JointMotion`][jaxcrank.physics.joints.JointMotion]).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from . import laws
from .joints import JointMotion, perp
from .memory import freeze_coordinate, memory_relaxation, memory_target, memory_target_rate, memory_tracking
from .params import Joint, Material, Mechanism


class JointContact(NamedTuple):
    """Everything about one clearance joint at one instant (SI)."""

    eccentricity: jax.Array  # pin centre minus hole centre, m, (2,)
    penetration: jax.Array  # delta = |d| - c, m (negative when separated)
    penetration_rate: jax.Array  # delta_dot, m/s (positive approaching)
    slip_speed: jax.Array  # v_t, m/s
    normal_force: jax.Array  # F_n >= 0, N
    friction_force: jax.Array  # F_t along the tangent, N
    force_on_pin: jax.Array  # -F_n n + F_t t, N, (2,)
    pin_point: jax.Array  # contact point on the pin, m, (2,)
    hole_point: jax.Array  # contact point on the hole, m, (2,)
    memory_rate: jax.Array  # relaxation part of d(approach-speed memory)/dt, m/s^2
    memory_tracking: jax.Array  # weight of d(target)/dt in it: 1 while separated, 0 in contact (memory_tracking)
    dissipation: jax.Array  # power dissipated by damping and friction, W
    elastic_energy: jax.Array  # energy stored in the contact, J


def joint_contact(
    mech: Mechanism,
    joint: Joint,
    pin_material: Material,
    hole_material: Material,
    motion: JointMotion,
    memory: Float[ArrayLike, ""],
) -> JointContact:
    """Kinematics and forces of one clearance joint (model.md, paper Eq. 1-13).

    Args:
        mech: the contact and friction laws and their parameters.
        joint: the joint's radii, m.
        pin_material: for the effective compliance (the same for hole_material).
        hole_material: for the effective compliance (the same for pin_material).
        motion: pin and hole centres (m), velocities (m/s) and angular velocities (rad/s).
        memory: the joint's approach-speed memory state, m/s.

    Returns:
        The joint's [`JointContact`][jaxcrank.physics.contact.JointContact].
    """
    d = motion.pin_position - motion.hole_position
    eps = laws.safe_norm(d)
    centred = eps > 0.0
    n = jnp.where(centred, d / jnp.where(centred, eps, 1.0), 0.0)
    tangent = perp(n)
    r_h, r_p = joint.hole_radius, joint.pin_radius
    delta = eps - joint.clearance
    v_rel = motion.pin_velocity - motion.hole_velocity
    delta_dot = jnp.dot(n, v_rel)
    v_t = jnp.dot(tangent, v_rel) + motion.pin_angular_velocity * r_p - motion.hole_angular_velocity * r_h

    c = mech.contact
    compliance = laws.effective_compliance(pin_material.compliance, hole_material.compliance)
    approach = jnp.maximum(memory, c.min_approach_speed)
    geometry = dict(hole_radius=r_h, pin_radius=r_p, compliance_sum=compliance, exponent=c.exponent)
    f_n, f_el = c.law.normal_force(delta, delta_dot, approach, c.restitution, **geometry)
    fr = mech.friction
    f_t = fr.law.force(v_t, f_n, fr.coefficient, fr.stick_speed, fr.slip_speed)
    # Only the relaxation part here; approach_memory_rate adds the target's time derivative.
    target = memory_target(d, v_rel, joint.clearance)
    x = freeze_coordinate(delta, target, c)
    tracking = memory_tracking(x)
    memory_rate = memory_relaxation(x, c) * (target - memory)
    return JointContact(
        eccentricity=d,
        penetration=delta,
        penetration_rate=delta_dot,
        slip_speed=v_t,
        normal_force=f_n,
        friction_force=f_t,
        force_on_pin=-f_n * n + f_t * tangent,
        pin_point=motion.pin_position + r_p * n,
        hole_point=motion.hole_position + r_h * n,
        memory_rate=memory_rate,
        memory_tracking=tracking,
        dissipation=(f_n - f_el) * delta_dot - f_t * v_t,
        elastic_energy=c.law.elastic_energy(delta, **geometry),
    )


def approach_memory_rate(
    contact: JointContact,
    relative_velocity: Float[ArrayLike, " 2"],
    relative_acceleration: Float[ArrayLike, " 2"],
    clearance: Float[ArrayLike, ""],
) -> Float[Array, ""]:
    """d(approach-speed memory)/dt of a joint, m/s^2: the relaxation part of its
    ``contact`` plus the [`memory_tracking`][jaxcrank.physics.memory.memory_tracking] weight
    times the time derivative of the memory target, for the pin's velocity (m/s) and
    acceleration (m/s^2) relative to the hole and the radial ``clearance`` (m).

    While the pins are apart the memory so follows d(delta_dot)/dt exactly, and at
    impact onset it equals the approach speed without lag; the relaxation only erases
    the offset the previous rebound left.
    """
    target_rate = memory_target_rate(contact.eccentricity, relative_velocity, relative_acceleration, clearance)
    return contact.memory_rate + contact.memory_tracking * target_rate
