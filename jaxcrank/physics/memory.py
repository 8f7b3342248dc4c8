"""The approach-speed memory law (model.md, "Approach-speed memory").

The contact laws divide by ``delta_dot_minus``, the normal speed at the onset of an
impact. Each clearance joint carries it as a state, the approach-speed memory: while
the pins are apart it tracks the normal speed exactly ([`memory_tracking`][jaxcrank.physics.memory.memory_tracking]
weights the time derivative of [`memory_target`][jaxcrank.physics.memory.memory_target]), it freezes in contact, and it
relaxes onto its target away from the wall ([`memory_relaxation`][jaxcrank.physics.memory.memory_relaxation]). Like the
laws
in [`jaxcrank.physics.laws`][] these are small pure functions of physical
arguments; [`jaxcrank.physics.contact.approach_memory_rate`][] assembles them into
d(memory)/dt, for the mechanism and for the free pin of [`jaxcrank.analysis.validation.wall_impact`][]
alike.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from . import laws


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
    rate, as a function of the [`freeze_coordinate`][jaxcrank.physics.memory.freeze_coordinate] x.

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
    for the [`freeze_coordinate`][jaxcrank.physics.memory.freeze_coordinate] x (time to or from the wall in units of
    t_f = ``freeze_time``).

    Contract:

    - zero in contact and within t_f of it (S(x - 1) = 0 for x <= 1; 1 for
      x >= 2), so the relaxation cannot pull the memory off the exact tracking of
      [`memory_tracking`][jaxcrank.physics.memory.memory_tracking] before an onset;
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
    """Time derivative of [`memory_target`][jaxcrank.physics.memory.memory_target] along the motion, m/s^2.

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
