"""The approach-speed memory laws (jaxcrank.physics.memory): the forgetting memory's rate
contract against the frozen memory, its relaxation in persistent contact against the
closed form, its dwell clock, finite gradients, validation and registry."""

import math

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxcrank.physics import memory
from jaxcrank.physics.joints import Clearance
from jaxcrank.physics.params import ParameterError

FORGETTING = memory.ForgettingMemory()
FROZEN = memory.FrozenMemory()


def _input(penetration, target=0.0, target_rate=0.0):
    return memory.MemoryInput(*(jnp.asarray(v, dtype=float) for v in (penetration, target, target_rate)))


def _integrate(law, y0, joint_at, t1, ts, rtol=1e-12, atol=1e-16, jump_ts=None):
    """The memory law's state alone from y0 (SI) over [0, t1] (s), fed ``joint_at(t)``
    (a MemoryInput), saved at ``ts``."""

    def field(t, y, args):
        return args.rate(y, joint_at(t))

    controller = diffrax.PIDController(rtol=rtol, atol=atol, jump_ts=jump_ts)
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(field),
        diffrax.Dopri8(),
        0.0,
        t1,
        1e-9,
        jnp.asarray(y0, dtype=float),
        args=law,
        saveat=diffrax.SaveAt(ts=jnp.asarray(ts, dtype=float)),
        stepsize_controller=controller,
        max_steps=100_000,
    )
    return sol.ys


# ---------------------------------------------------------------------------- rate contract


def test_forgetting_rate_equals_frozen_rate_until_the_dwell_ends():
    """With the dwell clock at or below t_dwell (or the pins a freeze time or more apart),
    the memory's rate is exactly the frozen memory's: separated, near the wall, at onset
    and in contact, for memories below, at and above the floor and targets of both signs."""
    t_dwell = FORGETTING.t_dwell
    penetrations = [-1e-4, -1e-8, -1e-11, 0.0, 1e-9, 1e-6]
    for pen in penetrations:
        for target in (-0.3, 0.0, 0.05):
            joint = _input(pen, target, 40.0)
            for m in (-0.1, 0.0, 5e-4, 0.02, 0.4):
                for dwell in (0.0, 0.5 * t_dwell, t_dwell):
                    got = FORGETTING.rate(jnp.array([m, dwell]), joint)
                    want = FROZEN.rate(jnp.array([m]), joint)
                    assert float(got[0]) == float(want[0])
    # far from the wall the gate is shut by the contact weight, whatever the clock says
    far = _input(-1e-4, -0.3, 40.0)
    got = FORGETTING.rate(jnp.array([0.4, 10.0 * t_dwell]), far)
    assert float(got[0]) == float(FROZEN.rate(jnp.array([0.4]), far)[0])


