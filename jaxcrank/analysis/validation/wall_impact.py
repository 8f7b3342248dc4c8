"""Validation rig: impacts of a free pin on a bearing wall, through the same joint model
as the mechanism ([`jaxcrank.physics.contact.joint_contact`][] and its approach-speed
memory).
Used to check each contact law's achieved restitution against the exact relation
``chi (1 + e) = ln((1 + chi) / (1 - chi e))`` (model.md):

* [`rebound_ratio`][jaxcrank.analysis.validation.wall_impact.rebound_ratio]: one impact on a fixed wall;
* [`reimpact`][jaxcrank.analysis.validation.wall_impact.reimpact] : a pin that rebounds and is caught again by the wall
a few
  microseconds after separating (the memory must forget the first impact);
* [`slow_approach`][jaxcrank.analysis.validation.wall_impact.slow_approach] : an impact at a slow approach speed reached
under a normal
  acceleration through the last microseconds before onset (the memory must follow
  the speed up to onset).

In the last two the hole (bearing) moves along x with a prescribed piecewise
constant acceleration; it moves at constant velocity during every impact, so each
impact is a free impact in the hole's frame and the exact relation applies to its
relative rebound speed.
"""

from __future__ import annotations

from typing import NamedTuple

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ...physics import model
from ...physics.params import Mechanism
from .events import crossings, dense_solve


@eqx.filter_jit
def rebound_ratio(
    mech: Mechanism,
    approach_speed: Float[ArrayLike, ""] = 0.5,
    pin_mass: Float[ArrayLike, ""] = 1.0,
    rtol=1e-10,
    atol=1e-12,
) -> Float[Array, ""]:
    """Radial rebound speed / approach speed of a pin (mass ``pin_mass``, kg) that
    reaches the wall of joint B's bearing at ``approach_speed`` (m/s), no
    gravity, no tangential motion. Contact law and restitution from ``mech``.
    """
    c = mech.joint_B.clearance
    # start 1 um before the wall, memory already equal to the approach speed, hole at rest
    y0 = jnp.stack([c - 1e-6, approach_speed, 0.0, 0.0, approach_speed])
    # past the contact (~0.2 ms for 1 kg at 0.5 m/s) but before the pin can cross
    # the bearing (2c / (e v) >= 8 ms) to the opposite wall
    t1 = 1e-6 / approach_speed + 2e-3
    sol = _solve_wall(mech, pin_mass, [0.0, 1.0], [0.0], y0, t1, rtol, atol)
    return -sol.ys[-1, 1] / approach_speed


# --------------------------------------------------------------------------- moving wall


def _hole_acceleration(t, breaks, accelerations):
    """The hole's acceleration, m/s^2: ``accelerations[i]`` on [breaks[i], breaks[i + 1]),
    zero outside [breaks[0], breaks[-1])."""
    i = jnp.searchsorted(breaks, t, side="right") - 1
    inside = (i >= 0) & (i < accelerations.shape[0])
    return jnp.where(inside, accelerations[jnp.clip(i, 0, accelerations.shape[0] - 1)], 0.0)


def _wall_field(t, y, args):
    """dy/dt of y = (pin x, pin v, hole x, hole v, memory) for a free pin (mass
    ``pin_mass``, kg) in joint B's bearing whose hole moves along x with the piecewise
    constant acceleration of `_hole_acceleration`; ``args = (mech, pin_mass,
    breaks, accelerations)``."""
    mech, pin_mass, breaks, accelerations = args
    joint = mech.joint_B
    x, v, xh, vh, memory = y
    motion = model.JointMotion(
        pin_position=jnp.stack([x, 0.0]),
        pin_velocity=jnp.stack([v, 0.0]),
        pin_angular_velocity=0.0,
        hole_position=jnp.stack([xh, 0.0]),
        hole_velocity=jnp.stack([vh, 0.0]),
        hole_angular_velocity=0.0,
    )
    contact = model.joint_contact(mech, joint, mech.crank_material, mech.rod_material, motion, memory)
    a_pin = contact.force_on_pin[0] / pin_mass
    a_hole = _hole_acceleration(t, breaks, accelerations)
    memory_rate = model.approach_memory_rate(
        contact, jnp.stack([v - vh, 0.0]), jnp.stack([a_pin - a_hole, 0.0]), joint.clearance
    )
    return jnp.stack([v, a_pin, vh, a_hole, memory_rate])


def _solve_wall(mech, pin_mass, breaks, accelerations, y0, t1, rtol, atol):
    """The free pin's run from 0 to ``t1`` (s) with dense output (Dopri8, steps landing
    on the ``breaks``); a solve that does not finish raises (diffrax's ``throw``)."""
    breaks = jnp.asarray(breaks, dtype=float)
    accelerations = jnp.asarray(accelerations, dtype=float)
    controller = diffrax.PIDController(rtol=rtol, atol=atol, jump_ts=breaks)
    args = (mech, pin_mass, breaks, accelerations)
    y0 = jnp.asarray(y0, dtype=float)
    return dense_solve(_wall_field, diffrax.Dopri8(), 0.0, t1, 1e-9, y0, args, controller, 400_000, throw=True)


def _penetration(mech, y):
    return y[..., 0] - y[..., 2] - mech.joint_B.clearance


