"""A planar linkage as data: bodies, the joints that connect them, the law of each joint,
and the driver.

- A [`Body`][jaxcrank.physics.linkage.Body] has a mass, an inertia about its centre of mass and named
  points in its own frame (where joints attach).
- A joint connects a point of one body to a point of another (or of the ground): a
  [`Revolute`][jaxcrank.physics.linkage.Revolute] (a pin in a hole) or a
  [`Prismatic`][jaxcrank.physics.linkage.Prismatic] (a slider on a guide). What the joint does is its law
  ([`jaxcrank.physics.joints`][]): ideal, or a force element with clearance.
- The driver ([`ConstantSpeed`][jaxcrank.physics.linkage.ConstantSpeed],
  [`SpeedProfile`][jaxcrank.physics.linkage.SpeedProfile], [`Torque`][jaxcrank.physics.linkage.Torque]) turns one
  body that is jointed to the ground.
- [`Outputs`][jaxcrank.physics.linkage.Outputs] say which deviations from the ideal motion and which
  transmission angle the mechanism reports as metrics.

Every mechanism is an [`AbstractMechanism`][jaxcrank.physics.linkage.AbstractMechanism]: a
[`Linkage`][jaxcrank.physics.linkage.Linkage] written out body by body (from a TOML file or Python), or a
preset ([`jaxcrank.physics.presets`][]) that builds its linkage from a few named
dimensions. Numbers are pytree leaves (differentiable, sweepable); names and the
structure are static. Everything is SI: m, kg, s, rad, N.
"""

from __future__ import annotations

import abc
import dataclasses
import math
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .joints import AbstractJointLaw
from .params import ParameterError, _concrete, check_range
from .safemath import rotation, turn

#: the name of the ground in joint and driver descriptions
GROUND = "ground"


class Point(eqx.Module):
    """A point in a body's frame (or the ground's), m."""

    x: float = 0.0
    y: float = 0.0

    def vector(self) -> Float[Array, " 2"]:
        """(x, y) as an array, m."""
        return jnp.stack([jnp.asarray(self.x, dtype=float), jnp.asarray(self.y, dtype=float)])

    def pair(self) -> tuple:
        """(x, y) as they are (numbers known at trace time stay numbers, so a point on a
        frame axis costs less to turn: [`jaxcrank.physics.safemath.turn`][])."""
        return (self.x, self.y)

    def minus(self, other: Point) -> tuple:
        """(x, y) of ``self - other``, as [`pair`][jaxcrank.physics.linkage.Point.pair]."""
        return (self.x - other.x, self.y - other.y)


class Pose(eqx.Module):
    """A body frame's origin (m) and angle (rad) in the world frame."""

    x: float = 0.0
    y: float = 0.0
    angle: float = 0.0

    def vector(self) -> Float[Array, " 3"]:
        return jnp.stack([jnp.asarray(v, dtype=float) for v in (self.x, self.y, self.angle)])


class Body(eqx.Module):
    """A rigid body of the linkage.

    Attributes:
        mass: kg, > 0.
        inertia: moment of inertia about the centre of mass, kg m^2, > 0.
        points: named points in the body's frame where joints attach, m.
        centre_of_mass: the centre of mass in the body's frame, m.
        guess: the body frame's approximate pose at the start (crank at the driver's
            initial angle): which of the ways the linkage can be assembled it is in.
            Needed only where the assembly is ambiguous (the side of a dyad).

    Raises:
        ParameterError: a mass or inertia that is not positive.
    """

    mass: float
    inertia: float
    points: dict[str, Point]
    centre_of_mass: Point = Point()
    guess: Pose | None = None

    def __check_init__(self):
        check_range("mass", self.mass, low=0.0, unit="kg")
        check_range("inertia", self.inertia, low=0.0, unit="kg m^2")


@dataclasses.dataclass(frozen=True)
class Site:
    """A point of a body (or of the ground): ``(body, point)`` names."""

    body: str
    point: str

    def __str__(self):
        return f"{self.body}.{self.point}"


class Revolute(eqx.Module):
    """A revolute joint: the pin at ``pin`` turns in the hole at ``hole``.

    Attributes:
        hole: the body and point of the hole (the bearing); ``"ground"`` for a fixed pivot.
        pin: the body and point of the pin (the journal).
    """

    kind: ClassVar[str] = "revolute"
    hole: Site = eqx.field(static=True)
    pin: Site = eqx.field(static=True)

    def sites(self) -> tuple[Site, Site]:
        return self.hole, self.pin


class Prismatic(eqx.Module):
    """A prismatic joint: the point ``slider`` of one body slides along an axis through
    the point ``guide`` of another, at a fixed angle to it.

    Attributes:
        guide: the body and point the axis runs through (``"ground"`` for a fixed guide).
        slider: the sliding body and its point on the axis.
        direction: the axis direction in the guide body's frame, rad.
        angle: the slider body's angle minus the guide body's, rad (held by the joint).
    """

    kind: ClassVar[str] = "prismatic"
    guide: Site = eqx.field(static=True)
    slider: Site = eqx.field(static=True)
    direction: float = 0.0
    angle: float = 0.0

    def sites(self) -> tuple[Site, Site]:
        return self.guide, self.slider


