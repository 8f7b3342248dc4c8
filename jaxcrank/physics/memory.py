"""The approach-speed memory laws (model.md, "Approach-speed memory").

The contact laws divide by ``delta_dot_minus``, the normal speed at the onset of an
impact. Each dry clearance joint carries it as a state, the approach-speed memory: while
the pins are apart it tracks the normal speed exactly ([`memory_tracking`][jaxcrank.physics.memory.memory_tracking]
weights the time derivative of [`memory_target`][jaxcrank.physics.memory.memory_target]), and it relaxes onto its
target away from the wall ([`memory_relaxation`][jaxcrank.physics.memory.memory_relaxation]). What it does in contact
is the law's choice: [`FrozenMemory`][jaxcrank.physics.memory.FrozenMemory] holds it for the whole contact;
[`ForgettingMemory`][jaxcrank.physics.memory.ForgettingMemory] holds it for a dwell time (isolated impacts keep their
exact restitution) and then relaxes it toward a reference speed (model.md, "Persistent contact: the memory must
forget").

A memory law is an equinox Module ([`AbstractMemoryLaw`][jaxcrank.physics.memory.AbstractMemoryLaw]) that declares the
state it needs and gives its rate; the building blocks are small pure functions of
physical arguments, shared by every law and by the free pin of
[`jaxcrank.analysis.validation.wall_impact`][].
"""

from __future__ import annotations

import abc
from typing import ClassVar, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .params import ParameterError, _concrete, check_range
from .safemath import safe_norm, smoothstep


def memory_target(
    eccentricity: Float[ArrayLike, " 2"], relative_velocity: Float[ArrayLike, " 2"], clearance: Float[ArrayLike, ""]
) -> Float[Array, ""]:
    """The normal speed the approach-speed memory tracks, m/s.

    ``d . v / max(|d|, c/2)``: equal to delta_dot = n . v wherever an impact can
    start (|d| >= c/2), and smooth near the centre, where n = d/|d| has
    derivatives ~1/|d| that would blow up gradients after the pins-centred start.
    """
    eps = safe_norm(eccentricity)
    return jnp.dot(eccentricity, relative_velocity) / jnp.maximum(eps, 0.5 * clearance)


# The approach-speed memory's blend just before contact (see memory_tracking):
# w(x) = S(x) + x^3 (1 - x)^3 (340 - 540 x), S the quintic smoothstep. The two
# coefficients make the integrals of 1 - w and of x (1 - w) over [0, 1] vanish.
_BLEND_BUMP = (340.0, -540.0)


def freeze_coordinate(penetration: Float[ArrayLike, ""], target: Float[ArrayLike, ""], memory) -> Float[Array, ""]:
    """Time to or from the wall at the current normal speed, in units of
    ``memory.freeze_time`` (a memory law's settings): ``x = gap / (t_f sqrt(target^2 + v_min^2))`` with gap =
    -delta (m), t_f = ``freeze_time``, the memory target (the normal speed, m/s)
    and v_min = ``min_approach_speed``. x < 0 in contact; before an onset x is the
    time left to it, after a separation the time since it (at constant speed)."""
    speed = jnp.sqrt(target**2 + memory.min_approach_speed**2)
    return -penetration / (memory.freeze_time * speed)


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
    return smoothstep(x) + x**3 * (1.0 - x) ** 3 * (b1 + b2 * x)


def memory_relaxation(x: Float[ArrayLike, ""], memory) -> Float[Array, ""]:
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
    c = memory
    near = 1.0 - smoothstep(x * c.freeze_time / c.reset_window - 1.0)
    return smoothstep(x - 1.0) * (1.0 / c.memory_time + near / c.reset_time)


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
    eps = safe_norm(eccentricity)
    half = 0.5 * clearance
    outside = eps > half
    d_v = jnp.dot(eccentricity, relative_velocity)
    m = jnp.maximum(eps, half)
    m_rate = jnp.where(outside, d_v / jnp.where(outside, eps, 1.0), 0.0)
    return (
        jnp.dot(relative_velocity, relative_velocity) + jnp.dot(eccentricity, relative_acceleration)
    ) / m - d_v * m_rate / m**2


