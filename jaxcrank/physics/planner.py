"""Making a linkage's structures ([`jaxcrank.physics.topology`][]) from its names: the tree
of the equations of motion ([`tree_of`][jaxcrank.physics.planner.tree_of]) and the ideal
mechanism's assembly plan ([`plan_of`][jaxcrank.physics.planner.plan_of]).

Both place bodies step by step from the bodies already placed. A closure comes first
wherever one exists: a dyad in closed form, else the smallest group of bodies that its
ideal joints hold fast (three freedoms per body, two equations per joint). The tree then
takes tree steps, breadth first from the ground, and floats the bodies no ideal joint
reaches; the plan has no coordinate to give, so what closures cannot place is an error.
Taking every closure before any tree step never fixes a body twice over: a tree step
gives a coordinate to a body that no zero-freedom set of bodies could place.
"""

from __future__ import annotations

import functools
import itertools

from .linkage import GROUND
from .params import ParameterError
from .topology import Closure, Dyad, Group, Placement, Plan, Skeleton, Tree

#: the largest group a root find closes (bodies); larger sets are searched no further
MAX_GROUP = 8


def _check_grounded_driver(sk: Skeleton) -> str:
    """The driven body's revolute joint to the ground (the first by name).

    Raises:
        ParameterError: a driver on a body with no revolute joint to the ground.
    """
    for j, kind, a, b in sk.connections:
        if kind == "revolute" and {a.body, b.body} == {GROUND, sk.driver_body}:
            return j
    raise ParameterError(
        f"the driver is on body {sk.driver_body!r}, which is not attached to the ground by a revolute joint: "
        "drive a body that turns about a ground pivot"
    )


