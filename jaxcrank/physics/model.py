"""Equations of motion of the slider-crank with clearance joints (model.md, Eq. 14).

The solver state is the *deviation from the ideal mechanism* in generalized
coordinates s, so s = 0 is the ideal motion and the zero-clearance limit is exact
in floating point. Which coordinates exist depends on which joints are ideal:

========================  ====================================================
clearance at B and C      s = (dx2, dy2, dtheta2, dx3): 4 degrees of freedom
ideal B, clearance at C   s = (dtheta2, dx3): rod end B follows the crank pin
clearance at B, ideal C   s = (dtheta2, dx3): rod end C follows the slider pin
both ideal                no s: the closed-form mechanism
========================  ====================================================

A map ``Q = full_positions(s, t)`` gives the full coordinates
Q = (x2, y2, theta2, x3); the equations of motion are Lagrange's
``J^T M J s'' = J^T (F - M gamma)`` with ``J = dQ/ds`` and ``gamma = dJ/dt s'``
computed by forward-mode autodiff, so ideal-joint reactions drop out and are
recovered afterwards by :func:`jaxcrank.physics.ideal.reactions`.

The state vector (all entries dimensionless, see :func:`state_scales`) is
``y = (s, s', approach-speed memory per clearance joint, driver work, dissipated work)``.
The two work entries are accumulated energy flows for the energy balance; they
do not feed back into the dynamics.

:func:`evaluate` computes every physical quantity at one (t, y); the vector field
and all outputs use it, so outputs are functions of the solution.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ..numerics import linalg
from . import ideal, laws
from .params import Joint, Material, Mechanism

# --------------------------------------------------------------------------- layout


def clearance_joints(mech: Mechanism) -> tuple[str, ...]:
    """Names of the joints with clearance, in state order (static)."""
    return tuple(name for name, j in (("B", mech.joint_B), ("C", mech.joint_C)) if not j.ideal)


def n_dof(mech: Mechanism) -> int:
    """Number of generalized coordinates s (static)."""
    return 2 * len(clearance_joints(mech))


def state_size(mech: Mechanism) -> int:
    return 2 * n_dof(mech) + len(clearance_joints(mech)) + 2


class State(NamedTuple):
    """The entries of a state vector in SI units (:func:`unpack`); each with the
    state's leading axes, if any."""

    deviation: jax.Array  # s, generalized-coordinate deviations from the ideal mechanism (m, rad)
    deviation_rate: jax.Array  # s', m/s and rad/s
    approach_memory: jax.Array  # approach-speed memory per clearance joint, m/s
    driver_work: jax.Array  # work done by the driving moment, J
    dissipated_work: jax.Array  # work dissipated by contact damping and friction, J


def unpack(mech: Mechanism, y: Float[ArrayLike, "*batch state"]) -> State:
    """The scaled state ``y`` (shape (..., :func:`state_size`)) as a :class:`State` in SI units."""
    phys = y * state_scales(mech)
    n, k = n_dof(mech), len(clearance_joints(mech))
    return State(phys[..., :n], phys[..., n : 2 * n], phys[..., 2 * n : 2 * n + k], phys[..., -2], phys[..., -1])


def auxiliary(mech: Mechanism, y: Float[ArrayLike, "*batch state"]) -> Float[Array, "*batch aux"]:
    """The state entries after the coordinates and their rates (approach-speed
    memories, m/s, then driver and dissipated work, J), in SI units, shape
    (..., state_size - 2 n_dof): what :func:`state_from_eccentricities` takes as ``rest``."""
    return (y * state_scales(mech))[..., 2 * n_dof(mech) :]


def length_scale(mech: Mechanism) -> Float[Array, ""]:
    """Reference length of the deviations, m: the largest clearance (1 m if none)."""
    clearances = [getattr(mech, f"joint_{j}").clearance for j in clearance_joints(mech)]
    if not clearances:
        return jnp.asarray(1.0)
    return jax.lax.stop_gradient(jnp.max(jnp.stack(clearances)))


