"""Kinematics of a mechanism with clearance joints: body poses from the deviations s,
their rates, and where each joint's two sides are.

The tree ([`jaxcrank.physics.topology.Tree`][]) places every body from its generalized
coordinates q and the driver's angle phi
([`tree_poses`][jaxcrank.physics.kinematics.tree_poses]). The state holds s = q - q_ideal(phi), where
q_ideal(phi) are the coordinates of the ideal mechanism
([`jaxcrank.physics.closure.ideal_poses`][]); a torque driver's angle is a coordinate of
its own, held as its deviation from the nominal angle phi_0 + omega t.
[`coordinates`][jaxcrank.physics.kinematics.coordinates] gives the bodies' centre-of-mass poses Q = (x, y, angle)
per body, their rates and ``gamma`` = d2Q/dt2 at zero s'': the ideal coordinates and
their time derivatives in one Taylor pass through the dyads' closed forms
([`ideal_jets`][jaxcrank.physics.kinematics.ideal_jets]), the bodies by the rigid-body formulas
([`jaxcrank.physics.forward`][]).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .closure import ideal_frames
from .forward import Placed, centres, forward, local_point
from .joints import JointAccelerations, JointKinematics
from .linkage import GROUND, AbstractMechanism, Linkage, Prismatic
from .safemath import Jet, add, cos_sin, mul, stop_gradient, sub, vadd, vdot, vperp, vscale, vsub, vturn
from .state import structure, unpack
from .topology import Skeleton, Tree, plan_of


def _stack(values) -> Array:
    return jnp.stack([jnp.asarray(v, dtype=float) for v in values]) if len(values) else jnp.zeros(0)


def tree_poses(lk: Linkage, tree: Tree, q: Float[ArrayLike, " n"], phi: Float[ArrayLike, ""]) -> dict[str, Array]:
    """Frame pose (x, y, angle) of every body (and the ground) for absolute tree
    coordinates ``q`` and driver angle ``phi`` (rad)."""
    zero = [0.0] * tree.n
    states = forward(lk, tree, [q[k] for k in range(tree.n)], zero, zero, phi, 0.0, 0.0)
    return {b: st.frame.pose() for b, st in states.items()}


def coordinates_of(lk: Linkage, tree: Tree, frames: dict[str, Placed]) -> list:
    """The tree coordinates q (a list of scalars) of body frames (inverse of
    [`tree_poses`][jaxcrank.physics.kinematics.tree_poses])."""
    q = [None] * tree.n
    for p in tree.placements:
        own = list(p.coordinates)
        frame = frames[p.body]
        if p.kind == "floating":
            centre = frame.point(lk.bodies[p.body].centre_of_mass.pair())
            for i, value in zip(own, (centre[0], centre[1], frame.angle)):
                q[i] = value
        elif p.kind == "revolute":
            if own:
                q[own[0]] = frame.angle
        else:
            conn = lk.connections[p.joint]
            guide = frames[conn.guide.body]
            d = cos_sin(add(guide.angle, conn.direction))
            g = guide.point(local_point(lk, conn.guide))
            slider = frames[conn.slider.body].point(local_point(lk, conn.slider))
            q[own[0]] = vdot(vsub(slider, g), d)
    return q


def tree_coordinates(lk: Linkage, tree: Tree, poses: dict[str, Array]) -> Array:
    """The tree coordinates q of given body poses (inverse of
    [`tree_poses`][jaxcrank.physics.kinematics.tree_poses])."""
    frames = {b: Placed.at((p[0], p[1]), p[2]) for b, p in poses.items()}
    return _stack(coordinates_of(lk, tree, frames))


def driver_angle(mech: AbstractMechanism, s: Float[ArrayLike, " n"], t: Float[ArrayLike, ""]) -> Float[Array, ""]:
    """The driver's angle phi, rad: prescribed at time t (s), or, for a torque driver,
    the nominal angle plus its deviation in ``s``."""
    lk, tree = structure(mech)
    if lk.driver.prescribed:
        return lk.driver.angle(t)
    omega = jax.lax.stop_gradient(lk.driver.speed_scale)
    return lk.driver.initial_angle + omega * t + s[tree.driver_coordinate]


def ideal_coordinates(mech: AbstractMechanism, phi: Float[ArrayLike, ""]) -> Float[Array, " n"]:
    """Tree coordinates q_ideal of the ideal mechanism at driver angle phi (rad)."""
    lk, tree = structure(mech)
    return _stack(coordinates_of(lk, tree, ideal_frames(lk, plan_of(Skeleton.of(lk)), jnp.asarray(phi, dtype=float))))


def ideal_jets(lk: Linkage, tree: Tree, phi: Jet) -> list[Jet]:
    """The ideal tree coordinates as [`Jet`][jaxcrank.physics.safemath.Jet]s along the driver angle's jet
    ``phi`` (its value and first two derivatives): the dyads' closed forms in one Taylor
    pass; bodies placed by the loop-closure Newton solve by nested forward-mode autodiff."""
    plan = plan_of(Skeleton.of(lk))
    if not plan.rest:
        return [Jet.of(v) for v in coordinates_of(lk, tree, ideal_frames(lk, plan, phi))]

    def at(p):
        return _stack(coordinates_of(lk, tree, ideal_frames(lk, plan, p)))

    value = jnp.asarray(phi.value, dtype=float)
    one = jnp.ones_like(value)
    (q, dq), (_, d2q) = jax.jvp(lambda p: jax.jvp(at, (p,), (one,)), (value,), (one,))
    rate2 = mul(phi.rate, phi.rate)
    return [Jet(q[k], mul(dq[k], phi.rate), add(mul(d2q[k], rate2), mul(dq[k], phi.second))) for k in range(tree.n)]


def absolute_coordinates(
    mech: AbstractMechanism, s: Float[ArrayLike, " n"], t: Float[ArrayLike, ""]
) -> tuple[Array, Array]:
    """(q, phi): absolute tree coordinates and the driver's angle from the deviations s at time t."""
    _, tree = structure(mech)
    phi = driver_angle(mech, s, t)
    q = ideal_coordinates(mech, phi) + s
    if tree.driver_coordinate is not None:
        q = q.at[tree.driver_coordinate].set(phi)
    return q, phi


