"""A prismatic joint with clearance: a rectangular slider between the two parallel faces of
its guide, touching them at its corners.

The slider is a rectangle of ``length`` (along the axis) by ``height`` (across it), centred
on the joint's slider point and turning with the slider body; the guide's two faces run
parallel to the axis at ``+/- (height / 2 + clearance)`` from it, so a slider centred on the
axis and aligned with it has ``clearance`` on each side. Each of the four corners is a
rounded edge of ``corner_radius`` and touches only the face on its own side (the upper
corners the upper face): a corner's penetration is its rounding circle's distance past that
face. This covers every configuration of a translational clearance joint (no contact, one
corner, two adjacent corners on one face, two opposite corners on opposite faces; Flores,
Ambrosio, Claro & Lankarani 2008, J. Comput. Nonlinear Dynam. 3, 011007) as a sum of four
independent corner contacts, so no case switching is needed.

Corner stiffness. The stiffness laws of [`jaxcrank.physics.laws`][] are for a pin in a hole
(paper Eq. 3 needs R_h > R_p; the hybrid law of Eq. 6-7 depends on the radial clearance R_h -
R_p). A rounded corner on a flat face is the limit R_h -> infinity of Eq. 3 with R_p the
corner radius r: the Hertz point contact of a sphere on a plane,
``K = 4 sqrt(r) / (3 (s1 + s2))`` with s_k = (1 - nu_k^2) / E_k (Johnson, Contact Mechanics,
1985, Sec. 4.2; [`corner_stiffness`][jaxcrank.physics.guide.corner_stiffness]). It is the same
point-contact model the paper applies to its pins, so the guide's and the pins' contacts are
alike. Each corner's normal force is ``K delta^n (1 + chi delta_dot / delta_dot_minus)`` with
the exponent n and the hysteresis factor chi(c_e) of the chosen contact law
([`corner_normal_force`][jaxcrank.physics.guide.corner_normal_force]): any law of
``laws.CONTACT_LAWS`` gives its damping; its pin-in-hole stiffness is replaced by K. With a
Hertz-type law this is exactly that law's ``normal_force`` with ``hole_radius = r`` and
``pin_radius = r / 2`` (R_h R_p / (R_h - R_p) = r). Friction acts along the axis at each
corner, from that corner's slip, by the chosen friction law. Each corner has its own
approach-speed memory ([`jaxcrank.physics.memory`][]), which tracks the corner's normal
speed.
"""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .joints import AbstractJointLaw, JointForces, JointKinematics, register_joint_law
from .laws import AbstractContactLaw, CorrectedDamping, effective_compliance
from .memory import AbstractMemoryLaw, ForgettingMemory, MemoryInput
from .params import Contact, Friction, Material, ParameterError, _concrete, check_range
from .safemath import cross, perp, positive_power

#: the slider's corners, in state order: front = along the axis direction, upper = on the
#: side of the axis's left normal (the axis direction turned by +90 degrees)
CORNERS: tuple[str, ...] = ("front_upper", "rear_upper", "rear_lower", "front_lower")
_AXIAL = (1.0, -1.0, -1.0, 1.0)  # each corner's side along the axis
_LATERAL = (1.0, 1.0, -1.0, -1.0)  # each corner's side across it (the face it touches)


def corner_stiffness(
    corner_radius: Float[ArrayLike, "*shape"], compliance_sum: Float[ArrayLike, "*shape"]
) -> Float[Array, "*shape"]:
    """Hertz stiffness of a rounded corner on a flat face, N/m^1.5.

    ``K = 4 sqrt(r) / (3 (s1 + s2))``: a sphere of radius r on a plane (Johnson 1985,
    Sec. 4.2), the limit of paper Eq. 3 ([`hertz_stiffness`][jaxcrank.physics.laws.hertz_stiffness]) as the
    hole radius grows without bound. Steel on steel, r = 1 mm: 4.80e9 N/m^1.5.

    Args:
        corner_radius: r, m (> 0).
        compliance_sum: s1 + s2 = sum of (1 - nu^2) / E, 1/Pa.
    """
    return 4.0 * jnp.sqrt(corner_radius) / (3.0 * compliance_sum)


