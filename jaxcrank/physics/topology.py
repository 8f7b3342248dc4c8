"""The structure of a linkage, worked out once from its names (static, plain Python).

Two structures matter:

- **The tree** ([`Tree`][jaxcrank.physics.topology.Tree]) of the equations of motion. The ideal joints form a
  spanning forest rooted at the ground, walked breadth first: a body reached through an
  ideal revolute joint has one coordinate, its angle; through an ideal prismatic joint,
  one coordinate, its slide along the axis; a body no ideal joint reaches from the ground
  *floats*, with three coordinates (its frame's x, y and angle). The driven body's angle
  is the driver's (no coordinate) when the driver prescribes it. Every joint that is not
  ideal is a force element that cuts its loop, so the coordinates it frees are the
  relative motion of its two sides (a pin's eccentricity).
- **The assembly plan** ([`Plan`][jaxcrank.physics.topology.Plan]) of the ideal mechanism (every joint ideal), which
  closes every loop: body poses follow from the driver's angle through RRR and RRP dyads
  in closed form (the classic slider-crank and four-bar loops and any linkage built of
  such dyads); what the dyads do not reach is closed by Newton's method
  ([`jaxcrank.physics.closure`][]).

[`check`][jaxcrank.physics.topology.check] turns a description that does not hold together into a one-line
[`ParameterError`][jaxcrank.physics.params.ParameterError] naming the joint, body or point.
"""

from __future__ import annotations

import dataclasses
import functools
from collections import deque

from .linkage import GROUND, Linkage, Site
from .params import ParameterError


@dataclasses.dataclass(frozen=True)
class Placement:
    """How one body's frame pose follows from the coordinates.

    Attributes:
        body: the body's name.
        kind: ``"revolute"`` or ``"prismatic"`` (reached through that ideal joint from
            ``parent``) or ``"floating"``.
        parent: the body (or ground) it hangs from; ``None`` when floating.
        joint: the ideal joint it hangs from; ``None`` when floating.
        coordinates: indices of its own generalized coordinates (angle; slide; or x, y,
            angle, less the angle when the driver prescribes it).
        driven: whether it is the driven body.
    """

    body: str
    kind: str
    parent: str | None
    joint: str | None
    coordinates: tuple[int, ...]
    driven: bool


@dataclasses.dataclass(frozen=True)
class Tree:
    """The structure of the equations of motion (see the module docstring).

    Attributes:
        bodies: body names, sorted (the order of every per-body array).
        joints: joint names, sorted (the order of every per-joint array).
        placements: one per body, parents first.
        coordinates: ``(body, kind)`` of each generalized coordinate, kind ``"x"``,
            ``"y"``, ``"angle"`` or ``"slide"`` (a floating body's x and y are its centre
            of mass's).
        cut: the joints that are force elements (not ideal), sorted.
        driver_coordinate: index of the driven body's angle among the coordinates when
            the driver does not prescribe it (a torque), else ``None``.
    """

    bodies: tuple[str, ...]
    joints: tuple[str, ...]
    placements: tuple[Placement, ...]
    coordinates: tuple[tuple[str, str], ...]
    cut: tuple[str, ...]
    driver_coordinate: int | None

    @property
    def n(self) -> int:
        """Number of generalized coordinates."""
        return len(self.coordinates)

    def placement(self, body: str) -> Placement:
        return next(p for p in self.placements if p.body == body)

    def below(self, body: str) -> tuple[str, ...]:
        """The bodies that hang, through ideal joints, from ``body`` (not itself)."""
        out = {body}
        for p in self.placements:
            if p.parent in out:
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
class Dyad:
    """One step of the assembly plan: two unknown bodies ``first`` and ``second`` joined
    by the revolute ``middle``; ``first`` is pinned by the revolute ``outer`` to a known
    body, ``second`` by ``other`` (a revolute: RRR; a prismatic: RRP, ``second`` slides)."""

    kind: str  # "RRR" or "RRP"
    first: str
    second: str
    outer: str
    middle: str
    other: str


