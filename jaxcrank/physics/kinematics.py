"""Kinematics of a mechanism with clearance joints: body poses from the deviations s,
their rates, and where each joint's two sides are.

The tree ([`jaxcrank.physics.topology.Tree`][]) places every body from its generalized
coordinates q and the driver's angle phi
([`poses`][jaxcrank.physics.kinematics.poses]); the bodies a loop of ideal joints slaves
follow the bodies they hang from through the same closed forms (or root finds) the ideal
mechanism uses ([`jaxcrank.physics.closure`][]), applied to the actual poses. The state
holds s = q - q_ideal(phi), where q_ideal(phi) are the coordinates of the ideal mechanism
([`ideal_poses`][jaxcrank.physics.kinematics.ideal_poses]); a torque driver's angle is a
coordinate of its own, held as its deviation from the nominal angle phi_0 + omega t.
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

from . import closure, loops
from .compiled import Model, as_model
from .forward import Placed, centres, forward, local_point
from .joints import JointAccelerations, JointKinematics
from .linkage import GROUND, AbstractMechanism
from .safemath import Jet, add, cos_sin, mul, stop_gradient, sub, vadd, vdot, vperp, vscale, vsub, vturn
from .state import initial_state, state_scales, unpack
from .topology import Dyad

Mechanism = AbstractMechanism | Model


def _stack(values) -> Array:
    return jnp.stack([jnp.asarray(v, dtype=float) for v in values]) if len(values) else jnp.zeros(0)


def ideal_frames(model: Model, phi) -> dict[str, Placed]:
    """The ideal mechanism's body frames ([`Placed`][jaxcrank.physics.forward.Placed], and
    the ground's) at the driver angle ``phi`` (rad: a number, an array or a
    [`Jet`][jaxcrank.physics.safemath.Jet])."""
    return closure.ideal_frames(model.linkage, model.plan, phi, model.signs, model.guesses)


def closures(model: Model, phi, columns: bool = True):
    """The function that places the bodies of the tree's closure steps
    ([`jaxcrank.physics.loops.closed_states`][]) for [`jaxcrank.physics.forward.forward`][]:
    each dyad on the branch of the ideal mechanism, each group from the ideal mechanism's
    poses at the driver angle ``phi`` (rad); ``columns=False``: no Jacobian columns."""
    tree = model.tree
    signs = dict(zip([c for c in tree.closures if isinstance(c, Dyad)], model.tree_signs))
    guess_frames = {}

    def closed(step, states):
        if isinstance(step, Dyad):
            return loops.closed_states(model.linkage, step, states, sign=signs[step], columns=columns)
        if not guess_frames:
            value = phi.value if isinstance(phi, Jet) else phi
            guess_frames.update(ideal_frames(model, stop_gradient(value)))
        guess = jnp.concatenate([guess_frames[b].pose() for b in step.bodies])
        return loops.closed_states(model.linkage, step, states, guess=guess, columns=columns)

    return closed


def poses(model: Model, q: Float[ArrayLike, " n"], phi: Float[ArrayLike, ""]) -> dict[str, Array]:
    """Frame pose (x, y, angle) of every body (and the ground) for absolute tree
    coordinates ``q`` and driver angle ``phi`` (rad)."""
    tree = model.tree
    zero = [0.0] * tree.n
    states = forward(
        model.linkage, tree, [q[k] for k in range(tree.n)], zero, zero, phi, 0.0, 0.0, closures(model, phi)
    )
    return {b: st.frame.pose() for b, st in states.items()}


def coordinates_of(model: Model, frames: dict[str, Placed]) -> list:
    """The tree coordinates q (a list of scalars) of body frames (inverse of
    [`poses`][jaxcrank.physics.kinematics.poses])."""
    lk, tree = model.linkage, model.tree
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
        elif p.kind == "prismatic":
            conn = lk.connections[p.joint]
            guide = frames[conn.guide.body]
            d = cos_sin(add(guide.angle, conn.direction))
            g = guide.point(local_point(lk, conn.guide))
            slider = frames[conn.slider.body].point(local_point(lk, conn.slider))
            q[own[0]] = vdot(vsub(slider, g), d)
    return q


def driver_angle(model: Mechanism, s: Float[ArrayLike, " n"], t: Float[ArrayLike, ""]) -> Float[Array, ""]:
    """The driver's angle phi, rad: prescribed at time t (s), or, for a torque driver,
    the nominal angle plus its deviation in ``s``."""
    model = as_model(model)
    lk = model.linkage
    if lk.driver.prescribed:
        return lk.driver.angle(t)
    omega = jax.lax.stop_gradient(lk.driver.speed_scale)
    return lk.driver.initial_angle + omega * t + s[model.tree.driver_coordinate]


def ideal_poses(model: Mechanism, phi: Float[ArrayLike, ""]) -> Float[Array, "bodies 3"]:
    """Frame poses (x, y in m; angle in rad) of every body of the ideal mechanism at the
    driver's angle ``phi`` (rad), in sorted body order (the order of every per-body
    array)."""
    model = as_model(model)
    frames = ideal_frames(model, jnp.asarray(phi, dtype=float))
    return jnp.stack([frames[b].pose() for b in model.tree.bodies])


def ideal_coordinates(model: Mechanism, phi: Float[ArrayLike, ""]) -> Float[Array, " n"]:
    """Tree coordinates q_ideal of the ideal mechanism at driver angle phi (rad)."""
    model = as_model(model)
    return _stack(coordinates_of(model, ideal_frames(model, jnp.asarray(phi, dtype=float))))


def _centre_list(model: Model, frames: dict) -> list:
    """Centre-of-mass poses (x, y, angle per body, flattened) of body frames, a list."""
    lk, out = model.linkage, []
    for b in model.tree.bodies:
        centre = frames[b].point(lk.bodies[b].centre_of_mass.pair())
        out += [centre[0], centre[1], frames[b].angle]
    return out


def ideal_motion(model: Model, phi: Jet) -> tuple[list[Jet], list[Jet]]:
    """The ideal mechanism along the driver angle's jet ``phi`` (its value and first two
    derivatives): its tree coordinates and its bodies' centre-of-mass poses Q (x, y,
    angle per body, flattened) as [`Jet`][jaxcrank.physics.safemath.Jet]s. The dyads'
    closed forms in one Taylor pass; a plan with groups (root finds) by nested forward-mode
    autodiff."""
    if not any(s.kind == "group" for s in model.plan.steps):
        frames = ideal_frames(model, phi)
        return [Jet.of(v) for v in coordinates_of(model, frames)], [Jet.of(v) for v in _centre_list(model, frames)]

    def at(p):
        frames = ideal_frames(model, p)
        return _stack([*coordinates_of(model, frames), *_centre_list(model, frames)])

    value = jnp.asarray(phi.value, dtype=float)
    one = jnp.ones_like(value)
    (q, dq), (_, d2q) = jax.jvp(lambda p: jax.jvp(at, (p,), (one,)), (value,), (one,))
    rate2 = mul(phi.rate, phi.rate)
    jets = [Jet(q[k], mul(dq[k], phi.rate), add(mul(d2q[k], rate2), mul(dq[k], phi.second))) for k in range(q.shape[0])]
    return jets[: model.tree.n], jets[model.tree.n :]


def ideal_jets(model: Model, phi: Jet) -> list[Jet]:
    """The ideal tree coordinates as [`Jet`][jaxcrank.physics.safemath.Jet]s along the driver
    angle's jet ``phi`` ([`ideal_motion`][jaxcrank.physics.kinematics.ideal_motion])."""
    return ideal_motion(model, phi)[0]


