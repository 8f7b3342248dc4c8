"""Wear in revolute clearance joints: Archard's law, worn profiles, and the contact of a
pin in a worn hole.

A worn surface is round plus a **wear depth** that depends on the angle around its own
body: ``w(theta) = a_0 + sum_m (a_m cos m theta + b_m sin m theta)``, m = 1..M, stored as
``(a_0, a_1..a_M, b_1..b_M)`` in metres (a Fourier series; M modes, 2 M + 1 numbers). The
hole's wear deepens the hole (its radius at angle theta becomes ``R_h + w_h(theta)``), the
pin's wear thins the pin (``R_p - w_p(theta)``); both open the gap.

[`Worn`][jaxcrank.physics.wear.Worn] (``law = "worn"`` in TOML files) is the dry clearance joint acting against
the worn profiles: the penetration, the normal direction and the curvature radii that the
contact law sees all come from the local geometry at the contact's angle. With both
profiles zero every one of these equals the round joint's exactly, so a new bushing
reproduces [`Clearance`][jaxcrank.physics.joints.Clearance] bit for bit.

[`wear_rates`][jaxcrank.physics.wear.wear_rates] gives the rate of change of both profiles at one instant from
Archard's law, ``dh/dt = k p |v_slip| / H``: the normal force is spread over the Hertz
half-width of a line contact of the bearing's length (a semi-elliptic pressure), so the
rate's Fourier coefficients carry the patch's factor ``2 J_1(x) / x``, x = m b / R. The
worn volume rate is exactly Archard's ``k F |v_slip| / H`` on each surface.
"""

from __future__ import annotations

import math
from typing import ClassVar, NamedTuple

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .joints import (
    AbstractPinInHole,
    JointForces,
    JointKinematics,
    check_dry_pin_in_hole,
    contact_forces,
    memory_state_rate,
    register_joint_law,
)
from .laws import effective_compliance
from .memory import AbstractMemoryLaw, ForgettingMemory
from .params import Contact, Friction, Material, ParameterError, _concrete, check_range
from .safemath import perp, safe_norm

#: Fourier modes of a worn profile by default: a patch of half-width b on a radius R is
#: resolved to about m b / R = 1 at the paper's loads
DEFAULT_MODES = 24
#: the least difference of the local radii of curvature (hole's less pin's) the contact law is
#: handed, in clearances: a worn patch that conforms to the pin stays a finite stiffness
CONFORMING_GAP = 0.1


def new_profile(modes: int = DEFAULT_MODES) -> Float[Array, " 2M+1"]:
    """A round surface's profile: 2 ``modes`` + 1 zeros (m)."""
    return jnp.zeros(2 * int(modes) + 1)


def profile_modes(profile) -> int:
    """M, the number of modes of a profile of 2 M + 1 coefficients (static)."""
    return (int(np.shape(profile)[-1]) - 1) // 2


def harmonics(cos_sin: tuple, modes: int) -> tuple[Array, Array]:
    """cos(m theta), sin(m theta) for m = 1..``modes`` from ``(cos theta, sin theta)``
    by repeated complex multiplication (no angle, so no atan2 and finite gradients at a
    zero direction, where every harmonic is zero)."""
    c1, s1 = cos_sin
    cs, ss = [c1], [s1]
    for _ in range(modes - 1):
        c, s = cs[-1], ss[-1]
        cs.append(c * c1 - s * s1)
        ss.append(s * c1 + c * s1)
    return jnp.stack(cs), jnp.stack(ss)


class Surface(NamedTuple):
    """A profile at one angle: depth, its first and second derivatives in the angle
    (m, m/rad, m/rad^2)."""

    depth: Array
    slope: Array
    bend: Array