class MemoryInput(NamedTuple):
    """What a memory law reads of its joint at one instant (SI).

    Attributes:
        penetration: delta = |d| - c, m (negative when separated).
        target: the normal speed the memory tracks ([`memory_target`][jaxcrank.physics.memory.memory_target]), m/s.
        target_rate: its time derivative along the motion
            ([`memory_target_rate`][jaxcrank.physics.memory.memory_target_rate]), m/s^2.
    """

    penetration: Array
    target: Array
    target_rate: Array


def frozen_memory_rate(memory: Float[ArrayLike, ""], joint: MemoryInput, settings) -> Float[Array, ""]:
    """d(memory)/dt, m/s^2, of an approach-speed memory ``memory`` (m/s) that tracks the
    normal speed while the pins are apart and holds it in contact (the rate of
    [`FrozenMemory`][jaxcrank.physics.memory.FrozenMemory]):
    ``memory_relaxation(x) (target - memory) + memory_tracking(x) target_rate`` at the
    [`freeze_coordinate`][jaxcrank.physics.memory.freeze_coordinate] x of ``joint``.

    ``settings`` is a memory law with ``min_approach_speed`` (m/s), ``memory_time``,
    ``freeze_time``, ``reset_window`` and ``reset_time`` (s). Zero in contact.
    """
    x = freeze_coordinate(joint.penetration, joint.target, settings)
    relax = memory_relaxation(x, settings) * (joint.target - memory)
    return relax + memory_tracking(x) * joint.target_rate


def contact_weight(x: Float[ArrayLike, "*shape"]) -> Float[Array, "*shape"]:
    """How much the pins count as touching, dimensionless, as a function of the
    [`freeze_coordinate`][jaxcrank.physics.memory.freeze_coordinate] x: ``1 - S(x)``, S the quintic smoothstep.

    Contract: 1 in contact (x <= 0), 0 from one ``freeze_time`` away from the wall on
    (x >= 1), C2 in between, so a rate it weights switches on before an onset, where the
    contact force is still zero, not with a jump at it.
    """
    return 1.0 - smoothstep(x)


def smoothstep_integral(r: Float[ArrayLike, "*shape"]) -> Float[Array, "*shape"]:
    """``R(r) = int_0^r S(s) ds`` of the quintic smoothstep S, dimensionless:
    0 for r <= 0, ``r^4 (5/2 - 3 r + r^2)`` on [0, 1], ``r - 1/2`` for r >= 1 (C3:
    a ramp that starts with zero slope and curvature and ends at slope 1)."""
    r = jnp.asarray(r)
    inner = jnp.clip(r, 0.0, 1.0)
    return inner**4 * (2.5 - 3.0 * inner + inner**2) + jnp.maximum(r - 1.0, 0.0)


def dwell_gate(dwell: Float[ArrayLike, ""], t_dwell, gate_width) -> Float[Array, ""]:
    """The gate g of the forgetting, dimensionless: ``S((dwell - t_dwell) / gate_width)``
    for a contact that has lasted ``dwell`` (s): 0 up to ``t_dwell`` (s), 1 from
    ``t_dwell + gate_width`` on, C2. Over a contact longer than that it has acted for
    ``dwell - t_dwell - gate_width / 2`` (the smoothstep's integral over its width is 1/2)."""
    return smoothstep((dwell - t_dwell) / gate_width)