class _Planner:
    """Places bodies step by step over the joints ``usable`` (see the module docstring)."""

    def __init__(self, sk: Skeleton, usable: set[str], known: list[str], exclude: set[str]):
        self.sk = sk
        self.kinds = {j: k[0].upper() for j, k, *_ in sk.connections}
        self.ends = {j: (a.body, b.body) for j, _, a, b in sk.connections}
        self.unused = set(usable)
        self.known = list(known)  # in the order they were placed (the breadth-first queue)
        self.exclude = exclude  # bodies no closure may place (the driven body)

    def unknown(self) -> list[str]:
        return [b for b in self.sk.bodies if b not in self.known]

    def _between(self, x: str, y: str) -> list[str]:
        return [j for j in sorted(self.unused) if set(self.ends[j]) == {x, y} and x != y]

    def _to_known(self, x: str) -> list[str]:
        return [j for j in sorted(self.unused) if x in self.ends[j] and self._far(j, x) in self.known]

    def _far(self, joint: str, x: str) -> str:
        a, b = self.ends[joint]
        return b if a == x else a

    def over_constrained(self) -> None:
        """Raise where an unplaced body is held to placed ones by more joints than it has
        freedoms (two or more ideal joints, or one prismatic joint and a driver)."""
        for x in self.unknown():
            held = self._to_known(x)
            if len(held) >= 2:
                raise ParameterError(
                    f"body {x!r} is held by joints {', '.join(held)}, which fix it twice over (an over-constrained "
                    "loop of ideal joints): give one of them a clearance law"
                )

    def dyad(self) -> Dyad | None:
        """The first dyad (in the order of the names) that closes in closed form."""
        unknown = [b for b in self.unknown() if b not in self.exclude]
        # (outer, middle, other) kinds by preference: RRR / RRP, then RPR, then PRP
        for wanted in (("R", "R", None), ("R", "P", "R"), ("P", "R", "P")):
            for u, v in itertools.permutations(unknown, 2):
                for middle in self._between(u, v):
                    if self.kinds[middle] != wanted[1]:
                        continue
                    outers = [j for j in self._to_known(u) if self.kinds[j] == wanted[0]]
                    others = [j for j in self._to_known(v) if wanted[2] is None or self.kinds[j] == wanted[2]]
                    if not outers or not others:
                        continue
                    outer, other = outers[0], others[0]
                    kind = wanted[0] + wanted[1] + self.kinds[other]
                    if kind == "RPR" and self._guide_body(middle) != u:
                        continue  # the same dyad comes with the guide's body first
                    parents = tuple(sorted({self._far(outer, u), self._far(other, v)}))
                    return Dyad(kind, u, v, outer, middle, other, parents)
        return None

    def _guide_body(self, joint: str) -> str:
        return self.ends[joint][0]  # a prismatic joint's sites: guide, then slider

    def group(self) -> Group | None:
        """The smallest set of unplaced bodies that its unused ideal joints hold fast to
        the placed bodies (three freedoms per body, two equations per joint)."""
        unknown = [b for b in self.unknown() if b not in self.exclude]
        for size in range(2, min(len(unknown), MAX_GROUP) + 1, 2):
            for bodies in itertools.combinations(unknown, size):
                inside = set(bodies)
                joints = [
                    j
                    for j in sorted(self.unused)
                    if set(self.ends[j]) & inside and set(self.ends[j]) <= inside | set(self.known)
                ]
                if 3 * size == 2 * len(joints) and self._connected(inside, joints):
                    parents = {e for j in joints for e in self.ends[j]} - inside
                    return Group(bodies, tuple(joints), tuple(sorted(parents)))
        return None

    def _connected(self, inside: set[str], joints: list[str]) -> bool:
        start = next(iter(sorted(inside)))
        seen, todo = {start}, [start]
        while todo:
            x = todo.pop()
            for j in joints:
                if x in self.ends[j]:
                    y = self._far(j, x)
                    if y in inside and y not in seen:
                        seen.add(y)
                        todo.append(y)
        return seen == inside

    def place(self, closure: Closure) -> None:
        self.unused -= set(closure.joints)
        self.known += list(closure.bodies)

    def tree_step(self) -> tuple[str, str, str] | None:
        """(body, joint, parent): the first unused ideal joint from a placed body (in the
        order they were placed) to an unplaced one, breadth first."""
        for x in self.known:
            for j in sorted(self.unused):
                if x in self.ends[j]:
                    y = self._far(j, x)
                    if y not in self.known:
                        self.unused.discard(j)
                        self.known.append(y)
                        return y, j, x
        return None