def evaluate_profile(profile: Float[Array, " 2M+1"], cos_sin: tuple) -> Surface:
    """The profile's depth and angular derivatives at the angle whose cosine and sine
    are ``cos_sin`` (each an array of the same shape, a direction in the body's frame)."""
    modes = profile_modes(profile)
    p = jnp.asarray(profile)
    if modes == 0:
        zero = jnp.zeros_like(cos_sin[0])
        return Surface(p[0] + zero, zero, zero)
    cm, sm = harmonics(cos_sin, modes)
    m = jnp.arange(1, modes + 1, dtype=float).reshape((modes,) + (1,) * jnp.ndim(cos_sin[0]))
    a = p[1 : modes + 1].reshape(m.shape)
    b = p[modes + 1 :].reshape(m.shape)
    depth = p[0] + jnp.sum(a * cm + b * sm, axis=0)
    slope = jnp.sum(m * (b * cm - a * sm), axis=0)
    bend = -jnp.sum(m * m * (a * cm + b * sm), axis=0)
    return Surface(depth, slope, bend)


def profile_on_grid(profile, angles: Float[Array, " n"]) -> Float[Array, " n"]:
    """Depth of ``profile`` at the body-frame ``angles`` (rad), m."""
    return evaluate_profile(profile, (jnp.cos(angles), jnp.sin(angles))).depth


def worn_volume(profile, radius, length):
    """Worn volume of a surface of nominal ``radius`` and axial ``length`` (m), m^3:
    the mean depth times the surface's area (``2 pi R L a_0``)."""
    return 2.0 * math.pi * radius * length * jnp.asarray(profile)[0]


def patch_factor(x: Float[Array, ...]) -> Float[Array, ...]:
    """``2 J_1(x) / x``, the Fourier transform of a semi-elliptic pressure of unit load
    at wavenumber x / b (x >= 0; 1 at x = 0). Its power series, exact to rounding for
    x <= 12 (x is clipped there; larger x means a patch wider than a wavelength)."""
    x = jnp.clip(jnp.asarray(x, dtype=float), 0.0, 12.0)
    q = -(x * x) / 4.0
    term = jnp.ones_like(x)
    out = term
    for k in range(1, 40):
        term = term * q / (k * (k + 1))
        out = out + term
    return out


class Archard(eqx.Module):
    """Archard's wear law on a pin-in-hole joint: the wear depth rate of each surface is
    ``k p |v_slip| / H`` (p the contact pressure, Pa; v_slip the sliding speed, m/s).

    Attributes:
        hole_coefficient: dimensionless wear coefficient k of the hole (bushing) surface, >= 0.
        pin_coefficient: dimensionless wear coefficient k of the pin (journal) surface, >= 0.
        hole_hardness: hardness H of the hole's material, Pa (> 0).
        pin_hardness: hardness H of the pin's material, Pa (> 0).
        length: the bearing's axial length, m (> 0): the pressure is the normal force per
            length spread over the Hertz half-width.
        slip_smoothing: the sliding speed's magnitude is ``sqrt(v^2 + v_s^2) - v_s``, m/s
            (> 0; keeps the rate differentiable at zero slip).

    Raises:
        ParameterError: a value outside its range.
    """

    hole_coefficient: float = 1e-6
    pin_coefficient: float = 1e-7
    hole_hardness: float = 0.64e9
    pin_hardness: float = 1.6e9
    length: float = 0.02
    slip_smoothing: float = 1e-4

    def __check_init__(self):
        check_range("hole_coefficient", self.hole_coefficient, low=0.0, low_open=False)
        check_range("pin_coefficient", self.pin_coefficient, low=0.0, low_open=False)
        check_range("hole_hardness", self.hole_hardness, low=0.0, unit="Pa")
        check_range("pin_hardness", self.pin_hardness, low=0.0, unit="Pa")
        check_range("length", self.length, low=0.0, unit="m")
        check_range("slip_smoothing", self.slip_smoothing, low=0.0, unit="m/s")