def _crossings(mech, sol, t0, t1, n=4000, upward=True):
    """Times in (t0, t1) where the penetration crosses zero upwards (or downwards),
    bracketed on ``n`` equally spaced times and located by bisection on the dense
    output ([`jaxcrank.analysis.validation.events.crossings`][])."""
    penetration = jax.jit(jax.vmap(lambda t: _penetration(mech, sol.evaluate(t))))
    ts = np.linspace(t0, t1, n)
    lo, hi = crossings(penetration, ts, penetration(ts), upward=upward)
    return list(hi if upward else lo)


class WallImpact(NamedTuple):
    """One impact of a [`reimpact`][jaxcrank.analysis.validation.wall_impact.reimpact] or
    [`slow_approach`][jaxcrank.analysis.validation.wall_impact.slow_approach] run (SI).

    Attributes:
        restitution: relative rebound speed / relative approach speed at onset.
        approach_speed: delta_dot at onset, m/s.
        memory_at_onset: the approach-speed memory at onset (what the damping uses), m/s.
        since_separation: time from the previous separation to this onset, s
            (inf when there was none).
    """

    restitution: float
    approach_speed: float
    memory_at_onset: float
    since_separation: float


def _wall_impact(mech: Mechanism, sol, onset: float, since_separation: float, what: str) -> WallImpact:
    """The [`WallImpact`][jaxcrank.analysis.validation.wall_impact.WallImpact] of the impact of ``sol`` (a `_solve_wall`
    solution)
    that starts at ``onset`` (s) and must have ended by the end of the run (else
    RuntimeError naming ``what``)."""
    y_on = np.asarray(sol.evaluate(onset))
    y1 = np.asarray(sol.ys[-1])
    if _penetration(mech, y1) >= 0.0:
        raise RuntimeError(f"{what} had not ended at the end of the run")
    return WallImpact(
        restitution=-(y1[1] - y1[3]) / (y_on[1] - y_on[3]),
        approach_speed=float(y_on[1] - y_on[3]),
        memory_at_onset=float(y_on[4]),
        since_separation=since_separation,
    )


def reimpact(
    mech: Mechanism,
    approach_speed: Float[ArrayLike, ""] = 0.5,
    second_speed: Float[ArrayLike, ""] = 0.2,
    delay: Float[ArrayLike, ""] = 1e-6,
    ramp: Float[ArrayLike, ""] = 4e-6,
    pin_mass: Float[ArrayLike, ""] = 1.0,
    rtol=1e-10,
    atol=1e-12,
) -> WallImpact:
    """The second impact of a pin that hits joint B's bearing wall at ``approach_speed``
    (m/s, hole at rest), rebounds, and is caught by the wall again: ``delay`` (s)
    after the separation the hole accelerates uniformly for ``ramp`` (s) to the
    velocity at which it approaches the free pin at ``second_speed`` (m/s), then
    moves at constant velocity. With the defaults the second onset comes about
    10 us after the separation, when a memory that relaxes with 10 us would still
    hold a third of the first impact's speed.
    """
    c = mech.joint_B.clearance
    y0 = np.array([c - 1e-7, approach_speed, 0.0, 0.0, approach_speed])
    # the first impact alone (hole at rest): its separation time and rebound speed
    t_first = 1e-7 / approach_speed + 1e-3
    first = _solve_wall(mech, pin_mass, [0.0, 1.0], [0.0], y0, t_first, rtol, atol)
    t_sep = _crossings(mech, first, 0.0, t_first, upward=False)[0]
    v_rebound = float(first.evaluate(t_sep)[1])
    hole_speed = v_rebound - second_speed  # (pin - hole) velocity along n = +x is second_speed
    t_a = t_sep + delay
    breaks = [t_a, t_a + ramp]
    t1 = t_a + ramp + 200e-6 + 3e-3 * (0.5 / second_speed) ** 0.2
    sol = _solve_wall(mech, pin_mass, breaks, [hole_speed / ramp], y0, t1, rtol, atol)
    onset = [t for t in _crossings(mech, sol, t_sep + 1e-9, t1) if t > t_sep][0]
    return _wall_impact(mech, sol, onset, float(onset - t_sep), "the second impact")


def slow_approach(
    mech: Mechanism,
    approach_speed: Float[ArrayLike, ""] = 0.02,
    deceleration: Float[ArrayLike, ""] = 1e3,
    duration: Float[ArrayLike, ""] = 1e-5,
    pin_mass: Float[ArrayLike, ""] = 1.0,
    rtol=1e-10,
    atol=1e-12,
) -> WallImpact:
    """An impact at ``approach_speed`` (m/s) on joint B's bearing wall reached under a
    normal deceleration: over the last ``duration`` (s) before onset the hole
    recedes with acceleration ``deceleration`` (m/s^2), so the approach speed
    falls from ``approach_speed + deceleration * duration`` to ``approach_speed``
    exactly at onset, and is constant from then on (the impact is free in the
    hole's frame). The memory must follow delta_dot to the onset: a freeze
    blended over 0.1 um of approach missed it by about 12 % here.
    """
    c = mech.joint_B.clearance
    v_a = approach_speed + deceleration * duration
    pre = 2e-6  # free approach before the deceleration
    gap0 = v_a * pre + v_a * duration - 0.5 * deceleration * duration**2
    t_on = pre + duration
    y0 = np.array([c - gap0, v_a, 0.0, 0.0, v_a])
    t1 = t_on + 3e-3 * (0.5 / approach_speed) ** 0.2
    sol = _solve_wall(mech, pin_mass, [pre, t_on], [deceleration], y0, t1, rtol, atol)
    return _wall_impact(mech, sol, t_on, float("inf"), "the impact")
