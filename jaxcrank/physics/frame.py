"""The output frame: every physical quantity of a mechanism at one instant.

[`evaluate`][jaxcrank.physics.frame.evaluate] is a function of (t, y) alone, so every output is a function of the
solution; it adds to [`dynamics`][jaxcrank.physics.dynamics.dynamics] what only the outputs need: the ideal
mechanism at the same driver angle, the ideal joints' reactions, energies and the
transmission angle. Per-body arrays are in sorted body order, per-joint arrays in
sorted joint order ([`jaxcrank.physics.topology.Tree`][]).
"""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .compiled import Model, as_model
from .dynamics import gravity_forces, masses, terms
from .forward import local_point
from .fusion import compute_once
from .kinematics import driver_motion, ideal_motion
from .linkage import GROUND, AbstractMechanism, BodyVector
from .loops import closure_residuals
from .safemath import (
    Jet,
    add,
    cos_sin,
    div,
    known_zero,
    ldl_solve,
    mul,
    neg,
    safe_norm,
    sub,
    total,
    vadd,
    vcross,
    vdot,
    vturn,
)
from .state import scales
from .topology import Dyad, Placement

Mechanism = AbstractMechanism | Model


class Frame(NamedTuple):
    """The mechanism at one instant; SI units, angles in rad.

    Attributes:
        t: s.
        driver_angle: the driven body's angle, rad.
        q: centre-of-mass poses (x, y, angle) per body, shape (bodies, 3).
        qd: their rates.
        qdd: their second rates.
        ideal_q: the ideal mechanism's, at the same driver angle.
        ideal_qd: the ideal mechanism's rates.
        ideal_qdd: the ideal mechanism's second rates.
        eccentricity: per joint, pin point minus hole point, m, (joints, 2) (zero for an
            ideal joint).
        penetration: per joint, m (negative when separated; zero for an ideal joint).
        normal_force: per joint, N: the contact's normal force, or an ideal joint's
            reaction magnitude.
        friction_force: per joint, N.
        joint_force: per joint, the force on its pin (or slider) side, world frame, N,
            (joints, 2): a joint law's force ([`JointForces.force`][jaxcrank.physics.joints.JointForces]),
            an ideal joint's reaction (its magnitude is ``normal_force``); the hole (or
            guide) side receives minus it.
        slip_speed: per joint, m/s.
        driving_moment: N m (a torque driver's torque).
        ideal_driving_moment: the moment the ideal mechanism needs for the same driver
            motion, N m.
        transmission_angle: rad (zero when the mechanism defines none).
        ideal_transmission_angle: rad.
        closure_residual: per ideal joint (in the order of ``structure.ideal_joints``),
            how far apart its two sides are, m: zero but for rounding where the loops of
            ideal joints close.
        kinetic_energy: J.
        potential_energy: J.
        contact_energy: J, stored in the joint laws.
        driver_work: J.
        dissipated_work: J.
        state_rate: dy/dt of the scaled state.
    """

    t: jax.Array
    driver_angle: jax.Array
    q: jax.Array
    qd: jax.Array
    qdd: jax.Array
    ideal_q: jax.Array
    ideal_qd: jax.Array
    ideal_qdd: jax.Array
    eccentricity: jax.Array
    penetration: jax.Array
    normal_force: jax.Array
    friction_force: jax.Array
    joint_force: jax.Array
    slip_speed: jax.Array
    driving_moment: jax.Array
    ideal_driving_moment: jax.Array
    transmission_angle: jax.Array
    ideal_transmission_angle: jax.Array
    closure_residual: jax.Array
    kinetic_energy: jax.Array
    potential_energy: jax.Array
    contact_energy: jax.Array
    driver_work: jax.Array
    dissipated_work: jax.Array
    state_rate: jax.Array


def _direction(model: Model, q, v: BodyVector) -> tuple:
    angle = q[3 * model.tree.bodies.index(v.body) + 2]
    if v.end is None:
        return cos_sin(add(angle, v.angle))
    pts = model.linkage.bodies[v.body].points
    return vturn(cos_sin(angle), pts[v.end].minus(pts[v.start]))


