"""The output frame: every physical quantity of a mechanism at one instant.

[`evaluate`][jaxcrank.physics.frame.evaluate] is a function of (t, y) alone, so every output is a function of the
solution; it adds to [`dynamics`][jaxcrank.physics.dynamics.dynamics] what only the outputs need: the ideal
mechanism at the same driver angle, the ideal joints' reactions, energies and the
transmission angle. Per-body arrays are in sorted body order, per-joint arrays in
sorted joint order ([`jaxcrank.physics.topology.Tree`][]).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .dynamics import tree_dynamics, tree_gravity, tree_masses
from .forward import Centres, centres, forward
from .fusion import compute_once
from .kinematics import driver_motion, ideal_jets
from .linkage import BodyVector, Linkage
from .safemath import Jet, add, cos_sin, div, mul, neg, safe_norm, sub, total, vadd, vdot, vturn
from .state import structure, tree_state_scales
from .topology import Tree


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
        slip_speed: per joint, m/s.
        driving_moment: N m (a torque driver's torque).
        ideal_driving_moment: the moment the ideal mechanism needs for the same driver
            motion, N m.
        transmission_angle: rad (zero when the mechanism defines none).
        ideal_transmission_angle: rad.
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
    slip_speed: jax.Array
    driving_moment: jax.Array
    ideal_driving_moment: jax.Array
    transmission_angle: jax.Array
    ideal_transmission_angle: jax.Array
    kinetic_energy: jax.Array
    potential_energy: jax.Array
    contact_energy: jax.Array
    driver_work: jax.Array
    dissipated_work: jax.Array
    state_rate: jax.Array


def _direction(lk: Linkage, tree: Tree, q, v: BodyVector) -> tuple:
    angle = q[3 * tree.bodies.index(v.body) + 2]
    if v.end is None:
        return cos_sin(add(angle, v.angle))
    pts = lk.bodies[v.body].points
    return vturn(cos_sin(angle), pts[v.end].minus(pts[v.start]))


def tree_transmission_angle(lk: Linkage, tree: Tree, q) -> Array:
    """[`transmission_angle`][jaxcrank.physics.frame.transmission_angle] for Q as a sequence of scalars."""
    spec = lk.outputs.transmission
    if spec is None:
        return jnp.zeros(())
    u, v = (_direction(lk, tree, q, side) for side in spec)
    cosine = vdot(u, v) / (safe_norm(_stack(u)) * safe_norm(_stack(v)))
    return jnp.arccos(jnp.clip(cosine, -1.0, 1.0))


def transmission_angle(mech, q: Float[ArrayLike, " 3bodies"]) -> Float[Array, ""]:
    """The transmission angle of centre-of-mass poses Q (flattened), rad: the angle
    between the mechanism's two transmission directions ([`Outputs`][jaxcrank.physics.linkage.Outputs]);
    zero when it defines none."""
    lk, tree = structure(mech)
    return tree_transmission_angle(lk, tree, q)


def ideal_kinematics(mech, phi, phi_dot, phi_ddot) -> tuple[Array, Array, Array]:
    """The ideal mechanism's centre-of-mass poses Q (flattened) and their first two time
    derivatives, for the driver at angle phi (rad) moving at phi_dot (rad/s) with
    acceleration phi_ddot (rad/s^2)."""
    lk, tree = structure(mech)
    phi = jnp.asarray(phi, dtype=float)
    c = _ideal_centres(lk, tree, ideal_jets(lk, tree, Jet(phi, 1.0, 0.0)), phi, phi_dot, phi_ddot, in_time=False)
    return _stack(c.q), _stack(c.qd), _stack(c.qdd)


def _ideal_centres(lk: Linkage, tree: Tree, jets: list, phi, phi_dot, phi_ddot, in_time: bool) -> Centres:
    """The ideal bodies' centres from the ideal coordinates' jets (in time, or in the driver
    angle to be scaled by the driver's rates)."""
    if in_time:
        q, qd, qdd = [j.value for j in jets], [j.rate for j in jets], [j.second for j in jets]
    else:
        q = [j.value for j in jets]
        qd = [mul(j.rate, phi_dot) for j in jets]
        qdd = [add(mul(j.second, mul(phi_dot, phi_dot)), mul(j.rate, phi_ddot)) for j in jets]
    return centres(lk, tree, forward(lk, tree, q, qd, qdd, phi, phi_dot, phi_ddot))


def _reactions(tree: Tree, mass, qdd, applied) -> dict[str, tuple]:
    net = [sub(mul(m, a), f) for m, a, f in zip(mass, qdd, applied)]
    carried = {b: (net[3 * i], net[3 * i + 1]) for i, b in enumerate(tree.bodies)}
    out = {}
    for p in reversed(tree.placements):
        if p.joint is None:
            continue
        out[p.joint] = carried[p.body]
        if p.parent in carried:
            carried[p.parent] = vadd(carried[p.parent], carried[p.body])
    return out


def tree_reactions(mech, q, qdd, applied) -> dict[str, Array]:
    """Force each ideal tree joint transmits to the body below it, N, (2,) per joint name:
    the sum of ``m a - F`` over the bodies it carries."""
    lk, tree = structure(mech)
    return {j: _stack(f) for j, f in _reactions(tree, tree_masses(lk, tree), qdd, applied).items()}


def _stack(values) -> Array:
    return jnp.stack([jnp.asarray(v, dtype=float) for v in values]) if len(values) else jnp.zeros(0)


def _frame(lk: Linkage, tree: Tree, t, y) -> Frame:
    e = tree_dynamics(lk, tree, t, y)
    mo = e.motion
    q, qd, qdd = mo.q, mo.qd, e.qdd
    mass = tree_masses(lk, tree)
    gravity = tree_gravity(lk, tree)
    phi, phi_dot = mo.driver_angle, mo.driver_speed
    if lk.driver.prescribed:
        phi_ddot = driver_motion(lk, t)[2]
    else:
        phi_ddot = qdd[3 * tree.bodies.index(lk.driver.body) + 2]
    ideal = _ideal_centres(lk, tree, mo.ideal, phi, phi_dot, phi_ddot, in_time=lk.driver.prescribed)
    ideal_power = sub(
        total([mul(mul(m, a), v) for m, a, v in zip(mass, ideal.qdd, ideal.qd)]),
        total([mul(g, v) for g, v in zip(gravity, ideal.qd)]),
    )
    kinetic = mul(0.5, total([mul(m, mul(v, v)) for m, v in zip(mass, qd)]))
    potential = neg(total([mul(g, x) for g, x in zip(gravity, q)]))

    reactions = _reactions(tree, mass, qdd, e.applied)
    zero2, zero = jnp.zeros(2), jnp.zeros(())
    per = {k: [] for k in ("eccentricity", "penetration", "normal_force", "friction_force", "slip_speed")}
    for j in tree.joints:
        f = e.forces.get(j)
        if f is None:
            values = dict(
                eccentricity=zero2,
                penetration=zero,
                normal_force=safe_norm(_stack(reactions[j])) if j in reactions else zero,
                friction_force=zero,
                slip_speed=zero,
            )
        else:
            values = {k: getattr(f, k) for k in per}
        for k in per:
            per[k].append(values[k])
    stacked = {k: (jnp.stack(v) if v else jnp.zeros((0, 2) if k == "eccentricity" else 0)) for k, v in per.items()}

    nb = len(tree.bodies)
    phys_works = y[-2:] * _stack(tree_state_scales(lk, tree)[-2:])
    return Frame(
        t=t,
        driver_angle=jnp.asarray(phi, dtype=float),
        q=_stack(q).reshape(nb, 3),
        qd=_stack(qd).reshape(nb, 3),
        qdd=_stack(qdd).reshape(nb, 3),
        ideal_q=_stack(ideal.q).reshape(nb, 3),
        ideal_qd=_stack(ideal.qd).reshape(nb, 3),
        ideal_qdd=_stack(ideal.qdd).reshape(nb, 3),
        **stacked,
        driving_moment=jnp.asarray(e.driving_moment, dtype=float),
        ideal_driving_moment=jnp.asarray(div(ideal_power, phi_dot), dtype=float),
        transmission_angle=tree_transmission_angle(lk, tree, q),
        ideal_transmission_angle=tree_transmission_angle(lk, tree, ideal.q),
        kinetic_energy=jnp.asarray(kinetic, dtype=float),
        potential_energy=jnp.asarray(potential, dtype=float),
        contact_energy=jnp.asarray(total([f.elastic_energy for f in e.forces.values()]), dtype=float),
        driver_work=phys_works[0],
        dissipated_work=phys_works[1],
        state_rate=e.state_rate,
    )


def evaluate(mech, t: Float[ArrayLike, ""], y: Float[ArrayLike, " state"]) -> Frame:
    """All physical quantities at time t (s) for scaled state y; also dy/dt."""
    lk, tree = structure(mech)
    t = jnp.asarray(t, dtype=float)
    y = jnp.asarray(y, dtype=float)
    return compute_once(lambda t_, y_: _frame(lk, tree, t_, y_), t, y)
