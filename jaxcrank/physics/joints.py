"""The two joints that may have clearance, as objects: the crank pin B and the slider
pin C (model.md, "Coordinates").

Each joint is a pin on one body (the crank at B, the slider at C) in a hole at one
end of the rod. An [`AbstractJointSite`][jaxcrank.physics.joints.AbstractJointSite] says which parameters belong to the
joint and how its pin and hole move; everything else (state layout, contact,
dynamics, outputs) loops over `JOINTS` or [`clearance_sites`][jaxcrank.physics.joints.clearance_sites] with one code
path, whatever the joint.
"""

from __future__ import annotations

import abc
from typing import ClassVar, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from . import ideal
from .params import Joint, Material, Mechanism


def perp(v: Float[ArrayLike, " 2"]) -> Float[Array, " 2"]:
    """Rotate a planar vector by +90 degrees."""
    return jnp.stack([-v[1], v[0]])


def rod_half(mech: Mechanism, q: Float[ArrayLike, " 4"]) -> Float[Array, " 2"]:
    """Vector from the rod's centre of mass to its end C (to end B: minus it), m, for
    full coordinates Q = (x2, y2, theta2, x3)."""
    return 0.5 * mech.rod_length * jnp.stack([jnp.cos(q[2]), jnp.sin(q[2])])


class JointMotion(NamedTuple):
    """Where the pin and the hole of one joint are and how they move (SI)."""

    pin_position: jax.Array  # pin centre, m, (2,)
    pin_velocity: jax.Array  # m/s, (2,)
    pin_angular_velocity: jax.Array | float  # of the body carrying the pin, rad/s
    hole_position: jax.Array  # hole centre (a rod end), m, (2,)
    hole_velocity: jax.Array  # m/s, (2,)
    hole_angular_velocity: jax.Array | float  # of the rod, rad/s


class AbstractJointSite(eqx.Module):
    """One joint of the mechanism: a pin on the crank or slider in a hole at one rod end.

    Subclasses say which [`Joint`][jaxcrank.physics.params.Joint] and pin material of
    the [`Mechanism`][jaxcrank.physics.params.Mechanism] are theirs, how the pin moves, at
    which rod end the hole sits, and what the contact force on the pin does to the
    slider coordinate x3.
    """

    name: eqx.AbstractClassVar[str]

    @abc.abstractmethod
    def joint(self, mech: Mechanism) -> Joint:
        """The joint's radii and ideal flag."""

    @abc.abstractmethod
    def pin_material(self, mech: Mechanism) -> Material:
        """Material of the pin's body (the hole is always in the rod)."""

    @abc.abstractmethod
    def pin_position(self, mech: Mechanism, slider_x: Float[ArrayLike, ""], t: Float[ArrayLike, ""]) -> Array:
        """Pin centre, m, at time t (s) with the slider at ``slider_x`` (m)."""

    @abc.abstractmethod
    def pin_motion(self, mech: Mechanism, q, qd, t) -> tuple[Array, Array, Array | float]:
        """(pin centre, m; its velocity, m/s; angular velocity of its body, rad/s) for
        full coordinates Q and their rates at time t (s)."""

    @abc.abstractmethod
    def pin_acceleration(self, mech: Mechanism, q, qd, qdd, t) -> Array:
        """Acceleration of the pin centre, m/s^2 (the crank turns at constant speed)."""

    @abc.abstractmethod
    def from_centre(self, centre, half):
        """The rod end of this joint from the rod's centre (or its rate) and
        [`rod_half`][jaxcrank.physics.joints.rod_half] (or its rate)."""

    @abc.abstractmethod
    def to_centre(self, end, half):
        """The rod's centre from this joint's rod end and [`rod_half`][jaxcrank.physics.joints.rod_half] (inverse of
        [`from_centre`][jaxcrank.physics.joints.AbstractJointSite.from_centre])."""

    @abc.abstractmethod
    def slider_load(self, force_on_pin: Float[ArrayLike, " 2"]) -> Array | float:
        """Generalized force on x3 of the contact force on the pin, N."""

    def motion(self, mech: Mechanism, q, qd, t) -> JointMotion:
        """The joint's [`JointMotion`][jaxcrank.physics.joints.JointMotion] for full coordinates Q = (x2, y2, theta2,
        x3)
        and their rates at time t (s)."""
        half = rod_half(mech, q)
        half_dot = qd[2] * perp(half)
        pin, pin_vel, pin_omega = self.pin_motion(mech, q, qd, t)
        return JointMotion(
            pin, pin_vel, pin_omega, self.from_centre(q[:2], half), self.from_centre(qd[:2], half_dot), qd[2]
        )

    def accelerations(self, mech: Mechanism, q, qd, qdd, t) -> tuple[Array, Array]:
        """(pin acceleration, hole acceleration), m/s^2: the time derivatives of the
        velocities in [`motion`][jaxcrank.physics.joints.AbstractJointSite.motion]."""
        half = rod_half(mech, q)
        half_ddot = qdd[2] * perp(half) - qd[2] ** 2 * half
        return self.pin_acceleration(mech, q, qd, qdd, t), self.from_centre(qdd[:2], half_ddot)


class CrankPin(AbstractJointSite):
    """Joint B: the crank pin in the hole at the rod's end B."""

    name: ClassVar[str] = "B"

    def joint(self, mech):
        return mech.joint_B

    def pin_material(self, mech):
        return mech.crank_material

    def pin_position(self, mech, slider_x, t):
        return ideal.crank_pin(mech, t)

    def pin_motion(self, mech, q, qd, t):
        pin = ideal.crank_pin(mech, t)
        return pin, mech.crank_speed * perp(pin), mech.crank_speed

    def pin_acceleration(self, mech, q, qd, qdd, t):
        return -(mech.crank_speed**2) * ideal.crank_pin(mech, t)

    def from_centre(self, centre, half):
        return centre - half

    def to_centre(self, end, half):
        return end + half

    def slider_load(self, force_on_pin):
        return 0.0


class SliderPin(AbstractJointSite):
    """Joint C: the slider pin (on the line y = e) in the hole at the rod's end C."""

    name: ClassVar[str] = "C"

    def joint(self, mech):
        return mech.joint_C

    def pin_material(self, mech):
        return mech.slider_material

    def pin_position(self, mech, slider_x, t):
        return jnp.stack([slider_x, jnp.asarray(mech.offset, dtype=float)])

    def pin_motion(self, mech, q, qd, t):
        return self.pin_position(mech, q[3], t), jnp.stack([qd[3], jnp.zeros_like(qd[3])]), 0.0

    def pin_acceleration(self, mech, q, qd, qdd, t):
        return jnp.stack([qdd[3], jnp.zeros_like(qdd[3])])

    def from_centre(self, centre, half):
        return centre + half

    def to_centre(self, end, half):
        return end - half

    def slider_load(self, force_on_pin):
        return force_on_pin[0]


CRANK_PIN = CrankPin()
SLIDER_PIN = SliderPin()
#: Every joint that may have clearance, in state order.
JOINTS: tuple[AbstractJointSite, ...] = (CRANK_PIN, SLIDER_PIN)


def clearance_sites(mech: Mechanism) -> tuple[AbstractJointSite, ...]:
    """The joints with clearance, in state order (static)."""
    return tuple(site for site in JOINTS if not site.joint(mech).ideal)


def clearance_joints(mech: Mechanism) -> tuple[str, ...]:
    """Names of the joints with clearance, in state order (static)."""
    return tuple(site.name for site in clearance_sites(mech))
