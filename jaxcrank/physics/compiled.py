"""The compiled model: a mechanism's description turned, in one step, into what every stage
of a solve reads.

[`compile_model`][jaxcrank.physics.compiled.compile_model] writes the mechanism out as a
[`Linkage`][jaxcrank.physics.linkage.Linkage], works out its static structure from the names
([`Structure`][jaxcrank.physics.compiled.Structure]: the tree of the equations of motion,
the ideal mechanism's assembly plan, the state layout) and checks it, chooses the ideal
mechanism's assembly (each dyad's branch, the warm starts of its root finds) and checks
that it assembles over a turn. The [`Model`][jaxcrank.physics.compiled.Model] holds the
structure beside the numbers: the numbers are pytree leaves (differentiable, sweepable,
values of a compiled program), the structure is static. As MuJoCo compiles a model and
Drake finalizes a plant, every stage (state, kinematics, dynamics, outputs, solves) takes
a model; a function that takes a mechanism compiles it first
([`as_model`][jaxcrank.physics.compiled.as_model]).
"""

from __future__ import annotations

import dataclasses
import functools
from typing import NamedTuple

import equinox as eqx
import jax
import numpy as np

from . import assembly, closure
from .joints import AbstractJointLaw
from .linkage import AbstractMechanism, Linkage
from .params import ParameterError, _concrete
from .planner import structure_of
from .topology import Dyad, Group, Plan, Skeleton, Tree


@dataclasses.dataclass(frozen=True)
class Structure:
    """A linkage's static structure, from its names alone (hashable).

    Attributes:
        skeleton: the names ([`Skeleton`][jaxcrank.physics.topology.Skeleton]).
        tree: the tree of the equations of motion ([`Tree`][jaxcrank.physics.topology.Tree]).
        plan: the ideal mechanism's assembly plan ([`Plan`][jaxcrank.physics.topology.Plan]).
    """

    skeleton: Skeleton
    tree: Tree
    plan: Plan

    @property
    def n(self) -> int:
        """Number of generalized coordinates s."""
        return self.tree.n

    @functools.cached_property
    def law_slices(self) -> dict[str, slice]:
        """Where each cut joint's law state sits in the state vector."""
        states = dict(self.skeleton.law_states)
        start, out = 2 * self.tree.n, {}
        for j in self.tree.cut:
            out[j] = slice(start, start + len(states[j]))
            start += len(states[j])
        return out

    @functools.cached_property
    def law_state_names(self) -> tuple[str, ...]:
        """Names of the law state entries, ``<joint>.<entry>`` in state order."""
        states = dict(self.skeleton.law_states)
        return tuple(f"{j}.{name}" for j in self.tree.cut for name in states[j])

    @property
    def state_size(self) -> int:
        """Length of the state vector: s, s', the law states, two works."""
        return 2 * self.tree.n + len(self.law_state_names) + 2

    @functools.cached_property
    def state_names(self) -> tuple[str, ...]:
        """A name for every state entry: ``<body>.<coordinate>``, ``d/dt <body>.<coordinate>``,
        ``<joint>.<law entry>``, ``driver_work``, ``dissipated_work``."""
        coords = [f"{b}.{k}" for b, k in self.tree.coordinates]
        return (*coords, *(f"d/dt {c}" for c in coords), *self.law_state_names, "driver_work", "dissipated_work")

    @functools.cached_property
    def ideal_joints(self) -> tuple[str, ...]:
        """The joints whose law is ideal, sorted."""
        return tuple(j for j in self.tree.joints if j not in self.tree.cut)


class Joint(NamedTuple):
    """One joint of a compiled model: its geometry and its law together.

    Attributes:
        name: the joint's name.
        connection: where it sits ([`Revolute`][jaxcrank.physics.linkage.Revolute] or
            [`Prismatic`][jaxcrank.physics.linkage.Prismatic]).
        law: what it does ([`AbstractJointLaw`][jaxcrank.physics.joints.AbstractJointLaw]).
    """

    name: str
    connection: object
    law: AbstractJointLaw

    @property
    def kind(self) -> str:
        return self.connection.kind

    @property
    def ideal(self) -> bool:
        return bool(self.law.ideal)