def absolute_coordinates(model: Mechanism, s: Float[ArrayLike, " n"], t: Float[ArrayLike, ""]) -> tuple[Array, Array]:
    """(q, phi): absolute tree coordinates and the driver's angle from the deviations s at time t."""
    model = as_model(model)
    phi = driver_angle(model, s, t)
    q = ideal_coordinates(model, phi) + s
    if model.tree.driver_coordinate is not None:
        q = q.at[model.tree.driver_coordinate].set(phi)
    return q, phi


def frame_poses(model: Mechanism, s: Float[ArrayLike, " n"], t: Float[ArrayLike, ""]) -> Array:
    """Frame poses (x, y, angle) of every body, sorted body order, shape (bodies, 3)."""
    model = as_model(model)
    q, phi = absolute_coordinates(model, s, t)
    frames = poses(model, q, phi)
    return jnp.stack([frames[b] for b in model.tree.bodies])


def centre_poses(model: Mechanism, frames: Float[ArrayLike, "bodies 3"]) -> Float[Array, " 3bodies"]:
    """Centre-of-mass poses (x, y, angle) of every body, flattened to (3 bodies,), from
    their frame poses (bodies, 3)."""
    model = as_model(model)
    lk = model.linkage
    out = []
    for i, b in enumerate(model.tree.bodies):
        com = Placed.at((frames[i][0], frames[i][1]), frames[i][2]).point(lk.bodies[b].centre_of_mass.pair())
        out += [com[0], com[1], frames[i][2]]
    return _stack(out)


