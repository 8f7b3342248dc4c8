"""The structure of a linkage, worked out once from its names (static, plain Python).

Bodies are placed one step at a time, each from bodies already placed (the ground first):

- a **tree step**: a body hangs from a placed one by an ideal revolute joint (one
  coordinate, its angle) or an ideal prismatic joint (one coordinate, its slide along the
  axis);
- a **floating** body, which no ideal joint reaches (three coordinates: its centre of
  mass's x and y, and its angle);
- a **dyad** ([`Dyad`][jaxcrank.physics.topology.Dyad]): two bodies joined to each other by
  an ideal joint and each to a placed body by another, placed in closed form (RRR, RRP,
  RPR, PRP; no coordinate);
- a **group** ([`Group`][jaxcrank.physics.topology.Group]): any other set of bodies that
  its ideal joints hold fast to the placed ones (a triad, a dyad of another kind), placed
  by a root find (no coordinate).

Two plans are made this way:

- **the tree** ([`Tree`][jaxcrank.physics.topology.Tree]) of the equations of motion, over
  the ideal joints alone: every joint that is not ideal is a force element that cuts its
  loop, so the coordinates it frees are the relative motion of its two sides (a pin's
  eccentricity). A loop of ideal joints is closed by a dyad or a group (its bodies follow
  the bodies they hang from); the other bodies are tree steps, breadth first from the
  ground. The driven body's angle is the driver's (no coordinate) when the driver
  prescribes it; it is never placed by a closure.
- **the assembly plan** ([`Plan`][jaxcrank.physics.topology.Plan]) of the ideal mechanism
  (every joint ideal), which closes every loop from the driver's angle with dyads and
  groups alone.

The state layout follows the names alone: coordinates are numbered body by body in
sorted body order, whatever the order of the steps. This module holds the structures;
[`jaxcrank.physics.planner`][] makes them.
"""

from __future__ import annotations

import dataclasses

from .linkage import GROUND, Site

#: the dyads placed in closed form ([`jaxcrank.physics.closure`][]): joint kinds outer,
#: middle, other (R revolute, P prismatic)
DYAD_KINDS = ("RRR", "RRP", "RPR", "PRP")


@dataclasses.dataclass(frozen=True)
class Placement:
    """How one body's frame pose follows from the coordinates.

    Attributes:
        body: the body's name.
        kind: ``"revolute"`` or ``"prismatic"`` (a tree step through that ideal joint from
            ``parent``), ``"floating"``, or ``"closed"`` (placed by a dyad or a group).
        parent: the body (or ground) it hangs from in a tree step, else ``None``.
        joint: the ideal joint of its tree step, else ``None``.
        coordinates: indices of its own generalized coordinates (angle; slide; or x, y,
            angle, less the angle when the driver prescribes it; none when closed).
        driven: whether it is the driven body.
    """

    body: str
    kind: str
    parent: str | None
    joint: str | None
    coordinates: tuple[int, ...]
    driven: bool


@dataclasses.dataclass(frozen=True)
class Dyad:
    """Two bodies placed in closed form: ``first`` and ``second`` are joined by the joint
    ``middle``; ``first`` is held to a placed body by ``outer``, ``second`` by ``other``.
    ``kind`` names the three joints' kinds in that order (R revolute, P prismatic): RRR
    (two circles), RRP (a circle and a line), RPR (a block on a turning guide: ``first``
    carries the guide) or PRP (two lines).

    Attributes:
        parents: the placed bodies (or the ground) that ``outer`` and ``other`` hold it to.
    """

    kind: str
    first: str
    second: str
    outer: str
    middle: str
    other: str
    parents: tuple[str, ...] = ()

    @property
    def bodies(self) -> tuple[str, str]:
        return (self.first, self.second)

    @property
    def joints(self) -> tuple[str, str, str]:
        return (self.outer, self.middle, self.other)


@dataclasses.dataclass(frozen=True)
class Group:
    """Bodies whose ideal joints ``joints`` (each with two equations) hold them fast to the
    placed bodies ``parents``: placed together by a root find of those equations."""

    bodies: tuple[str, ...]
    joints: tuple[str, ...]
    parents: tuple[str, ...] = ()
    kind: str = "group"


Closure = Dyad | Group


@dataclasses.dataclass(frozen=True)
class Skeleton:
    """The names of a linkage, hashable (the key of the cached structures).

    Attributes:
        bodies: body names, sorted.
        points: per body (and the ground) its point names.
        connections: per joint, sorted by name: (name, kind, first site, second site).
        ideal: per joint, whether its law is ideal.
        laws: per joint: (name, law name, the joint kinds the law is for).
        law_states: per joint: (name, the names of its law's state entries).
        driver_body: the driven body.
        prescribed: whether the driver prescribes its angle.
    """

    bodies: tuple[str, ...]
    points: tuple[tuple[str, tuple[str, ...]], ...]
    connections: tuple[tuple[str, str, Site, Site], ...]
    ideal: tuple[tuple[str, bool], ...]
    laws: tuple[tuple[str, str, tuple[str, ...]], ...]
    law_states: tuple[tuple[str, tuple[str, ...]], ...]
    driver_body: str
    prescribed: bool

    @classmethod
    def of(cls, lk) -> Skeleton:
        """The skeleton of a [`Linkage`][jaxcrank.physics.linkage.Linkage]."""
        points = [(b, tuple(sorted(lk.bodies[b].points))) for b in sorted(lk.bodies)]
        points.append((GROUND, tuple(sorted(lk.ground))))
        joints = sorted(lk.joints.items())
        return cls(
            tuple(sorted(lk.bodies)),
            tuple(points),
            tuple((j, c.kind, *c.sites()) for j, c in sorted(lk.connections.items())),
            tuple((j, bool(law.ideal)) for j, law in joints),
            tuple((j, law.name, tuple(law.kinds)) for j, law in joints),
            tuple((j, tuple(law.state_names())) for j, law in joints),
            lk.driver.body,
            bool(lk.driver.prescribed),
        )

    def kind(self, joint: str) -> str:
        return next(k for j, k, *_ in self.connections if j == joint)

    def ends(self, joint: str) -> tuple[str, str]:
        """The two bodies (or the ground) a joint joins."""
        a, b = next(sites for j, _, *sites in self.connections if j == joint)
        return a.body, b.body


