"""Validation rig: impacts of a free pin on a bearing wall, through the same joint law as
the mechanism (a [`Clearance`][jaxcrank.physics.joints.Clearance] joint: its contact, friction and memory laws and
radii, asked for its forces and its state's rate exactly as the equations of motion ask it).
Used to check each contact law's achieved restitution against the exact relation
``chi (1 + e) = ln((1 + chi) / (1 - chi e))`` (model.md):

* [`rebound_ratio`][jaxcrank.analysis.validation.wall_impact.rebound_ratio]: one impact on a fixed wall (jitted,
  differentiable);
* [`single_impact`][jaxcrank.analysis.validation.wall_impact.single_impact]: the same impact with its onset, memory
  and duration;
* [`reimpact`][jaxcrank.analysis.validation.wall_impact.reimpact]: a pin that rebounds and is caught again by the
  wall a few microseconds after separating (the memory must forget the first impact);
* [`slow_approach`][jaxcrank.analysis.validation.wall_impact.slow_approach]: an impact at a slow approach speed
  reached under a normal acceleration through the last microseconds before onset (the
  memory must follow the speed up to onset).

The pin moves along x (the wall's normal, no tangential motion, so no friction) in a
hole that is at rest or, in the last two, moves along x with a prescribed piecewise
constant acceleration; the hole moves at constant velocity during every impact, so each
impact is a free impact in the hole's frame and the exact relation applies to its
relative rebound speed. The run's state is ``(pin x, pin v, hole x, hole v, the joint
law's state)`` in SI units (m, m/s; the law's entries as it names them,
[`state_names`][jaxcrank.physics.joints.AbstractJointLaw.state_names]).
"""

from __future__ import annotations

from typing import NamedTuple

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ...physics.joints import Clearance, JointAccelerations, JointKinematics
from .events import crossings, dense_solve


def _initial(joint: Clearance, gap, approach_speed) -> Array:
    """The run's state with the pin ``gap`` (m) inside the wall at +x moving towards it at
    ``approach_speed`` (m/s), the hole at rest, the law's state at its initial value but
    the memory (its first entry) already equal to the approach speed."""
    law = jnp.asarray(joint.initial_state(), dtype=float).at[0].set(approach_speed)
    free = jnp.stack([joint.clearance - gap, jnp.asarray(approach_speed, dtype=float), 0.0, 0.0])
    return jnp.concatenate([free, law])


def _free_flight(joint: Clearance, approach_speed):
    """How long a run with one impact at ``approach_speed`` (m/s) lasts after the onset, s:
    2 ms, but at most c / v, so that the rebounding pin cannot reach the opposite wall
    (2 c / (e v) away). A longer impact has not ended by then
    ([`rebound_ratio`][jaxcrank.analysis.validation.wall_impact.rebound_ratio] gives NaN,
    [`single_impact`][jaxcrank.analysis.validation.wall_impact.single_impact] raises)."""
    return jnp.minimum(2e-3, joint.clearance / approach_speed)


@eqx.filter_jit
def rebound_ratio(
    joint: Clearance,
    approach_speed: Float[ArrayLike, ""] = 0.5,
    pin_mass: Float[ArrayLike, ""] = 1.0,
    rtol=1e-10,
    atol=1e-12,
) -> Float[Array, ""]:
    """Radial rebound speed / approach speed of a pin (mass ``pin_mass``, kg) that
    reaches the wall of the clearance joint ``joint``'s bearing at ``approach_speed``
    (m/s), no gravity, no tangential motion.

    Returns:
        The ratio, dimensionless; NaN if the pin is still in contact at the end of the
        run (an impact longer than the run, see `_free_flight`).
    """
    # start 1 um before the wall, memory already equal to the approach speed, hole at rest
    y0 = _initial(joint, 1e-6, approach_speed)
    t1 = 1e-6 / approach_speed + _free_flight(joint, approach_speed)
    sol = _solve_wall(joint, pin_mass, [0.0, 1.0], [0.0], y0, t1, rtol, atol)
    ratio = -sol.ys[-1, 1] / approach_speed
    return jnp.where(_penetration(joint, sol.ys[-1]) < 0.0, ratio, jnp.nan)


# --------------------------------------------------------------------------- moving wall


def _hole_acceleration(t, breaks, accelerations):
    """The hole's acceleration, m/s^2: ``accelerations[i]`` on [breaks[i], breaks[i + 1]),
    zero outside [breaks[0], breaks[-1])."""
    i = jnp.searchsorted(breaks, t, side="right") - 1
    inside = (i >= 0) & (i < accelerations.shape[0])
    return jnp.where(inside, accelerations[jnp.clip(i, 0, accelerations.shape[0] - 1)], 0.0)


def _along_x(value) -> Array:
    return jnp.stack([value, jnp.zeros_like(value)])