def frame_poses(mech: AbstractMechanism, s: Float[ArrayLike, " n"], t: Float[ArrayLike, ""]) -> Array:
    """Frame poses (x, y, angle) of every body, sorted body order, shape (bodies, 3)."""
    lk, tree = structure(mech)
    q, phi = absolute_coordinates(mech, s, t)
    poses = tree_poses(lk, tree, q, phi)
    return jnp.stack([poses[b] for b in tree.bodies])


def centre_poses(lk: Linkage, tree: Tree, frames: Float[ArrayLike, "bodies 3"]) -> Float[Array, " 3bodies"]:
    """Centre-of-mass poses (x, y, angle) of every body, flattened to (3 bodies,)."""
    out = []
    for i, b in enumerate(tree.bodies):
        com = Placed.at((frames[i][0], frames[i][1]), frames[i][2]).point(lk.bodies[b].centre_of_mass.pair())
        out += [com[0], com[1], frames[i][2]]
    return _stack(out)


def positions(mech: AbstractMechanism, s: Float[ArrayLike, " n"], t: Float[ArrayLike, ""]) -> Array:
    """Q: centre-of-mass poses (x [m], y [m], angle [rad]) of every body, flattened, (3 bodies,)."""
    lk, tree = structure(mech)
    return centre_poses(lk, tree, frame_poses(mech, s, t))


def driver_motion(mech: AbstractMechanism, t: Float[ArrayLike, ""]) -> tuple[Array, Array, Array]:
    """A prescribed driver's angle, rad, and its first two time derivatives at t (s)."""
    lk = mech.linkage()
    t = jnp.asarray(t, dtype=float)
    one = jnp.ones_like(t)

    def rate(tt):
        return jax.jvp(lk.driver.angle, (tt,), (one,))

    (phi, phid), (_, phidd) = jax.jvp(rate, (t,), (one,))
    return phi, phid, phidd