def state_scales(mech: Mechanism) -> Float[Array, " state"]:
    """Physical value of one unit of each state entry.

    Lengths in clearances l, rod angle in l / L2 rad, velocities in those times
    omega, approach-speed memory in l omega m/s, work in m2 (L1 omega)(l omega) J.
    The scales carry no gradient: they only condition the error control, so a
    scalar ``rtol``/``atol`` means the same for every entry.
    """
    ell = length_scale(mech)
    sg = jax.lax.stop_gradient
    omega, l2 = sg(mech.crank_speed), sg(mech.rod_length)
    n = n_dof(mech)
    if n == 4:
        q = jnp.stack([ell, ell, ell / l2, ell])
    elif n == 2:
        q = jnp.stack([ell / l2, ell])
    else:
        q = jnp.zeros(0)
    k = len(clearance_joints(mech))
    memory = jnp.full((k,), ell * omega)
    work = sg(mech.rod_mass * mech.crank_length * omega) * ell * omega
    return jnp.concatenate([q, q * omega, memory, jnp.stack([work, work])])


# --------------------------------------------------------------------------- kinematics


def full_positions(mech: Mechanism, s: Float[ArrayLike, " dof"], t: Float[ArrayLike, ""]) -> Float[Array, " 4"]:
    """Full coordinates Q = (x2, y2, theta2, x3) from deviations s at time t."""
    qi = ideal.positions(mech, t)
    joints = clearance_joints(mech)
    if joints == ("B", "C"):
        return qi + s
    if not joints:
        return qi
    th2 = qi[2] + s[0]
    x3 = qi[3] + s[1]
    half = 0.5 * mech.rod_length * jnp.stack([jnp.cos(th2), jnp.sin(th2)])
    if joints == ("C",):  # ideal B: rod end B on the crank pin
        centre = ideal.crank_pin(mech, t) + half
    else:  # ideal C: rod end C on the slider pin
        centre = jnp.stack([x3, mech.offset]) - half
    return jnp.stack([centre[0], centre[1], th2, x3])


def coordinates(
    mech: Mechanism, s: Float[ArrayLike, " dof"], sd: Float[ArrayLike, " dof"], t: Float[ArrayLike, ""]
) -> tuple[Float[Array, " 4"], Float[Array, " 4"], Float[Array, " 4"]]:
    """Full coordinates Q, their rate dQ/dt and ``gamma`` = d2Q/dt2 at zero s''
    (the velocity-product terms), from the deviations s, s' at time t."""
    t = jnp.asarray(t, dtype=float)
    one = jnp.ones_like(t)

    def velocity(s_, t_):
        return jax.jvp(lambda a, b: full_positions(mech, a, b), (s_, t_), (sd, one))

    (q, qd), (_, gamma) = jax.jvp(velocity, (s, t), (sd, one))
    return q, qd, gamma


def _rod_half(mech: Mechanism, q):
    """Vector from the rod's centre of mass to its end C (to end B: minus it), m."""
    return 0.5 * mech.rod_length * jnp.stack([jnp.cos(q[2]), jnp.sin(q[2])])


def joint_points(
    mech: Mechanism, name: str, q: Float[ArrayLike, " 4"], qd: Float[ArrayLike, " 4"], t: Float[ArrayLike, ""]
) -> tuple[Float[Array, " 2"], Float[Array, " 2"], Float[Array, " 2"], Float[Array, " 2"]]:
    """(pin centre, pin velocity, hole centre, hole velocity) of joint ``name`` for full
    coordinates Q = (x2, y2, theta2, x3) and their rates, m and m/s. The hole is on the
    rod (its end B or C); the pin is the crank pin (B) or the slider pin (C)."""
    half = _rod_half(mech, q)
    half_dot = qd[2] * _perp(half)
    if name == "B":
        pin = ideal.crank_pin(mech, t)
        return pin, mech.crank_speed * _perp(pin), q[:2] - half, qd[:2] - half_dot
    pin = jnp.stack([q[3], jnp.asarray(mech.offset, dtype=float)])
    return pin, jnp.stack([qd[3], jnp.zeros_like(qd[3])]), q[:2] + half, qd[:2] + half_dot


def joint_accelerations(
    mech: Mechanism,
    name: str,
    q: Float[ArrayLike, " 4"],
    qd: Float[ArrayLike, " 4"],
    qdd: Float[ArrayLike, " 4"],
    t: Float[ArrayLike, ""],
) -> tuple[Float[Array, " 2"], Float[Array, " 2"]]:
    """(pin acceleration, hole acceleration) of joint ``name``, m/s^2: the time
    derivatives of :func:`joint_points`' velocities (the crank turns at constant speed)."""
    half = _rod_half(mech, q)
    half_ddot = qdd[2] * _perp(half) - qd[2] ** 2 * half
    if name == "B":
        return -(mech.crank_speed**2) * ideal.crank_pin(mech, t), qdd[:2] - half_ddot
    return jnp.stack([qdd[3], jnp.zeros_like(qdd[3])]), qdd[:2] + half_ddot


