"""A planar linkage as data: bodies, the joints that connect them, the law of each joint,
and the driver.

- A [`Body`][jaxcrank.physics.linkage.Body] has a mass, an inertia about its centre of mass and named
  points in its own frame (where joints attach).
- A joint connects a point of one body to a point of another (or of the ground): a
  [`Revolute`][jaxcrank.physics.linkage.Revolute] (a pin in a hole) or a
  [`Prismatic`][jaxcrank.physics.linkage.Prismatic] (a slider on a guide). What the joint does is its law
  ([`jaxcrank.physics.joints`][]): ideal, or a force element with clearance.
- The driver ([`ConstantSpeed`][jaxcrank.physics.drivers.ConstantSpeed],
  [`SpeedProfile`][jaxcrank.physics.drivers.SpeedProfile], [`Torque`][jaxcrank.physics.drivers.Torque]) turns one
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
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .drivers import AbstractDriver
from .joints import AbstractJointLaw
from .params import ParameterError, check_range
from .safemath import add, atan2, cos_sin, mul, neg, rotation, sub, turn, vcross, vsub

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


#: the words a joint's ``branch`` takes (see [`Revolute`][jaxcrank.physics.linkage.Revolute])
BRANCHES = ("+", "-", "positive", "negative")


def _check_branch(joint) -> None:
    if joint.branch is not None and joint.branch not in BRANCHES:
        raise ParameterError(f"branch = {joint.branch!r} must be one of {', '.join(repr(b) for b in BRANCHES)}")


class Revolute(eqx.Module):
    """A revolute joint: the pin at ``pin`` turns in the hole at ``hole``.

    Attributes:
        hole: the body and point of the hole (the bearing); ``"ground"`` for a fixed pivot.
        pin: the body and point of the pin (the journal).
        branch: where the ideal mechanism's two links meet at this joint (the middle joint
            of a dyad), which of the two ways they can be assembled: ``"+"`` (or
            ``"positive"``) where the turn at this joint from the hole body's other joint to
            the pin body's other joint is counter-clockwise; where one of the two bodies
            slides on a line instead, ``"+"`` where this joint lies ahead of the other
            body's pivot along the line's direction; ``"-"`` the other way. ``None``: the
            assembly nearest the bodies' ``guess`` poses, or ``"+"`` without them.
    """

    kind: ClassVar[str] = "revolute"
    hole: Site = eqx.field(static=True)
    pin: Site = eqx.field(static=True)
    branch: str | None = eqx.field(static=True, default=None)

    def __check_init__(self):
        _check_branch(self)

    def sites(self) -> tuple[Site, Site]:
        return self.hole, self.pin

    def residual(self, hole_frame, pin_frame, hole_local, pin_local) -> tuple:
        """The joint's two closure equations for frames of its two bodies (objects with
        ``point(local)`` and ``angle``) and its points in them: hole point minus pin point,
        m; zero where the joint holds."""
        return vsub(hole_frame.point(hole_local), pin_frame.point(pin_local))

    def gap(self, residual: tuple):
        """How far apart the joint's two sides are, m, from its
        [`residual`][jaxcrank.physics.linkage.Revolute.residual]."""
        return jnp.hypot(jnp.asarray(residual[0], dtype=float), jnp.asarray(residual[1], dtype=float))

    def side_angles(self) -> tuple:
        """The angles of the joint's hole and pin frames on their bodies, rad (none for a pin)."""
        return 0.0, 0.0

    def load(self, unknowns: tuple, hole_angle) -> tuple:
        """The load an ideal joint passes to its pin side for its two unknowns (the
        force's x and y, N): (force, a pair, N; pure moment, N m)."""
        return (unknowns[0], unknowns[1]), 0.0