def transmission_angle(model: Mechanism, q: Float[ArrayLike, " 3bodies"]) -> Float[Array, ""]:
    """The transmission angle of centre-of-mass poses Q (flattened; an array or a sequence
    of scalars), rad: the angle between the mechanism's two transmission directions
    ([`Outputs`][jaxcrank.physics.linkage.Outputs]); zero when it defines none."""
    model = as_model(model)
    spec = model.linkage.outputs.transmission
    if spec is None:
        return jnp.zeros(())
    u, v = (_direction(model, q, side) for side in spec)
    cosine = vdot(u, v) / (safe_norm(_stack(u)) * safe_norm(_stack(v)))
    return jnp.arccos(jnp.clip(cosine, -1.0, 1.0))


def ideal_kinematics(model: Mechanism, phi, phi_dot, phi_ddot) -> tuple[Array, Array, Array]:
    """The ideal mechanism's centre-of-mass poses Q (flattened) and their first two time
    derivatives, for the driver at angle phi (rad) moving at phi_dot (rad/s) with
    acceleration phi_ddot (rad/s^2)."""
    model = as_model(model)
    phi = jnp.asarray(phi, dtype=float)
    c = _ideal_centres(ideal_motion(model, Jet(phi, 1.0, 0.0))[1], phi_dot, phi_ddot, in_time=False)
    return _stack(c[0]), _stack(c[1]), _stack(c[2])


def _ideal_centres(jets: list, phi_dot, phi_ddot, in_time: bool) -> tuple[list, list, list]:
    """The ideal bodies' centre-of-mass poses and their first two time derivatives, from
    their jets (in time, or in the driver angle to be scaled by the driver's rates)."""
    if in_time:
        return [j.value for j in jets], [j.rate for j in jets], [j.second for j in jets]
    q = [j.value for j in jets]
    qd = [mul(j.rate, phi_dot) for j in jets]
    qdd = [add(mul(j.second, mul(phi_dot, phi_dot)), mul(j.rate, phi_ddot)) for j in jets]
    return q, qd, qdd


def _closure_loads(model: Model, step, frames: dict, carried: dict, moment: dict) -> dict[str, tuple]:
    """The reactions of a closure step's joints (force on each joint's pin or slider side,
    a pair, N), from the loads its bodies carry (force and moment about the origin);
    adds what the joints pass to the bodies it hangs from to theirs."""
    lk = model.linkage
    bodies = list(step.bodies)
    rows = {b: i for i, b in enumerate(bodies)}
    columns, passed = [], []  # per unknown: {row: (fx, fy, m)} on the step's bodies
    for j in step.joints:
        conn = lk.connections[j]
        first, second = conn.sites()  # hole or guide side, pin or slider side
        point = frames[second.body].point(local_point(lk, second))
        for unit in ((1.0, 0.0), (0.0, 1.0)):
            force, pure = conn.load(unit, frames[first.body].angle)
            wrench = (force[0], force[1], add(vcross(point, force), pure))
            entry = {}
            for site, sign in ((second, 1.0), (first, -1.0)):
                if site.body in rows:
                    entry[rows[site.body]] = tuple(mul(sign, w) for w in wrench)
            columns.append(entry)
            passed.append([(site.body, sign, wrench) for site, sign in ((second, 1.0), (first, -1.0))])
    size = 3 * len(bodies)
    a = [[0.0] * len(columns) for _ in range(size)]
    for c, entry in enumerate(columns):
        for r, w in entry.items():
            for k in range(3):
                a[3 * r + k][c] = w[k]
    b = [v for body in bodies for v in (*carried[body], moment[body])]
    x = _dyad_loads(a, b) if isinstance(step, Dyad) else _least_squares(a, b)
    out = {}
    for i, j in enumerate(step.joints):
        conn = lk.connections[j]
        out[j] = conn.load((x[2 * i], x[2 * i + 1]), frames[conn.sites()[0].body].angle)[0]
    for c, sides in enumerate(passed):
        for body, sign, wrench in sides:
            if body in rows or body == GROUND:
                continue
            load = [mul(mul(-sign, w), x[c]) for w in wrench]  # a parent carries what it passes on
            carried[body] = vadd(carried[body], (load[0], load[1]))
            moment[body] = add(moment[body], load[2])
    return out


def _solve2(a: list, b: list) -> list:
    """x of the 2 x 2 system ``a x = b`` (scalars), by Cramer's rule."""
    det = sub(mul(a[0][0], a[1][1]), mul(a[0][1], a[1][0]))
    return [
        div(sub(mul(a[1][1], b[0]), mul(a[0][1], b[1])), det),
        div(sub(mul(a[0][0], b[1]), mul(a[1][0], b[0])), det),
    ]