@dataclasses.dataclass(frozen=True)
class Plan:
    """How the ideal mechanism's body poses follow from the driver's angle.

    Attributes:
        driven: the driven body (pinned to the ground by ``pivot``).
        pivot: the driven body's revolute joint to the ground.
        steps: dyads in order.
        rest: bodies no dyad reaches (closed by Newton's method), sorted.
        constraints: joints whose closure the Newton step solves (those not used by the
            pivot and the dyads), sorted.
    """

    driven: str
    pivot: str
    steps: tuple[Dyad, ...]
    rest: tuple[str, ...]
    constraints: tuple[str, ...]


@dataclasses.dataclass(frozen=True)
class Skeleton:
    """The names of a linkage, hashable (the key of the cached structures)."""

    bodies: tuple[str, ...]
    points: tuple[tuple[str, tuple[str, ...]], ...]  # per body (and ground), its point names
    connections: tuple[tuple[str, str, Site, Site], ...]  # name, kind, first site, second site
    ideal: tuple[tuple[str, bool], ...]
    laws: tuple[tuple[str, str, tuple[str, ...]], ...]  # name, law name, law kinds
    driver_body: str
    prescribed: bool

    @classmethod
    def of(cls, lk: Linkage) -> Skeleton:
        points = [(b, tuple(sorted(lk.bodies[b].points))) for b in sorted(lk.bodies)]
        points.append((GROUND, tuple(sorted(lk.ground))))
        conns = tuple((j, c.kind, *c.sites()) for j, c in sorted(lk.connections.items()))
        ideal = tuple((j, bool(law.ideal)) for j, law in sorted(lk.joints.items()))
        laws = tuple((j, law.name, tuple(law.kinds)) for j, law in sorted(lk.joints.items()))
        return cls(
            tuple(sorted(lk.bodies)),
            tuple(points),
            conns,
            ideal,
            laws,
            lk.driver.body,
            bool(lk.driver.prescribed),
        )


def _check_names(sk: Skeleton) -> None:
    points = dict(sk.points)
    if GROUND in sk.bodies:
        raise ParameterError(f"a body cannot be named {GROUND!r}: that name is the ground's")
    if not sk.bodies:
        raise ParameterError("a linkage needs at least one moving body")
    law_names = {j for j, *_ in sk.laws}
    conn_names = {j for j, *_ in sk.connections}
    for j in sorted(conn_names - law_names):
        raise ParameterError(f'joint {j!r} has no law: give it one (e.g. law = "ideal")')
    for j in sorted(law_names - conn_names):
        raise ParameterError(f"joint {j!r} has a law but no connection (which bodies and points it joins)")
    kinds = {j: k for j, k, *_ in sk.connections}
    for j, law, law_kinds in sk.laws:
        if kinds[j] not in law_kinds:
            raise ParameterError(
                f"joint {j!r} is {kinds[j]} but its law {law!r} is for {' and '.join(law_kinds)} joints"
            )
    for j, _, *sites in sk.connections:
        for site in sites:
            if site.body not in points:
                raise ParameterError(
                    f"joint {j!r} is on an unknown body {site.body!r}; bodies: {', '.join(sk.bodies)} (and {GROUND!r})"
                )
            if site.point not in points[site.body]:
                raise ParameterError(
                    f"joint {j!r}: body {site.body!r} has no point {site.point!r}; "
                    f"its points: {', '.join(points[site.body]) or 'none'}"
                )
        if sites[0].body == sites[1].body:
            raise ParameterError(f"joint {j!r} joins body {sites[0].body!r} to itself")
    if sk.driver_body not in sk.bodies:
        raise ParameterError(f"the driver is on an unknown body {sk.driver_body!r}; bodies: {', '.join(sk.bodies)}")
    grounded = {
        s.body
        for _, kind, *sites in sk.connections
        if kind == "revolute"
        for s in sites
        if GROUND in {t.body for t in sites}
    }
    if sk.driver_body not in grounded:
        raise ParameterError(
            f"the driver is on body {sk.driver_body!r}, which is not attached to the ground by a revolute joint: "
            "drive a body that turns about a ground pivot"
        )