def corner_normal_force(
    penetration: Float[ArrayLike, "*shape"],
    penetration_rate: Float[ArrayLike, "*shape"],
    approach_speed: Float[ArrayLike, "*shape"],
    restitution,
    *,
    stiffness,
    exponent,
    law: AbstractContactLaw,
) -> tuple[Array, Array]:
    """Normal force of one corner contact and its elastic part, N.

    ``F_n = K delta^n (1 + chi(c_e) delta_dot / delta_dot_minus)`` for delta > 0, else 0,
    clipped at zero (contacts push, never pull); chi is ``law``'s hysteresis factor
    (model.md, "Normal contact force").

    Args:
        penetration: delta, m (negative when separated).
        penetration_rate: delta_dot, m/s (positive approaching).
        approach_speed: delta_dot_minus, m/s (> 0).
        restitution: c_e in (0, 1].
        stiffness: K, N/m^n ([`corner_stiffness`][jaxcrank.physics.guide.corner_stiffness]).
        exponent: n.
        law: the contact law whose hysteresis factor damps the contact.

    Returns:
        ``(F_n, F_elastic)``, N.
    """
    f_el = stiffness * positive_power(penetration, exponent)
    f = f_el * (1.0 + law.hysteresis_factor(restitution) * penetration_rate / approach_speed)
    return jnp.maximum(f, 0.0), f_el


def _axes(angle):
    """Unit vector at ``angle`` (rad) and its left normal."""
    e = jnp.stack([jnp.cos(angle), jnp.sin(angle)])
    return e, perp(e)


def _as_float(value) -> Array:
    """``value`` as a float array (the ground's kinematics may be Python numbers)."""
    return jnp.asarray(value, dtype=float)


