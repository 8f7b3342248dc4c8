"""The lubricated revolute joint (model.md, "Lubricated revolute joint"): an oil film
between pin (journal) and hole (bearing) that carries load before the surfaces touch,
handed over to the dry contact law of [`Clearance`][jaxcrank.physics.joints.Clearance]
when the film becomes thinner than the surfaces' roughness.

The film is the short-bearing (Ocvirk) solution of Reynolds' equation with the
half-Sommerfeld (pi-film) cavitation condition, with squeeze and whirl and both
surfaces turning, as in the multibody literature on lubricated joints (Flores,
Ambrosio, Claro & Lankarani, "Lubricated revolute joints in rigid multibody systems",
Nonlinear Dyn. 56 (2009) 277-295; the positive-pressure region in general: Daniel,
Machado & Cavalca, Mech. Mach. Theory 99 (2016) 19-36).

In the frame of the line of centres (unit vector n along the eccentricity d = pin
centre - hole centre, t = n rotated by +90 degrees), with eps = |d| / c and phi the
angle of n, the film is h = c (1 - eps cos theta) at the angle theta from n, and the
pressure integrated over the bearing's length L is

    P(theta) = eta L^3 / (2 c^2) * g(theta) / (1 - eps cos theta)^3,
    g(theta) = squeeze cos theta + wedge sin theta,
    squeeze = 2 eps_dot,   wedge = -eps (omega_pin + omega_hole - 2 phi_dot)   (1/s),

kept where g > 0, a half circle centred on atan2(wedge, squeeze) that turns with the
signs of the squeeze and the effective whirl. The force on the pin is
``-R int P (cos theta, sin theta) dtheta`` over that half circle; the three integrals
it needs are polynomials in the Sommerfeld angle nu, tan(nu/2) = sqrt((1 + eps) /
(1 - eps)) tan(theta/2) ([`film_integrals`][jaxcrank.physics.lubrication.film_integrals]), finite and smooth
down to eps = 0.
"""

from __future__ import annotations

import math
from typing import ClassVar

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .joints import AbstractPinInHole, Clearance, JointForces, JointKinematics, clearance_contact, register_joint_law
from .memory import AbstractMemoryLaw, ForgettingMemory
from .params import Contact, Friction, Material, ParameterError, _concrete, check_range
from .safemath import cross, perp, safe_norm, smoothstep

Scalar = Float[ArrayLike, ""]


def sommerfeld_angle(angle: Scalar, eccentricity_ratio: Scalar) -> Float[Array, ""]:
    """The Sommerfeld angle nu of the film angle theta, rad:
    ``tan(nu/2) = sqrt((1 + eps) / (1 - eps)) tan(theta/2)``, continuous and increasing
    in theta on (-2 pi, 2 pi), equal to theta at eps = 0.

    Under it ``dtheta / (1 - eps cos theta) = dnu / sqrt(1 - eps^2)`` and
    ``1 - eps cos theta = (1 - eps^2) / (1 + eps cos nu)``, which turn the film integrals
    into trigonometric polynomials.

    Args:
        angle: theta, rad, in (-2 pi, 2 pi).
        eccentricity_ratio: eps in [0, 1).
    """
    half = 0.5 * angle
    return 2.0 * jnp.arctan2(
        jnp.sqrt(1.0 + eccentricity_ratio) * jnp.sin(half), jnp.sqrt(1.0 - eccentricity_ratio) * jnp.cos(half)
    )


def film_integrals(eccentricity_ratio: Scalar, start: Scalar) -> tuple[Array, Array, Array]:
    """The integrals of ``(cos^2, sin cos, sin^2)(theta) / (1 - eps cos theta)^3`` over
    the half circle ``[start, start + pi]``, dimensionless.

    With the Sommerfeld angle nu ([`sommerfeld_angle`][jaxcrank.physics.lubrication.sommerfeld_angle]) they are
    ``[(eps^2 + 1/2) nu + 2 eps sin nu + sin(2 nu) / 4] / (1 - eps^2)^(5/2)``,
    ``[-eps cos nu - cos^2 nu / 2] / (1 - eps^2)^2`` and
    ``[nu / 2 - sin(2 nu) / 4] / (1 - eps^2)^(3/2)``, taken between the ends.

    Args:
        eccentricity_ratio: eps in [0, 1).
        start: the half circle's first angle, rad, in (-3 pi/2, pi/2].

    Returns:
        ``(I_cc, I_cs, I_ss)``.
    """
    e = eccentricity_ratio
    nu = jnp.stack([sommerfeld_angle(start, e), sommerfeld_angle(start + math.pi, e)])
    s, c, s2 = jnp.sin(nu), jnp.cos(nu), jnp.sin(2.0 * nu)
    cc = (e**2 + 0.5) * nu + 2.0 * e * s + 0.25 * s2
    cs = -e * c - 0.5 * c**2
    ss = 0.5 * nu - 0.25 * s2
    q = 1.0 - e**2
    return (cc[1] - cc[0]) / q**2.5, (cs[1] - cs[0]) / q**2, (ss[1] - ss[0]) / q**1.5