def eccentricities(
    mech: Mechanism, t: Float[ArrayLike, ""], y: Float[ArrayLike, " state"]
) -> tuple[Float[Array, "2 2"], Float[Array, "2 2"]]:
    """Pin-in-bearing state of a run with clearance at B and C: eccentricities
    d = pin centre - hole centre, shape (2, 2) for (B, C), m, and their rates, m/s."""
    if clearance_joints(mech) != ("B", "C"):
        raise ValueError("eccentricities() needs clearance at both B and C")
    return joint_eccentricities(mech, t, y)


def joint_eccentricities(
    mech: Mechanism, t: Float[ArrayLike, ""], y: Float[ArrayLike, " state"]
) -> tuple[Float[Array, "joints 2"], Float[Array, "joints 2"]]:
    """Eccentricities d = pin centre - hole centre, m, and their rates, m/s, of every
    joint with clearance (:func:`clearance_joints` order), shape (joints, 2) each."""
    state = unpack(mech, y)
    q, qd, _ = coordinates(mech, state.deviation, state.deviation_rate, t)
    d, dd = [], []
    for name in clearance_joints(mech):
        pin, pin_vel, hole, hole_vel = joint_points(mech, name, q, qd, t)
        d.append(pin - hole)
        dd.append(pin_vel - hole_vel)
    return jnp.stack(d), jnp.stack(dd)


def state_from_eccentricities(
    mech: Mechanism,
    t: Float[ArrayLike, ""],
    d: Float[ArrayLike, "2 2"],
    d_rate: Float[ArrayLike, "2 2"],
    rest: Float[ArrayLike, " aux"],
) -> Float[Array, " state"]:
    """Inverse of :func:`eccentricities`: the scaled state whose pins sit at
    eccentricities ``d`` (2, 2) m moving at ``d_rate`` (2, 2) m/s in bearings B and
    C at time t; ``rest`` are the remaining state entries in SI units (approach-speed
    memories, m/s; driver and dissipated work, J), scaled here for ``mech``.
    Used to carry a pin-in-bearing state over to another design: the state scales
    depend on the design's clearances, so a scaled entry carried over unchanged
    would change its physical value with the clearance."""
    if clearance_joints(mech) != ("B", "C"):
        raise ValueError("state_from_eccentricities() needs clearance at both B and C")
    t = jnp.asarray(t, dtype=float)

    def positions(d_, t_):
        a = ideal.crank_pin(mech, t_)
        hole_b = a - d_[0]
        sin2 = (mech.offset - d_[1, 1] - hole_b[1]) / mech.rod_length
        th2 = jnp.arcsin(sin2)
        u = jnp.stack([jnp.cos(th2), sin2])
        x3 = hole_b[0] + mech.rod_length * u[0] + d_[1, 0]
        centre = hole_b + 0.5 * mech.rod_length * u
        return jnp.stack([centre[0], centre[1], th2, x3]) - ideal.positions(mech, t_)

    s, sd = jax.jvp(positions, (d, t), (d_rate, jnp.ones_like(t)))
    return jnp.concatenate([s, sd, rest]) / state_scales(mech)


def memory_target(
    eccentricity: Float[ArrayLike, " 2"], relative_velocity: Float[ArrayLike, " 2"], clearance: Float[ArrayLike, ""]
) -> Float[Array, ""]:
    """The normal speed the approach-speed memory tracks, m/s.

    ``d . v / max(|d|, c/2)``: equal to delta_dot = n . v wherever an impact can
    start (|d| >= c/2), and smooth near the centre, where n = d/|d| has
    derivatives ~1/|d| that would blow up gradients after the pins-centred start.
    """
    eps = laws.safe_norm(eccentricity)
    return jnp.dot(eccentricity, relative_velocity) / jnp.maximum(eps, 0.5 * clearance)


# The approach-speed memory's blend just before contact (see memory_tracking):
# w(x) = S(x) + x^3 (1 - x)^3 (340 - 540 x), S the quintic smoothstep. The two
# coefficients make the integrals of 1 - w and of x (1 - w) over [0, 1] vanish.
_BLEND_BUMP = (340.0, -540.0)