class GuideClearance(AbstractJointLaw):
    """A prismatic joint with clearance: a rectangular slider between the guide's two
    parallel faces, with contact at its corners (module docstring).

    The joint's guide site is a point on the axis and its direction the axis direction
    (``Prismatic.guide``, ``Prismatic.direction``); its slider site is the centre of the
    slider's rectangle, whose long side lies along the axis when the joint's ``angle`` is
    held ([`jaxcrank.physics.kinematics.joint_motion`][]).

    Attributes:
        length: the slider's length along the axis, m.
        height: the slider's height across the axis, m.
        clearance: the gap on each side between the slider's faces and the guide's, m (the
            guide's faces are at +/- (height / 2 + clearance) from the axis); default 0.25 mm.
        corner_radius: radius r of the slider's rounded corners (edges), m; sets the corner
            stiffness ([`corner_stiffness`][jaxcrank.physics.guide.corner_stiffness]); default 1 mm.
        contact: the contact law (its hysteresis factor), restitution and exponent; default
            the paper's Eq. 5 damping (the hybrid law's) with c_e = 0.9.
        friction: the friction law and its settings, along the axis at each corner.
        memory: the approach-speed memory law; each corner has a state block of its own.
        slider_material: elastic properties of the slider's surface.
        guide_material: elastic properties of the guide's faces.

    Raises:
        ParameterError: a length, height, clearance or corner radius that is not positive
            and finite, corners rounded by half the slider's length or height or more, or a
            memory that is not a memory law.
    """

    name: ClassVar[str] = "guide_clearance"
    kinds: ClassVar[tuple[str, ...]] = ("prismatic",)

    length: float
    height: float
    clearance: float = 2.5e-4  # a field with a default shadows the base class's property
    corner_radius: float = 1e-3
    contact: Contact = Contact(law=CorrectedDamping())
    friction: Friction = Friction()
    memory: AbstractMemoryLaw = ForgettingMemory()
    slider_material: Material = Material()
    guide_material: Material = Material()

    def with_clearance(self, clearance, joint: str | None = None) -> GuideClearance:
        """This law with the gap ``clearance`` (m) on each side of the slider; ``joint``
        names the joint in messages.

        Raises:
            ParameterError: a known clearance that is not positive and finite.
        """
        check_range("clearance" if joint is None else f"clearance_{joint}", clearance, low=0.0, unit="m")
        return eqx.tree_at(lambda law: law.clearance, self, clearance)

    def __check_init__(self):
        for field in ("length", "height", "clearance", "corner_radius"):
            check_range(field, getattr(self, field), low=0.0, unit="m")
        r, length, height = (_concrete(getattr(self, f)) for f in ("corner_radius", "length", "height"))
        if r is not None and length is not None and height is not None:
            half = 0.5 * np.minimum(length, height)
            if np.any(r >= half):
                raise ParameterError(
                    f"corner_radius = {np.max(r):g} m must be smaller than half the slider's length and height "
                    f"(min(length, height) / 2 = {np.min(half):g} m; valid range: 0 < corner_radius < "
                    "min(length, height) / 2)"
                )
        if not isinstance(self.memory, AbstractMemoryLaw):
            raise ParameterError(f"memory {self.memory!r} is not a jaxcrank.physics.memory.AbstractMemoryLaw")

    @property
    def stiffness(self):
        """The corner stiffness K, N/m^1.5 ([`corner_stiffness`][jaxcrank.physics.guide.corner_stiffness])."""
        s = effective_compliance(self.slider_material.compliance, self.guide_material.compliance)
        return corner_stiffness(self.corner_radius, s)

    def state_names(self):
        """``<corner>.<memory entry>`` for each corner of `CORNERS` in turn."""
        return tuple(f"{c}.{n}" for c in CORNERS for n in self.memory.state_names)

    def state_scales(self, speed_scale):
        return tuple(self.memory.state_scales(speed_scale)) * len(CORNERS)

    def corners(self, kin: JointKinematics) -> tuple[Array, Array, Array, Array]:
        """Each corner's penetration (m), contact point (m, world), normal speed (m/s,
        positive approaching its face) and slip speed along the axis (m/s), shapes (4,),
        (4, 2), (4,), (4,), in `CORNERS` order.

        The contact point is the point of the corner's rounding circle nearest its face;
        the speeds are those of the slider's material point there relative to the guide's,
        so the normal speed is the time derivative of the penetration.
        """
        e, n = _axes(kin.hole_angle)
        a, b = _axes(kin.pin_angle)
        r = self.corner_radius
        axial, lateral = jnp.asarray(_AXIAL), jnp.asarray(_LATERAL)
        centres = (
            kin.pin_position
            + (axial * (0.5 * self.length - r))[:, None] * a
            + (lateral * (0.5 * self.height - r))[:, None] * b
        )
        penetration = lateral * ((centres - kin.hole_position) @ n) + r - (0.5 * self.height + self.clearance)
        points = centres + (lateral * r)[:, None] * n
        v_slider = kin.pin_velocity + kin.pin_angular_velocity * perp(points - kin.pin_position)
        v_guide = kin.hole_velocity + kin.hole_angular_velocity * perp(points - kin.hole_position)
        v_rel = v_slider - v_guide
        return penetration, points, lateral * (v_rel @ n), v_rel @ e

    def forces(self, kin, state):
        return guide_contact(self, kin, state)

    def state_rate(self, kin, acc, state, forces):
        """Each corner's memory rate (SI), in `CORNERS` order. A corner's memory tracks its
        normal speed; the target's rate, the corner's normal acceleration, is the normal
        speed of [`corners`][jaxcrank.physics.guide.GuideClearance.corners] differentiated along the motion
        (forward mode, from ``acc``)."""
        penetration, target = forces.aux
        tangent = JointKinematics(
            _as_float(kin.hole_velocity),
            _as_float(acc.hole_acceleration),
            _as_float(kin.hole_angular_velocity),
            _as_float(acc.hole_angular_acceleration),
            _as_float(kin.pin_velocity),
            _as_float(acc.pin_acceleration),
            _as_float(kin.pin_angular_velocity),
            _as_float(acc.pin_angular_acceleration),
        )
        primal = JointKinematics(*(_as_float(v) for v in kin))
        _, target_rate = jax.jvp(lambda k: self.corners(k)[2], (primal,), (tangent,))
        blocks = jnp.reshape(jnp.asarray(state), (len(CORNERS), -1))
        rates = jax.vmap(self.memory.rate)(blocks, MemoryInput(penetration, target, target_rate))
        return jnp.reshape(rates, (-1,))