def ideal_derivatives(mech: AbstractMechanism, phi: Float[ArrayLike, ""]) -> tuple[Array, Array, Array]:
    """q_ideal(phi) and its first two derivatives in phi (per rad)."""
    lk, tree = structure(mech)
    jets = ideal_jets(lk, tree, Jet(jnp.asarray(phi, dtype=float), 1.0, 0.0))
    return tuple(_stack([getattr(j, k) for j in jets]) for k in ("value", "rate", "second"))


class Motion(NamedTuple):
    """Q (centre-of-mass poses, flattened, a list of scalars), its rate, ``gamma`` =
    d2Q/dt2 at zero s'', ``J`` = dQ/ds as a dict (row, coordinate) -> scalar of its
    structurally nonzero entries, ``J_phi`` = dQ/dphi at fixed tree coordinates as a dict
    row -> scalar (empty for a torque driver, whose angle is a coordinate), the bodies'
    [`BodyState`][jaxcrank.physics.forward.BodyState]s, the driver's angle and speed (rad, rad/s), and the
    ideal tree coordinates as [`Jet`][jaxcrank.physics.safemath.Jet]s: in time for a prescribed driver, in
    the driver angle for a torque driver."""

    q: list
    qd: list
    gamma: list
    jacobian: dict
    driver_jacobian: dict
    states: dict
    driver_angle: object
    driver_speed: object
    ideal: list


def tree_motion(lk: Linkage, tree: Tree, s, sd, t) -> Motion:
    """[`Motion`][jaxcrank.physics.kinematics.Motion] from the deviations s, s' (sequences of scalars) at time t (s)."""
    n, dc = tree.n, tree.driver_coordinate
    if lk.driver.prescribed:
        phi, phid, phidd = driver_motion(lk, t)
        ideal = ideal_jets(lk, tree, Jet(phi, phid, phidd))
        q = [add(j.value, s[k]) for k, j in enumerate(ideal)]
        qd = [add(j.rate, sd[k]) for k, j in enumerate(ideal)]
        qdd = [j.second for j in ideal]
    else:
        omega = stop_gradient(lk.driver.speed_scale)
        phi = add(lk.driver.initial_angle, mul(omega, t)) + s[dc]
        phid, phidd = add(omega, sd[dc]), 0.0
        ideal = ideal_jets(lk, tree, Jet(phi, 1.0, 0.0))  # derivatives in phi
        q = [add(j.value, s[k]) for k, j in enumerate(ideal)]
        qd = [add(mul(j.rate, phid), sd[k]) for k, j in enumerate(ideal)]
        qdd = [mul(j.second, mul(phid, phid)) for j in ideal]
        q[dc], qd[dc], qdd[dc] = phi, phid, 0.0
    states = forward(lk, tree, q, qd, qdd, phi, phid, phidd)
    c = centres(lk, tree, states)
    jac = {rk: v for rk, v in c.jacobian.items() if rk[1] < n}
    jac_phi = {r: v for (r, k), v in c.jacobian.items() if k == n}
    if dc is not None:  # the other coordinates follow the driver angle through q_ideal
        for (r, k), v in list(jac.items()):
            if k != dc:
                jac[(r, dc)] = add(jac.get((r, dc), 0.0), mul(v, ideal[k].rate))
        jac_phi = {}
    return Motion(c.q, c.qd, c.qdd, jac, jac_phi, states, phi, phid, ideal)


def motion(
    mech: AbstractMechanism, s: Float[ArrayLike, " n"], sd: Float[ArrayLike, " n"], t: Float[ArrayLike, ""]
) -> Motion:
    """The bodies' [`Motion`][jaxcrank.physics.kinematics.Motion] from the deviations s, s' at time t (s).

    The ideal coordinates and their time derivatives come from the dyads' closed forms in
    one Taylor pass ([`ideal_jets`][jaxcrank.physics.kinematics.ideal_jets]); the tree is walked once by
    [`jaxcrank.physics.forward.forward`][] with the rigid-body formulas, giving positions,
    velocities, bias accelerations and the Jacobian columns together.
    """
    lk, tree = structure(mech)
    return tree_motion(lk, tree, [s[k] for k in range(tree.n)], [sd[k] for k in range(tree.n)], jnp.asarray(t, float))