def positions(model: Mechanism, s: Float[ArrayLike, " n"], t: Float[ArrayLike, ""]) -> Array:
    """Q: centre-of-mass poses (x [m], y [m], angle [rad]) of every body, flattened, (3 bodies,)."""
    model = as_model(model)
    return centre_poses(model, frame_poses(model, s, t))


def driver_motion(model: Mechanism, t: Float[ArrayLike, ""]) -> tuple[Array, Array, Array]:
    """A prescribed driver's angle, rad, and its first two time derivatives at t (s)."""
    driver = as_model(model).linkage.driver
    t = jnp.asarray(t, dtype=float)
    one = jnp.ones_like(t)

    def rate(tt):
        return jax.jvp(driver.angle, (tt,), (one,))

    (phi, phid), (_, phidd) = jax.jvp(rate, (t,), (one,))
    return phi, phid, phidd


def ideal_derivatives(model: Mechanism, phi: Float[ArrayLike, ""]) -> tuple[Array, Array, Array]:
    """q_ideal(phi) and its first two derivatives in phi (per rad)."""
    model = as_model(model)
    jets = ideal_jets(model, Jet(jnp.asarray(phi, dtype=float), 1.0, 0.0))
    return tuple(_stack([getattr(j, k) for j in jets]) for k in ("value", "rate", "second"))


class Motion(NamedTuple):
    """Q (centre-of-mass poses, flattened, a list of scalars), its rate, ``gamma`` =
    d2Q/dt2 at zero s'', ``J`` = dQ/ds as a dict (row, coordinate) -> scalar of its
    structurally nonzero entries, ``J_phi`` = dQ/dphi at fixed tree coordinates as a dict
    row -> scalar (empty for a torque driver, whose angle is a coordinate), the bodies'
    [`BodyState`][jaxcrank.physics.forward.BodyState]s, the driver's angle and speed (rad, rad/s), and the
    ideal tree coordinates and centre-of-mass poses as [`Jet`][jaxcrank.physics.safemath.Jet]s: in time
    for a prescribed driver, in the driver angle for a torque driver."""

    q: list
    qd: list
    gamma: list
    jacobian: dict
    driver_jacobian: dict
    states: dict
    driver_angle: object
    driver_speed: object
    ideal: list
    ideal_centres: list


def motion(model: Mechanism, s, sd, t) -> Motion:
    """The bodies' [`Motion`][jaxcrank.physics.kinematics.Motion] from the deviations s, s'
    (sequences of scalars, or arrays) at time t (s).

    The ideal coordinates and their time derivatives come from the dyads' closed forms in
    one Taylor pass ([`ideal_jets`][jaxcrank.physics.kinematics.ideal_jets]); the tree is walked once by
    [`jaxcrank.physics.forward.forward`][] with the rigid-body formulas, giving positions,
    velocities, bias accelerations and the Jacobian columns together.
    """
    model = as_model(model)
    lk, tree = model.linkage, model.tree
    n, dc = tree.n, tree.driver_coordinate
    s, sd = [s[k] for k in range(n)], [sd[k] for k in range(n)]
    t = jnp.asarray(t, dtype=float)
    if lk.driver.prescribed:
        phi, phid, phidd = driver_motion(model, t)
        ideal, ideal_centres = ideal_motion(model, Jet(phi, phid, phidd))
        q = [add(j.value, s[k]) for k, j in enumerate(ideal)]
        qd = [add(j.rate, sd[k]) for k, j in enumerate(ideal)]
        qdd = [j.second for j in ideal]
    else:
        omega = stop_gradient(lk.driver.speed_scale)
        phi = add(lk.driver.initial_angle, mul(omega, t)) + s[dc]
        phid, phidd = add(omega, sd[dc]), 0.0
        ideal, ideal_centres = ideal_motion(model, Jet(phi, 1.0, 0.0))  # derivatives in phi
        q = [add(j.value, s[k]) for k, j in enumerate(ideal)]
        qd = [add(mul(j.rate, phid), sd[k]) for k, j in enumerate(ideal)]
        qdd = [mul(j.second, mul(phid, phid)) for j in ideal]
        q[dc], qd[dc], qdd[dc] = phi, phid, 0.0
    states = forward(lk, tree, q, qd, qdd, phi, phid, phidd, closures(model, phi))
    c = centres(lk, tree, states)
    jac = {rk: v for rk, v in c.jacobian.items() if rk[1] < n}
    jac_phi = {r: v for (r, k), v in c.jacobian.items() if k == n}
    if dc is not None:  # the other coordinates follow the driver angle through q_ideal
        for (r, k), v in list(jac.items()):
            if k != dc:
                jac[(r, dc)] = add(jac.get((r, dc), 0.0), mul(v, ideal[k].rate))
        jac_phi = {}
    return Motion(c.q, c.qd, c.qdd, jac, jac_phi, states, phi, phid, ideal, ideal_centres)


