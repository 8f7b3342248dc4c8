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

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .compiled import Model, as_model
from .fusion import compute_once
from .joints import JointForces
from .kinematics import Motion, joint_motion, motion
from .linkage import GROUND, AbstractMechanism
from .safemath import add, ldl_solve, mul, neg, sub, total, vcross, vsub
from .state import scales
from .topology import Tree

Mechanism = AbstractMechanism | Model


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


def masses(model: Model) -> list:
    """Masses and inertias of Q's entries, (m, m, J) per body, as scalars; kg, kg m^2."""
    out = []
    for b in model.tree.bodies:
        body = model.linkage.bodies[b]
        out += [body.mass, body.mass, body.inertia]
    return out


def mass_vector(model: Mechanism) -> Float[Array, " 3bodies"]:
    """Masses and inertias of Q's entries, (m, m, J) per body; kg, kg m^2."""
    return _stack(masses(as_model(model)))


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


def gravity_forces(model: Mechanism) -> list:
    """Generalized gravity forces on Q, per entry (N, N, N m per body), as scalars."""
    model = as_model(model)
    out = []
    for b in model.tree.bodies:
        out += [0.0, neg(mul(model.linkage.bodies[b].mass, model.linkage.gravity)), 0.0]
    return out


def joint_forces(model: Mechanism, q, qd, law_state, rots=None) -> dict[str, JointForces]:
    """Every cut joint's [`JointForces`][jaxcrank.physics.joints.JointForces] (by name) for Q, dQ/dt (arrays
    or sequences of scalars) and the law states (SI, the state's law entries); ``rots``:
    the bodies' rotations by name, when known."""
    model = as_model(model)
    slices = model.structure.law_slices
    n2 = 2 * model.tree.n
    out = {}
    for j in model.tree.cut:
        kin, _ = joint_motion(model, j, q, qd, rots=rots)
        sl = slices[j]
        out[j] = model.linkage.joints[j].forces(kin, law_state[sl.start - n2 : sl.stop - n2])
    return out


def _pair(v) -> tuple:
    return v[0], v[1]


def applied(model: Model, q, forces: dict) -> list:
    """[`applied_forces`][jaxcrank.physics.dynamics.applied_forces] as a list of scalars."""
    lk, tree = model.linkage, model.tree
    out = gravity_forces(model)
    for j, f in forces.items():
        hole, pin = lk.connections[j].sites()
        force = _pair(f.force)
        _add_wrench(out, tree, q, pin.body, force, _pair(f.pin_point), f.pin_moment)
        _add_wrench(out, tree, q, hole.body, (neg(force[0]), neg(force[1])), _pair(f.hole_point), f.hole_moment)
    if not lk.driver.prescribed:
        i = tree.bodies.index(lk.driver.body)
        out[3 * i + 2] = add(out[3 * i + 2], lk.driver.torque)
    return out


def applied_forces(model: Mechanism, q, qd, forces: dict) -> Array:
    """Generalized forces on Q: gravity, a torque driver's torque, and each cut joint's wrench."""
    return _stack(applied(as_model(model), q, forces))


def driver_jacobian(model: Mechanism, s, t) -> Array:
    """dQ/dphi at fixed tree coordinates (zeros for a torque driver, whose angle is a coordinate)."""
    model = as_model(model)
    zero = [0.0] * model.tree.n
    mo = motion(model, [s[k] for k in range(model.tree.n)], zero, jnp.asarray(t, dtype=float))
    return _stack([mo.driver_jacobian.get(r, 0.0) for r in range(3 * len(model.tree.bodies))])


def driver_speed(model: Mechanism, s, sd, t) -> Array:
    """d(phi)/dt of the driver, rad/s."""
    model = as_model(model)
    lk = model.linkage
    if lk.driver.prescribed:
        t = jnp.asarray(t, dtype=float)
        return jax.jvp(lk.driver.angle, (t,), (jnp.ones_like(t),))[1]
    return jax.lax.stop_gradient(jnp.asarray(lk.driver.speed_scale, dtype=float)) + sd[model.tree.driver_coordinate]


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