def wall_kinematics(y: Float[ArrayLike, " state"]) -> JointKinematics:
    """The [`JointKinematics`][jaxcrank.physics.joints.JointKinematics] of the free pin and its hole for the run's
    state ``y`` (SI): both on the x axis, neither turning."""
    zero = jnp.zeros(())
    return JointKinematics(
        hole_position=_along_x(y[2]),
        hole_velocity=_along_x(y[3]),
        hole_angle=zero,
        hole_angular_velocity=zero,
        pin_position=_along_x(y[0]),
        pin_velocity=_along_x(y[1]),
        pin_angle=zero,
        pin_angular_velocity=zero,
    )


def _wall_field(t, y, args):
    """dy/dt of the run's state y = (pin x, pin v, hole x, hole v, law state) (SI) for a
    free pin (mass ``pin_mass``, kg) in the bearing of the clearance joint ``joint``, whose
    hole moves along x with the piecewise constant acceleration of `_hole_acceleration`;
    ``args = (joint, pin_mass, breaks, accelerations)``. The pin's force and the law
    state's rate come from the joint law (``forces``, ``state_rate``)."""
    joint, pin_mass, breaks, accelerations = args
    kin = wall_kinematics(y)
    law_state = y[4:]
    forces = joint.forces(kin, law_state)
    a_pin = forces.force[0] / pin_mass
    a_hole = _hole_acceleration(t, breaks, accelerations)
    zero = jnp.zeros(())
    acc = JointAccelerations(_along_x(a_hole), zero, _along_x(a_pin), zero)
    law_rate = joint.state_rate(kin, acc, law_state, forces)
    return jnp.concatenate([jnp.stack([y[1], a_pin, y[3], a_hole]), law_rate])


def _solve_wall(joint, pin_mass, breaks, accelerations, y0, t1, rtol, atol):
    """The free pin's run from 0 to ``t1`` (s) with dense output (Dopri8, steps landing
    on the ``breaks``); a solve that does not finish raises (diffrax's ``throw``)."""
    breaks = jnp.asarray(breaks, dtype=float)
    accelerations = jnp.asarray(accelerations, dtype=float)
    controller = diffrax.PIDController(rtol=rtol, atol=atol, jump_ts=breaks)
    args = (joint, jnp.asarray(pin_mass, dtype=float), breaks, accelerations)
    y0 = jnp.asarray(y0, dtype=float)
    return dense_solve(_wall_field, diffrax.Dopri8(), 0.0, t1, 1e-9, y0, args, controller, 400_000, throw=True)


def _penetration(joint, y):
    """delta = (pin x - hole x) - c of the run's state(s) ``y``, m."""
    return y[..., 0] - y[..., 2] - joint.clearance


@eqx.filter_jit
def _penetration_at(joint, sol, ts):
    """The penetration of the dense solution ``sol`` at the times ``ts`` (s), m."""
    return jax.vmap(lambda t: _penetration(joint, sol.evaluate(t)))(ts)


def _crossings(joint, sol, t0, t1, n=4000, upward=True):
    """Times in (t0, t1) where the penetration crosses zero upwards (or downwards),
    bracketed on ``n`` equally spaced times and located by bisection on the dense
    output ([`jaxcrank.analysis.validation.events.crossings`][])."""
    penetration = lambda t: np.asarray(_penetration_at(joint, sol, jnp.asarray(t, dtype=float)))
    ts = np.linspace(t0, t1, n)
    lo, hi = crossings(penetration, ts, penetration(ts), upward=upward)
    return list(hi if upward else lo)


class WallImpact(NamedTuple):
    """One impact of a [`single_impact`][jaxcrank.analysis.validation.wall_impact.single_impact],
    [`reimpact`][jaxcrank.analysis.validation.wall_impact.reimpact] or
    [`slow_approach`][jaxcrank.analysis.validation.wall_impact.slow_approach] run (SI).

    Attributes:
        restitution: relative rebound speed / relative approach speed at onset,
            dimensionless.
        approach_speed: delta_dot at onset, m/s.
        memory_at_onset: the approach-speed memory at onset (the law state's first
            entry), m/s.
        since_separation: time from the previous separation to this onset, s
            (inf when there was none).
        duration: time from the onset to the separation, s.
        law_state_at_separation: the joint law's state at the separation (SI, in the
            order of its ``state_names``).
    """

    restitution: float
    approach_speed: float
    memory_at_onset: float
    since_separation: float
    duration: float
    law_state_at_separation: np.ndarray


def _wall_impact(joint: Clearance, sol, onset: float, since_separation: float, what: str) -> WallImpact:
    """The [`WallImpact`][jaxcrank.analysis.validation.wall_impact.WallImpact] of the impact of ``sol`` (a
    `_solve_wall` solution) that starts at ``onset`` (s) and must have ended by the end of
    the run (else RuntimeError naming ``what``)."""
    y_on = np.asarray(sol.evaluate(onset))
    y1 = np.asarray(sol.ys[-1])
    if _penetration(joint, y1) >= 0.0:
        raise RuntimeError(f"{what} had not ended at the end of the run")
    separation = _crossings(joint, sol, onset, float(sol.ts[-1]), upward=False)[0]
    return WallImpact(
        restitution=-(y1[1] - y1[3]) / (y_on[1] - y_on[3]),
        approach_speed=float(y_on[1] - y_on[3]),
        memory_at_onset=float(y_on[4]),
        since_separation=since_separation,
        duration=float(separation - onset),
        law_state_at_separation=np.asarray(sol.evaluate(separation))[4:],
    )