def guide_contact(joint: GuideClearance, kin: JointKinematics, state: Float[ArrayLike, " k"]) -> JointForces:
    """Forces of a prismatic clearance joint at one instant (SI, world frame).

    Args:
        joint: the slider's and guide's geometry, materials and laws.
        kin: the guide's axis point and frame (``hole_*``, ``hole_angle`` the axis
            direction) and the slider's centre and frame (``pin_*``).
        state: the corners' memory states, one block per corner in `CORNERS` order (SI).

    Returns:
        The joint's [`JointForces`][jaxcrank.physics.joints.JointForces]: the four corner
        forces as one force on the slider at its centre (``pin_point``) with the moment
        ``pin_moment`` of the corner forces about it, and the reaction on the guide at the
        same point (``hole_moment = -pin_moment``). ``eccentricity`` is, in the guide frame,
        (the slider centre's lateral offset from the axis, the tilt times half the length),
        m: each corner's penetration is about ``+/-`` their sum ``- clearance``.
        ``penetration`` is the largest corner penetration, m; ``normal_force`` and
        ``friction_force`` are the sums over the corners, N; ``slip_speed`` is the slider
        centre's speed along the axis relative to the guide, m/s. ``aux`` holds the corners'
        penetrations and normal speeds (the memory inputs), (4,) each.
    """
    e, n = _axes(kin.hole_angle)
    penetration, points, normal_speed, slip = joint.corners(kin)
    blocks = jnp.reshape(jnp.asarray(state), (len(CORNERS), -1))
    approach = jax.vmap(joint.memory.approach_speed)(blocks)
    c = joint.contact
    k = joint.stiffness
    f_n, f_el = corner_normal_force(
        penetration, normal_speed, approach, c.restitution, stiffness=k, exponent=c.exponent, law=c.law
    )
    fr = joint.friction
    f_t = fr.law.force(slip, f_n, fr.coefficient, fr.stick_speed, fr.slip_speed)
    lateral = jnp.asarray(_LATERAL)
    corner_force = (-lateral * f_n)[:, None] * n + f_t[:, None] * e
    moment = jnp.sum(cross(points - kin.pin_position, corner_force))
    a, _ = _axes(kin.pin_angle)
    tilt = jnp.arctan2(cross(e, a), jnp.dot(e, a))
    offset = kin.pin_position - kin.hole_position
    centre_velocity = kin.pin_velocity - kin.hole_velocity - kin.hole_angular_velocity * perp(offset)
    return JointForces(
        force=jnp.sum(corner_force, axis=0),
        pin_point=kin.pin_position,
        hole_point=kin.pin_position,
        pin_moment=moment,
        hole_moment=-moment,
        dissipation=jnp.sum((f_n - f_el) * normal_speed - f_t * slip),
        elastic_energy=jnp.sum(k * positive_power(penetration, c.exponent + 1.0) / (c.exponent + 1.0)),
        eccentricity=jnp.stack([jnp.dot(offset, n), 0.5 * joint.length * tilt]),
        penetration=jnp.max(penetration),
        normal_force=jnp.sum(f_n),
        friction_force=jnp.sum(f_t),
        slip_speed=jnp.dot(centre_velocity, e),
        aux=(penetration, normal_speed),
    )


__all__ = ["CORNERS", "GuideClearance", "corner_normal_force", "corner_stiffness", "guide_contact"]


register_joint_law(GuideClearance)
