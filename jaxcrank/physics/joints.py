"""Joint laws: what a joint of a mechanism does, independent of where it sits.

Every joint of a mechanism carries a law ([`AbstractJointLaw`][jaxcrank.physics.joints.AbstractJointLaw]):

- [`Ideal`][jaxcrank.physics.joints.Ideal]: a perfect joint; the mechanism's tree of ideal joints holds it in
  minimal coordinates, and it has neither force law nor state;
- [`Clearance`][jaxcrank.physics.joints.Clearance]: a dry revolute clearance joint, a pin in a larger hole
  with a normal contact law, a friction law and an approach-speed memory law
  (model.md, paper Eq. 1-13);
- [`Lubricated`][jaxcrank.physics.lubrication.Lubricated]: a revolute clearance joint with an oil film,
  handed over to the dry law at high eccentricity (model.md, "Lubricated revolute joint"), registered
  from [`jaxcrank.physics.lubrication`][].

A law that is not ideal is a force element between the two bodies its joint connects:
the equations of motion ask it for the wrench it applies ([`forces`][jaxcrank.physics.joints.AbstractJointLaw.forces])
from where the joint's two sides are ([`JointKinematics`][jaxcrank.physics.joints.JointKinematics]), and for the rate
of the state it declares ([`state_names`][jaxcrank.physics.joints.AbstractJointLaw.state_names],
[`state_rate`][jaxcrank.physics.joints.AbstractJointLaw.state_rate]) once the accelerations are known. The
equations of motion never look at a law's type or name.

``name`` is a law's name in TOML files (``law = "clearance"``).
"""

from __future__ import annotations

from typing import Any, ClassVar, NamedTuple

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .laws import effective_compliance
from .memory import AbstractMemoryLaw, ForgettingMemory, MemoryInput, memory_target, memory_target_rate
from .params import Contact, Friction, Material, ParameterError, _concrete, check_range
from .safemath import perp, safe_norm


class JointKinematics(NamedTuple):
    """Where the two sides of a joint are and how they move (SI, world frame).

    The *hole* side is the bearing (or the guide of a prismatic joint), the *pin* side
    the journal (or the slider). Positions are the joint's points on each body.

    Attributes:
        hole_position: m, (2,).
        hole_velocity: m/s, (2,).
        hole_angle: angle of the hole side's frame, rad (its body's angle plus the
            joint's direction on it).
        hole_angular_velocity: rad/s.
        pin_position: m, (2,).
        pin_velocity: m/s, (2,).
        pin_angle: rad.
        pin_angular_velocity: rad/s.
    """

    hole_position: Array
    hole_velocity: Array
    hole_angle: Array
    hole_angular_velocity: Array
    pin_position: Array
    pin_velocity: Array
    pin_angle: Array
    pin_angular_velocity: Array


class JointAccelerations(NamedTuple):
    """Accelerations of a joint's two points and bodies (SI, world frame), for the state
    rates that need them."""

    hole_acceleration: Array  # m/s^2, (2,)
    hole_angular_acceleration: Array  # rad/s^2
    pin_acceleration: Array
    pin_angular_acceleration: Array


class JointForces(NamedTuple):
    """The wrench a joint law applies and what it reports (SI, world frame).

    The pin side receives ``force`` at ``pin_point`` plus the pure moment ``pin_moment``;
    the hole side receives ``-force`` at ``hole_point`` plus ``hole_moment``.

    Attributes:
        force: on the pin side, N, (2,).
        pin_point: where it acts on the pin side, m, (2,).
        hole_point: where its reaction acts on the hole side, m, (2,).
        pin_moment: pure moment on the pin side, N m.
        hole_moment: pure moment on the hole side, N m.
        dissipation: power the law dissipates, W (>= 0).
        elastic_energy: energy stored in the law, J.
        eccentricity: pin position relative to the hole, m, (2,).
        penetration: largest penetration, m (negative when separated).
        normal_force: magnitude of the normal force, N.
        friction_force: friction force along the tangent, N.
        slip_speed: tangential slip speed at the contact, m/s.
        aux: what the law's [`state_rate`][jaxcrank.physics.joints.AbstractJointLaw.state_rate] needs of this
            instant (law-specific).
    """

    force: Array
    pin_point: Array
    hole_point: Array
    pin_moment: Array
    hole_moment: Array
    dissipation: Array
    elastic_energy: Array
    eccentricity: Array
    penetration: Array
    normal_force: Array
    friction_force: Array
    slip_speed: Array
    aux: Any = None


