"""The ideal mechanism (every joint ideal) of any description, driven by its prescribed
driver: motion, transmission angle, joint reactions and driving moment by inverse
dynamics, and the contact margin.

Positions come from [`jaxcrank.physics.kinematics.ideal_poses`][] (dyads in closed form,
a root find for the rest); velocities and accelerations are their exact time
derivatives by forward-mode autodiff. Per-body arrays are in sorted body order. All
functions take a compiled model (or a mechanism) and a scalar time t (s); ``jax.vmap``
over t for trajectories.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .compiled import Model, as_model
from .frame import transmission_angle as _transmission_angle
from .kinematics import centre_poses, ideal_poses
from .linkage import GROUND, AbstractMechanism, world_point
from .safemath import cross, safe_norm, solve_dense

Mechanism = AbstractMechanism | Model


def _prescribed(mech: Mechanism):
    driver = as_model(mech).linkage.driver
    if not driver.prescribed:
        raise ValueError(
            f"the ideal motion in time needs a prescribed driver; a {driver.name!r} driver's angle is not known in "
            "advance (evaluate the ideal mechanism at a driver angle: jaxcrank.physics.kinematics.ideal_poses)"
        )
    return driver


def driver_angle(mech: Mechanism, t: Float[ArrayLike, ""]) -> Float[Array, ""]:
    """The prescribed driver angle phi(t), rad."""
    return _prescribed(mech).angle(jnp.asarray(t, dtype=float))


def positions(mech: Mechanism, t: Float[ArrayLike, ""]) -> Float[Array, "bodies 3"]:
    """Centre-of-mass poses (x [m], y [m], angle [rad]) of every body at time t."""
    model = as_model(mech)
    return centre_poses(model, ideal_poses(model, driver_angle(model, t))).reshape(-1, 3)


def kinematics(
    mech: Mechanism, t: Float[ArrayLike, ""]
) -> tuple[Float[Array, "bodies 3"], Float[Array, "bodies 3"], Float[Array, "bodies 3"]]:
    """Ideal (Q, dQ/dt, d2Q/dt2) at time t, per body; units m, rad and their per-second rates."""
    mech = as_model(mech)
    t = jnp.asarray(t, dtype=float)

    def vel(tt):
        return jax.jvp(lambda s: positions(mech, s), (tt,), (jnp.ones_like(tt),))

    (q, qd), (_, qdd) = jax.jvp(vel, (t,), (jnp.ones_like(t),))
    return q, qd, qdd


def transmission_angle(mech: Mechanism, t: Float[ArrayLike, ""]) -> Float[Array, ""]:
    """The ideal mechanism's transmission angle at time t, rad (zero when it defines none)."""
    return _transmission_angle(mech, jnp.ravel(positions(mech, t)))


def body_index(mech: Mechanism, body: str) -> int:
    """Position of ``body`` in the per-body arrays (sorted names)."""
    return as_model(mech).tree.bodies.index(body)


def _local(lk, site):
    return (lk.ground if site.body == GROUND else lk.bodies[site.body].points)[site.point].vector()


