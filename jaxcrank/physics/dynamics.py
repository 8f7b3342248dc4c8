"""Equations of motion of a mechanism with clearance joints (model.md, Eq. 14, for any
planar linkage).

Lagrange's ``J^T M J s'' = J^T (F - M gamma)`` on the tree's coordinates, with
Q the bodies' centre-of-mass poses, ``J = dQ/ds`` (its structurally nonzero entries),
``gamma = dJ/dt s'`` ([`jaxcrank.physics.kinematics.motion`][]) and M the bodies' masses
and inertias:
ideal-joint reactions drop out. F holds gravity, the driver's torque and the wrench of
every cut joint's law, which each joint's law gives from where the joint's two sides
are; the equations never look at a law's type. The generalised mass matrix is solved
by an LDL^T factorisation that skips the entries the tree makes zero
([`jaxcrank.physics.safemath.ldl_solve`][]). Everything is written on scalars
([`jaxcrank.physics.safemath`][]), so the entries a mechanism makes constant cost
nothing.

A prescribed driver's moment is the generalized force of its angle,
``J_phi^T (M Q'' - F)`` with ``J_phi = dQ/dphi`` at fixed coordinates (virtual work).
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .fusion import compute_once
from .joints import JointForces
from .kinematics import Motion, tree_joint_motion, tree_motion
from .linkage import GROUND, AbstractMechanism, Linkage
from .safemath import add, ldl_solve, mul, neg, sub, total, vcross, vsub
from .state import structure, tree_law_slices, tree_state_scales
from .topology import Tree


class Dynamics(NamedTuple):
    """What the equations of motion give at one instant (SI): the bodies'
    centre-of-mass poses Q (flattened, 3 per body) and their first two rates, the cut
    joints' forces (by joint name), the driving moment and dy/dt of the scaled state."""

    q: jax.Array
    qd: jax.Array
    qdd: jax.Array
    forces: dict
    driving_moment: jax.Array
    applied: jax.Array  # generalized forces on Q: gravity, the driver's torque and the joint wrenches
    state_rate: jax.Array


def _stack(values) -> Array:
    return jnp.stack([jnp.asarray(v, dtype=float) for v in values]) if len(values) else jnp.zeros(0)


def tree_masses(lk: Linkage, tree: Tree) -> list:
    """Masses and inertias of Q's entries, (m, m, J) per body, as scalars; kg, kg m^2."""
    out = []
    for b in tree.bodies:
        body = lk.bodies[b]
        out += [body.mass, body.mass, body.inertia]
    return out


def mass_vector(mech: AbstractMechanism) -> Float[Array, " 3bodies"]:
    """Masses and inertias of Q's entries, (m, m, J) per body; kg, kg m^2."""
    return _stack(tree_masses(*structure(mech)))


@functools.lru_cache(maxsize=256)
def _pattern(tree: Tree) -> tuple[tuple[bool, ...], ...]:
    """Which entries of the generalised mass matrix the tree lets be nonzero (static)."""
    rows = tree.rows()
    n = tree.n
    return tuple(tuple(bool(set(rows[i]) & set(rows[k])) for k in range(n)) for i in range(n))


def _add_wrench(applied: list, tree: Tree, q, body: str, force: tuple, point: tuple, moment):
    if body == GROUND:
        return
    i = tree.bodies.index(body)
    arm = vsub(point, (q[3 * i], q[3 * i + 1]))
    applied[3 * i] = add(applied[3 * i], force[0])
    applied[3 * i + 1] = add(applied[3 * i + 1], force[1])
    applied[3 * i + 2] = total([applied[3 * i + 2], vcross(arm, force), moment])


def tree_gravity(lk: Linkage, tree: Tree) -> list:
    """Generalized gravity forces on Q, per entry (N, N, N m per body)."""
    out = []
    for b in tree.bodies:
        out += [0.0, neg(mul(lk.bodies[b].mass, lk.gravity)), 0.0]
    return out


