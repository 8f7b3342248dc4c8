"""Loops of ideal joints in the equations of motion: the bodies a closure of the tree
places (a dyad, a group) follow the bodies they hang from
([`closed_states`][jaxcrank.physics.loops.closed_states]), every ideal joint stays closed
([`closure_residuals`][jaxcrank.physics.loops.closure_residuals]), and the ideal mechanism
placed by one root find alone ([`newton_poses`][jaxcrank.physics.loops.newton_poses]) is the
reference the closed forms are tested against.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from . import assembly, closure
from .closure import group_frames, place_dyad
from .compiled import Model, as_model
from .forward import GROUND_FRAME, BodyState, Placed
from .linkage import GROUND, AbstractMechanism, Linkage
from .safemath import Jet, cos_sin, vsub, vturn
from .topology import Dyad, Group, Plan

Mechanism = AbstractMechanism | Model


def _dyad_states(lk: Linkage, step: Dyad, states: dict, sign, columns: bool) -> dict:
    """[`closed_states`][jaxcrank.physics.loops.closed_states] of a dyad: the closed form on
    [`Jet`][jaxcrank.physics.safemath.Jet]s, once along the parents' motion (the poses, their
    rates and bias accelerations in one Taylor pass) and once along every Jacobian column
    at a time (first derivatives only, the columns as the rate's entries)."""
    parents = [b for b in step.parents if b != GROUND]

    def along(jet):
        frames = {GROUND: GROUND_FRAME}
        for b in parents:
            origin, angle = jet(states[b])
            frames[b] = Placed.at(origin, angle)
        placed = place_dyad(lk, frames, step, sign)[0]
        return {b: (*placed[b].origin, placed[b].angle) for b in step.bodies}, placed

    def motion(s):
        x, y = (Jet(s.frame.origin[i], s.velocity[i], s.acceleration[i]) for i in range(2))
        return (x, y), Jet(s.frame.angle, s.angular_velocity, s.angular_acceleration)

    moving, placed = along(motion)
    keys = sorted({k for b in parents for k in (*states[b].position_jacobian, *states[b].angle_jacobian)})
    keys = keys if columns else []

    def rates(values):
        return jnp.stack([jnp.asarray(v, dtype=float) for v in values])

    def tangent(s):
        pj = [s.position_jacobian.get(k, (0.0, 0.0)) for k in keys]
        x, y = (Jet(s.frame.origin[i], rates([p[i] for p in pj]), None) for i in range(2))
        return (x, y), Jet(s.frame.angle, rates([s.angle_jacobian.get(k, 0.0) for k in keys]), None)

    stacked = along(tangent)[0] if keys else {}
    out = {}
    for b in step.bodies:
        x, y, angle = (Jet.of(v) for v in moving[b])
        rot = tuple(Jet.of(r).value for r in placed[b].rot)
        cols = [jnp.broadcast_to(jnp.asarray(Jet.of(v).rate, dtype=float), (len(keys),)) for v in stacked.get(b, ())]
        out[b] = BodyState(
            Placed((x.value, y.value), angle.value, rot),
            (x.rate, y.rate),
            angle.rate,
            (x.second, y.second),
            angle.second,
            {k: (cols[0][i], cols[1][i]) for i, k in enumerate(keys)},
            {k: cols[2][i] for i, k in enumerate(keys)},
        )
    return out


def closed_states(lk: Linkage, step, states: dict, sign=1.0, guess=None, columns: bool = True) -> dict:
    """The [`BodyState`][jaxcrank.physics.forward.BodyState]s of the bodies a closure step
    places (a dyad on the branch ``sign``, or a group by its root find from ``guess``),
    from the states of the bodies it hangs from: their poses by the closure, and the
    velocities, bias accelerations and Jacobian columns by forward-mode derivatives of it
    (``J p'``, ``J p'' + p'^T H p'`` and ``J`` times the parents' columns; ``columns=False``:
    none)."""
    if isinstance(step, Dyad):
        return _dyad_states(lk, step, states, sign, columns)
    parents = [b for b in step.parents if b != GROUND]

    def poses(p):
        frames = {GROUND: GROUND_FRAME}
        for i, b in enumerate(parents):
            frames[b] = Placed.at((p[3 * i], p[3 * i + 1]), p[3 * i + 2])
        out = place_dyad(lk, frames, step, sign)[0] if isinstance(step, Dyad) else group_frames(lk, step, frames, guess)
        return jnp.concatenate([out[b].pose() for b in step.bodies])

    def flat(values):
        return jnp.stack([jnp.asarray(v, dtype=float) for v in values]) if values else jnp.zeros(0)

    st = [states[b] for b in parents]
    p = flat([v for s in st for v in (*s.frame.origin, s.frame.angle)])
    pd = flat([v for s in st for v in (*s.velocity, s.angular_velocity)])
    pdd = flat([v for s in st for v in (*s.acceleration, s.angular_acceleration)])
    (value, rate), (_, curvature) = jax.jvp(lambda x: jax.jvp(poses, (x,), (pd,)), (p,), (pd,))
    jac = jax.jacfwd(poses)(p)
    acc = jac @ pdd + curvature
    keys = sorted({k for s in st for k in (*s.position_jacobian, *s.angle_jacobian)}) if columns else []
    columns = {}
    for k in keys:
        entries = []
        for s in st:
            px, py = s.position_jacobian.get(k, (0.0, 0.0))
            entries += [px, py, s.angle_jacobian.get(k, 0.0)]
        columns[k] = jac @ flat(entries)
    out = {}
    for i, b in enumerate(step.bodies):
        x, y, angle = (3 * i, 3 * i + 1, 3 * i + 2)
        out[b] = BodyState(
            Placed.at((value[x], value[y]), value[angle]),
            (rate[x], rate[y]),
            rate[angle],
            (acc[x], acc[y]),
            acc[angle],
            {k: (c[x], c[y]) for k, c in columns.items()},
            {k: c[angle] for k, c in columns.items()},
        )
    return out


def closure_residuals(model: Mechanism, q) -> Array:
    """Each ideal joint's closure residual for centre-of-mass poses Q (flattened), m: the
    distance between its two points (a revolute joint), or of the slider point from the
    guide's line (a prismatic joint); zero where the loops close exactly. In the order
    of ``structure.ideal_joints``."""
    model = as_model(model)
    lk, tree = model.linkage, model.tree
    frames = {GROUND: GROUND_FRAME}
    for i, b in enumerate(tree.bodies):
        rot = cos_sin(q[3 * i + 2])
        com = vturn(rot, lk.bodies[b].centre_of_mass.pair())
        frames[b] = Placed(vsub((q[3 * i], q[3 * i + 1]), com), q[3 * i + 2], rot)
    out = []
    for j in model.structure.ideal_joints:
        conn = lk.connections[j]
        out.append(conn.gap(closure.residuals(lk, frames, [j])))
    return jnp.stack(out) if out else jnp.zeros(0)


def newton_poses(model: Mechanism, phi: Float[ArrayLike, ""]) -> Float[Array, "bodies 3"]:
    """The same poses as [`ideal_poses`][jaxcrank.physics.kinematics.ideal_poses], every body
    but the driven one placed together by one root find (no dyads), followed over the
    turn from the bodies' ``guess`` poses: the reference the closed forms are tested
    against. Every body needs a ``guess``."""
    model = as_model(model)
    lk, plan = model.linkage, model.plan
    bodies = tuple(b for b in model.tree.bodies if b != plan.driven)
    joints = tuple(j for j in model.tree.joints if j != plan.pivot)
    group = Group(
        bodies, joints, tuple(sorted({e for j in joints for e in model.structure.skeleton.ends(j)} - set(bodies)))
    )
    bare = Plan(plan.driven, plan.pivot, (group,))
    frames = closure.ideal_frames(
        lk, bare, jnp.asarray(phi, dtype=float), (), (assembly.group_guesses(lk, bare, group, ()),)
    )
    return jnp.stack([frames[b].pose() for b in model.tree.bodies])