class Model(eqx.Module):
    """A compiled mechanism ([`compile_model`][jaxcrank.physics.compiled.compile_model]).

    Attributes:
        mechanism: the description compiled; its numbers are the model's parameters (SI).
        branches: the ideal mechanism's dyads' branches (+1 or -1), in the order of
            ``structure.plan.dyads``, then the branches of the dyads that close loops in the
            equations of motion, in the order of the tree's dyads (those of the ideal
            mechanism at the driver's initial angle): while they are traced (chosen from
            traced guesses); else ``()``.
        guesses: per group of the assembly plan, its bodies' poses over one turn (the warm
            starts of its root find), stop-gradient.
        structure: the static structure ([`Structure`][jaxcrank.physics.compiled.Structure]).
        known_branches: the branches where they are numbers (static, so that a program
            that uses them is made for them), else ``None``.
    """

    mechanism: AbstractMechanism
    branches: tuple
    guesses: tuple
    structure: Structure = eqx.field(static=True)
    known_branches: tuple | None = eqx.field(static=True, default=None)

    @property
    def signs(self) -> tuple:
        """The ideal mechanism's dyads' branches (+1 or -1), in the order of ``plan.dyads``."""
        every = self.branches if self.known_branches is None else self.known_branches
        return tuple(every[: len(self.plan.dyads)])

    @property
    def tree_signs(self) -> tuple:
        """The branches of the tree's dyads, in their order."""
        every = self.branches if self.known_branches is None else self.known_branches
        return tuple(every[len(self.plan.dyads) :])

    @functools.cached_property
    def linkage(self) -> Linkage:
        """The mechanism written out body by body (made from ``mechanism`` once per model
        instance, where it is used: the numbers a description fixes, such as the zeros of
        points on a body's axis, stay numbers in a traced program)."""
        return self.mechanism.linkage()

    @property
    def tree(self) -> Tree:
        return self.structure.tree

    @property
    def plan(self) -> Plan:
        return self.structure.plan

    @property
    def driver(self):
        return self.mechanism.driver

    @property
    def period(self):
        """Time of one revolution of the driven body at its nominal speed, s."""
        return self.mechanism.period

    @property
    def speed(self):
        """Nominal angular speed of the driven body, rad/s."""
        return self.mechanism.speed

    @property
    def joints(self) -> dict[str, Joint]:
        """Every joint ([`Joint`][jaxcrank.physics.compiled.Joint]) by name, sorted."""
        lk = self.linkage
        return {j: Joint(j, lk.connections[j], lk.joints[j]) for j in self.tree.joints}

    def joint(self, name: str) -> Joint:
        """The joint ``name`` ([`Joint`][jaxcrank.physics.compiled.Joint])."""
        lk = self.linkage
        return Joint(name, lk.connections[name], lk.joints[name])


def _concrete_values(lk: Linkage) -> tuple | None:
    """The linkage's values as a hashable tuple, or None while any is traced."""
    out = []
    for leaf in jax.tree_util.tree_leaves(lk):
        value = _concrete(leaf)
        if value is None:
            return None
        value = np.asarray(value, dtype=float)
        out.append(float(value) if value.ndim == 0 else (value.shape, tuple(np.ravel(value))))
    return tuple(out)


def _check_branches(lk: Linkage, plan: Plan) -> None:
    middles = {d.middle for d in plan.dyads if d.kind != "PRP"}
    for j, conn in sorted(lk.connections.items()):
        if conn.branch is not None and j not in middles:
            where = f"it can be set at: {', '.join(sorted(middles))}" if middles else "this linkage has no such joint"
            raise ParameterError(
                f"joint {j!r} sets branch = {conn.branch!r}, but no two links of the ideal mechanism meet there "
                f"in a way that can be assembled two ways ({where})"
            )


def _assembly(lk: Linkage, structure: Structure) -> tuple[tuple, tuple, tuple]:
    """(signs, tree_signs, guesses) of a linkage (see [`Model`][jaxcrank.physics.compiled.Model])."""
    plan, tree = structure.plan, structure.tree
    signs, guesses, done = [], [], []
    for step in plan.steps:  # in order: a group's warm starts follow the branches before it
        done.append(step)
        if isinstance(step, Group):
            guesses.append(assembly.group_guesses(lk, plan, step, tuple(signs), tuple(guesses)))
        else:
            head = Plan(plan.driven, plan.pivot, tuple(done))
            signs.append(closure.branch_signs(lk, head, tuple(guesses))[-1])
    tree_dyads = [c for c in tree.closures if isinstance(c, Dyad)]
    tree_signs = ()
    if tree_dyads:
        frames = closure.ideal_frames(lk, plan, lk.driver.initial_angle, tuple(signs), tuple(guesses))
        tree_signs = tuple(closure.branch(lk, frames, d) for d in tree_dyads)
    return tuple(signs), tree_signs, tuple(guesses)


_CACHE: dict = {}


def compile_model(mech: AbstractMechanism | Model) -> Model:
    """Compile a mechanism: its linkage, its structure and its assembly
    ([`Model`][jaxcrank.physics.compiled.Model]); a model is returned as it is.

    Traceable in the mechanism's values (under ``jax.jit``, ``jax.vmap``, ``jax.grad``);
    with values known (not traced) it also checks that the linkage assembles at its
    driver's initial angle and, for a prescribed driver, over a whole turn.

    Raises:
        ParameterError: naming the problem: a loop of ideal joints that fixes its bodies
            twice over, a driver on a body not pivoted on the ground or whose angle a
            prismatic joint holds, an ideal mechanism without one degree of freedom, a
            ``branch`` on a joint where no dyad meets, a group of bodies without guess
            poses, or a linkage that cannot be assembled.
    """
    if isinstance(mech, Model):
        return mech
    lk = mech.linkage()
    sk = Skeleton.of(lk)
    tree, plan = structure_of(sk)
    structure = Structure(sk, tree, plan)
    _check_branches(lk, plan)
    values = _concrete_values(lk)
    key = None if values is None else (sk, jax.tree_util.tree_structure(lk), values)
    if key is None or key not in _CACHE:
        signs, tree_signs, guesses = _assembly(lk, structure)
        branches = (*signs, *tree_signs)
        if key is None:
            return Model(mech, branches, guesses, structure)
        assembly.check_assembly(lk, plan, signs)
        if len(_CACHE) > 1024:
            _CACHE.clear()
        _CACHE[key] = (tuple(float(b) for b in branches), guesses)
    branches, guesses = _CACHE[key]
    return Model(mech, (), guesses, structure, known_branches=branches)


def as_model(mech: AbstractMechanism | Model) -> Model:
    """``mech`` compiled ([`compile_model`][jaxcrank.physics.compiled.compile_model]), or the model itself."""
    return mech if isinstance(mech, Model) else compile_model(mech)