class AbstractJointLaw(eqx.Module):
    """What a joint does: ideal, or a force element with a state of its own.

    ``kinds`` lists the joint kinds (``"revolute"``, ``"prismatic"``) the law applies
    to; ``ideal`` says whether the joint is held by the mechanism's tree (no force law,
    no state). Subclasses that are not ideal give
    [`forces`][jaxcrank.physics.joints.AbstractJointLaw.forces], their state's names, scales and rates,
    and the length that scales their deviations
    ([`clearance`][jaxcrank.physics.joints.AbstractJointLaw.clearance]).
    """

    name: ClassVar[str]
    kinds: ClassVar[tuple[str, ...]]
    ideal: ClassVar[bool] = False

    def state_names(self) -> tuple[str, ...]:
        """Names of the law's state entries (in state order); none by default."""
        return ()

    def state_scales(self, speed_scale) -> tuple:
        """Physical value of one scaled unit of each state entry (SI), given the
        mechanism's speed scale (m/s: clearance times crank speed)."""
        return ()

    def initial_state(self) -> Float[Array, " k"]:
        """The law's state at the start of a run from rest relative to the ideal motion (SI)."""
        return jnp.zeros(len(self.state_names()))

    @property
    def clearance(self):
        """The length over which the joint's two sides can move apart, m (none for ideal
        joints)."""
        raise NotImplementedError(f"the {self.name!r} law has no clearance")

    def with_clearance(self, clearance, joint: str | None = None) -> AbstractJointLaw:
        """This law with its clearance (``clearance``, m) set as the law sets it: the one
        place a joint's clearance is changed (``clearance_<joint>`` of
        [`jaxcrank.physics.parameters`][]). Traceable in ``clearance``; ``joint`` names the
        joint in messages.

        Raises:
            ParameterError: for an ideal law (it has no clearance), or a known value
                outside the law's range.
        """
        raise ParameterError(f"the {self.name!r} law has no clearance; give the joint a clearance law first")

    def forces(self, kin: JointKinematics, state: Float[Array, " k"]) -> JointForces:
        """The wrench the law applies at one instant, from its kinematics and state (SI)."""
        raise NotImplementedError(f"the {self.name!r} law applies no force")

    def state_rate(
        self, kin: JointKinematics, acc: JointAccelerations, state: Float[Array, " k"], forces: JointForces
    ) -> Float[Array, " k"]:
        """d(state)/dt (SI), given the accelerations and this instant's ``forces``."""
        return jnp.zeros(len(self.state_names()))


class Ideal(AbstractJointLaw):
    """A perfect joint: no clearance, no force law, no state (revolute or prismatic)."""

    name: ClassVar[str] = "ideal"
    kinds: ClassVar[tuple[str, ...]] = ("revolute", "prismatic")
    ideal: ClassVar[bool] = True


class AbstractPinInHole(AbstractJointLaw):
    """A revolute joint law of a pin (journal) in a larger hole (bearing), whose state is
    its approach-speed memory's: the radial clearance and the state's names and scales,
    shared by the dry [`Clearance`][jaxcrank.physics.joints.Clearance] and the
    lubricated joint. Subclasses have the fields ``hole_radius`` and ``pin_radius`` (m) first,
    and a field ``memory`` (an [`AbstractMemoryLaw`][jaxcrank.physics.memory.AbstractMemoryLaw])."""

    hole_radius: eqx.AbstractVar[float]
    pin_radius: eqx.AbstractVar[float]

    @property
    def clearance(self):
        """Radial clearance c = R_h - R_p, m."""
        return self.hole_radius - self.pin_radius

    def with_clearance(self, clearance, joint: str | None = None) -> AbstractPinInHole:
        """This law with radial clearance ``clearance`` (m): the pin shrinks, the hole stays.

        Raises:
            ParameterError: a known clearance outside (0, hole_radius).
        """
        value, hole = _concrete(clearance), _concrete(self.hole_radius)
        if value is not None and hole is not None and not np.all((value > 0.0) & (value < hole)):
            name = "clearance" if joint is None else f"clearance_{joint}"
            hole_name = "hole_radius" if joint is None else f"joints.{joint}.hole_radius"
            raise ParameterError(
                f"{name} = {np.asarray(value).ravel()[0]:g} m is out of range (valid range: 0 < {name} < "
                f"{hole_name} = {np.min(hole):g} m, so that pin_radius = hole_radius - clearance stays positive)"
            )
        return eqx.tree_at(lambda law: law.pin_radius, self, self.hole_radius - clearance)

    def state_names(self):
        return self.memory.state_names

    def state_scales(self, speed_scale):
        return self.memory.state_scales(speed_scale)