def coordinates(
    mech: AbstractMechanism, s: Float[ArrayLike, " n"], sd: Float[ArrayLike, " n"], t: Float[ArrayLike, ""]
) -> tuple[Array, Array, Array]:
    """Q, dQ/dt and ``gamma`` = d2Q/dt2 at zero s'' (the velocity-product terms), from
    the deviations s, s' at time t; Q as in [`positions`][jaxcrank.physics.kinematics.positions]."""
    m = motion(mech, s, sd, t)
    return _stack(m.q), _stack(m.qd), _stack(m.gamma)


def _body_point(lk: Linkage, tree: Tree, body: str, local, q, qd, qdd=None, rots=None):
    """World position, velocity (and acceleration) of a body point (local frame
    coordinates), as pairs, from the centre-of-mass poses Q (``rots``: the bodies'
    rotations, when known)."""
    if body == GROUND:
        return tuple(local), (0.0, 0.0), (0.0, 0.0), 0.0, 0.0, 0.0
    i = tree.bodies.index(body)
    com = lk.bodies[body].centre_of_mass
    angle, omega = q[3 * i + 2], qd[3 * i + 2]
    rot = rots[body] if rots is not None else cos_sin(angle)
    r = vturn(rot, (sub(local[0], com.x), sub(local[1], com.y)))
    pos = vadd((q[3 * i], q[3 * i + 1]), r)
    vel = vadd((qd[3 * i], qd[3 * i + 1]), vscale(omega, vperp(r)))
    if qdd is None:
        return pos, vel, None, angle, omega, None
    alpha = qdd[3 * i + 2]
    acc = vsub(vadd((qdd[3 * i], qdd[3 * i + 1]), vscale(alpha, vperp(r))), vscale(mul(omega, omega), r))
    return pos, vel, acc, angle, omega, alpha


def tree_joint_motion(
    lk: Linkage, tree: Tree, joint: str, q, qd, qdd=None, rots=None
) -> tuple[JointKinematics, JointAccelerations | None]:
    """[`joint_motion`][jaxcrank.physics.kinematics.joint_motion] for Q, its rates (and accelerations) as
    sequences of scalars; ``rots``: the bodies' rotations (cos, sin) by name, when known."""
    conn = lk.connections[joint]
    hole_site, pin_site = conn.sites()
    extra_hole = extra_pin = 0.0
    if isinstance(conn, Prismatic):
        extra_hole = conn.direction
        extra_pin = conn.direction - conn.angle
    hp, hv, ha, h_angle, h_omega, h_alpha = _body_point(
        lk, tree, hole_site.body, local_point(lk, hole_site), q, qd, qdd, rots
    )
    pp, pv, pa, p_angle, p_omega, p_alpha = _body_point(
        lk, tree, pin_site.body, local_point(lk, pin_site), q, qd, qdd, rots
    )
    kin = JointKinematics(
        _stack(hp),
        _stack(hv),
        jnp.asarray(add(h_angle, extra_hole), dtype=float),
        jnp.asarray(h_omega, dtype=float),
        _stack(pp),
        _stack(pv),
        jnp.asarray(add(p_angle, extra_pin), dtype=float),
        jnp.asarray(p_omega, dtype=float),
    )
    if qdd is None:
        return kin, None
    acc = JointAccelerations(
        _stack(ha), jnp.asarray(h_alpha, dtype=float), _stack(pa), jnp.asarray(p_alpha, dtype=float)
    )
    return kin, acc


def joint_motion(
    mech: AbstractMechanism, joint: str, q: Array, qd: Array, qdd: Array | None = None
) -> tuple[JointKinematics, JointAccelerations | None]:
    """Where the two sides of ``joint`` are and how they move, from the centre-of-mass
    poses Q, their rates (and accelerations), as in [`coordinates`][jaxcrank.physics.kinematics.coordinates]."""
    lk, tree = structure(mech)
    return tree_joint_motion(lk, tree, joint, q, qd, qdd)