def terms(model: Model, t, y) -> Terms:
    """The equations of motion of a compiled model at time t (s) for the scaled state y."""
    lk, tree = model.linkage, model.tree
    n = tree.n
    scale = _stack(scales(model))
    phys = y * scale
    law_state = phys[2 * n : -2]
    mo = motion(model, [phys[k] for k in range(n)], [phys[n + k] for k in range(n)], t)
    q, gamma = mo.q, mo.gamma
    rots = {b: st.frame.rot for b, st in mo.states.items()}
    mass = masses(model)
    forces = joint_forces(model, q, mo.qd, law_state, rots)
    applied_ = applied(model, q, forces)

    residual = [sub(a, mul(m, g)) for a, m, g in zip(applied_, mass, gamma)]
    by_column = {i: [(r, v) for (r, k), v in mo.jacobian.items() if k == i] for i in range(n)}
    pattern = _pattern(tree)
    lhs = [[0.0] * n for _ in range(n)]
    for i in range(n):
        for k in range(i, n):
            if pattern[i][k]:
                col_k = dict(by_column[k])
                products = [mul(mul(v, mass[r]), col_k[r]) for r, v in by_column[i] if r in col_k]
                lhs[i][k] = lhs[k][i] = total(products)
    rhs = [total([mul(v, residual[r]) for r, v in by_column[i]]) for i in range(n)]
    sdd = ldl_solve(lambda i, k: lhs[i][k], rhs, pattern)
    qdd = list(gamma)
    for (r, k), v in mo.jacobian.items():
        qdd[r] = add(qdd[r], mul(v, sdd[k]))

    slices = model.structure.law_slices
    law_rates = []
    for j in tree.cut:
        kin, acc = joint_motion(model, j, q, mo.qd, qdd, rots)
        law_rates.append(lk.joints[j].state_rate(kin, acc, phys[slices[j]], forces[j]))

    if lk.driver.prescribed:
        moment = total([mul(v, sub(mul(mass[r], qdd[r]), applied_[r])) for r, v in mo.driver_jacobian.items()])
    else:
        moment = lk.driver.torque
    dissipation = total([f.dissipation for f in forces.values()])
    rate = jnp.concatenate(
        [phys[n : 2 * n], _stack(sdd), *law_rates, _stack([mul(moment, mo.driver_speed), dissipation])]
    )
    return Terms(mo, qdd, applied_, forces, moment, rate / scale)


def dynamics(model: Mechanism, t: Float[ArrayLike, ""], y: Float[ArrayLike, " state"]) -> Dynamics:
    """The equations of motion at time t (s) for scaled state y: only what dy/dt
    needs ([`jaxcrank.physics.frame.evaluate`][] adds the output-only quantities)."""
    model = as_model(model)
    e = terms(model, jnp.asarray(t, dtype=float), y)
    mo = e.motion
    moment = jnp.asarray(e.driving_moment, dtype=float)
    return Dynamics(_stack(mo.q), _stack(mo.qd), _stack(e.qdd), e.forces, moment, _stack(e.applied), e.state_rate)


@eqx.filter_jit
def vector_field(t: Float[ArrayLike, ""], y: Float[ArrayLike, " state"], model: Model) -> Float[Array, " state"]:
    """dy/dt of the scaled state ``y`` (shape (state_size,)) at time ``t`` (s), for
    diffrax: ``diffrax.ODETerm(vector_field)`` with ``args=model`` (a compiled
    [`Model`][jaxcrank.physics.compiled.Model]).

    Jitted, so a solve holds one call of the field per solver stage, which JAX
    linearizes and transposes once (shorter compiles of gradients); XLA inlines it,
    computing each value the equations share once ([`jaxcrank.physics.fusion`][]).
    """
    model = as_model(model)
    _ = model.linkage  # written out here, outside the fused function: its numbers are inputs there
    return compute_once(lambda t_, y_: terms(model, t_, y_).state_rate, jnp.asarray(t, dtype=float), y)