class Clearance(AbstractPinInHole):
    """A dry revolute clearance joint: a pin (journal) of radius ``pin_radius`` in a
    hole (bearing) of radius ``hole_radius`` (model.md, paper Eq. 1-13).

    The radial clearance is ``c = hole_radius - pin_radius`` (paper Eq. 1). The pin
    touches the wall when its eccentricity exceeds c; the normal force follows
    ``contact``, the tangential force ``friction``, and the approach speed the contact
    law divides by is the state of ``memory``.

    Attributes:
        hole_radius: bearing radius R_h, m.
        pin_radius: journal radius R_p, m; must be smaller than ``hole_radius``.
        contact: the normal contact law and its settings.
        friction: the friction law and its settings.
        memory: the approach-speed memory law.
        pin_material: elastic properties of the pin's surface.
        hole_material: elastic properties of the hole's surface.

    Raises:
        ParameterError: a radius that is not positive, or a pin not smaller than its hole.
    """

    name: ClassVar[str] = "clearance"
    kinds: ClassVar[tuple[str, ...]] = ("revolute",)

    hole_radius: float
    pin_radius: float
    contact: Contact = Contact()
    friction: Friction = Friction()
    memory: AbstractMemoryLaw = ForgettingMemory()
    pin_material: Material = Material()
    hole_material: Material = Material()

    def __check_init__(self):
        check_dry_pin_in_hole(self)

    def forces(self, kin, state):
        return clearance_contact(self, kin, state)

    def state_rate(self, kin, acc, state, forces):
        return memory_state_rate(self, kin, acc, state, forces)


def check_dry_pin_in_hole(law) -> None:
    """Raise [`ParameterError`][jaxcrank.physics.params.ParameterError] for a dry pin-in-hole law's radius
    that is not positive, a pin not smaller than its hole, or a memory that is not a memory law."""
    check_range("hole_radius", law.hole_radius, low=0.0, unit="m")
    check_range("pin_radius", law.pin_radius, low=0.0, unit="m")
    hole, pin = _concrete(law.hole_radius), _concrete(law.pin_radius)
    if hole is not None and pin is not None and np.any(pin >= hole):
        raise ParameterError(
            f"pin_radius = {np.max(pin):g} m must be smaller than hole_radius = "
            f"{np.min(hole):g} m (valid range: 0 < pin_radius < hole_radius); "
            'for a joint without clearance use law = "ideal"'
        )
    if not isinstance(law.memory, AbstractMemoryLaw):
        raise ParameterError(f"memory {law.memory!r} is not a jaxcrank.physics.memory.AbstractMemoryLaw")


def memory_state_rate(law, kin, acc, state, forces):
    """d(state)/dt of a dry pin-in-hole law's approach-speed memory (SI)."""
    v_rel = kin.pin_velocity - kin.hole_velocity
    a_rel = acc.pin_acceleration - acc.hole_acceleration
    target_rate = memory_target_rate(forces.eccentricity, v_rel, a_rel, law.clearance)
    return law.memory.rate(state, MemoryInput(forces.penetration, forces.aux, target_rate))


def clearance_contact(joint: Clearance, kin: JointKinematics, state: Float[ArrayLike, " k"]) -> JointForces:
    """Kinematics and forces of one dry revolute clearance joint (model.md, paper Eq. 1-13).

    Args:
        joint: the joint's radii, materials and laws.
        kin: where its pin and hole centres are and how they move.
        state: its memory law's state (SI; the first entry is the approach-speed memory, m/s).

    Returns:
        The joint's [`JointForces`][jaxcrank.physics.joints.JointForces]; ``aux`` is the memory's target
        normal speed ([`memory_target`][jaxcrank.physics.memory.memory_target]), m/s.
    """
    d = kin.pin_position - kin.hole_position
    eps = safe_norm(d)
    centred = eps > 0.0
    n = jnp.where(centred, d / jnp.where(centred, eps, 1.0), 0.0)
    tangent = perp(n)
    r_h, r_p = joint.hole_radius, joint.pin_radius
    delta = eps - joint.clearance
    v_rel = kin.pin_velocity - kin.hole_velocity
    delta_dot = jnp.dot(n, v_rel)
    v_t = jnp.dot(tangent, v_rel) + kin.pin_angular_velocity * r_p - kin.hole_angular_velocity * r_h

    return contact_forces(joint, kin, state, d, n, n, delta, delta_dot, v_t, (r_h, r_p), (r_h, r_p))