def dwell_rate(dwell: Float[ArrayLike, ""], x: Float[ArrayLike, ""], law) -> Float[Array, ""]:
    """d(dwell)/dt, s/s, of the contact dwell clock (s) of a
    [`ForgettingMemory`][jaxcrank.physics.memory.ForgettingMemory] ``law`` at the
    [`freeze_coordinate`][jaxcrank.physics.memory.freeze_coordinate] x:

    ``w(x) (1 - R((dwell - t_open) / gate_width)) - memory_relaxation(x) dwell``

    with w the [`contact_weight`][jaxcrank.physics.memory.contact_weight], R the
    [`smoothstep_integral`][jaxcrank.physics.memory.smoothstep_integral] and ``t_open = t_dwell + gate_width``
    (the gate fully open).

    Contract:

    - in contact the clock runs at rate 1 until the gate is open (dwell <= t_open),
      so it measures the time since the onset exactly (from about ``freeze_time / 2``
      at the onset, the blend of w before it);
    - it then stops: its rate falls to zero at ``t_open + 1.5 gate_width``, which it
      approaches with time constant ``gate_width``, so a contact that never ends leaves a
      bounded state that repeats with the mechanism (the memory no longer depends on
      the clock there: the gate is 1);
    - apart it decays at the memory's relaxation rate
      ([`memory_relaxation`][jaxcrank.physics.memory.memory_relaxation]): by about exp(-27) within
      two ``reset_window`` after a separation, then with ``memory_time``, so the next
      onset finds it at zero; it costs no step-size limit the memory does not already set.
    """
    opened = (dwell - law.t_dwell - law.gate_width) / law.gate_width
    running = 1.0 - smoothstep_integral(opened)
    return contact_weight(x) * running - memory_relaxation(x, law) * dwell


def forgetting_rate(memory: Float[ArrayLike, ""], floor, v_ref, tau) -> Float[Array, ""]:
    """d(memory)/dt, m/s^2, of the log-space relaxation of an approach-speed memory
    ``memory`` (m/s) toward ``v_ref`` (m/s) with time constant ``tau`` (s):

    ``-(u ln(u / v_ref) + memory - u) / tau``, ``u = max(memory, floor)``

    with ``floor`` the approach-speed floor (m/s, > 0). It acts on the approach speed the
    contact law uses, u: where the memory is above the floor this is exactly
    ``d(ln memory)/dt = -ln(memory / v_ref) / tau``; below it (an onset so slow that the
    memory latched less than the floor, or a negative memory) the second term brings the
    memory up onto the floor with ``tau`` while the first pushes it at ``u ln(v_ref / u) / tau``,
    so the logarithm only ever sees u >= floor, and values and gradients are finite for
    every memory. ``v_ref >= floor`` keeps the target reachable.
    """
    u = jnp.maximum(memory, floor)
    return -(u * jnp.log(u / v_ref) + (memory - u)) / tau


class AbstractMemoryLaw(eqx.Module):
    """A law for the approach-speed memory of a dry clearance joint: the state it needs,
    the approach speed it gives the contact law, and the state's rate.

    ``name`` is the law's name in TOML files and on the command line; ``state_names``
    names its state entries (the first is the memory itself, m/s).
    """

    name: ClassVar[str]
    state_names: ClassVar[tuple[str, ...]]

    @abc.abstractmethod
    def state_scales(self, speed_scale) -> tuple:
        """Physical value of one scaled unit of each state entry (SI), for a speed
        scale ``speed_scale`` (m/s): the memory is scaled like a speed."""

    @abc.abstractmethod
    def approach_speed(self, state: Float[Array, " k"]) -> Float[Array, ""]:
        """delta_dot_minus, m/s (> 0), from the law's state entries (SI)."""

    @abc.abstractmethod
    def rate(self, state: Float[Array, " k"], joint: MemoryInput) -> Float[Array, " k"]:
        """d(state)/dt (SI) at one instant."""