def _edges(sk: Skeleton, only_ideal: bool):
    ideal = dict(sk.ideal)
    for j, kind, a, b in sk.connections:
        if only_ideal and not ideal[j]:
            continue
        yield j, kind, a, b


def _cycle(parent_of: dict, a: str, b: str) -> list[str]:
    """Joints on the tree path between bodies a and b (``parent_of``: body -> (parent,
    joint), or None at a root)."""

    def chain(x):
        out = [(x, None)]
        while parent_of.get(x) is not None:
            parent, joint = parent_of[x]
            out[-1] = (x, joint)
            out.append((parent, None))
            x = parent
        return out

    ca, cb = chain(a), chain(b)
    above_b = {x for x, _ in cb}
    joints = []
    meet = None
    for x, joint in ca:
        if x in above_b:
            meet = x
            break
        joints.append(joint)
    for x, joint in cb:
        if x == meet:
            break
        joints.append(joint)
    return [j for j in joints if j is not None]


@functools.lru_cache(maxsize=256)
def tree_of(sk: Skeleton) -> Tree:
    """The [`Tree`][jaxcrank.physics.topology.Tree] of a linkage's names.

    Raises:
        ParameterError: a loop of ideal joints (no clearance joint cuts it), or a driver on
            a body whose angle a prismatic joint holds.
    """
    _check_names(sk)
    adjacency: dict[str, list] = {b: [] for b in (*sk.bodies, GROUND)}
    for j, kind, a, b in _edges(sk, only_ideal=True):
        adjacency[a.body].append((j, kind, a, b))
        adjacency[b.body].append((j, kind, a, b))
    placed: dict[str, tuple | None] = {}  # body -> (parent, joint) or None for a root
    order: list[tuple[str, str, str | None, str | None]] = []  # body, kind, parent, joint
    used: set[str] = set()

    def walk(root: str, root_kind: str):
        placed[root] = None
        if root != GROUND:
            order.append((root, root_kind, None, None))
        queue = deque([root])
        while queue:
            x = queue.popleft()
            for j, kind, a, b in sorted(adjacency[x], key=lambda e: e[0]):
                if j in used:
                    continue
                used.add(j)
                other = b.body if a.body == x else a.body
                if other in placed:
                    loop = sorted({j, *_cycle(placed, x, other)})
                    raise ParameterError(
                        f"the loop through joints {', '.join(loop)} has no clearance joint and no closure: "
                        "give one of its joints a clearance law (the dynamics integrate a tree of ideal joints)"
                    )
                placed[other] = (x, j)
                order.append((other, kind, x, j))
                queue.append(other)

    walk(GROUND, "ground")
    # islands: bodies no ideal joint reaches from the ground float; the driven body, if
    # there, roots its island so its angle stays a coordinate of its own
    remaining = [b for b in sk.bodies if b not in placed]
    if sk.driver_body in remaining:
        remaining.remove(sk.driver_body)
        remaining.insert(0, sk.driver_body)
    for b in remaining:
        if b not in placed:
            walk(b, "floating")

    # coordinates numbered body by body in sorted body order (x, y, angle, slide within a
    # body), whatever the walk's order: the state layout follows the names alone
    own_names = {}
    for body, kind, _parent, joint in order:
        driven = body == sk.driver_body
        if kind == "floating":
            own_names[body] = ["x", "y"] + ([] if driven and sk.prescribed else ["angle"])
        elif kind == "revolute":
            own_names[body] = [] if driven and sk.prescribed else ["angle"]
        else:
            if driven:
                raise ParameterError(
                    f"the driver turns body {body!r}, whose angle its prismatic joint {joint!r} holds: "
                    "drive a body that turns"
                )
            own_names[body] = ["slide"]
    coordinates: list[tuple[str, str]] = []
    index: dict[tuple[str, str], int] = {}
    for body in sk.bodies:
        for name in own_names[body]:
            index[(body, name)] = len(coordinates)
            coordinates.append((body, name))
    placements = []
    for body, kind, parent, joint in order:
        idx = tuple(index[(body, name)] for name in own_names[body])
        placements.append(Placement(body, kind, parent, joint, idx, body == sk.driver_body))
    driver_coordinate = index.get((sk.driver_body, "angle"))
    ideal = dict(sk.ideal)
    cut = tuple(j for j, _, _, _ in sk.connections if not ideal[j])
    return Tree(
        bodies=sk.bodies,
        joints=tuple(j for j, *_ in sk.connections),
        placements=tuple(placements),
        coordinates=tuple(coordinates),
        cut=cut,
        driver_coordinate=driver_coordinate,
    )