def single_impact(
    joint: Clearance,
    approach_speed: Float[ArrayLike, ""] = 0.5,
    pin_mass: Float[ArrayLike, ""] = 1.0,
    rtol=1e-10,
    atol=1e-12,
) -> WallImpact:
    """The impact of [`rebound_ratio`][jaxcrank.analysis.validation.wall_impact.rebound_ratio] (a pin of
    ``pin_mass``, kg, reaching the fixed wall of ``joint``'s bearing at ``approach_speed``,
    m/s) as a [`WallImpact`][jaxcrank.analysis.validation.wall_impact.WallImpact], with its duration.

    Raises:
        RuntimeError: the impact had not ended at the end of the run.
    """
    y0 = _initial(joint, 1e-6, approach_speed)
    t_on = 1e-6 / float(approach_speed)
    t1 = t_on + float(_free_flight(joint, approach_speed))
    sol = _solve_wall(joint, pin_mass, [0.0, 1.0], [0.0], y0, t1, rtol, atol)
    return _wall_impact(joint, sol, t_on, float("inf"), "the impact")


def reimpact(
    joint: Clearance,
    approach_speed: Float[ArrayLike, ""] = 0.5,
    second_speed: Float[ArrayLike, ""] = 0.2,
    delay: Float[ArrayLike, ""] = 1e-6,
    ramp: Float[ArrayLike, ""] = 4e-6,
    pin_mass: Float[ArrayLike, ""] = 1.0,
    rtol=1e-10,
    atol=1e-12,
) -> WallImpact:
    """The second impact of a pin that hits the bearing wall of the clearance joint
    ``joint`` at ``approach_speed`` (m/s, hole at rest), rebounds, and is caught by the
    wall again: ``delay`` (s) after the separation the hole accelerates uniformly for
    ``ramp`` (s) to the velocity at which it approaches the free pin at ``second_speed``
    (m/s), then moves at constant velocity. With the defaults the second onset comes
    about 10 us after the separation, when a memory that relaxes with 10 us would still
    hold a third of the first impact's speed.

    Raises:
        RuntimeError: the second impact had not ended at the end of the run.
    """
    y0 = _initial(joint, 1e-7, approach_speed)
    # the first impact alone (hole at rest): its separation time and rebound speed
    t_first = 1e-7 / approach_speed + 1e-3
    first = _solve_wall(joint, pin_mass, [0.0, 1.0], [0.0], y0, t_first, rtol, atol)
    t_sep = _crossings(joint, first, 0.0, t_first, upward=False)[0]
    v_rebound = float(first.evaluate(t_sep)[1])
    hole_speed = v_rebound - second_speed  # (pin - hole) velocity along n = +x is second_speed
    t_a = t_sep + delay
    breaks = [t_a, t_a + ramp]
    t1 = t_a + ramp + 200e-6 + 3e-3 * (0.5 / second_speed) ** 0.2
    sol = _solve_wall(joint, pin_mass, breaks, [hole_speed / ramp], y0, t1, rtol, atol)
    onset = [t for t in _crossings(joint, sol, t_sep + 1e-9, t1) if t > t_sep][0]
    return _wall_impact(joint, sol, onset, float(onset - t_sep), "the second impact")


def slow_approach(
    joint: Clearance,
    approach_speed: Float[ArrayLike, ""] = 0.02,
    deceleration: Float[ArrayLike, ""] = 1e3,
    duration: Float[ArrayLike, ""] = 1e-5,
    pin_mass: Float[ArrayLike, ""] = 1.0,
    rtol=1e-10,
    atol=1e-12,
) -> WallImpact:
    """An impact at ``approach_speed`` (m/s) on the bearing wall of the clearance joint
    ``joint`` reached under a normal deceleration: over the last ``duration`` (s) before
    onset the hole recedes with acceleration ``deceleration`` (m/s^2), so the approach
    speed falls from ``approach_speed + deceleration * duration`` to ``approach_speed``
    exactly at onset, and is constant from then on (the impact is free in the hole's
    frame). The memory must follow delta_dot to the onset: a freeze blended over 0.1 um
    of approach missed it by about 12 % here.

    Raises:
        RuntimeError: the impact had not ended at the end of the run.
    """
    v_a = approach_speed + deceleration * duration
    pre = 2e-6  # free approach before the deceleration
    gap0 = v_a * pre + v_a * duration - 0.5 * deceleration * duration**2
    t_on = pre + duration
    y0 = _initial(joint, gap0, v_a)
    t1 = t_on + 3e-3 * (0.5 / approach_speed) ** 0.2
    sol = _solve_wall(joint, pin_mass, [pre, t_on], [deceleration], y0, t1, rtol, atol)
    return _wall_impact(joint, sol, t_on, float("inf"), "the impact")