class FrozenMemory(AbstractMemoryLaw):
    """The memory that tracks the normal speed while the pins are apart and holds it
    for the whole of a contact (model.md, "Approach-speed memory"): one state entry.

    Attributes:
        min_approach_speed: floor on the impact approach speed delta_dot_minus,
            m/s. Guards the damping term chi * delta_dot / delta_dot_minus against
            grazing contacts (division by ~0). Impacts slower than this are damped
            as if they arrived at this speed.
        memory_time: relaxation time of the memory away from the walls, s. While a
            joint is separated the memory follows the normal speed's time derivative
            exactly and relaxes onto the normal speed (which erases the offset left by
            the last rebound); during contact it is frozen, so it holds the speed at
            the onset of the impact ([`memory_relaxation`][jaxcrank.physics.memory.memory_relaxation]). Shorter
            values make the problem stiffer everywhere; the fast reset near the walls
            is ``reset_time``.
        freeze_time: time to contact, s, at the current normal speed, over which the
            memory's exact tracking is blended off before an onset (and on again after
            a separation) rather than switched (keeps reverse-mode gradients exact
            through impact onsets). The blend weight is moment-matched, so the memory
            misses the onset speed by only O((a t_f / v)^3) for a normal acceleration
            a ([`memory_tracking`][jaxcrank.physics.memory.memory_tracking]). The contact force is zero there.
        reset_window: time to or from the wall, s, at the current normal speed,
            within which the memory relaxes with ``reset_time`` (fading out by twice
            it); a separation is always followed by such a window, so a re-impact
            microseconds later finds the memory reset.
        reset_time: relaxation time of the memory inside ``reset_window``, s
            (exp(-27) of the last impact's offset left with the defaults). The solver
            resolves this decay: about 25 steps per separation.

    Raises:
        ParameterError: a setting that is not positive and finite.
    """

    name: ClassVar[str] = "frozen"
    state_names: ClassVar[tuple[str, ...]] = ("approach_memory",)

    min_approach_speed: float = 1e-3
    memory_time: float = 1e-5
    freeze_time: float = 1e-7
    reset_window: float = 1e-6
    reset_time: float = 5e-8

    def __check_init__(self):
        check_range("min_approach_speed", self.min_approach_speed, low=0.0, unit="m/s")
        for field in ("memory_time", "freeze_time", "reset_window", "reset_time"):
            check_range(field, getattr(self, field), low=0.0, unit="s")

    def state_scales(self, speed_scale):
        return (speed_scale,)

    def approach_speed(self, state):
        return jnp.maximum(state[0], self.min_approach_speed)

    def rate(self, state, joint):
        return jnp.stack([frozen_memory_rate(state[0], joint, self)])