def coordinates(
    model: Mechanism, s: Float[ArrayLike, " n"], sd: Float[ArrayLike, " n"], t: Float[ArrayLike, ""]
) -> tuple[Array, Array, Array]:
    """Q, dQ/dt and ``gamma`` = d2Q/dt2 at zero s'' (the velocity-product terms), from
    the deviations s, s' at time t; Q as in [`positions`][jaxcrank.physics.kinematics.positions]."""
    m = motion(model, s, sd, t)
    return _stack(m.q), _stack(m.qd), _stack(m.gamma)


def _body_point(model: Model, body: str, local, q, qd, qdd=None, rots=None):
    """World position, velocity (and acceleration) of a body point (local frame
    coordinates), as pairs, from the centre-of-mass poses Q (``rots``: the bodies'
    rotations, when known)."""
    if body == GROUND:
        return tuple(local), (0.0, 0.0), (0.0, 0.0), 0.0, 0.0, 0.0
    i = model.tree.bodies.index(body)
    com = model.linkage.bodies[body].centre_of_mass
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


def joint_motion(
    model: Mechanism, joint: str, q, qd, qdd=None, rots=None
) -> tuple[JointKinematics, JointAccelerations | None]:
    """Where the two sides of ``joint`` are and how they move, from the centre-of-mass
    poses Q, their rates (and accelerations), as in [`coordinates`][jaxcrank.physics.kinematics.coordinates]
    (arrays or sequences of scalars); ``rots``: the bodies' rotations (cos, sin) by name,
    when known."""
    model = as_model(model)
    lk = model.linkage
    conn = lk.connections[joint]
    hole_site, pin_site = conn.sites()
    extra_hole, extra_pin = conn.side_angles()
    hp, hv, ha, h_angle, h_omega, h_alpha = _body_point(
        model, hole_site.body, local_point(lk, hole_site), q, qd, qdd, rots
    )
    pp, pv, pa, p_angle, p_omega, p_alpha = _body_point(
        model, pin_site.body, local_point(lk, pin_site), q, qd, qdd, rots
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


def joint_eccentricities(
    model: Mechanism, t: Float[ArrayLike, ""], y: Float[ArrayLike, " state"]
) -> tuple[Float[Array, "joints 2"], Float[Array, "joints 2"]]:
    """Eccentricities d = pin point - hole point, m, and their rates, m/s, of every cut
    (clearance) joint in sorted order, shape (joints, 2) each."""
    model = as_model(model)
    state = unpack(model, y)
    q, qd, _ = coordinates(model, state.deviation, state.deviation_rate, t)
    d, dd = [], []
    for j in model.tree.cut:
        kin, _ = joint_motion(model, j, q, qd)
        d.append(kin.pin_position - kin.hole_position)
        dd.append(kin.pin_velocity - kin.hole_velocity)
    if not d:
        return jnp.zeros((0, 2)), jnp.zeros((0, 2))
    return jnp.stack(d), jnp.stack(dd)


def state_from_eccentricities(
    model: Mechanism,
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
    model = as_model(model)
    tree = model.tree
    n = tree.n
    d = jnp.asarray(d, dtype=float)
    if 2 * d.shape[0] != n or tree.driver_coordinate is not None:
        raise ValueError(
            f"{d.shape[0]} eccentricities do not determine the {n} coordinates of this mechanism "
            "(state_from_eccentricities needs two coordinates per clearance joint and a prescribed driver)"
        )
    t = jnp.asarray(t, dtype=float)
    scale = state_scales(model)
    y = initial_state(model) if guess is None else jnp.asarray(guess, dtype=float)

    def ecc(s_, tt):
        q = positions(model, s_, tt)
        out = []
        for j in tree.cut:
            kin, _ = joint_motion(model, j, q, jnp.zeros_like(q))
            out.append(kin.pin_position - kin.hole_position)
        return jnp.concatenate(out)

    s = y[:n] * scale[:n]
    target = jnp.ravel(d)
    for _ in range(iterations):
        jac = jax.jacfwd(lambda s_: ecc(s_, t))(s)
        s = s - jnp.linalg.solve(jac, ecc(s, t) - target)
    # rates: d(ecc)/dt = J s' + d(ecc)/dt at fixed s
    jac = jax.jacfwd(lambda s_: ecc(s_, t))(s)
    _, explicit = jax.jvp(lambda tt: ecc(s, tt), (t,), (jnp.ones_like(t),))
    sd = jnp.linalg.solve(jac, jnp.ravel(d_rate) - explicit)
    return jnp.concatenate([s, sd, jnp.asarray(rest, dtype=float)]) / scale