Connection = Revolute | Prismatic


# --------------------------------------------------------------------------- drivers


class AbstractDriver(eqx.Module):
    """What turns the linkage: a prescribed angle of ``body`` (``prescribed``), or a
    torque on it. The body must be jointed to the ground. Every driver has an
    ``initial_angle`` (rad), the body's angle at t = 0.

    ``speed_scale`` (rad/s) scales the state's rates; ``period`` (s) is the time of one
    revolution (at the nominal speed for a torque driver).
    """

    name: ClassVar[str]
    prescribed: ClassVar[bool]
    body: eqx.AbstractVar[str]

    @property
    @abc.abstractmethod
    def speed_scale(self):
        """Nominal angular speed, rad/s (stop-gradient where used as a scale)."""

    @property
    def period(self):
        """Time of one revolution at the nominal speed, s."""
        return 2.0 * math.pi / self.speed_scale

    def angle(self, t: Float[ArrayLike, ""]) -> Float[Array, ""]:
        """The prescribed angle of the driven body at time t, rad."""
        raise NotImplementedError(f"a {self.name!r} driver prescribes no angle")


class ConstantSpeed(AbstractDriver):
    """The driven body turns at a constant speed: angle = initial_angle + speed t.

    Attributes:
        body: the driven body (jointed to the ground).
        speed: rad/s, > 0.
        initial_angle: its angle at t = 0, rad.
    """

    name: ClassVar[str] = "constant_speed"
    prescribed: ClassVar[bool] = True
    body: str = eqx.field(static=True)
    speed: float
    initial_angle: float = 0.0

    def __check_init__(self):
        check_range("driver.speed", self.speed, low=0.0, unit="rad/s")
        check_range("driver.initial_angle", self.initial_angle, unit="rad")

    @property
    def speed_scale(self):
        return self.speed

    def angle(self, t):
        return self.initial_angle + self.speed * t


class SpeedProfile(AbstractDriver):
    """A prescribed, periodic speed: ``omega(t) = speed (1 + sum_k c_k cos(k speed t) +
    s_k sin(k speed t))`` for harmonics k = 1, 2, ..., so the angle is
    ``initial_angle + speed t + sum_k (c_k sin(k speed t) + s_k (1 - cos(k speed t))) / k``
    and one revolution still takes 2 pi / speed.

    Attributes:
        body: the driven body (jointed to the ground).
        speed: mean angular speed, rad/s, > 0.
        initial_angle: rad.
        cosine: relative amplitudes c_k of the cosine harmonics (dimensionless).
        sine: relative amplitudes s_k of the sine harmonics (dimensionless).

    Raises:
        ParameterError: when the amplitudes could make the speed reach zero
            (sum of |c_k| + |s_k| must stay below 1).
    """

    name: ClassVar[str] = "speed_profile"
    prescribed: ClassVar[bool] = True
    body: str = eqx.field(static=True)
    speed: float
    initial_angle: float = 0.0
    cosine: tuple[float, ...] = ()
    sine: tuple[float, ...] = ()

    def __check_init__(self):
        check_range("driver.speed", self.speed, low=0.0, unit="rad/s")
        amps = [_concrete(a) for a in (*self.cosine, *self.sine)]
        if all(a is not None for a in amps) and sum(float(np.abs(a)) for a in amps) >= 1.0:
            raise ParameterError(
                "driver harmonics: the sum of |cosine| + |sine| amplitudes must be below 1 (valid range: [0, 1)), "
                "or the speed would reach zero"
            )

    @property
    def speed_scale(self):
        return self.speed

    def angle(self, t):
        w = self.speed
        out = self.initial_angle + w * t
        for k, c in enumerate(self.cosine, start=1):
            out = out + c * jnp.sin(k * w * t) / k
        for k, s in enumerate(self.sine, start=1):
            out = out + s * (1.0 - jnp.cos(k * w * t)) / k
        return out


class Torque(AbstractDriver):
    """A constant torque on the driven body, which turns freely from an initial speed
    (zero torque: a free-running mechanism).

    Attributes:
        body: the driven body (jointed to the ground).
        torque: N m, on the body, counter-clockwise positive.
        initial_angle: rad.
        initial_speed: rad/s, > 0 (also the nominal speed that scales the state).
    """

    name: ClassVar[str] = "torque"
    prescribed: ClassVar[bool] = False
    body: str = eqx.field(static=True)
    torque: float = 0.0
    initial_angle: float = 0.0
    initial_speed: float = 1.0

    def __check_init__(self):
        check_range("driver.torque", self.torque, unit="N m")
        check_range("driver.initial_speed", self.initial_speed, low=0.0, unit="rad/s")

    @property
    def speed_scale(self):
        return self.initial_speed


DRIVERS: dict[str, type[AbstractDriver]] = {d.name: d for d in (ConstantSpeed, SpeedProfile, Torque)}


# --------------------------------------------------------------------------- outputs