class ForgettingMemory(AbstractMemoryLaw):
    """The memory that keeps the exact restitution of isolated impacts and forgets in
    persistent contact (model.md, "Persistent contact: the memory must forget"): two
    state entries, the memory (m/s) and a contact dwell clock (s).

    - While the pins are apart, and for the first ``t_dwell`` of a contact, the memory
      does exactly what [`FrozenMemory`][jaxcrank.physics.memory.FrozenMemory] does (its
      [`frozen_memory_rate`][jaxcrank.physics.memory.frozen_memory_rate]): it tracks the normal speed and latches
      it at the onset, so an impact shorter than ``t_dwell`` rebounds with the exact
      restitution relation ``chi (1 + e) = ln((1 + chi) / (1 - chi e))``.
    - The dwell clock runs at rate 1 in contact and returns to zero within a few
      microseconds of a separation ([`dwell_rate`][jaxcrank.physics.memory.dwell_rate]).
    - Once the clock passes ``t_dwell``, the approach speed the contact law uses, u, relaxes
      in log space toward ``v_ref``: ``d(ln u)/dt = -g(dwell) ln(u / v_ref) / tau``, with the
      gate g rising from 0 at ``t_dwell`` to 1 at ``t_dwell + gate_width`` by a quintic
      smoothstep ([`dwell_gate`][jaxcrank.physics.memory.dwell_gate],
      [`forgetting_rate`][jaxcrank.physics.memory.forgetting_rate]). The gate is also weighted by
      [`contact_weight`][jaxcrank.physics.memory.contact_weight], so it never acts away from the wall.
      In a contact held at constant penetration, ``ln(u / v_ref)`` so decays as
      ``exp(-(t - t_dwell - gate_width / 2) / tau)`` from ``t_dwell + gate_width`` on (t
      from the onset).

    A persistent contact thereby damps as if every impact arrived at ``v_ref``: ``chi / v_ref``
    plays the part of Hunt and Crossley's material damping constant, and the steady state
    no longer depends on the approach speed the start-up left (the memory's Floquet
    multiplier over a period T of permanent contact is exp(-T / tau), not 1).

    Attributes:
        min_approach_speed: floor on the approach speed delta_dot_minus, m/s (as in
            [`FrozenMemory`][jaxcrank.physics.memory.FrozenMemory]).
        memory_time: relaxation time of the memory away from the walls, s (as in
            [`FrozenMemory`][jaxcrank.physics.memory.FrozenMemory]); the dwell clock decays with it too.
        freeze_time: blend time of the exact tracking before an onset, s (as in
            [`FrozenMemory`][jaxcrank.physics.memory.FrozenMemory]).
        reset_window: time to or from the wall, s, within which the memory and the
            dwell clock relax with ``reset_time`` (as in [`FrozenMemory`][jaxcrank.physics.memory.FrozenMemory]).
        reset_time: their relaxation time inside ``reset_window``, s.
        v_ref: reference approach speed, m/s (>= ``min_approach_speed``): the impact
            speed at which the restitution coefficient ce holds for a persistent contact.
            Like ce a physical parameter; it decides the regime at some designs. The
            default lies within the range of approach speeds the frozen memory latches
            at the onsets of persistent contacts (4 mm/s to 0.1 m/s); the docs' numerics
            page gives the measurement behind it.
        tau: time constant of the forgetting, s.
        t_dwell: contact duration, s, after which the memory starts to forget: several
            durations of an isolated impact, so that impacts keep the exact restitution.
        gate_width: time, s, over which the gate opens after ``t_dwell``; the dwell clock
            stops at ``t_dwell + 2.5 gate_width``.

    Raises:
        ParameterError: a setting that is not positive and finite, or ``v_ref`` below
            ``min_approach_speed``.
    """

    name: ClassVar[str] = "forgetting"
    state_names: ClassVar[tuple[str, ...]] = ("approach_memory", "contact_dwell")

    min_approach_speed: float = 1e-3
    memory_time: float = 1e-5
    freeze_time: float = 1e-7
    reset_window: float = 1e-6
    reset_time: float = 5e-8
    v_ref: float = 0.03
    tau: float = 20e-3
    t_dwell: float = 2e-3
    gate_width: float = 1e-3

    def __check_init__(self):
        for field in ("min_approach_speed", "v_ref"):
            check_range(field, getattr(self, field), low=0.0, unit="m/s")
        for field in ("memory_time", "freeze_time", "reset_window", "reset_time", "tau", "t_dwell", "gate_width"):
            check_range(field, getattr(self, field), low=0.0, unit="s")
        v_ref, floor = _concrete(self.v_ref), _concrete(self.min_approach_speed)
        if v_ref is not None and floor is not None and np.any(v_ref < floor):
            raise ParameterError(
                f"v_ref = {np.min(v_ref):g} m/s must not be below min_approach_speed = {np.max(floor):g} m/s "
                "(valid range: v_ref >= min_approach_speed > 0)"
            )

    def state_scales(self, speed_scale):
        # the dwell clock in units of t_dwell: tolerances then mean a fraction of the dwell
        return (speed_scale, jax.lax.stop_gradient(jnp.asarray(self.t_dwell, dtype=float)))

    def approach_speed(self, state):
        return jnp.maximum(state[0], self.min_approach_speed)

    def rate(self, state, joint):
        memory, dwell = state[0], state[1]
        x = freeze_coordinate(joint.penetration, joint.target, self)
        gate = contact_weight(x) * dwell_gate(dwell, self.t_dwell, self.gate_width)
        forget = gate * forgetting_rate(memory, self.min_approach_speed, self.v_ref, self.tau)
        return jnp.stack([frozen_memory_rate(memory, joint, self) + forget, dwell_rate(dwell, x, self)])


#: memory laws by their TOML/CLI name
MEMORY_LAWS: dict[str, type[AbstractMemoryLaw]] = {law.name: law for law in (FrozenMemory, ForgettingMemory)}


def memory_law_from_name(name: str) -> type[AbstractMemoryLaw]:
    """The memory-law class named ``name`` (a key of `MEMORY_LAWS`).

    Raises:
        ParameterError: for an unknown name (the message lists the valid ones).
    """
    if name not in MEMORY_LAWS:
        raise ParameterError(f"memory law {name!r} is unknown; valid names: {', '.join(MEMORY_LAWS)}")
    return MEMORY_LAWS[name]