class Worn(AbstractPinInHole):
    """A dry revolute clearance joint whose hole and pin have worn profiles, with
    Archard's law for how they wear (``law = "worn"``).

    The fields are [`Clearance`][jaxcrank.physics.joints.Clearance]'s, plus ``wear`` (the law's coefficients)
    and the two profiles: ``hole_wear`` in the frame of the body that holds the hole,
    ``pin_wear`` in the pin's, each the 2 M + 1 Fourier coefficients of the depth (m,
    see [`jaxcrank.physics.wear`][]; zeros: a new joint, exactly the round one). The
    joint's ``clearance`` stays the new joint's radial clearance ``hole_radius -
    pin_radius``; wear adds to it where it falls.

    Raises:
        ParameterError: a radius that is not positive, a pin not smaller than its hole,
            profiles that are not 1-D of the same odd length, or a profile whose deepest
            point would cross the pin's centre.
    """

    name: ClassVar[str] = "worn"
    kinds: ClassVar[tuple[str, ...]] = ("revolute",)
    #: the fields that are arrays (lists of numbers in TOML files)
    array_fields: ClassVar[tuple[str, ...]] = ("hole_wear", "pin_wear")

    hole_radius: float
    pin_radius: float
    contact: Contact = Contact()
    friction: Friction = Friction()
    memory: AbstractMemoryLaw = ForgettingMemory()
    pin_material: Material = Material()
    hole_material: Material = Material()
    wear: Archard = Archard()
    hole_wear: Float[Array, " 2M+1"] = eqx.field(default_factory=new_profile, converter=jnp.asarray)
    pin_wear: Float[Array, " 2M+1"] = eqx.field(default_factory=new_profile, converter=jnp.asarray)

    def __check_init__(self):
        check_dry_pin_in_hole(self)
        pin = _concrete(self.pin_radius)
        if not isinstance(self.wear, Archard):
            raise ParameterError(f"wear {self.wear!r} is not a jaxcrank.physics.wear.Archard")
        shapes = {np.shape(self.hole_wear)[-1:], np.shape(self.pin_wear)[-1:]}
        if len(shapes) != 1 or np.ndim(self.hole_wear) != 1 or np.shape(self.hole_wear)[0] % 2 != 1:
            raise ParameterError(
                f"hole_wear and pin_wear must be 1-D with the same odd length 2 M + 1 (M Fourier modes); got shapes "
                f"{np.shape(self.hole_wear)} and {np.shape(self.pin_wear)}"
            )
        pin_profile = _concrete(self.pin_wear)
        if pin_profile is not None and pin is not None:
            deepest = float(np.abs(pin_profile).sum())
            if deepest >= float(np.min(pin)):
                raise ParameterError(f"pin_wear reaches {deepest:g} m, not less than pin_radius = {np.min(pin):g} m")

    @property
    def modes(self) -> int:
        """M, the Fourier modes of the profiles (static)."""
        return profile_modes(self.hole_wear)

    def forces(self, kin, state):
        return worn_contact(self, kin, state)

    def state_rate(self, kin, acc, state, forces):
        return memory_state_rate(self, kin, acc, state, forces)

    def worn(self, hole_wear, pin_wear) -> Worn:
        """This joint with the profiles ``hole_wear`` and ``pin_wear`` (m; traceable)."""
        return eqx.tree_at(lambda law: (law.hole_wear, law.pin_wear), self, (hole_wear, pin_wear))


def from_clearance(law, wear: Archard | None = None, modes: int = DEFAULT_MODES) -> Worn:
    """The [`Worn`][jaxcrank.physics.wear.Worn] joint with the same radii, laws and materials as the round
    dry joint ``law`` (a [`Clearance`][jaxcrank.physics.joints.Clearance] or ``Worn``), new, with ``modes``
    Fourier modes and the wear law ``wear`` (default: ``Archard()``, or ``law``'s own).

    Raises:
        ParameterError: for a law that is not a dry revolute clearance joint.
    """
    fields = ("hole_radius", "pin_radius", "contact", "friction", "memory", "pin_material", "hole_material")
    if not all(hasattr(law, f) for f in fields) or getattr(law, "name", None) not in ("clearance", "worn"):
        what = getattr(law, "name", None) or type(law).__name__
        raise ParameterError(
            f"its law {what!r} is not a dry revolute clearance joint (law 'clearance' or 'worn'): wear is "
            "modelled in dry pin-in-hole joints only"
        )
    if wear is None:
        wear = getattr(law, "wear", Archard())
    return Worn(
        **{f: getattr(law, f) for f in fields}, wear=wear, hole_wear=new_profile(modes), pin_wear=new_profile(modes)
    )