@functools.lru_cache(maxsize=256)
def plan_of(sk: Skeleton) -> Plan:
    """The assembly [`Plan`][jaxcrank.physics.topology.Plan] of the ideal mechanism (every joint ideal).

    Raises:
        ParameterError: a linkage whose ideal mechanism cannot move with one degree of
            freedom (a count of bodies and joints that does not give mobility one).
    """
    _check_names(sk)
    conns = {j: (kind, a, b) for j, kind, a, b in sk.connections}
    mobility = 3 * len(sk.bodies) - 2 * len(conns)
    if mobility != 1:
        raise ParameterError(
            f"with every joint ideal the linkage has {mobility} degrees of freedom "
            f"({len(sk.bodies)} bodies, {len(conns)} joints): the driver needs exactly one"
        )
    pivot = next(
        j
        for j, (kind, a, b) in sorted(conns.items())
        if kind == "revolute" and {a.body, b.body} == {GROUND, sk.driver_body}
    )
    known = {GROUND, sk.driver_body}
    used = {pivot}
    steps = []

    def joints_between(x, y):
        return [j for j, (k, a, b) in sorted(conns.items()) if j not in used and {a.body, b.body} == {x, y}]

    def to_known(x):
        out = []
        for j, (k, a, b) in sorted(conns.items()):
            if j in used:
                continue
            if a.body == x and b.body in known:
                out.append((j, k, b.body))
            elif b.body == x and a.body in known:
                out.append((j, k, a.body))
        return out

    progress = True
    while progress:
        progress = False
        unknown = [b for b in sk.bodies if b not in known]
        for u in unknown:
            for v in unknown:
                if u == v:
                    continue
                middle = [j for j in joints_between(u, v) if conns[j][0] == "revolute"]
                outer = [(j, k, o) for j, k, o in to_known(u) if k == "revolute"]
                other = to_known(v)
                if not middle or not outer or not other:
                    continue
                j_other, k_other, _ = other[0]
                steps.append(Dyad("RRR" if k_other == "revolute" else "RRP", u, v, outer[0][0], middle[0], j_other))
                used.update({outer[0][0], middle[0], j_other})
                known.update({u, v})
                progress = True
                break
            if progress:
                break
    rest = tuple(b for b in sk.bodies if b not in known)
    constraints = tuple(j for j in sorted(conns) if j not in used)
    return Plan(sk.driver_body, pivot, tuple(steps), rest, constraints)


def check(lk: Linkage) -> None:
    """Check a linkage's description: names, the tree of its ideal joints, its ideal
    mechanism's mobility, and (with concrete values) that it can be assembled at the
    driver's initial angle.

    Raises:
        ParameterError: naming the problem: a joint on an unknown body or point, a law
            for the wrong kind of joint, a loop with no clearance joint, a driver on a
            body that is not attached to the ground, or a linkage that cannot be
            assembled at its start angle.
    """
    sk = Skeleton.of(lk)
    tree_of(sk)
    plan_of(sk)
    from .closure import check_assembly

    check_assembly(lk)