def freeze_coordinate(penetration: Float[ArrayLike, ""], target: Float[ArrayLike, ""], contact) -> Float[Array, ""]:
    """Time to or from the wall at the current normal speed, in units of
    ``contact.freeze_time``: ``x = gap / (t_f sqrt(target^2 + v_min^2))`` with gap =
    -delta (m), t_f = ``freeze_time``, the memory target (the normal speed, m/s)
    and v_min = ``min_approach_speed``. x < 0 in contact; before an onset x is the
    time left to it, after a separation the time since it (at constant speed)."""
    speed = jnp.sqrt(target**2 + contact.min_approach_speed**2)
    return -penetration / (contact.freeze_time * speed)


def memory_tracking(x: Float[ArrayLike, "*shape"]) -> Float[Array, "*shape"]:
    """Weight w of the exact tracking term d(target)/dt in the approach-speed memory's
    rate, as a function of the :func:`freeze_coordinate` x.

    Contract: w = 1 for x >= 1, w = 0 for x <= 0 (contact), C2 in between, and
    ``int_0^1 (1 - w) dx = int_0^1 x (1 - w) dx = 0``. Over the last t_f of
    approach the memory changes by ``int w d(delta_dot)`` instead of
    ``int d(delta_dot)``; at a normal acceleration a that is nearly constant over
    t_f, the memory at onset misses delta_dot there by O((a t_f / v)^3) relative
    (a plain smoothstep, which lags, misses it by a t_f / (2 v)). w overshoots to
    about 1.6 mid-blend and dips to about 0.88 near its end: a weight, not a
    fraction. A sharp switch at delta = 0 would make d(memory)/dt jump at the onset,
    and reverse-mode gradients through the discrete solve miss the resulting
    saltation term (measured: 2.4e-4 relative error in d/d(clearance)); the blend
    ends before contact, where the force is still zero.
    """
    x = jnp.clip(x, 0.0, 1.0)
    b1, b2 = _BLEND_BUMP
    return laws.smoothstep(x) + x**3 * (1.0 - x) ** 3 * (b1 + b2 * x)


def memory_relaxation(x: Float[ArrayLike, ""], contact) -> Float[Array, ""]:
    """Rate, 1/s, at which the approach-speed memory relaxes onto its target:
    ``S(x - 1) (1 / memory_time + (1 - S(x t_f / reset_window - 1)) / reset_time)``
    for the :func:`freeze_coordinate` x (time to or from the wall in units of
    t_f = ``freeze_time``).

    Contract:

    - zero in contact and within t_f of it (S(x - 1) = 0 for x <= 1; 1 for
      x >= 2), so the relaxation cannot pull the memory off the exact tracking of
      :func:`memory_tracking` before an onset;
    - ``1 / memory_time`` everywhere else;
    - plus ``1 / reset_time`` while the time to or from the wall is below
      ``reset_window`` (fading out by twice it): right after a separation the
      offset the last impact left decays by about
      exp(-1.5 (reset_window - t_f) / reset_time) (exp(-27) with the defaults)
      within 2 reset_window, whatever the time until the next onset, and again
      on the way to an onset from further away.

    A short ``reset_time`` costs no step-size limit outside the window; inside it
    the solver resolves the memory's fast decay, about 25 steps per separation on
    the paper mechanism at rtol = atol = 1e-6 (docs/numerics.md).
    """
    c = contact
    near = 1.0 - laws.smoothstep(x * c.freeze_time / c.reset_window - 1.0)
    return laws.smoothstep(x - 1.0) * (1.0 / c.memory_time + near / c.reset_time)


def memory_target_rate(
    eccentricity: Float[ArrayLike, " 2"],
    relative_velocity: Float[ArrayLike, " 2"],
    relative_acceleration: Float[ArrayLike, " 2"],
    clearance: Float[ArrayLike, ""],
) -> Float[Array, ""]:
    """Time derivative of :func:`memory_target` along the motion, m/s^2.

    With m = max(|d|, c/2): ``(v.v + d.a) / m - (d.v) m' / m^2``, where
    ``m' = d.v / |d|`` while |d| > c/2 and 0 inside (c is constant in time).
    """
    eps = laws.safe_norm(eccentricity)
    half = 0.5 * clearance
    outside = eps > half
    d_v = jnp.dot(eccentricity, relative_velocity)
    m = jnp.maximum(eps, half)
    m_rate = jnp.where(outside, d_v / jnp.where(outside, eps, 1.0), 0.0)
    return (
        jnp.dot(relative_velocity, relative_velocity) + jnp.dot(eccentricity, relative_acceleration)
    ) / m - d_v * m_rate / m**2