class ContactPoint(NamedTuple):
    """Where a worn joint touches (SI): the direction of the pin from the hole's centre in
    the world (``n``, unit; zero when centred), in the hole's and the pin's frames
    (``(cos, sin)`` pairs), the two surfaces there, and the contact normal (tilted by the
    profiles' slopes)."""

    eccentricity: Array
    distance: Array
    n: Array
    hole_dir: tuple
    pin_dir: tuple
    hole: Surface
    pin: Surface
    normal: Array


def _in_frame(n, angle):
    c, s = jnp.cos(angle), jnp.sin(angle)
    return (c * n[0] + s * n[1], c * n[1] - s * n[0])


def contact_point(joint: Worn, kin: JointKinematics) -> ContactPoint:
    """The contact geometry of a worn joint at one instant
    ([`ContactPoint`][jaxcrank.physics.wear.ContactPoint])."""
    d = kin.pin_position - kin.hole_position
    eps = safe_norm(d)
    centred = eps > 0.0
    n = jnp.where(centred, d / jnp.where(centred, eps, 1.0), 0.0)
    hole_dir, pin_dir = _in_frame(n, kin.hole_angle), _in_frame(n, kin.pin_angle)
    hole = evaluate_profile(joint.hole_wear, hole_dir)
    pin = evaluate_profile(joint.pin_wear, pin_dir)
    # the outward normals of r = R_h + w_h and r = R_p - w_p tilt from the radius by
    # -w_h'/R_h and +w_p'/R_p; the contact normal takes their mean (zero wear: exactly n)
    tilt = 0.5 * (pin.slope / joint.pin_radius - hole.slope / joint.hole_radius)
    normal = jnp.cos(tilt) * n + jnp.sin(tilt) * perp(n)
    return ContactPoint(d, eps, n, hole_dir, pin_dir, hole, pin, normal)


def worn_contact(joint: Worn, kin: JointKinematics, state) -> JointForces:
    """Kinematics and forces of a dry clearance joint with worn profiles (SI).

    The penetration is ``|d| - c - w_h - w_p`` at the contact's angle, its rate the exact
    time derivative of that (the profiles turn with their bodies), the normal the mean of
    the two surfaces' normals, and the contact law sees the local radii of curvature
    ``R_h + w_h + w_h''`` and ``R_p - w_p - w_p''`` (their difference kept at least a tenth
    of the clearance, so a worn patch that conforms to the pin stays a finite stiffness).
    With zero profiles every quantity equals [`clearance_contact`][jaxcrank.physics.joints.clearance_contact]'s.

    Returns:
        The joint's [`JointForces`][jaxcrank.physics.joints.JointForces]; ``aux`` is the memory's target
        normal speed, m/s.
    """
    cp = contact_point(joint, kin)
    n, eps = cp.n, cp.distance
    tangent = perp(cp.normal)
    r_h, r_p = joint.hole_radius, joint.pin_radius
    delta = eps - joint.clearance - cp.hole.depth - cp.pin.depth
    v_rel = kin.pin_velocity - kin.hole_velocity
    centred = eps > 0.0
    turning = jnp.where(centred, jnp.dot(perp(n), v_rel) / jnp.where(centred, eps, 1.0), 0.0)
    delta_dot = (
        jnp.dot(cp.normal, v_rel)
        - cp.hole.slope * (turning - kin.hole_angular_velocity)
        - cp.pin.slope * (turning - kin.pin_angular_velocity)
    )
    lever_h, lever_p = r_h + cp.hole.depth, r_p - cp.pin.depth
    v_t = jnp.dot(tangent, v_rel) + kin.pin_angular_velocity * lever_p - kin.hole_angular_velocity * lever_h
    rho_h = r_h + cp.hole.depth + cp.hole.bend
    rho_p = r_p - cp.pin.depth - cp.pin.bend
    rho_h = jnp.maximum(rho_h, rho_p + CONFORMING_GAP * joint.clearance)

    return contact_forces(
        joint, kin, state, cp.eccentricity, n, cp.normal, delta, delta_dot, v_t, (rho_h, rho_p), (lever_h, lever_p)
    )