def gravity_forces(mech: AbstractMechanism) -> list:
    """Generalized gravity forces on Q, per entry (N, N, N m per body)."""
    return tree_gravity(*structure(mech))


def tree_joint_forces(lk: Linkage, tree: Tree, q, qd, law_state, rots=None) -> dict[str, JointForces]:
    """[`joint_forces`][jaxcrank.physics.dynamics.joint_forces] for Q and dQ/dt as sequences of scalars
    (``rots``: the bodies' rotations by name, when known)."""
    slices = tree_law_slices(lk, tree)
    n2 = 2 * tree.n
    out = {}
    for j in tree.cut:
        kin, _ = tree_joint_motion(lk, tree, j, q, qd, rots=rots)
        sl = slices[j]
        out[j] = lk.joints[j].forces(kin, law_state[sl.start - n2 : sl.stop - n2])
    return out


def joint_forces(mech: AbstractMechanism, q, qd, law_state) -> dict[str, JointForces]:
    """Every cut joint's [`JointForces`][jaxcrank.physics.joints.JointForces] (by name) for Q, dQ/dt and the law
    states (SI, the state's law entries)."""
    return tree_joint_forces(*structure(mech), q, qd, law_state)


def _pair(v) -> tuple:
    return v[0], v[1]


def tree_applied(lk: Linkage, tree: Tree, q, forces: dict) -> list:
    """[`applied_forces`][jaxcrank.physics.dynamics.applied_forces] as a list of scalars."""
    applied = tree_gravity(lk, tree)
    for j, f in forces.items():
        hole, pin = lk.connections[j].sites()
        force = _pair(f.force)
        _add_wrench(applied, tree, q, pin.body, force, _pair(f.pin_point), f.pin_moment)
        _add_wrench(applied, tree, q, hole.body, (neg(force[0]), neg(force[1])), _pair(f.hole_point), f.hole_moment)
    if not lk.driver.prescribed:
        i = tree.bodies.index(lk.driver.body)
        applied[3 * i + 2] = add(applied[3 * i + 2], lk.driver.torque)
    return applied


def applied_forces(mech: AbstractMechanism, q, qd, forces: dict) -> Array:
    """Generalized forces on Q: gravity, a torque driver's torque, and each cut joint's wrench."""
    return _stack(tree_applied(*structure(mech), q, forces))


def driver_jacobian(mech: AbstractMechanism, s, t) -> Array:
    """dQ/dphi at fixed tree coordinates (zeros for a torque driver, whose angle is a coordinate)."""
    lk, tree = structure(mech)
    zero = [0.0] * tree.n
    mo = tree_motion(lk, tree, [s[k] for k in range(tree.n)], zero, jnp.asarray(t, dtype=float))
    return _stack([mo.driver_jacobian.get(r, 0.0) for r in range(3 * len(tree.bodies))])


def driver_speed(mech: AbstractMechanism, s, sd, t) -> Array:
    """d(phi)/dt of the driver, rad/s."""
    lk, tree = structure(mech)
    if lk.driver.prescribed:
        t = jnp.asarray(t, dtype=float)
        return jax.jvp(lk.driver.angle, (t,), (jnp.ones_like(t),))[1]
    return jax.lax.stop_gradient(jnp.asarray(lk.driver.speed_scale, dtype=float)) + sd[tree.driver_coordinate]


class Terms(NamedTuple):
    """The equations of motion at one instant as scalars (lists over Q's entries), with
    the [`Motion`][jaxcrank.physics.kinematics.Motion] they came from: what
    [`jaxcrank.physics.frame.evaluate`][] reuses."""

    motion: Motion
    qdd: list
    applied: list
    forces: dict
    driving_moment: object
    state_rate: Array


