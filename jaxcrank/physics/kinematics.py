"""Kinematics with clearance joints: full coordinates from the deviations s, their
rates, and the pin-in-hole eccentricities (model.md, "Coordinates").

A map ``Q = full_positions(s, t)`` gives the full coordinates
Q = (x2, y2, theta2, x3): with clearance at both joints Q = Q_ideal + s; with one
ideal joint s = (dtheta2, dx3) and the ideal joint's pin holds its rod end.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from . import ideal
from .joints import JOINTS, clearance_joints, clearance_sites
from .params import Mechanism
from .state import state_scales, unpack


def full_positions(mech: Mechanism, s: Float[ArrayLike, " dof"], t: Float[ArrayLike, ""]) -> Float[Array, " 4"]:
    """Full coordinates Q = (x2, y2, theta2, x3) from deviations s at time t."""
    qi = ideal.positions(mech, t)
    sites = clearance_sites(mech)
    if len(sites) == len(JOINTS):
        return qi + s
    if not sites:
        return qi
    (anchor,) = (site for site in JOINTS if site.joint(mech).ideal)  # its pin holds its rod end
    th2 = qi[2] + s[0]
    x3 = qi[3] + s[1]
    half = 0.5 * mech.rod_length * jnp.stack([jnp.cos(th2), jnp.sin(th2)])
    centre = anchor.to_centre(anchor.pin_position(mech, x3, t), half)
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


def joint_eccentricities(
    mech: Mechanism, t: Float[ArrayLike, ""], y: Float[ArrayLike, " state"]
) -> tuple[Float[Array, "joints 2"], Float[Array, "joints 2"]]:
    """Eccentricities d = pin centre - hole centre, m, and their rates, m/s, of every
    joint with clearance ([`clearance_joints`][jaxcrank.physics.joints.clearance_joints] order),
    shape (joints, 2) each."""
    state = unpack(mech, y)
    q, qd, _ = coordinates(mech, state.deviation, state.deviation_rate, t)
    d, dd = [], []
    for site in clearance_sites(mech):
        m = site.motion(mech, q, qd, t)
        d.append(m.pin_position - m.hole_position)
        dd.append(m.pin_velocity - m.hole_velocity)
    return jnp.stack(d), jnp.stack(dd)


def _check_all_clearance(mech: Mechanism, what: str) -> None:
    if len(clearance_joints(mech)) != len(JOINTS):
        raise ValueError(f"{what}() needs clearance at both B and C")


def eccentricities(
    mech: Mechanism, t: Float[ArrayLike, ""], y: Float[ArrayLike, " state"]
) -> tuple[Float[Array, "2 2"], Float[Array, "2 2"]]:
    """Pin-in-bearing state of a run with clearance at B and C: eccentricities
    d = pin centre - hole centre, shape (2, 2) for (B, C), m, and their rates, m/s.

    Raises:
        ValueError: if a joint of ``mech`` is ideal.
    """
    _check_all_clearance(mech, "eccentricities")
    return joint_eccentricities(mech, t, y)


def state_from_eccentricities(
    mech: Mechanism,
    t: Float[ArrayLike, ""],
    d: Float[ArrayLike, "2 2"],
    d_rate: Float[ArrayLike, "2 2"],
    rest: Float[ArrayLike, " aux"],
) -> Float[Array, " state"]:
    """Inverse of [`eccentricities`][jaxcrank.physics.kinematics.eccentricities]: the scaled state whose pins sit at
    eccentricities ``d`` (2, 2) m moving at ``d_rate`` (2, 2) m/s in bearings B and
    C at time t; ``rest`` are the remaining state entries in SI units (approach-speed
    memories, m/s; driver and dissipated work, J), scaled here for ``mech``.
    Used to carry a pin-in-bearing state over to another design: the state scales
    depend on the design's clearances, so a scaled entry carried over unchanged
    would change its physical value with the clearance.

    Raises:
        ValueError: if a joint of ``mech`` is ideal.
    """
    _check_all_clearance(mech, "state_from_eccentricities")
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
