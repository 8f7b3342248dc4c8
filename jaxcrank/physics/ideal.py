"""The ideal (zero-clearance) offset slider-crank in closed form.

Coordinates follow model.md: crank angle theta1 (prescribed), rod centre of mass
(x2, y2) at mid-length, rod angle theta2 from +x, slider position x3 on the line
y = e. Positions are closed form; velocities and accelerations are their exact
time derivatives (forward-mode autodiff of the closed form, no finite
differences). Inverse dynamics gives the joint reactions and the driving moment.

All functions take a [`Mechanism`][jaxcrank.physics.params.Mechanism] and a scalar time t (s);
``jax.vmap`` over t for trajectories.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ..numerics import linalg
from .laws import safe_norm
from .params import Mechanism


def crank_angle(mech: Mechanism, t: Float[ArrayLike, ""]) -> Float[Array, ""]:
    """theta1(t) = theta1_0 + omega t, rad."""
    return mech.initial_crank_angle + mech.crank_speed * t


def crank_pin(mech: Mechanism, t: Float[ArrayLike, ""]) -> Float[Array, " 2"]:
    """Crank pin centre P_B = L1 (cos theta1, sin theta1), m."""
    th1 = crank_angle(mech, t)
    return mech.crank_length * jnp.stack([jnp.cos(th1), jnp.sin(th1)])


def positions(mech: Mechanism, t: Float[ArrayLike, ""]) -> Float[Array, " 4"]:
    """Ideal generalized positions Q = (x2 [m], y2 [m], theta2 [rad], x3 [m]).

    ``sin theta2 = (e - L1 sin theta1) / L2``, ``x3 = L1 cos theta1 + L2 cos theta2``.
    Requires L2 > L1 + |e| (checked by [`Mechanism`][jaxcrank.physics.params.Mechanism]).
    """
    th1 = crank_angle(mech, t)
    l1, l2, e = mech.crank_length, mech.rod_length, mech.offset
    s2 = (e - l1 * jnp.sin(th1)) / l2
    th2 = jnp.arcsin(s2)
    c2 = jnp.sqrt(1.0 - s2**2)
    x2 = l1 * jnp.cos(th1) + 0.5 * l2 * c2
    y2 = l1 * jnp.sin(th1) + 0.5 * l2 * s2
    x3 = l1 * jnp.cos(th1) + l2 * c2
    return jnp.stack([x2, y2, th2, x3])


def kinematics(
    mech: Mechanism, t: Float[ArrayLike, ""]
) -> tuple[Float[Array, " 4"], Float[Array, " 4"], Float[Array, " 4"]]:
    """Ideal (Q, dQ/dt, d2Q/dt2) at time t; units m, rad, and their per-second rates."""
    t = jnp.asarray(t, dtype=float)

    def vel(tt):
        return jax.jvp(lambda s: positions(mech, s), (tt,), (jnp.ones_like(tt),))

    (q, qd), (_, qdd) = jax.jvp(vel, (t,), (jnp.ones_like(t),))
    return q, qd, qdd


def transmission_angle(rod_angle: Float[ArrayLike, "*shape"]) -> Float[Array, "*shape"]:
    """Transmission angle alpha = arccos(-sin theta2), rad (paper Eq. 17-18).

    Equals ``arccos((L1 sin theta1 - e) / L2)`` for the ideal mechanism, and the
    paper's Eq. 18 (rod end heights) with clearance, since
    ``y_B - y_C = -L2 sin theta2``.
    """
    return jnp.arccos(jnp.clip(-jnp.sin(rod_angle), -1.0, 1.0))


def mass_matrix(mech: Mechanism) -> Float[Array, " 4"]:
    """Diagonal mass matrix of (x2, y2, theta2, x3): (m2, m2, J2, m3); kg, kg m^2."""
    return jnp.stack([mech.rod_mass, mech.rod_mass, mech.rod_inertia, mech.slider_mass])


def rod_ends(mech: Mechanism, q: Float[ArrayLike, " 4"]) -> tuple[Float[Array, " 2"], Float[Array, " 2"]]:
    """Rod joint-end points (B_rod, C_rod) for generalized positions q, m."""
    u2 = jnp.stack([jnp.cos(q[2]), jnp.sin(q[2])])
    centre = q[:2]
    half = 0.5 * mech.rod_length * u2
    return centre - half, centre + half


def _cross(r, f):
    return r[0] * f[1] - r[1] * f[0]


def reactions(
    mech: Mechanism, q: Float[ArrayLike, " 4"], residual: Float[ArrayLike, " 4"], ideal_B: bool, ideal_C: bool
) -> tuple[Float[Array, " 2"], Float[Array, " 2"]]:
    """Forces on the rod from the pins of the *ideal* joints, N.

    ``residual = M q'' - F_applied`` (generalized, on (x2, y2, theta2, x3)) is what
    the ideal joints must supply. A force F_B at rod end B contributes
    ``(F_x, F_y, r_BG x F, 0)``; F_C at rod end C contributes
    ``(F_x, F_y, r_CG x F, -F_x)`` (the slider feels -F_C; the guide takes y).
    Solved in the least-squares sense (exact when the motion satisfies the
    constraints). Returns ``(F_B, F_C)``, zeros for clearance joints.
    """
    b_end, c_end = rod_ends(mech, q)
    centre = q[:2]
    columns = []
    if ideal_B:
        r = b_end - centre
        columns += [jnp.stack([1.0, 0.0, -r[1], 0.0]), jnp.stack([0.0, 1.0, r[0], 0.0])]
    if ideal_C:
        r = c_end - centre
        columns += [jnp.stack([1.0, 0.0, -r[1], -1.0]), jnp.stack([0.0, 1.0, r[0], 0.0])]
    zero = jnp.zeros(2)
    if not columns:
        return zero, zero
    a = jnp.stack(columns, axis=1)
    normal, rhs = a.T @ a, a.T @ residual
    # plain-op linear algebra: a LAPACK call would take a solver loop that evaluates
    # outputs (jaxcrank.numerics.tracking) off XLA's one-kernel path
    lam = linalg.solve_2x2(normal, rhs) if len(columns) == 2 else linalg.inverse(normal) @ rhs
    f_b = lam[:2] if ideal_B else zero
    f_c = lam[-2:] if ideal_C else zero
    return f_b, f_c


def driving_moment_from_pin_force(
    mech: Mechanism,
    t: Float[ArrayLike, ""],
    force_on_rod_at_B: Float[ArrayLike, " 2"],
    contact_point: Float[ArrayLike, " 2"],
) -> Float[Array, ""]:
    """Driving moment that keeps the crank at constant speed, N m.

    ``M = p x F_B + m1 g (L1/2) cos theta1``, where F_B is the force the crank pin
    exerts on the rod (the crank feels -F_B) at point p (contact point on the pin).
    J_crank theta1'' = 0 at constant speed.
    """
    th1 = crank_angle(mech, t)
    return _cross(
        contact_point, force_on_rod_at_B
    ) + mech.crank_mass * mech.gravity * 0.5 * mech.crank_length * jnp.cos(th1)


def rod_gravity(mech: Mechanism) -> Float[Array, " 4"]:
    """Generalized gravity force on (x2, y2, theta2, x3), N and N m."""
    return jnp.stack([0.0, -mech.rod_mass * mech.gravity, 0.0, 0.0])


def driving_moment(mech: Mechanism, t: Float[ArrayLike, ""]) -> Float[Array, ""]:
    """Ideal driving moment by inverse dynamics, N m (the paper's Fig. 8 ideal curve)."""
    q, _, qdd = kinematics(mech, t)
    residual = mass_matrix(mech) * qdd - rod_gravity(mech)
    f_b, _ = reactions(mech, q, residual, True, True)
    return driving_moment_from_pin_force(mech, t, f_b, crank_pin(mech, t))


def joint_reactions(mech: Mechanism, t: Float[ArrayLike, ""]) -> tuple[Float[Array, " 2"], Float[Array, " 2"]]:
    """Forces on the rod from the crank pin B and the slider pin C of the ideal
    mechanism at time t, by inverse dynamics: ``(F_B, F_C)``, N (both joints ideal,
    whatever ``mech``'s joints are)."""
    q, _, qdd = kinematics(mech, t)
    residual = mass_matrix(mech) * qdd - rod_gravity(mech)
    return reactions(mech, q, residual, True, True)


def contact_margin(mech: Mechanism, samples: int = 360, softness: float = 0.005) -> Float[Array, ""]:
    """How far the ideal mechanism's joint loads stay from zero over one revolution:
    ``min_j softmin_t |F_j(t)| / rms_t |F_j(t)|`` over the joints j = B, C
    ([`joint_reactions`][jaxcrank.physics.ideal.joint_reactions]), dimensionless, in [0, 1].

    A pin in a clearance joint stays pressed against its bearing while the load through
    the joint keeps its magnitude; where |F_j| passes near zero the load reverses and the
    pin crosses the clearance, the contact-loss that starts impacts. 0: some load
    reverses through zero; near 1: both loads are nearly constant in magnitude.

    Args:
        mech: the mechanism (its clearances, laws and friction are not used).
        samples: equally spaced times over one crank period (>= 8).
        softness: width of the soft minimum over the samples,
            ``-s ln mean exp(-x / s)`` with s = ``softness`` (> 0; it exceeds the sampled minimum by at most s ln
            ``samples`` of the sampled minimum): smooth in the design, so it can be
            differentiated.

    Raises:
        ValueError: ``samples < 8`` or ``softness <= 0``.
    """
    if int(samples) < 8 or not softness > 0:
        raise ValueError(f"samples = {samples} must be >= 8 and softness = {softness} > 0")
    ts = mech.period * jnp.arange(int(samples), dtype=float) / int(samples)
    f_b, f_c = jax.vmap(lambda t: joint_reactions(mech, t))(ts)
    margins = []
    for f in (f_b, f_c):
        size = safe_norm(f)
        x = size / jnp.sqrt(jnp.mean(size**2))
        margins.append(-softness * jax.scipy.special.logsumexp(-x / softness, b=1.0 / x.shape[0]))
    return jnp.minimum(*margins)