@functools.lru_cache(maxsize=256)
def tree_of(sk: Skeleton) -> Tree:
    """The [`Tree`][jaxcrank.physics.topology.Tree] of a linkage's names.

    Raises:
        ParameterError: a driver on a body whose angle a prismatic joint holds, or a loop
            of ideal joints that fixes a body twice over.
    """
    _check_grounded_driver(sk)
    ideal = {j for j, is_ideal in sk.ideal if is_ideal}
    planner = _Planner(sk, ideal, [GROUND], exclude={sk.driver_body})
    steps: list = []  # ("tree", body, joint, parent) | ("floating", body) | closure
    pivot = next((j for j in planner._to_known(sk.driver_body) if sk.kind(j) == "revolute"), None)
    if pivot is not None:  # the driven body on its ideal ground pivot: placed first, from its angle alone
        planner.unused.discard(pivot)
        planner.known.append(sk.driver_body)
        steps.append(("tree", sk.driver_body, pivot, GROUND))
    while planner.unknown():
        planner.over_constrained()
        closure = planner.dyad() or planner.group()
        if closure is not None:
            planner.place(closure)
            steps.append(closure)
            continue
        step = planner.tree_step()
        if step is not None:
            steps.append(("tree", *step))
            continue
        unknown = planner.unknown()
        root = sk.driver_body if sk.driver_body in unknown else unknown[0]
        planner.known.append(root)
        steps.append(("floating", root))
    if planner.unused:
        raise ParameterError(
            f"joints {', '.join(sorted(planner.unused))} close a loop of ideal joints that fixes its bodies twice over "
            "(an over-constrained loop): give one of them a clearance law"
        )

    own_names: dict[str, list[str]] = {}
    kinds: dict[str, str] = {}
    for step in steps:
        if isinstance(step, (Dyad, Group)):
            for b in step.bodies:
                own_names[b], kinds[b] = [], "closed"
            continue
        body = step[1]
        driven = body == sk.driver_body
        if step[0] == "floating":
            own_names[body] = ["x", "y"] + ([] if driven and sk.prescribed else ["angle"])
            kinds[body] = "floating"
        elif sk.kind(step[2]) == "revolute":
            own_names[body] = [] if driven and sk.prescribed else ["angle"]
            kinds[body] = "revolute"
        else:
            if driven:
                raise ParameterError(
                    f"the driver turns body {body!r}, whose angle its prismatic joint {step[2]!r} holds: "
                    "drive a body that turns"
                )
            own_names[body] = ["slide"]
            kinds[body] = "prismatic"
    coordinates: list[tuple[str, str]] = []
    index: dict[tuple[str, str], int] = {}
    for body in sk.bodies:
        for name in own_names[body]:
            index[(body, name)] = len(coordinates)
            coordinates.append((body, name))

    def placement(body, parent=None, joint=None):
        idx = tuple(index[(body, name)] for name in own_names[body])
        return Placement(body, kinds[body], parent, joint, idx, body == sk.driver_body)

    placements, order = [], []
    for step in steps:
        if isinstance(step, (Dyad, Group)):
            placements += [placement(b) for b in step.bodies]
            order.append(step)
        else:
            p = placement(step[1], *(step[3:1:-1] if step[0] == "tree" else ()))
            placements.append(p)
            order.append(p)
    ideal_flags = dict(sk.ideal)
    return Tree(
        bodies=sk.bodies,
        joints=tuple(j for j, *_ in sk.connections),
        placements=tuple(placements),
        coordinates=tuple(coordinates),
        cut=tuple(j for j, *_ in sk.connections if not ideal_flags[j]),
        driver_coordinate=index.get((sk.driver_body, "angle")),
        steps=tuple(order),
    )


@functools.lru_cache(maxsize=256)
def plan_of(sk: Skeleton) -> Plan:
    """The assembly [`Plan`][jaxcrank.physics.topology.Plan] of the ideal mechanism (every joint ideal).

    Raises:
        ParameterError: a linkage whose ideal mechanism cannot move with one degree of
            freedom (a count of bodies and joints that does not give mobility one), or
            that dyads and groups cannot assemble from the driver's angle.
    """
    pivot = _check_grounded_driver(sk)
    joints = [j for j, *_ in sk.connections]
    mobility = 3 * len(sk.bodies) - 2 * len(joints)
    if mobility != 1:
        raise ParameterError(
            f"with every joint ideal the linkage has {mobility} degrees of freedom "
            f"({len(sk.bodies)} bodies, {len(joints)} joints): the driver needs exactly one"
        )
    planner = _Planner(sk, set(joints) - {pivot}, [GROUND, sk.driver_body], exclude=set())
    steps = []
    while planner.unknown():
        planner.over_constrained()
        closure = planner.dyad() or planner.group()
        if closure is None:
            raise ParameterError(
                f"bodies {', '.join(planner.unknown())} cannot be placed from the driver's angle: with every joint "
                "ideal they are not held fast by the bodies before them (a loop with freedom of its own)"
            )
        planner.place(closure)
        steps.append(closure)
    return Plan(sk.driver_body, pivot, tuple(steps))


def structure_of(sk: Skeleton) -> tuple[Tree, Plan]:
    """The [`Tree`][jaxcrank.physics.topology.Tree] and the [`Plan`][jaxcrank.physics.topology.Plan] of a
    linkage's names (cached).

    Raises:
        ParameterError: see [`tree_of`][jaxcrank.physics.planner.tree_of] and
            [`plan_of`][jaxcrank.physics.planner.plan_of].
    """
    return tree_of(sk), plan_of(sk)