def pressure_region(squeeze: Scalar, wedge: Scalar) -> Float[Array, ""]:
    """First angle of the half circle where ``g = squeeze cos theta + wedge sin theta`` is
    positive, rad, in (-3 pi/2, pi/2]: ``atan2(wedge, squeeze) - pi/2``.

    With neither squeeze nor wedge there is no pressure; the region is then [-pi/2, pi/2]
    (any half circle gives the same zero force), with a finite gradient.

    Args:
        squeeze: 2 eps_dot, 1/s.
        wedge: -eps (omega_pin + omega_hole - 2 phi_dot), 1/s.
    """
    moving = squeeze**2 + wedge**2 > 0.0
    centre = jnp.arctan2(jnp.where(moving, wedge, 0.0), jnp.where(moving, squeeze, 1.0))
    return jnp.where(moving, centre, 0.0) - 0.5 * math.pi


def film_force(
    eccentricity_ratio: Scalar,
    squeeze: Scalar,
    wedge: Scalar,
    *,
    viscosity: Scalar,
    length: Scalar,
    radius: Scalar,
    clearance: Scalar,
) -> tuple[Array, Array]:
    """Short-bearing film force on the journal in the frame of the line of centres, N.

    ``F_r = -k (squeeze I_cc + wedge I_cs)``, ``F_t = -k (squeeze I_cs + wedge I_ss)``
    with ``k = eta R L^3 / (2 c^2)`` and the integrals of
    [`film_integrals`][jaxcrank.physics.lubrication.film_integrals] over the region where the pressure is
    positive ([`pressure_region`][jaxcrank.physics.lubrication.pressure_region]).

    Args:
        eccentricity_ratio: eps = |d| / c in [0, 1).
        squeeze: 2 eps_dot, 1/s.
        wedge: -eps (omega_pin + omega_hole - 2 phi_dot), 1/s.
        viscosity: eta, Pa s.
        length: bearing length L, m.
        radius: journal radius R, m.
        clearance: radial clearance c, m.

    Returns:
        ``(F_r, F_t)``: the components along n (negative: towards the hole's centre) and
        along t, N.
    """
    i_cc, i_cs, i_ss = film_integrals(eccentricity_ratio, pressure_region(squeeze, wedge))
    k = viscosity * radius * length**3 / (2.0 * clearance**2)
    return -k * (squeeze * i_cc + wedge * i_cs), -k * (squeeze * i_cs + wedge * i_ss)


def short_bearing_force(
    eccentricity_ratio: Scalar,
    eccentricity_rate: Scalar,
    whirl_speed: Scalar,
    journal_speed: Scalar,
    bearing_speed: Scalar,
    *,
    viscosity: Scalar,
    length: Scalar,
    radius: Scalar,
    clearance: Scalar,
) -> tuple[Array, Array]:
    """[`film_force`][jaxcrank.physics.lubrication.film_force] in the variables of the literature, N.

    Where squeeze and whirl keep the pressure on ``theta in [-pi, 0]`` (``eps_dot = 0``,
    ``omega_pin + omega_hole > 2 phi_dot``) this is Flores et al.'s
    ``F_r = -k [2 eps^2 w / (1 - eps^2)^2 + pi eps_dot (1 + 2 eps^2) / (1 - eps^2)^(5/2)]``,
    ``F_t = k [pi eps w / (2 (1 - eps^2)^(3/2)) + 4 eps eps_dot / (1 - eps^2)^2]`` with
    ``w = omega_pin + omega_hole - 2 phi_dot``; in general the region follows the signs.

    Args:
        eccentricity_ratio: eps, in [0, 1).
        eccentricity_rate: eps_dot, 1/s.
        whirl_speed: phi_dot, the line of centres' angular speed, rad/s.
        journal_speed: omega_pin, rad/s.
        bearing_speed: omega_hole, rad/s.
        viscosity: eta, Pa s.
        length: L, m.
        radius: journal radius R, m.
        clearance: c, m.

    Returns:
        ``(F_r, F_t)`` on the journal along n and t, N.
    """
    e = eccentricity_ratio
    wedge = -e * (journal_speed + bearing_speed - 2.0 * whirl_speed)
    return film_force(
        e, 2.0 * eccentricity_rate, wedge, viscosity=viscosity, length=length, radius=radius, clearance=clearance
    )