def contact_forces(
    joint, kin: JointKinematics, state, d, n, normal, delta, delta_dot, v_t, radii, levers
) -> JointForces:
    """The dry pin-in-hole contact's forces from its geometry at one instant (SI): the normal
    force of ``joint.contact``'s law at penetration ``delta`` and rate ``delta_dot`` along
    ``normal``, the friction of ``joint.friction`` at slip ``v_t``; ``radii``: the (hole, pin)
    radii of curvature the law sees, ``levers``: the (hole, pin) distances from the centres
    to the contact along ``n``; ``d``: the eccentricity. Shared by the round and the worn joint."""
    c = joint.contact
    compliance = effective_compliance(joint.pin_material.compliance, joint.hole_material.compliance)
    approach = joint.memory.approach_speed(jnp.asarray(state))
    geometry = dict(hole_radius=radii[0], pin_radius=radii[1], compliance_sum=compliance, exponent=c.exponent)
    f_n, f_el = c.law.normal_force(delta, delta_dot, approach, c.restitution, **geometry)
    fr = joint.friction
    f_t = fr.law.force(v_t, f_n, fr.coefficient, fr.stick_speed, fr.slip_speed)
    zero = jnp.zeros_like(f_n)
    return JointForces(
        force=-f_n * normal + f_t * perp(normal),
        pin_point=kin.pin_position + levers[1] * n,
        hole_point=kin.hole_position + levers[0] * n,
        pin_moment=zero,
        hole_moment=zero,
        dissipation=(f_n - f_el) * delta_dot - f_t * v_t,
        elastic_energy=c.law.elastic_energy(delta, **geometry),
        eccentricity=d,
        penetration=delta,
        normal_force=f_n,
        friction_force=f_t,
        slip_speed=v_t,
        aux=memory_target(d, kin.pin_velocity - kin.hole_velocity, joint.clearance),
    )


#: joint laws by their TOML name (modules that define more laws add them with `register_joint_law`)
JOINT_LAWS: dict[str, type[AbstractJointLaw]] = {law.name: law for law in (Ideal, Clearance)}


def register_joint_law(law: type[AbstractJointLaw]) -> type[AbstractJointLaw]:
    """Add a joint-law class to `JOINT_LAWS` under its ``name``; returns it.

    Raises:
        ParameterError: for a class that is not an `AbstractJointLaw`, or a name already
            taken by another class.
    """
    if not (isinstance(law, type) and issubclass(law, AbstractJointLaw)):
        raise ParameterError(f"{law!r} is not a jaxcrank.physics.joints.AbstractJointLaw subclass")
    if JOINT_LAWS.get(law.name, law) is not law:
        raise ParameterError(f"joint law name {law.name!r} is already taken by {JOINT_LAWS[law.name].__name__}")
    JOINT_LAWS[law.name] = law
    return law


def joint_state_size(law: AbstractJointLaw) -> int:
    """Number of state entries a joint law declares (static)."""
    return len(law.state_names())


def stack_forces(forces: list[JointForces]) -> JointForces:
    """Per-joint reports stacked along a leading joint axis (``aux`` dropped)."""
    if not forces:
        z2, z = jnp.zeros((0, 2)), jnp.zeros(0)
        return JointForces(z2, z2, z2, z, z, z, z, z2, z, z, z, z)
    fields = JointForces._fields[:-1]
    return JointForces(*[jnp.stack([getattr(f, k) for f in forces]) for k in fields])


__all__ = [
    "JOINT_LAWS",
    "AbstractJointLaw",
    "Clearance",
    "Ideal",
    "JointAccelerations",
    "JointForces",
    "JointKinematics",
    "check_dry_pin_in_hole",
    "clearance_contact",
    "contact_forces",
    "joint_state_size",
    "memory_state_rate",
    "register_joint_law",
]
