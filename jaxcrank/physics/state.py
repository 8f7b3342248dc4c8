"""The state vector of a run with clearance joints and its scales (model.md, Eq. 14).

The solver state is the *deviation from the ideal mechanism* in generalized
coordinates s; which coordinates exist depends on which joints are ideal
([`jaxcrank.physics.model`][]). The state vector, every entry dimensionless
([`state_scales`][jaxcrank.physics.state.state_scales]), is
``y = (s, s', approach-speed memory per clearance joint, driver work, dissipated work)``.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .joints import clearance_joints, clearance_sites
from .params import Mechanism


def n_dof(mech: Mechanism) -> int:
    """Number of generalized coordinates s (static)."""
    return 2 * len(clearance_joints(mech))


def state_size(mech: Mechanism) -> int:
    """Length of the state vector (static): s, s', one memory per clearance joint, two works."""
    return 2 * n_dof(mech) + len(clearance_joints(mech)) + 2


class State(NamedTuple):
    """The entries of a state vector in SI units ([`unpack`][jaxcrank.physics.state.unpack]); each with the
    state's leading axes, if any."""

    deviation: jax.Array  # s, generalized-coordinate deviations from the ideal mechanism (m, rad)
    deviation_rate: jax.Array  # s', m/s and rad/s
    approach_memory: jax.Array  # approach-speed memory per clearance joint, m/s
    driver_work: jax.Array  # work done by the driving moment, J
    dissipated_work: jax.Array  # work dissipated by contact damping and friction, J


def unpack(mech: Mechanism, y: Float[ArrayLike, "*batch state"]) -> State:
    """The scaled state ``y`` (shape (..., [`state_size`][jaxcrank.physics.state.state_size] )) as a
    [`State`][jaxcrank.physics.state.State] in SI units."""
    phys = y * state_scales(mech)
    n, k = n_dof(mech), len(clearance_joints(mech))
    return State(phys[..., :n], phys[..., n : 2 * n], phys[..., 2 * n : 2 * n + k], phys[..., -2], phys[..., -1])


def auxiliary(mech: Mechanism, y: Float[ArrayLike, "*batch state"]) -> Float[Array, "*batch aux"]:
    """The state entries after the coordinates and their rates (approach-speed
    memories, m/s, then driver and dissipated work, J), in SI units, shape
    (..., state_size - 2 n_dof): what
    [`state_from_eccentricities`][jaxcrank.physics.kinematics.state_from_eccentricities] takes as ``rest``."""
    return (y * state_scales(mech))[..., 2 * n_dof(mech) :]


def length_scale(mech: Mechanism) -> Float[Array, ""]:
    """Reference length of the deviations, m: the largest clearance (1 m if none)."""
    clearances = [site.joint(mech).clearance for site in clearance_sites(mech)]
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


def initial_state(mech: Mechanism) -> Float[Array, " state"]:
    """Pins centred and moving with the ideal mechanism; memories and work zero."""
    return jnp.zeros(state_size(mech))