def _perp(v):
    """Rotate a planar vector by +90 degrees."""
    return jnp.stack([-v[1], v[0]])


class JointContact(NamedTuple):
    """Everything about one clearance joint at one instant (SI)."""

    eccentricity: jax.Array  # pin centre minus hole centre, m, (2,)
    penetration: jax.Array  # delta = |d| - c, m (negative when separated)
    penetration_rate: jax.Array  # delta_dot, m/s (positive approaching)
    slip_speed: jax.Array  # v_t, m/s
    normal_force: jax.Array  # F_n >= 0, N
    friction_force: jax.Array  # F_t along the tangent, N
    force_on_pin: jax.Array  # -F_n n + F_t t, N, (2,)
    pin_point: jax.Array  # contact point on the pin, m, (2,)
    hole_point: jax.Array  # contact point on the hole, m, (2,)
    memory_rate: jax.Array  # relaxation part of d(approach-speed memory)/dt, m/s^2
    memory_tracking: jax.Array  # weight of d(target)/dt in it: 1 while separated, 0 in contact (memory_tracking)
    dissipation: jax.Array  # power dissipated by damping and friction, W
    elastic_energy: jax.Array  # energy stored in the contact, J


def joint_contact(
    mech: Mechanism,
    joint: Joint,
    pin_material: Material,
    hole_material: Material,
    pin_pos: Float[ArrayLike, " 2"],
    pin_vel: Float[ArrayLike, " 2"],
    pin_omega: Float[ArrayLike, ""],
    hole_pos: Float[ArrayLike, " 2"],
    hole_vel: Float[ArrayLike, " 2"],
    hole_omega: Float[ArrayLike, ""],
    memory: Float[ArrayLike, ""],
) -> JointContact:
    """Kinematics and forces of one clearance joint (model.md, paper Eq. 1-13).

    ``memory`` is the approach-speed memory state (m/s). Positions in m,
    velocities in m/s, angular velocities in rad/s.
    """
    d = pin_pos - hole_pos
    eps = laws.safe_norm(d)
    centred = eps > 0.0
    n = jnp.where(centred, d / jnp.where(centred, eps, 1.0), 0.0)
    tangent = _perp(n)
    r_h, r_p = joint.hole_radius, joint.pin_radius
    delta = eps - joint.clearance
    v_rel = pin_vel - hole_vel
    delta_dot = jnp.dot(n, v_rel)
    v_t = jnp.dot(tangent, v_rel) + pin_omega * r_p - hole_omega * r_h

    c = mech.contact
    compliance = laws.effective_compliance(pin_material.compliance, hole_material.compliance)
    approach = jnp.maximum(memory, c.min_approach_speed)
    geometry = dict(hole_radius=r_h, pin_radius=r_p, compliance_sum=compliance, exponent=c.exponent)
    f_n, f_el = c.law.normal_force(delta, delta_dot, approach, c.restitution, **geometry)
    fr = mech.friction
    f_t = fr.law.force(v_t, f_n, fr.coefficient, fr.stick_speed, fr.slip_speed)
    # Only the relaxation part here; evaluate() adds the target's time derivative.
    target = memory_target(d, v_rel, joint.clearance)
    x = freeze_coordinate(delta, target, c)
    tracking = memory_tracking(x)
    memory_rate = memory_relaxation(x, c) * (target - memory)
    return JointContact(
        eccentricity=d,
        penetration=delta,
        penetration_rate=delta_dot,
        slip_speed=v_t,
        normal_force=f_n,
        friction_force=f_t,
        force_on_pin=-f_n * n + f_t * tangent,
        pin_point=pin_pos + r_p * n,
        hole_point=hole_pos + r_h * n,
        memory_rate=memory_rate,
        memory_tracking=tracking,
        dissipation=(f_n - f_el) * delta_dot - f_t * v_t,
        elastic_energy=c.law.elastic_energy(delta, **geometry),
    )


# --------------------------------------------------------------------------- evaluation


