"""The model's parts (jaxcrank.physics: joints, state, kinematics, memory, dynamics),
each against a fact: closed-form contracts, inverses, time derivatives by autodiff of
the closed form, the ideal mechanism."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcrank as jc
from jaxcrank.physics import ideal, joints, kinematics, memory, model, state

from .helpers import with_ideal

LAYOUTS = [(), ("B",), ("C",)]


@pytest.mark.parametrize("ideal_names", LAYOUTS)
def test_state_layout_follows_the_clearance_joints(paper, ideal_names):
    mech = with_ideal(paper, *ideal_names)
    _, tree = model.compile_model(mech).linkage, model.compile_model(mech).tree
    names = tree.cut
    assert names == tuple(n for n in "BC" if n not in ideal_names)
    k = len(names)
    # per clearance joint: two coordinates, two rates, the default (forgetting) memory's
    # approach-speed memory and dwell clock; then the two works
    assert state.n_dof(mech) == 2 * k and state.state_size(mech) == 4 * k + 2 * k + 2
    assert model.law_state_names(mech) == tuple(f"{j}.{e}" for j in names for e in ("approach_memory", "contact_dwell"))
    y = jnp.arange(1.0, state.state_size(mech) + 1.0)
    s = state.unpack(mech, y)
    phys = y * state.state_scales(mech)
    np.testing.assert_array_equal(np.concatenate([s.deviation, s.deviation_rate, s.law_state]), phys[:-2])
    assert float(s.driver_work) == float(phys[-2]) and float(s.dissipated_work) == float(phys[-1])


def test_a_loop_of_ideal_joints_is_closed_by_a_dyad(paper):
    """With B and C ideal the slider-crank's loop has no clearance joint: the rod and the
    slider follow the crank through the closed-form dyad, and no coordinate is left."""
    compiled = model.compile_model(with_ideal(paper, "B", "C"))
    assert compiled.tree.n == 0
    (dyad,) = compiled.tree.closures
    assert (dyad.kind, set(dyad.bodies), set(dyad.joints)) == ("RRP", {"rod", "slider"}, {"B", "C", "guide"})


@pytest.mark.parametrize("ideal_names", [("B",), ("C",)])
def test_an_ideal_joints_pin_holds_its_rod_end(paper, ideal_names):
    """For any deviation s, the ideal joint's pin and rod end coincide, and so do their
    velocities (1e-12 m, 1e-9 m/s)."""
    mech = with_ideal(paper, *ideal_names)
    (name,) = ideal_names
    rng = np.random.default_rng(0)
    for t in (0.0, 0.0123, 0.07):
        s, sd = rng.normal(size=2) * 1e-4, rng.normal(size=2) * 1e-2
        q, qd, _ = kinematics.coordinates(mech, jnp.asarray(s), jnp.asarray(sd), t)
        m, _ = kinematics.joint_motion(mech, name, q, qd)
        np.testing.assert_allclose(m.pin_position, m.hole_position, rtol=0, atol=1e-12)
        np.testing.assert_allclose(m.pin_velocity, m.hole_velocity, rtol=0, atol=1e-9)


def test_state_from_eccentricities_inverts_eccentricities(paper):
    t = 0.0123
    d = jnp.array([[1e-4, -5e-5], [-3e-5, 8e-5]])
    d_rate = jnp.array([[1e-2, 3e-3], [-2e-3, 5e-3]])
    rest = jnp.array([0.1, 1e-3, 0.2, 2e-3, 3.0, 0.5])  # memory, dwell (s) at B, at C; works
    y = kinematics.state_from_eccentricities(paper, t, d, d_rate, rest)
    d2, d2_rate = kinematics.joint_eccentricities(paper, t, y)
    np.testing.assert_allclose(d2, d, rtol=0, atol=1e-15)
    np.testing.assert_allclose(d2_rate, d_rate, rtol=0, atol=1e-12)
    np.testing.assert_allclose(model.auxiliary(paper, y), rest, rtol=1e-15)
    # one clearance joint holds the two coordinates of a slider-crank with B ideal
    only_c = with_ideal(paper, "B")
    y = kinematics.state_from_eccentricities(only_c, t, d[1:], d_rate[1:], rest[2:])
    d2, d2_rate = kinematics.joint_eccentricities(only_c, t, y)
    np.testing.assert_allclose(d2, d[1:], rtol=0, atol=1e-15)
    np.testing.assert_allclose(d2_rate, d_rate[1:], rtol=0, atol=1e-12)
    # a torque driver's angle is a coordinate the eccentricities do not give
    free = jc.SliderCrank(driver=jc.Torque(body="crank", initial_speed=float(paper.speed)))
    with pytest.raises(ValueError, match="prescribed driver"):
        kinematics.state_from_eccentricities(free, t, d, d_rate, rest)


def test_memory_tracking_weight_contract():
    """w = 1 for x >= 1, 0 for x <= 0; the deficit 1 - w and x (1 - w) integrate to zero
    over [0, 1] (Gauss-Legendre with 8 points: exact for w, a polynomial of degree 10)."""
    assert float(memory.memory_tracking(1.0)) == 1.0 and float(memory.memory_tracking(3.0)) == 1.0
    assert float(memory.memory_tracking(0.0)) == 0.0 and float(memory.memory_tracking(-2.0)) == 0.0
    x, w = np.polynomial.legendre.leggauss(8)
    x, w = 0.5 * (x + 1.0), 0.5 * w
    deficit = 1.0 - np.asarray(memory.memory_tracking(jnp.asarray(x)))
    assert abs(np.sum(w * deficit)) < 1e-14 and abs(np.sum(w * x * deficit)) < 1e-14


def test_memory_relaxation_is_zero_near_contact_and_the_memory_rate_far_away(paper):
    c = paper.joints["B"].memory
    for x in (-1.0, 0.0, 0.5, 1.0):
        assert float(memory.memory_relaxation(x, c)) == 0.0
    far = 3.0 * float(c.reset_window / c.freeze_time)
    np.testing.assert_allclose(float(memory.memory_relaxation(far, c)), 1.0 / float(c.memory_time), rtol=1e-15)


@pytest.mark.parametrize("eccentricity", [[2e-4, 1e-4], [1e-5, -2e-5]])  # outside and inside c/2
def test_memory_target_rate_is_the_time_derivative_of_the_target(eccentricity):
    """Along d(t) = d0 + v t + a t^2 / 2, memory_target_rate equals d/dt memory_target
    (forward-mode autodiff of the closed form), 1e-12 relative."""
    d0, v, a, c = jnp.asarray(eccentricity), jnp.array([0.3, -0.1]), jnp.array([-40.0, 25.0]), 2.5e-4

    def target(t):
        return memory.memory_target(d0 + v * t + 0.5 * a * t**2, v + a * t, c)

    _, exact = jax.jvp(target, (0.0,), (1.0,))
    np.testing.assert_allclose(float(memory.memory_target_rate(d0, v, a, c)), float(exact), rtol=1e-12)


def test_a_separated_pin_feels_no_force_and_a_penetrating_one_is_pushed_back(paper):
    joint = paper.joints["B"]
    c = float(joint.clearance)

    def contact(offset):
        zero2 = jnp.zeros(2)
        kin = joints.JointKinematics(
            hole_position=zero2,
            hole_velocity=zero2,
            hole_angle=jnp.zeros(()),
            hole_angular_velocity=jnp.zeros(()),
            pin_position=jnp.array([offset, 0.0]),
            pin_velocity=jnp.array([0.1, 0.0]),
            pin_angle=jnp.zeros(()),
            pin_angular_velocity=jnp.zeros(()),
        )
        return joints.clearance_contact(joint, kin, jnp.array([0.1]))

    apart, touching = contact(0.5 * c), contact(c + 1e-6)
    assert float(apart.normal_force) == 0.0 and float(apart.friction_force) == 0.0
    np.testing.assert_allclose(float(apart.penetration), -0.5 * c, rtol=1e-12)
    assert float(touching.normal_force) > 0.0 and float(touching.force[0]) < 0.0


def test_at_the_pins_centred_start_the_model_is_the_ideal_mechanism(paper):
    """At s = s' = 0 the bodies sit and move as the ideal mechanism's (the frame's own
    poses and its ideal ones), and the frame's ideal driving moment (power balance,
    M omega = d/dt (T + V)) equals the inverse dynamics of ideal.driving_moment. (The
    dynamics with every joint ideal cannot be run: a loop of ideal joints is refused,
    test_a_loop_of_ideal_joints_is_refused.)"""
    for t in (0.0, 0.0123, 0.05):
        f = model.evaluate(paper, t, model.initial_state(paper))
        q, qd, qdd = ideal.kinematics(paper, t)
        np.testing.assert_allclose(f.q, q, rtol=1e-14)
        np.testing.assert_allclose(f.qd, qd, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(f.ideal_q, q, rtol=1e-14)
        np.testing.assert_allclose(f.ideal_qdd, qdd, rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(
            float(f.ideal_driving_moment), float(ideal.driving_moment(paper, t)), rtol=1e-10, atol=1e-12
        )