@pytest.mark.parametrize("m0", [0.5, 0.01])  # above and below v_ref
def test_persistent_contact_relaxes_log_memory_toward_v_ref_with_tau(m0):
    """Held at a constant penetration: the memory stays latched up to t_dwell, then
    ln(m / v_ref) = ln(m0 / v_ref) exp(-(t - t_dwell - gate_width / 2) / tau) from
    t_dwell + gate_width on (the gate's smoothstep integrates to half its width), 1e-9
    relative; the clock reads the contact time exactly until the gate is open, then
    stops at t_dwell + 2.5 gate_width."""
    law = FORGETTING
    t_dwell, width, tau, v_ref = law.t_dwell, law.gate_width, law.tau, law.v_ref
    t_open = t_dwell + width
    t1 = t_open + 3.0 * tau
    before = np.linspace(0.0, t_dwell, 9)
    after = np.linspace(t_open, t1, 13)
    ys = _integrate(law, [m0, 0.0], lambda t: _input(1e-6), t1, np.concatenate([before, after]))
    m, dwell = np.asarray(ys[:, 0]), np.asarray(ys[:, 1])
    n = before.size
    np.testing.assert_allclose(m[:n], m0, rtol=1e-12)
    np.testing.assert_allclose(dwell[:n], before, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(dwell[n], t_open, rtol=1e-12)
    expected = math.log(m0 / v_ref) * np.exp(-(after - t_dwell - 0.5 * width) / tau)
    np.testing.assert_allclose(np.log(m[n:] / v_ref), expected, rtol=1e-9)
    # the clock stops with time constant gate_width: 60 of them after t_open
    np.testing.assert_allclose(dwell[-1], t_dwell + 2.5 * width, rtol=1e-12)


def test_a_memory_latched_below_the_floor_rises_onto_it_and_relaxes_toward_v_ref():
    """A grazing onset can latch a memory below min_approach_speed v_min (or a negative
    one). Both forgetting terms carry the gate, so in the gate's time
    sigma = t - t_dwell - gate_width / 2 (after the gate) the memory follows, below the
    floor, m = m* - (m* - m0) exp(-sigma / tau) with m* = v_min (1 + ln(v_ref / v_min)), up
    to the floor at sigma_1 = tau ln((m* - m0) / (m* - v_min)), and then
    ln(m / v_ref) = ln(v_min / v_ref) exp(-(sigma - sigma_1) / tau); 1e-9 relative (and
    1e-12 m/s where m crosses zero). The
    approach speed used stays in [v_min, v_ref] and never falls."""
    law = FORGETTING
    v_min, v_ref, tau = law.min_approach_speed, law.v_ref, law.tau
    t_open = law.t_dwell + law.gate_width
    m_star = v_min * (1.0 + math.log(v_ref / v_min))
    t1 = t_open + 5.0 * tau
    ts = np.linspace(t_open, t1, 200)
    sigma = ts - law.t_dwell - 0.5 * law.gate_width
    for m0 in (-0.05, 0.0, 2e-4):
        ys = np.asarray(_integrate(law, [m0, 0.0], lambda t: _input(1e-6), t1, ts))
        sigma_1 = tau * math.log((m_star - m0) / (m_star - v_min))
        below = sigma < sigma_1
        exact_below = m_star - (m_star - m0) * np.exp(-sigma[below] / tau)
        np.testing.assert_allclose(ys[below, 0], exact_below, rtol=1e-9, atol=1e-12)  # m crosses 0 m/s
        exact_above = math.log(v_min / v_ref) * np.exp(-(sigma[~below] - sigma_1) / tau)
        np.testing.assert_allclose(np.log(ys[~below, 0] / v_ref), exact_above, rtol=1e-9)
        used = np.asarray(jax.vmap(law.approach_speed)(jnp.asarray(ys)))
        assert np.all(used >= v_min) and np.all(used <= v_ref)
        assert np.all(np.diff(used) >= 0.0)


def test_dwell_clock_and_memory_reset_after_a_separation():
    """A pin leaves the wall at 0.2 m/s after a long contact (clock stopped at
    t_dwell + 2.5 gate_width): two reset windows later the clock has decayed by more than
    exp(-26) (the reset relaxation gives about exp(-27)) and the memory has caught the
    receding normal speed, so the next onset starts a fresh clock and a fresh latch."""
    law = FORGETTING
    speed = 0.2
    d0 = law.t_dwell + 2.5 * law.gate_width
    t_check = 2.0 * law.reset_window
    ys = _integrate(
        law,
        [0.03, d0],
        lambda t: _input(-speed * t, -speed),
        2.5 * t_check,
        [t_check, 2.5 * t_check],
        rtol=1e-10,
        atol=1e-20,
    )
    assert float(ys[0, 1]) / d0 < math.exp(-26.0)
    assert abs(float(ys[0, 0]) + speed) < 1e-9
    assert float(ys[1, 1]) >= 0.0
    # at the next onset the forgetting is off again: the rate is the frozen memory's
    state = jnp.array([0.1, ys[1, 1]])
    onset = _input(1e-9, 0.1)
    assert float(law.rate(state, onset)[0]) == float(FROZEN.rate(state[:1], onset)[0])


# ---------------------------------------------------------------------------- gradients


def test_rate_gradients_are_finite_at_the_floor_at_zero_dwell_and_across_the_gate():
    """Forward and reverse derivatives of the rate with respect to the state, the law's
    settings and the joint's penetration and normal speed are finite at the floor, for
    zero and negative memories, at zero dwell, at the gate's ends and middle and where the
    clock stops, separated, at the wall and in contact."""
    law = FORGETTING
    t_dwell, width = law.t_dwell, law.gate_width
    memories = [law.min_approach_speed, 0.0, -0.1, law.v_ref, 0.5]
    dwells = [0.0, t_dwell, t_dwell + 0.5 * width, t_dwell + width, t_dwell + 2.5 * width]
    penetrations = [-1e-6, -1e-11, 0.0, 1e-6]
    grid = np.array([(m, d, p) for m in memories for d in dwells for p in penetrations])
    params, static = eqx.partition(law, eqx.is_inexact_array_like)

    def rate(p, state, pen, target):
        return eqx.combine(p, static).rate(state, _input(pen, target, 3.0))

    def derivatives(row):
        state, pen = row[:2], row[2]
        return (
            jax.jacfwd(rate, argnums=(0, 1, 2, 3))(params, state, pen, 0.1),
            jax.jacrev(rate, argnums=(0, 1, 2, 3))(params, state, pen, 0.1),
        )

    out = jax.jit(jax.vmap(derivatives))(jnp.asarray(grid))
    for leaf in jax.tree_util.tree_leaves(out):
        bad = ~np.isfinite(np.asarray(leaf)).reshape(len(grid), -1).all(axis=1)
        assert not bad.any(), grid[bad]


def test_gradients_through_the_relaxation_match_the_closed_form():
    """d ln m(t) / d(tau, t_dwell, gate_width, v_ref) by reverse mode through the solve,
    after the gate has opened, against the derivatives of
    ln m = ln v_ref + ln(m0 / v_ref) exp(-(t - t_dwell - gate_width / 2) / tau), 1e-6 relative."""
    m0, t = 0.4, 30e-3
    law = FORGETTING

    def log_memory(p):
        trial = memory.ForgettingMemory(v_ref=p[0], tau=p[1], t_dwell=p[2], gate_width=p[3])
        ys = _integrate(trial, [m0, 0.0], lambda s: _input(1e-6), t, [t])
        return jnp.log(ys[0, 0])

    p = jnp.array([law.v_ref, law.tau, law.t_dwell, law.gate_width])
    grad = np.asarray(jax.grad(log_memory)(p))
    v_ref, tau, t_dwell, width = (float(v) for v in p)
    s = t - t_dwell - 0.5 * width
    decay = math.exp(-s / tau)
    big_l = math.log(m0 / v_ref) * decay
    exact = [(1.0 - decay) / v_ref, big_l * s / tau**2, big_l / tau, big_l / (2.0 * tau)]
    np.testing.assert_allclose(grad, exact, rtol=1e-6)


# ---------------------------------------------------------------------------- settings


@pytest.mark.parametrize(
    "field, value, match",
    [
        ("v_ref", 0.0, r"v_ref = 0 m/s is outside its valid range \(0, inf\)"),
        ("tau", -1.0, r"tau = -1 s is outside its valid range \(0, inf\)"),
        ("t_dwell", float("nan"), r"t_dwell = nan s must be a finite number in \(0, inf\)"),
        ("gate_width", 0.0, r"gate_width = 0 s is outside its valid range \(0, inf\)"),
        ("min_approach_speed", float("inf"), r"min_approach_speed = inf m/s must be a finite number in \(0, inf\)"),
        ("v_ref", 1e-4, r"v_ref = 0.0001 m/s must not be below min_approach_speed = 0.001 m/s"),
    ],
)
def test_forgetting_memory_rejects_bad_settings(field, value, match):
    with pytest.raises(ParameterError, match=match):
        memory.ForgettingMemory(**{field: value})


def test_memory_laws_by_name_and_state_declaration():
    assert memory.memory_law_from_name("frozen") is memory.FrozenMemory
    assert memory.memory_law_from_name("forgetting") is memory.ForgettingMemory
    with pytest.raises(ParameterError, match="valid names: frozen, forgetting"):
        memory.memory_law_from_name("forgetful")
    joint = Clearance(hole_radius=8e-3, pin_radius=7.5e-3, memory=memory.ForgettingMemory(t_dwell=3e-3))
    assert joint.state_names() == ("approach_memory", "contact_dwell")
    np.testing.assert_array_equal(np.asarray(joint.initial_state()), [0.0, 0.0])
    scales = [float(s) for s in joint.state_scales(0.25)]
    assert scales == [0.25, 3e-3]
    # the default memory law is the forgetting one (model.md); the frozen one is chosen by name
    assert Clearance(hole_radius=8e-3, pin_radius=7.5e-3).memory == memory.ForgettingMemory()
    frozen = Clearance(hole_radius=8e-3, pin_radius=7.5e-3, memory=memory.FrozenMemory())
    assert frozen.state_names() == ("approach_memory",)