def patch_half_width(joint: Worn, normal_force):
    """Hertz half-width b of the line contact (m) under ``normal_force`` (N):
    ``b = sqrt(4 F R* (s_p + s_h) / (pi L))``, R* = R_h R_p / (R_h - R_p) of the new joint,
    s = (1 - nu^2) / E, L the bearing's length; zero without load (finite gradient)."""
    r_star = joint.hole_radius * joint.pin_radius / joint.clearance
    compliance = effective_compliance(joint.pin_material.compliance, joint.hole_material.compliance)
    x = 4.0 * jnp.maximum(normal_force, 0.0) * r_star * compliance / (math.pi * joint.wear.length)
    loaded = x > 0.0
    return jnp.where(loaded, jnp.sqrt(jnp.where(loaded, x, 1.0)), 0.0)


def _rate(coefficient, hardness, radius, length, load_speed, half_width, direction, modes):
    """Fourier coefficients of one surface's depth rate (m/s) for a patch centred at
    ``direction`` (cos, sin in the surface's frame)."""
    q = coefficient * load_speed / (hardness * length * radius)  # integral of dh/dt over the angle, m/s
    if modes == 0:
        return jnp.reshape(q / (2.0 * math.pi), (1,))
    cm, sm = harmonics(direction, modes)
    g = patch_factor(jnp.arange(1, modes + 1, dtype=float) * half_width / radius)
    return jnp.concatenate([jnp.reshape(q / (2.0 * math.pi), (1,)), q / math.pi * g * cm, q / math.pi * g * sm])


class WearRate(NamedTuple):
    """The rates of a worn joint's two profiles (m/s each coefficient) and of its worn
    volumes (m^3/s)."""

    hole: Array
    pin: Array
    hole_volume: Array
    pin_volume: Array


def wear_rates(joint: Worn, kin: JointKinematics, forces: JointForces) -> WearRate:
    """Archard's law at one instant: d/dt of both profiles' Fourier coefficients (m/s),
    from the normal force and the slip at the contact (``forces`` from
    [`worn_contact`][jaxcrank.physics.wear.worn_contact]) spread over the Hertz patch."""
    a = joint.wear
    cp = contact_point(joint, kin)
    v = forces.slip_speed
    slip = jnp.sqrt(v * v + a.slip_smoothing**2) - a.slip_smoothing
    load_speed = jnp.maximum(forces.normal_force, 0.0) * slip  # W
    b = patch_half_width(joint, forces.normal_force)
    m = joint.modes
    hole = _rate(a.hole_coefficient, a.hole_hardness, joint.hole_radius, a.length, load_speed, b, cp.hole_dir, m)
    pin = _rate(a.pin_coefficient, a.pin_hardness, joint.pin_radius, a.length, load_speed, b, cp.pin_dir, m)
    return WearRate(
        hole, pin, a.hole_coefficient * load_speed / a.hole_hardness, a.pin_coefficient * load_speed / a.pin_hardness
    )


register_joint_law(Worn)

__all__ = [
    "DEFAULT_MODES",
    "Archard",
    "ContactPoint",
    "Surface",
    "WearRate",
    "Worn",
    "contact_point",
    "evaluate_profile",
    "from_clearance",
    "harmonics",
    "new_profile",
    "patch_factor",
    "patch_half_width",
    "profile_modes",
    "profile_on_grid",
    "wear_rates",
    "worn_contact",
    "worn_volume",
]