class Frame(NamedTuple):
    """The mechanism at one instant; SI units, angles in rad."""

    t: jax.Array
    crank_angle: jax.Array
    q: jax.Array  # (x2, y2, theta2, x3)
    qd: jax.Array
    qdd: jax.Array
    ideal_q: jax.Array
    ideal_qd: jax.Array
    ideal_qdd: jax.Array
    eccentricity_B: jax.Array
    eccentricity_C: jax.Array
    penetration_B: jax.Array
    penetration_C: jax.Array
    normal_force_B: jax.Array  # contact force; for an ideal joint, the reaction magnitude
    normal_force_C: jax.Array
    friction_force_B: jax.Array
    friction_force_C: jax.Array
    slip_speed_B: jax.Array
    slip_speed_C: jax.Array
    driving_moment: jax.Array
    ideal_driving_moment: jax.Array
    kinetic_energy: jax.Array
    potential_energy: jax.Array
    contact_energy: jax.Array
    driver_work: jax.Array
    dissipated_work: jax.Array
    state_rate: jax.Array  # dy/dt of the scaled state


class Dynamics(NamedTuple):
    """What the equations of motion give at one instant (SI): full coordinates and
    their first two rates, the clearance joints' contacts, ideal-joint reactions,
    the driving moment and dy/dt of the scaled state."""

    q: jax.Array
    qd: jax.Array
    qdd: jax.Array
    contacts: dict
    reaction_B: jax.Array  # force of an ideal joint's pin on the rod, N (zeros for a clearance joint)
    reaction_C: jax.Array
    driving_moment: jax.Array
    state_rate: jax.Array


def dynamics(mech: Mechanism, t: Float[ArrayLike, ""], y: Float[ArrayLike, " state"]) -> Dynamics:
    """The equations of motion at time t (s) for scaled state y: only what dy/dt
    needs (:func:`evaluate` adds the output-only quantities)."""
    n = n_dof(mech)
    joints = clearance_joints(mech)
    k = len(joints)
    scale = state_scales(mech)
    phys = y * scale
    s, sd, memory = phys[:n], phys[n : 2 * n], phys[2 * n : 2 * n + k]
    t = jnp.asarray(t, dtype=float)
    q, qd, gamma = coordinates(mech, s, sd, t)
    mass = ideal.mass_matrix(mech)
    centre = q[:2]

    applied = ideal.rod_gravity(mech)
    contacts, velocities = {}, {}
    for i, name in enumerate(joints):
        pin, pin_vel, hole, hole_vel = joint_points(mech, name, q, qd, t)
        if name == "B":
            cj = joint_contact(
                mech,
                mech.joint_B,
                mech.crank_material,
                mech.rod_material,
                pin,
                pin_vel,
                mech.crank_speed,
                hole,
                hole_vel,
                qd[2],
                memory[i],
            )
        else:
            cj = joint_contact(
                mech,
                mech.joint_C,
                mech.slider_material,
                mech.rod_material,
                pin,
                pin_vel,
                0.0,
                hole,
                hole_vel,
                qd[2],
                memory[i],
            )
        f_hole = -cj.force_on_pin
        arm = cj.hole_point - centre
        slider_x = cj.force_on_pin[0] if name == "C" else 0.0
        applied = applied + jnp.stack([f_hole[0], f_hole[1], arm[0] * f_hole[1] - arm[1] * f_hole[0], slider_x])
        contacts[name] = cj
        velocities[name] = pin_vel - hole_vel

    if n == 4:  # Q = Q_ideal + s: J is the identity, M is diagonal
        sdd = (applied - mass * gamma) / mass
        qdd = sdd + gamma
    elif n == 2:
        jac = jax.jacfwd(lambda a: full_positions(mech, a, t))(s)
        lhs = jac.T @ (mass[:, None] * jac)
        rhs = jac.T @ (applied - mass * gamma)
        sdd = linalg.solve_2x2(lhs, rhs)
        qdd = jac @ sdd + gamma
    else:
        sdd = jnp.zeros(0)
        qdd = gamma

    # While separated the memory follows d(delta_dot)/dt exactly (the time derivative
    # of the memory target along the motion), so at impact onset it equals the
    # approach speed without lag; the relaxation term in memory_rate only erases the
    # offset left by the previous rebound.
    memory_rates = []
    for name in joints:
        cj = contacts[name]
        pin_acc, hole_acc = joint_accelerations(mech, name, q, qd, qdd, t)
        target_rate = memory_target_rate(
            cj.eccentricity, velocities[name], pin_acc - hole_acc, getattr(mech, f"joint_{name}").clearance
        )
        memory_rates.append(cj.memory_rate + cj.memory_tracking * target_rate)

    residual = mass * qdd - applied
    react_b, react_c = ideal.reactions(mech, q, residual, mech.joint_B.ideal, mech.joint_C.ideal)
    if "B" in contacts:
        moment = ideal.driving_moment_from_pin_force(mech, t, -contacts["B"].force_on_pin, contacts["B"].pin_point)
    else:
        moment = ideal.driving_moment_from_pin_force(mech, t, react_b, ideal.crank_pin(mech, t))
    dissipation = sum((cj.dissipation for cj in contacts.values()), jnp.zeros(()))
    rate = (
        jnp.concatenate(
            [
                sd,
                sdd,
                jnp.stack(memory_rates) if k else jnp.zeros(0),
                jnp.stack([moment * mech.crank_speed, dissipation]),
            ]
        )
        / scale
    )
    return Dynamics(q, qd, qdd, contacts, react_b, react_c, moment, rate)