def _dot3(u, v):
    return total([mul(p, q) for p, q in zip(u, v)])


def _dyad_loads(a: list, b: list) -> list:
    """[`_least_squares`][] for a dyad's Newton-Euler equations (rows: the first body's
    force and moment, then the second's; columns: the outer, middle and other joint's two
    unknowns), by elimination: on each body, the combination of its three equations
    that the unknowns of its joint to a placed body do not enter (the cross product of
    their two columns: the moment about a pin, the force along a slide) gives one equation
    in the middle joint's two unknowns; then each outer joint's pair from its body's
    equations less the middle joint's load (2 x 2 normal equations)."""
    col = [[[a[3 * body + r][c] for r in range(3)] for c in range(6)] for body in range(2)]
    rhs = [b[0:3], b[3:6]]
    own = ((0, 1), (4, 5))  # the outer joint's columns on the first body, the other joint's on the second
    weights = []
    for body in range(2):
        p, q = (col[body][c] for c in own[body])
        weights.append(
            (
                sub(mul(p[1], q[2]), mul(p[2], q[1])),
                sub(mul(p[2], q[0]), mul(p[0], q[2])),
                sub(mul(p[0], q[1]), mul(p[1], q[0])),
            )
        )
    middle = _solve2(
        [[_dot3(weights[body], col[body][c]) for c in (2, 3)] for body in range(2)],
        [_dot3(weights[body], rhs[body]) for body in range(2)],
    )
    out = [None] * 6
    out[2], out[3] = middle
    for body in range(2):
        left = [
            sub(rhs[body][r], add(mul(col[body][2][r], middle[0]), mul(col[body][3][r], middle[1]))) for r in range(3)
        ]
        p, q = (col[body][c] for c in own[body])
        pair = _solve2([[_dot3(p, p), _dot3(p, q)], [_dot3(q, p), _dot3(q, q)]], [_dot3(p, left), _dot3(q, left)])
        out[own[body][0]], out[own[body][1]] = pair
    return out


def _least_squares(a: list, b: list) -> list:
    """x of ``a x = b`` for a square, well-posed system written as scalars (the
    Newton-Euler equations of a closure's bodies), by the normal equations
    ``a^T a x = a^T b`` and an LDL^T factorisation without pivoting on the entries that
    are not known to be zero: unrolled arithmetic, no row exchanges."""
    n = len(a[0])
    ata = [[total([mul(row[i], row[k]) for row in a]) for k in range(n)] for i in range(n)]
    atb = [total([mul(row[i], v) for row, v in zip(a, b)]) for i in range(n)]
    pattern = [[not known_zero(ata[i][k]) for k in range(n)] for i in range(n)]
    return ldl_solve(lambda i, k: ata[i][k], atb, pattern)


def _reactions(model: Model, frames: dict, q, mass, qdd, applied) -> dict[str, tuple]:
    """Force each ideal joint transmits to its pin (or slider) side, N, a pair per joint
    name: in a tree step the sum of ``m a - F`` over the bodies it carries; in a closure
    step from the Newton-Euler equations of its bodies."""
    tree = model.tree
    net = [sub(mul(m, a), f) for m, a, f in zip(mass, qdd, applied)]
    carried = {b: (net[3 * i], net[3 * i + 1]) for i, b in enumerate(tree.bodies)}
    moment = {}
    if tree.closures:  # moments about the origin: m a - F's moment, r x (m a - F)
        for i, b in enumerate(tree.bodies):
            moment[b] = add(net[3 * i + 2], vcross((q[3 * i], q[3 * i + 1]), carried[b]))
    out = {}
    for p in reversed(tree.steps):
        if not isinstance(p, Placement):
            out.update(_closure_loads(model, p, frames, carried, moment))
            continue
        if p.joint is None:
            continue
        out[p.joint] = carried[p.body]
        if p.parent in carried:
            carried[p.parent] = vadd(carried[p.parent], carried[p.body])
            if moment:
                moment[p.parent] = add(moment[p.parent], moment[p.body])
    return out


def _stack(values) -> Array:
    return jnp.stack([jnp.asarray(v, dtype=float) for v in values]) if len(values) else jnp.zeros(0)