def joint_eccentricities(
    mech: AbstractMechanism, t: Float[ArrayLike, ""], y: Float[ArrayLike, " state"]
) -> tuple[Float[Array, "joints 2"], Float[Array, "joints 2"]]:
    """Eccentricities d = pin point - hole point, m, and their rates, m/s, of every cut
    (clearance) joint in sorted order, shape (joints, 2) each."""
    _, tree = structure(mech)
    state = unpack(mech, y)
    q, qd, _ = coordinates(mech, state.deviation, state.deviation_rate, t)
    d, dd = [], []
    for j in tree.cut:
        kin, _ = joint_motion(mech, j, q, qd)
        d.append(kin.pin_position - kin.hole_position)
        dd.append(kin.pin_velocity - kin.hole_velocity)
    if not d:
        return jnp.zeros((0, 2)), jnp.zeros((0, 2))
    return jnp.stack(d), jnp.stack(dd)


def state_from_eccentricities(
    mech: AbstractMechanism,
    t: Float[ArrayLike, ""],
    d: Float[ArrayLike, "joints 2"],
    d_rate: Float[ArrayLike, "joints 2"],
    rest: Float[ArrayLike, " aux"],
    guess: Float[ArrayLike, " state"] | None = None,
    iterations: int = 8,
) -> Float[Array, " state"]:
    """Inverse of [`joint_eccentricities`][jaxcrank.physics.kinematics.joint_eccentricities]: the scaled state whose cut
    joints sit at eccentricities ``d`` (m) moving at ``d_rate`` (m/s) at time t, by
    Newton's method from ``guess`` (default: the pins centred); ``rest`` are the remaining
    state entries in SI units (law states, then driver and dissipated work). Used to carry
    a pin-in-bearing state over to another design, whose state scales differ.

    Raises:
        ValueError: when the cut joints' eccentricities do not determine the coordinates
            (a count that is not two per cut joint).
    """
    from .state import initial_state, state_scales

    _, tree = structure(mech)
    n = tree.n
    d = jnp.asarray(d, dtype=float)
    if 2 * d.shape[0] != n or tree.driver_coordinate is not None:
        raise ValueError(
            f"{d.shape[0]} eccentricities do not determine the {n} coordinates of this mechanism "
            "(state_from_eccentricities needs two coordinates per clearance joint and a prescribed driver)"
        )
    t = jnp.asarray(t, dtype=float)
    scale = state_scales(mech)
    y = initial_state(mech) if guess is None else jnp.asarray(guess, dtype=float)

    def ecc(s_):
        q = positions(mech, s_, t)
        out = []
        for j in tree.cut:
            kin, _ = joint_motion(mech, j, q, jnp.zeros_like(q))
            out.append(kin.pin_position - kin.hole_position)
        return jnp.concatenate(out)

    s = y[:n] * scale[:n]
    target = jnp.ravel(d)
    for _ in range(iterations):
        jac = jax.jacfwd(ecc)(s)
        s = s - jnp.linalg.solve(jac, ecc(s) - target)
    # rates: d(ecc)/dt = J s' + d(ecc)/dt at fixed s
    jac = jax.jacfwd(ecc)(s)
    _, explicit = jax.jvp(lambda tt: _ecc_at(mech, tree, s, tt), (t,), (jnp.ones_like(t),))
    sd = jnp.linalg.solve(jac, jnp.ravel(d_rate) - explicit)
    return jnp.concatenate([s, sd, jnp.asarray(rest, dtype=float)]) / scale


def _ecc_at(mech, tree, s, t):
    q = positions(mech, s, t)
    out = []
    for j in tree.cut:
        kin, _ = joint_motion(mech, j, q, jnp.zeros_like(q))
        out.append(kin.pin_position - kin.hole_position)
    return jnp.concatenate(out)