@dataclasses.dataclass(frozen=True)
class Tree:
    """The structure of the equations of motion (see the module docstring).

    Attributes:
        bodies: body names, sorted (the order of every per-body array).
        joints: joint names, sorted (the order of every per-joint array).
        placements: one per body, in the order of ``steps``.
        coordinates: ``(body, kind)`` of each generalized coordinate, kind ``"x"``,
            ``"y"``, ``"angle"`` or ``"slide"`` (a floating body's x and y are its centre
            of mass's).
        cut: the joints that are force elements (not ideal), sorted.
        driver_coordinate: index of the driven body's angle among the coordinates when
            the driver does not prescribe it (a torque), else ``None``.
        steps: the order bodies are placed in: a [`Placement`][jaxcrank.physics.topology.Placement]
            (a tree step or a floating body) or a closure (a
            [`Dyad`][jaxcrank.physics.topology.Dyad] or [`Group`][jaxcrank.physics.topology.Group]),
            each after the bodies it hangs from.
    """

    bodies: tuple[str, ...]
    joints: tuple[str, ...]
    placements: tuple[Placement, ...]
    coordinates: tuple[tuple[str, str], ...]
    cut: tuple[str, ...]
    driver_coordinate: int | None
    steps: tuple = ()

    @property
    def n(self) -> int:
        """Number of generalized coordinates."""
        return len(self.coordinates)

    @property
    def closures(self) -> tuple[Closure, ...]:
        """The dyads and groups that close loops of ideal joints in the dynamics."""
        return tuple(s for s in self.steps if not isinstance(s, Placement))

    def placement(self, body: str) -> Placement:
        return next(p for p in self.placements if p.body == body)

    def _parents(self) -> dict[str, tuple[str, ...]]:
        out = {p.body: (p.parent,) for p in self.placements if p.parent is not None}
        for c in self.closures:
            for b in c.bodies:
                out[b] = c.parents
        return out

    def below(self, body: str) -> tuple[str, ...]:
        """The bodies whose poses follow ``body``'s through ideal joints (not itself)."""
        parents = self._parents()
        out = {body}
        for p in self.placements:  # parents come first
            if set(parents.get(p.body, ())) & out:
                out.add(p.body)
        out.discard(body)
        return tuple(b for b in self.bodies if b in out)

    def rows(self) -> tuple[tuple[int, ...], ...]:
        """For each coordinate and, last, the driver angle: the entries of Q (x, y, angle of
        each body's centre of mass, in body order) it can move. A floating body's x, y and
        angle move only their own entry; a revolute child's angle its x, y and angle; a
        slide its x and y; every coordinate also moves the bodies below its body. A torque
        driver's angle moves every entry (the ideal coordinates follow it)."""
        index = {b: i for i, b in enumerate(self.bodies)}

        def whole(b):
            return [3 * index[b] + r for r in range(3)]

        out = []
        for body, kind in self.coordinates:
            p = self.placement(body)
            i = index[body]
            if p.kind == "floating":
                own = [3 * i + {"x": 0, "y": 1, "angle": 2}[kind]]
            elif kind == "slide":
                own = [3 * i, 3 * i + 1]
            else:
                own = whole(body)
            if self.driver_coordinate is not None and (body, kind) == self.coordinates[self.driver_coordinate]:
                own = list(range(3 * len(self.bodies)))
            out.append(tuple(sorted({*own, *(r for b in self.below(body) for r in whole(b))})))
        driven = next((p for p in self.placements if p.driven), None)
        phi = []
        if driven is not None and self.driver_coordinate is None:
            i = index[driven.body]
            phi = [3 * i + 2] if driven.kind == "floating" else whole(driven.body)
            phi = sorted({*phi, *(r for b in self.below(driven.body) for r in whole(b))})
        out.append(tuple(phi))
        return tuple(out)


@dataclasses.dataclass(frozen=True)
class Plan:
    """How the ideal mechanism's body poses follow from the driver's angle.

    Attributes:
        driven: the driven body (pinned to the ground by ``pivot``).
        pivot: the driven body's revolute joint to the ground.
        steps: dyads and groups in order.
    """

    driven: str
    pivot: str
    steps: tuple[Closure, ...]

    @property
    def dyads(self) -> tuple[Dyad, ...]:
        return tuple(s for s in self.steps if isinstance(s, Dyad))