def joint_reactions(mech: Mechanism, t: Float[ArrayLike, ""]) -> tuple[dict[str, Array], Array]:
    """The ideal mechanism's joint loads at time t by inverse dynamics (Newton-Euler for
    every body; the loads of a one-degree-of-freedom linkage are determinate).

    Returns:
        ``(forces, torque)``: the force on each joint's pin side (the slider, for a
        prismatic joint) from its hole side (the guide), N, (2,) by joint name; and the
        driver's torque, N m.
    """
    model = as_model(mech)
    lk, tree = model.linkage, model.tree
    driver = _prescribed(model)
    q, qd, qdd = kinematics(model, t)
    frames = ideal_poses(model, driver.angle(jnp.asarray(t, dtype=float)))
    poses = {b: frames[i] for i, b in enumerate(tree.bodies)}
    poses[GROUND] = jnp.zeros(3)
    joints = tree.joints

    def unknowns(x):
        """(force on the pin side, moment on it) per joint, and the torque."""
        out = {}
        for k, j in enumerate(joints):
            conn = lk.connections[j]
            out[j] = conn.load((x[2 * k], x[2 * k + 1]), poses[conn.sites()[0].body][2])
        return out, x[2 * len(joints)]

    def residual(x):
        loads, torque = unknowns(x)
        res = []
        for i, b in enumerate(tree.bodies):
            body = lk.bodies[b]
            force = jnp.stack([0.0, -body.mass * lk.gravity])
            moment = torque if b == driver.body else jnp.zeros(())
            com = q[i, :2]
            for j in joints:
                hole, pin = lk.connections[j].sites()
                f, m = loads[j]
                f = jnp.stack([jnp.asarray(v, dtype=float) for v in f])
                for site, sign in ((pin, 1.0), (hole, -1.0)):
                    if site.body == b:
                        point = world_point(poses[b], _local(lk, site))
                        force = force + sign * f
                        moment = moment + sign * (cross(point - com, f) + m)
            res += [
                body.mass * qdd[i, 0] - force[0],
                body.mass * qdd[i, 1] - force[1],
                body.inertia * qdd[i, 2] - moment,
            ]
        return jnp.stack(res)

    size = 2 * len(joints) + 1
    zero = jnp.zeros(size)
    a = jax.jacfwd(residual)(zero)
    x = solve_dense(a, -residual(zero))
    loads, torque = unknowns(x)
    return {j: jnp.stack([jnp.asarray(v, dtype=float) for v in loads[j][0]]) for j in joints}, torque


def driving_moment(mech: Mechanism, t: Float[ArrayLike, ""]) -> Float[Array, ""]:
    """The moment the driver needs to keep the ideal mechanism on its prescribed motion, N m."""
    return joint_reactions(mech, t)[1]


def contact_margin(mech: Mechanism, samples: int = 360, softness: float = 0.005) -> Float[Array, ""]:
    """How far the ideal mechanism's joint loads stay from zero over one revolution:
    ``min_j softmin_t |F_j(t)| / rms_t |F_j(t)|`` over the joints j with clearance (all
    joints where none has) ([`joint_reactions`][jaxcrank.physics.ideal.joint_reactions]), dimensionless, in [0, 1].

    A pin in a clearance joint stays pressed against its bearing while the load through
    the joint keeps its magnitude; where |F_j| passes near zero the load reverses and the
    pin crosses the clearance, the contact-loss that starts impacts. 0: some load
    reverses through zero; near 1: every load is nearly constant in magnitude.

    Args:
        mech: the mechanism (its clearances, laws and friction are not used).
        samples: equally spaced times over one revolution (>= 8).
        softness: width of the soft minimum over the samples,
            ``-s ln mean exp(-x / s)`` with s = ``softness`` (> 0; it exceeds the sampled
            minimum by at most s ln ``samples``): smooth in the design, so it can be
            differentiated.

    Raises:
        ValueError: ``samples < 8`` or ``softness <= 0``.
    """
    if int(samples) < 8 or not softness > 0:
        raise ValueError(f"samples = {samples} must be >= 8 and softness = {softness} > 0")
    mech = as_model(mech)
    joints = mech.tree.cut or mech.tree.joints
    ts = mech.period * jnp.arange(int(samples), dtype=float) / int(samples)
    forces = jax.vmap(lambda t: joint_reactions(mech, t)[0])(ts)
    margins = []
    for j in joints:
        size = safe_norm(forces[j])
        x = size / jnp.sqrt(jnp.mean(size**2))
        margins.append(-softness * jax.scipy.special.logsumexp(-x / softness, b=1.0 / x.shape[0]))
    out = margins[0]
    for m in margins[1:]:
        out = jnp.minimum(out, m)
    return out