@dataclasses.dataclass(frozen=True)
class BodyVector:
    """A direction fixed in a body: from point ``start`` to point ``end``, or, without
    ``end``, the unit vector at ``angle`` (rad) in the body's frame."""

    body: str
    start: str | None = None
    end: str | None = None
    angle: float = 0.0


@dataclasses.dataclass(frozen=True)
class Outputs:
    """What a mechanism reports as metrics besides its joints and driver.

    Attributes:
        deviations: ``(body, coordinate)`` pairs whose deviation from the ideal motion
            is a metric (largest and RMS); coordinate ``"x"``, ``"y"`` (of the centre of
            mass, m) or ``"angle"`` (deg).
        acceleration: the ``(body, coordinate)`` whose acceleration deviation is a
            metric (the output link), or ``None``.
        transmission: the two directions whose angle is the transmission angle
            (``(link, output)``), or ``None``.
    """

    deviations: tuple[tuple[str, str], ...] = ()
    acceleration: tuple[str, str] | None = None
    transmission: tuple[BodyVector, BodyVector] | None = None


# --------------------------------------------------------------------------- mechanisms


class AbstractMechanism(eqx.Module):
    """A mechanism: every simulation, steady state, sweep and design problem takes one.

    Subclasses give the description ([`linkage`][jaxcrank.physics.linkage.AbstractMechanism.linkage]) and hold
    the joint laws by joint name (``joints``) and the driver as fields (and ``gravity``,
    m/s^2), so every mechanism's parameters are addressed alike (``joints.B.pin_radius``,
    ``driver.speed``, ``gravity``).
    """

    joints: eqx.AbstractVar[dict[str, AbstractJointLaw]]
    driver: eqx.AbstractVar[AbstractDriver]

    @abc.abstractmethod
    def linkage(self) -> Linkage:
        """The mechanism written out as a [`Linkage`][jaxcrank.physics.linkage.Linkage] (traceable)."""

    @property
    def period(self):
        """Time of one revolution of the driven body at its nominal speed, s."""
        return self.driver.period

    @property
    def speed(self):
        """Nominal angular speed of the driven body, rad/s."""
        return self.driver.speed_scale


class Linkage(AbstractMechanism):
    """A planar linkage written out body by body.

    Attributes:
        bodies: the moving bodies by name.
        ground: the ground's named points, m.
        connections: each joint's geometry by name ([`Revolute`][jaxcrank.physics.linkage.Revolute] or
            [`Prismatic`][jaxcrank.physics.linkage.Prismatic]).
        joints: each joint's law by name (the same names as ``connections``).
        driver: what turns the linkage.
        gravity: g along -y, m/s^2, >= 0.
        outputs: what it reports besides its joints ([`Outputs`][jaxcrank.physics.linkage.Outputs]).
        name: a label for reports.

    Raises:
        ParameterError: a description that does not hold together (the message names
            the joint, body or point): see [`jaxcrank.physics.topology.check`][].
    """

    bodies: dict[str, Body]
    ground: dict[str, Point]
    connections: dict[str, Connection]
    joints: dict[str, AbstractJointLaw]
    driver: AbstractDriver
    gravity: float = 9.81
    outputs: Outputs = eqx.field(static=True, default=Outputs())
    name: str = eqx.field(static=True, default="linkage")

    def __check_init__(self):
        check_range("gravity", self.gravity, low=0.0, low_open=False, unit="m/s^2")
        from .topology import check

        check(self)
        _check_outputs(self.outputs, self.bodies)

    def linkage(self) -> Linkage:
        return self


def _check_outputs(outputs: Outputs, bodies: dict[str, Body]) -> None:
    """Raise a one-line ParameterError for outputs that name an unknown body, coordinate or point."""
    pairs = [("deviations", d) for d in outputs.deviations]
    pairs += [("acceleration", outputs.acceleration)] if outputs.acceleration is not None else []
    for what, (body, coordinate) in pairs:
        if body not in bodies:
            raise ParameterError(f"outputs.{what}: unknown body {body!r}; bodies: {', '.join(sorted(bodies))}")
        if coordinate not in ("x", "y", "angle"):
            raise ParameterError(f"outputs.{what}: {body}.{coordinate}: the coordinate must be x, y or angle")
    for v in outputs.transmission or ():
        if v.body not in bodies:
            raise ParameterError(f"outputs.transmission: unknown body {v.body!r}; bodies: {', '.join(sorted(bodies))}")
        for point in (v.start, v.end) if v.end is not None else ():
            if point not in bodies[v.body].points:
                raise ParameterError(
                    f"outputs.transmission: body {v.body!r} has no point {point!r}; "
                    f"its points: {', '.join(bodies[v.body].points) or 'none'}"
                )


def world_point(pose: Float[ArrayLike, " 3"], local: Float[ArrayLike, " 2"]) -> Float[Array, " 2"]:
    """A body point's world position (m), for the body frame's pose (x, y, angle); ``local``
    an array (2,) or a pair of numbers."""
    return pose[:2] + turn(rotation(pose[2]), local)