def film_dissipation(
    radial_force: Scalar, tangential_force: Scalar, squeeze: Scalar, wedge: Scalar, clearance: Scalar
) -> Float[Array, ""]:
    """Power the film dissipates, W: ``-(c/2) (squeeze F_r + wedge F_t)``.

    It is ``-F . d_dot + (omega_pin + omega_hole) |d| F_t / 2``: the power of the pressure
    force on the relative motion of the centres and of the pressure-driven shear
    torques ``-|d| F_t / 2`` on each side ([`Lubricated`][jaxcrank.physics.lubrication.Lubricated]). It equals
    ``k c / 2 * int g^2 / (1 - eps cos theta)^3`` over the positive-pressure region, so
    it is never negative.

    Args:
        radial_force: F_r, N.
        tangential_force: F_t, N.
        squeeze: 1/s.
        wedge: 1/s.
        clearance: c, m.
    """
    return -0.5 * clearance * (squeeze * radial_force + wedge * tangential_force)


def film_weight(eccentricity_ratio: Scalar, film_start: Scalar, film_end: Scalar) -> Float[Array, ""]:
    """Share of the film force, dimensionless: 1 below ``film_start``, 0 above
    ``film_end``, the C2 quintic ``1 - smoothstep`` between; the dry law gets the rest."""
    return 1.0 - smoothstep((eccentricity_ratio - film_start) / (film_end - film_start))


#: the fields a lubricated joint shares with its dry clearance joint
_DRY_FIELDS = ("hole_radius", "pin_radius", "contact", "friction", "memory", "pin_material", "hole_material")


class Lubricated(AbstractPinInHole):
    """A lubricated revolute clearance joint: an oil film of viscosity ``viscosity`` in a
    bearing of length ``length``, and the dry contact of
    [`Clearance`][jaxcrank.physics.joints.Clearance] when the film breaks down (model.md, "Lubricated
    revolute joint").

    Below the eccentricity ratio ``film_start`` the joint carries the short-bearing film
    force ([`film_force`][jaxcrank.physics.lubrication.film_force]); above ``film_end`` the dry law
    ([`clearance_contact`][jaxcrank.physics.joints.clearance_contact]); in between a C2 blend
    ([`film_weight`][jaxcrank.physics.lubrication.film_weight]). The defaults, 0.95 and 0.98, are the literature's
    values (model.md). The dry law pushes only once the pin touches the wall
    (eps > 1).

    The film force acts through the pin's centre on the pin and through the hole's
    centre on the hole, with the pressure-driven shear torque ``-|d| F_t / 2`` on each
    side (so the law's net moment is zero and its dissipation
    [`film_dissipation`][jaxcrank.physics.lubrication.film_dissipation] is never negative). The shear torque of
    the surfaces' relative rotation (Petroff's torque) is not modelled. The radius of the
    film is the pin's; the short-bearing model holds for bearings no longer than about
    half their diameter (L / (2 R) up to about 1/2) and overestimates the load capacity of
    longer ones.

    The state is the dry law's approach-speed memory ([`memory`][jaxcrank.physics.memory]), which keeps
    latching for the dry contacts.

    Attributes:
        hole_radius: bearing radius R_h, m.
        pin_radius: journal radius R_p, m; smaller than ``hole_radius``.
        viscosity: dynamic viscosity of the oil eta, Pa s, >= 0 (0: the dry joint).
        length: bearing length L, m, > 0.
        contact: the dry normal contact law and its settings.
        friction: the dry friction law and its settings.
        memory: the approach-speed memory law.
        pin_material: elastic properties of the pin's surface.
        hole_material: elastic properties of the hole's surface.
        film_start: eps0, eccentricity ratio up to which the film alone acts.
        film_end: eps1, eccentricity ratio from which the dry law alone acts;
            0 < film_start < film_end < 1.

    Raises:
        ParameterError: a radius, viscosity, length or hand-over ratio out of its range.
    """

    name: ClassVar[str] = "lubricated"
    kinds: ClassVar[tuple[str, ...]] = ("revolute",)

    hole_radius: float
    pin_radius: float
    viscosity: float
    length: float
    contact: Contact = Contact()
    friction: Friction = Friction()
    memory: AbstractMemoryLaw = ForgettingMemory()
    pin_material: Material = Material()
    hole_material: Material = Material()
    film_start: float = 0.95
    film_end: float = 0.98

    def __check_init__(self):
        _ = self.dry  # the dry law's checks: radii, laws
        check_range("viscosity", self.viscosity, low=0.0, low_open=False, unit="Pa s")
        check_range("length", self.length, low=0.0, unit="m")
        check_range("film_start", self.film_start, low=0.0, high=1.0)
        check_range("film_end", self.film_end, low=0.0, high=1.0)
        start, end = _concrete(self.film_start), _concrete(self.film_end)
        if start is not None and end is not None and np.any(start >= end):
            raise ParameterError(
                f"film_start = {np.max(start):g} must be smaller than film_end = {np.min(end):g} "
                "(valid range: 0 < film_start < film_end < 1)"
            )

    @property
    def dry(self) -> Clearance:
        """The dry clearance joint with the same radii, laws and materials."""
        return Clearance(**{f: getattr(self, f) for f in _DRY_FIELDS})

    @classmethod
    def oiled(cls, dry: Clearance, viscosity: float, length: float) -> Lubricated:
        """The lubricated joint with ``dry``'s radii, laws and materials, an oil of
        ``viscosity`` (Pa s) and a bearing ``length`` (m); its [`dry`][jaxcrank.physics.lubrication.Lubricated.dry]
        is ``dry`` again."""
        return cls(viscosity=viscosity, length=length, **{f: getattr(dry, f) for f in _DRY_FIELDS})

    def forces(self, kin, state):
        return lubricated_contact(self, kin, state)

    def state_rate(self, kin, acc, state, forces):
        return self.dry.state_rate(kin, acc, state, forces)