def evaluate(mech: Mechanism, t: Float[ArrayLike, ""], y: Float[ArrayLike, " state"]) -> Frame:
    """All physical quantities at time t (s) for scaled state y; also dy/dt."""
    t = jnp.asarray(t, dtype=float)
    dyn = dynamics(mech, t, y)
    q, qd, qdd, contacts = dyn.q, dyn.qd, dyn.qdd, dyn.contacts
    react_b, react_c, moment, rate = dyn.reaction_B, dyn.reaction_C, dyn.driving_moment, dyn.state_rate
    state = unpack(mech, y)
    mass = ideal.mass_matrix(mech)
    th1 = ideal.crank_angle(mech, t)

    qi, qdi, qddi = ideal.kinematics(mech, t)
    kinetic = 0.5 * jnp.sum(mass * qd**2)
    potential = mech.rod_mass * mech.gravity * q[
        1
    ] + mech.crank_mass * mech.gravity * 0.5 * mech.crank_length * jnp.sin(th1)
    zero2, zero = jnp.zeros(2), jnp.zeros(())

    def pick(name, field, ideal_value):
        return getattr(contacts[name], field) if name in contacts else ideal_value

    return Frame(
        t=t,
        crank_angle=th1,
        q=q,
        qd=qd,
        qdd=qdd,
        ideal_q=qi,
        ideal_qd=qdi,
        ideal_qdd=qddi,
        eccentricity_B=pick("B", "eccentricity", zero2),
        eccentricity_C=pick("C", "eccentricity", zero2),
        penetration_B=pick("B", "penetration", zero),
        penetration_C=pick("C", "penetration", zero),
        normal_force_B=pick("B", "normal_force", laws.safe_norm(react_b)),
        normal_force_C=pick("C", "normal_force", laws.safe_norm(react_c)),
        friction_force_B=pick("B", "friction_force", zero),
        friction_force_C=pick("C", "friction_force", zero),
        slip_speed_B=pick("B", "slip_speed", zero),
        slip_speed_C=pick("C", "slip_speed", zero),
        driving_moment=moment,
        ideal_driving_moment=ideal.driving_moment(mech, t),
        kinetic_energy=kinetic,
        potential_energy=potential,
        contact_energy=sum((cj.elastic_energy for cj in contacts.values()), jnp.zeros(())),
        driver_work=state.driver_work,
        dissipated_work=state.dissipated_work,
        state_rate=rate,
    )


@jax.jit
def vector_field(t: Float[ArrayLike, ""], y: Float[ArrayLike, " state"], mech: Mechanism) -> Float[Array, " state"]:
    """dy/dt of the scaled state ``y`` (shape (state_size,)) at time ``t`` (s), for
    diffrax: ``diffrax.ODETerm(vector_field)`` with ``args=mech``.

    Jitted, so a solve holds one call of the field per solver stage, which JAX
    linearizes and transposes once (shorter compiles of gradients); XLA inlines it.
    """
    return dynamics(mech, t, y).state_rate


def initial_state(mech: Mechanism) -> Float[Array, " state"]:
    """Pins centred and moving with the ideal mechanism; memories and work zero."""
    return jnp.zeros(state_size(mech))