def tree_dynamics(lk: Linkage, tree: Tree, t, y) -> Terms:
    """The equations of motion of a linkage and its tree at time t (s) for the scaled state y."""
    n = tree.n
    scale = _stack(tree_state_scales(lk, tree))
    phys = y * scale
    law_state = phys[2 * n : -2]
    mo = tree_motion(lk, tree, [phys[k] for k in range(n)], [phys[n + k] for k in range(n)], t)
    q, gamma = mo.q, mo.gamma
    rots = {b: st.frame.rot for b, st in mo.states.items()}
    mass = tree_masses(lk, tree)
    forces = tree_joint_forces(lk, tree, q, mo.qd, law_state, rots)
    applied = tree_applied(lk, tree, q, forces)

    residual = [sub(a, mul(m, g)) for a, m, g in zip(applied, mass, gamma)]
    by_column = {i: [(r, v) for (r, k), v in mo.jacobian.items() if k == i] for i in range(n)}
    pattern = _pattern(tree)
    lhs = [[0.0] * n for _ in range(n)]
    for i in range(n):
        for k in range(i, n):
            if pattern[i][k]:
                col_k = dict(by_column[k])
                terms = [mul(mul(v, mass[r]), col_k[r]) for r, v in by_column[i] if r in col_k]
                lhs[i][k] = lhs[k][i] = total(terms)
    rhs = [total([mul(v, residual[r]) for r, v in by_column[i]]) for i in range(n)]
    sdd = ldl_solve(lambda i, k: lhs[i][k], rhs, pattern)
    qdd = list(gamma)
    for (r, k), v in mo.jacobian.items():
        qdd[r] = add(qdd[r], mul(v, sdd[k]))

    slices = tree_law_slices(lk, tree)
    law_rates = []
    for j in tree.cut:
        kin, acc = tree_joint_motion(lk, tree, j, q, mo.qd, qdd, rots)
        law_rates.append(lk.joints[j].state_rate(kin, acc, phys[slices[j]], forces[j]))

    if lk.driver.prescribed:
        moment = total([mul(v, sub(mul(mass[r], qdd[r]), applied[r])) for r, v in mo.driver_jacobian.items()])
    else:
        moment = lk.driver.torque
    dissipation = total([f.dissipation for f in forces.values()])
    rate = jnp.concatenate(
        [phys[n : 2 * n], _stack(sdd), *law_rates, _stack([mul(moment, mo.driver_speed), dissipation])]
    )
    return Terms(mo, qdd, applied, forces, moment, rate / scale)


def dynamics(mech: AbstractMechanism, t: Float[ArrayLike, ""], y: Float[ArrayLike, " state"]) -> Dynamics:
    """The equations of motion at time t (s) for scaled state y: only what dy/dt
    needs ([`jaxcrank.physics.frame.evaluate`][] adds the output-only quantities)."""
    lk, tree = structure(mech)
    e = tree_dynamics(lk, tree, jnp.asarray(t, dtype=float), y)
    mo = e.motion
    moment = jnp.asarray(e.driving_moment, dtype=float)
    return Dynamics(_stack(mo.q), _stack(mo.qd), _stack(e.qdd), e.forces, moment, _stack(e.applied), e.state_rate)


@jax.jit
def vector_field(
    t: Float[ArrayLike, ""], y: Float[ArrayLike, " state"], mech: AbstractMechanism
) -> Float[Array, " state"]:
    """dy/dt of the scaled state ``y`` (shape (state_size,)) at time ``t`` (s), for
    diffrax: ``diffrax.ODETerm(vector_field)`` with ``args=mech``.

    Jitted, so a solve holds one call of the field per solver stage, which JAX
    linearizes and transposes once (shorter compiles of gradients); XLA inlines it,
    computing each value the equations share once ([`jaxcrank.physics.fusion`][]).
    """
    lk, tree = structure(mech)
    return compute_once(lambda t_, y_: tree_dynamics(lk, tree, t_, y_).state_rate, jnp.asarray(t, dtype=float), y)