class Prismatic(eqx.Module):
    """A prismatic joint: the point ``slider`` of one body slides along an axis through
    the point ``guide`` of another, at a fixed angle to it.

    Attributes:
        guide: the body and point the axis runs through (``"ground"`` for a fixed guide).
        slider: the sliding body and its point on the axis.
        direction: the axis direction in the guide body's frame, rad (the angle from the
            guide body's x axis to the axis, counter-clockwise; on the ground, from the
            world's x axis).
        angle: the slider body's angle minus the guide body's, rad (held by the joint).
        branch: where this joint is the middle joint of a dyad of the ideal mechanism (a
            block on a turning guide), which way it is assembled: ``"+"`` where the axis
            direction points from the guide body's pivot towards the slider body's pivot,
            ``"-"`` the other way; ``None``: nearest the ``guess`` poses, or ``"+"``.
    """

    kind: ClassVar[str] = "prismatic"
    guide: Site = eqx.field(static=True)
    slider: Site = eqx.field(static=True)
    direction: float = 0.0
    angle: float = 0.0
    branch: str | None = eqx.field(static=True, default=None)

    def __check_init__(self):
        _check_branch(self)

    def sites(self) -> tuple[Site, Site]:
        return self.guide, self.slider

    def residual(self, guide_frame, moving_frame, guide_local, moving_local) -> tuple:
        """The joint's two closure equations for frames of its two bodies (the guide's, the
        sliding one's: objects with ``point(local)`` and ``angle``) and its points in them:
        the sliding point's distance from the guide's line, m, and the sliding body's angle
        less the guide body's and ``angle``, rad (wrapped to (-pi, pi]); zero where the joint
        holds."""
        g = guide_frame.point(guide_local)
        s = moving_frame.point(moving_local)
        d = cos_sin(add(guide_frame.angle, self.direction))
        c, s_ = cos_sin(sub(sub(moving_frame.angle, guide_frame.angle), self.angle))
        return vcross(d, vsub(s, g)), atan2(s_, c)

    def gap(self, residual: tuple):
        """How far the slider point is from the guide's line, m, from the joint's
        [`residual`][jaxcrank.physics.linkage.Prismatic.residual]."""
        return jnp.abs(jnp.asarray(residual[0], dtype=float))

    def side_angles(self) -> tuple:
        """The angles of the joint's guide and slider frames on their bodies, rad: the axis
        direction on the guide body, and the same axis seen from the slider body."""
        return self.direction, self.direction - self.angle

    def load(self, unknowns: tuple, guide_angle) -> tuple:
        """The load an ideal joint passes to its slider side for its two unknowns (the
        force normal to the axis, N, and the moment, N m), the guide body at ``guide_angle``
        (rad): (force, a pair, N; pure moment, N m)."""
        c, s = cos_sin(add(guide_angle, self.direction))
        return (mul(unknowns[0], neg(s)), mul(unknowns[0], c)), unknowns[1]


Connection = Revolute | Prismatic


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
        ParameterError: names that do not hold together (the message names the joint,
            body or point). The structure (its loops, its driver) and the assembly are
            checked when the linkage is compiled ([`jaxcrank.physics.compiled.compile_model`][]).
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
        _check_names(self)
        _check_outputs(self.outputs, self.bodies)

    def linkage(self) -> Linkage:
        return self


def _check_names(lk: Linkage) -> None:
    """Raise a one-line ParameterError for names that do not hold together: a body named
    like the ground, a joint without a law (or a law without a joint), a law for the other
    kind of joint, a joint on an unknown body or point or joining a body to itself, a
    driver on an unknown body."""
    if GROUND in lk.bodies:
        raise ParameterError(f"a body cannot be named {GROUND!r}: that name is the ground's")
    if not lk.bodies:
        raise ParameterError("a linkage needs at least one moving body")
    for j in sorted(set(lk.connections) - set(lk.joints)):
        raise ParameterError(f'joint {j!r} has no law: give it one (e.g. law = "ideal")')
    for j in sorted(set(lk.joints) - set(lk.connections)):
        raise ParameterError(f"joint {j!r} has a law but no connection (which bodies and points it joins)")
    points = {b: body.points for b, body in lk.bodies.items()} | {GROUND: lk.ground}
    bodies = ", ".join(sorted(lk.bodies))
    for j, conn in sorted(lk.connections.items()):
        law = lk.joints[j]
        if not isinstance(law, AbstractJointLaw):
            raise ParameterError(f"joint {j}: {law!r} is not a joint law (e.g. jaxcrank.Clearance(...))")
        if conn.kind not in law.kinds:
            raise ParameterError(
                f"joint {j!r} is {conn.kind} but its law {law.name!r} is for {' and '.join(law.kinds)} joints"
            )
        for site in conn.sites():
            if site.body not in points:
                raise ParameterError(
                    f"joint {j!r} is on an unknown body {site.body!r}; bodies: {bodies} (and {GROUND!r})"
                )
            if site.point not in points[site.body]:
                raise ParameterError(
                    f"joint {j!r}: body {site.body!r} has no point {site.point!r}; "
                    f"its points: {', '.join(sorted(points[site.body])) or 'none'}"
                )
        if conn.sites()[0].body == conn.sites()[1].body:
            raise ParameterError(f"joint {j!r} joins body {conn.sites()[0].body!r} to itself")
    if lk.driver.body not in lk.bodies:
        raise ParameterError(f"the driver is on an unknown body {lk.driver.body!r}; bodies: {bodies}")


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