def _frame(model: Model, t, y) -> Frame:
    lk, tree = model.linkage, model.tree
    e = terms(model, t, y)
    mo = e.motion
    q, qd, qdd = mo.q, mo.qd, e.qdd
    mass = masses(model)
    gravity = gravity_forces(model)
    phi, phi_dot = mo.driver_angle, mo.driver_speed
    if lk.driver.prescribed:
        phi_ddot = driver_motion(model, t)[2]
    else:
        phi_ddot = qdd[3 * tree.bodies.index(lk.driver.body) + 2]
    ideal_q, ideal_qd, ideal_qdd = _ideal_centres(mo.ideal_centres, phi_dot, phi_ddot, in_time=lk.driver.prescribed)
    ideal_power = sub(
        total([mul(mul(m, a), v) for m, a, v in zip(mass, ideal_qdd, ideal_qd)]),
        total([mul(g, v) for g, v in zip(gravity, ideal_qd)]),
    )
    kinetic = mul(0.5, total([mul(m, mul(v, v)) for m, v in zip(mass, qd)]))
    potential = neg(total([mul(g, x) for g, x in zip(gravity, q)]))

    frames = {b: st.frame for b, st in mo.states.items()}
    reactions = _reactions(model, frames, q, mass, qdd, e.applied)
    zero2, zero = jnp.zeros(2), jnp.zeros(())
    vectors = ("eccentricity", "joint_force")
    per = {
        k: [] for k in ("eccentricity", "penetration", "normal_force", "friction_force", "joint_force", "slip_speed")
    }
    for j in tree.joints:
        f = e.forces.get(j)
        if f is None:
            reaction = _stack(reactions[j]) if j in reactions else zero2
            values = dict(
                eccentricity=zero2,
                penetration=zero,
                normal_force=safe_norm(reaction) if j in reactions else zero,
                friction_force=zero,
                joint_force=reaction,
                slip_speed=zero,
            )
        else:
            values = {k: getattr(f, "force" if k == "joint_force" else k) for k in per}
        for k in per:
            per[k].append(jnp.asarray(values[k], dtype=float))
    stacked = {k: (jnp.stack(v) if v else jnp.zeros((0, 2) if k in vectors else 0)) for k, v in per.items()}

    nb = len(tree.bodies)
    phys_works = y[-2:] * _stack(scales(model)[-2:])
    return Frame(
        t=t,
        driver_angle=jnp.asarray(phi, dtype=float),
        q=_stack(q).reshape(nb, 3),
        qd=_stack(qd).reshape(nb, 3),
        qdd=_stack(qdd).reshape(nb, 3),
        ideal_q=_stack(ideal_q).reshape(nb, 3),
        ideal_qd=_stack(ideal_qd).reshape(nb, 3),
        ideal_qdd=_stack(ideal_qdd).reshape(nb, 3),
        **stacked,
        driving_moment=jnp.asarray(e.driving_moment, dtype=float),
        ideal_driving_moment=jnp.asarray(div(ideal_power, phi_dot), dtype=float),
        transmission_angle=transmission_angle(model, q),
        ideal_transmission_angle=transmission_angle(model, ideal_q),
        closure_residual=closure_residuals(model, q),
        kinetic_energy=jnp.asarray(kinetic, dtype=float),
        potential_energy=jnp.asarray(potential, dtype=float),
        contact_energy=jnp.asarray(total([f.elastic_energy for f in e.forces.values()]), dtype=float),
        driver_work=phys_works[0],
        dissipated_work=phys_works[1],
        state_rate=e.state_rate,
    )


def evaluate(model: Mechanism, t: Float[ArrayLike, ""], y: Float[ArrayLike, " state"]) -> Frame:
    """All physical quantities at time t (s) for scaled state y; also dy/dt.

    Jitted (as [`jaxcrank.physics.dynamics.vector_field`][] is): a solve that evaluates the
    frame in several places (the tracked metrics) traces it once."""
    return _evaluate(jnp.asarray(t, dtype=float), jnp.asarray(y, dtype=float), as_model(model))


@eqx.filter_jit
def _evaluate(t, y, model: Model) -> Frame:
    _ = model.linkage  # written out here, outside the fused function: its numbers are inputs there
    return compute_once(lambda t_, y_: _frame(model, t_, y_), t, y)