def lubricated_contact(joint: Lubricated, kin: JointKinematics, state: Float[ArrayLike, " k"]) -> JointForces:
    """Forces of one lubricated revolute joint: the film, the dry contact and their blend.

    Args:
        joint: the joint's radii, oil, hand-over and dry laws.
        kin: where its pin and hole centres are and how they move.
        state: its memory law's state (SI; the first entry is the approach-speed memory, m/s).

    Returns:
        The joint's [`JointForces`][jaxcrank.physics.joints.JointForces] at the dry law's points (on the
        pin's and the hole's surfaces along n); ``normal_force`` is the radial force pushing
        the pin towards the hole's centre (film and contact, N; negative where the film
        pushes outwards), ``friction_force`` the tangential force (film and dry friction,
        N); ``dissipation`` adds the film's and the dry law's; ``aux`` is the dry law's.
    """
    dry = clearance_contact(joint.dry, kin, state)
    d = dry.eccentricity
    c = joint.clearance
    distance = safe_norm(d)
    centred = distance > 0.0
    n = jnp.where(centred, d / jnp.where(centred, distance, 1.0), jnp.array([1.0, 0.0]))
    t = perp(n)
    v_rel = kin.pin_velocity - kin.hole_velocity
    eps = jnp.minimum(distance / c, joint.film_end)  # the film's weight is zero beyond film_end
    squeeze = 2.0 * jnp.dot(n, v_rel) / c
    wedge = 2.0 * jnp.dot(t, v_rel) / c - eps * (kin.pin_angular_velocity + kin.hole_angular_velocity)
    geometry = dict(viscosity=joint.viscosity, length=joint.length, radius=joint.pin_radius, clearance=c)
    f_r, f_t = film_force(eps, squeeze, wedge, **geometry)
    weight = film_weight(distance / c, joint.film_start, joint.film_end)
    film = weight * (f_r * n + f_t * t)
    shear = -0.5 * cross(d, film)  # pressure-driven shear torque on each side
    force = (1.0 - weight) * dry.force + film
    return JointForces(
        force=force,
        pin_point=dry.pin_point,
        hole_point=dry.hole_point,
        pin_moment=(1.0 - weight) * dry.pin_moment + cross(kin.pin_position - dry.pin_point, film) + shear,
        hole_moment=(1.0 - weight) * dry.hole_moment + cross(dry.hole_point - kin.hole_position, film) + shear,
        dissipation=(1.0 - weight) * dry.dissipation + weight * film_dissipation(f_r, f_t, squeeze, wedge, c),
        elastic_energy=(1.0 - weight) * dry.elastic_energy,
        eccentricity=d,
        penetration=dry.penetration,
        normal_force=-jnp.dot(force, n),
        friction_force=jnp.dot(force, t),
        slip_speed=dry.slip_speed,
        aux=dry.aux,
    )


register_joint_law(Lubricated)

__all__ = [
    "Lubricated",
    "film_dissipation",
    "film_force",
    "film_integrals",
    "film_weight",
    "lubricated_contact",
    "pressure_region",
    "short_bearing_force",
    "sommerfeld_angle",
]
