"""The closed-form ideal mechanism."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxcrank import ideal


def test_positions_satisfy_loop_closure(paper):
    for t in np.linspace(0, 0.1, 7):
        q = ideal.positions(paper, t)
        b_end, c_end = ideal.rod_ends(paper, q)
        np.testing.assert_allclose(b_end, ideal.crank_pin(paper, t), atol=1e-15)
        np.testing.assert_allclose(c_end, [q[3], paper.offset], atol=1e-15)


def test_velocity_and_acceleration_match_finite_differences(paper):
    t, h = 0.0123, 1e-6
    q, qd, qdd = ideal.kinematics(paper, t)
    qp, qm = ideal.positions(paper, t + h), ideal.positions(paper, t - h)
    np.testing.assert_allclose(qd, (qp - qm) / (2 * h), rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(qdd, (qp - 2 * q + qm) / h**2, rtol=1e-4, atol=1e-3)


def test_transmission_angle_formula(paper):
    t = 0.037
    th1 = float(ideal.crank_angle(paper, t))
    q = ideal.positions(paper, t)
    expected = math.acos((paper.crank_length * math.sin(th1) - paper.offset) / paper.rod_length)
    assert float(ideal.transmission_angle(q[2])) == pytest.approx(expected, rel=1e-12)


def test_ideal_driving_moment_balances_power(paper):
    # virtual power: M omega = d/dt(kinetic + potential) for the ideal mechanism
    def energy(t):
        q, qd, _ = ideal.kinematics(paper, t)
        kin = 0.5 * jnp.sum(ideal.mass_matrix(paper) * qd**2)
        th1 = ideal.crank_angle(paper, t)
        pot = paper.rod_mass * paper.gravity * q[
            1
        ] + paper.crank_mass * paper.gravity * 0.5 * paper.crank_length * jnp.sin(th1)
        return kin + pot

    for t in np.linspace(0.001, 0.099, 9):
        power = float(ideal.driving_moment(paper, t)) * paper.crank_speed
        assert power == pytest.approx(float(jax.grad(energy)(t)), rel=1e-9, abs=1e-9)


def test_joint_reactions_satisfy_newtons_laws(paper):
    """The rod: m2 a_G = F_B + F_C + m2 g and J2 theta2'' = r_BG x F_B + r_CG x F_C; the
    slider (pushed by -F_C, guided in y): m3 x3'' = -F_Cx. To 1e-9 of the force scale."""
    for t in np.linspace(0.0, float(paper.period), 5):
        q, _, qdd = ideal.kinematics(paper, t)
        f_b, f_c = (np.asarray(f) for f in ideal.joint_reactions(paper, t))
        b_end, c_end = (np.asarray(p) for p in ideal.rod_ends(paper, q))
        g = np.array([0.0, -paper.rod_mass * paper.gravity])
        scale = np.linalg.norm(f_b) + np.linalg.norm(f_c)
        np.testing.assert_allclose(paper.rod_mass * np.asarray(qdd[:2]), f_b + f_c + g, atol=1e-9 * scale)
        rb, rc = b_end - np.asarray(q[:2]), c_end - np.asarray(q[:2])
        torque = rb[0] * f_b[1] - rb[1] * f_b[0] + rc[0] * f_c[1] - rc[1] * f_c[0]
        np.testing.assert_allclose(paper.rod_inertia * float(qdd[2]), torque, atol=1e-9 * scale * paper.rod_length)
        np.testing.assert_allclose(paper.slider_mass * float(qdd[3]), -f_c[0], atol=1e-9 * scale)


def test_contact_margin_is_a_soft_minimum_of_the_relative_load(paper):
    """Between the sampled minimum of |F_j| / rms |F_j| over the joints and that plus
    softness * ln(samples); differentiable, matching central differences to 1e-5."""
    from jaxcrank.physics.params import set_parameter

    n, s, m0, h = 360, 0.005, float(paper.rod_mass), 1e-4
    ts = np.arange(n) * float(paper.period) / n
    f_b, f_c = jax.jit(jax.vmap(lambda t: ideal.joint_reactions(paper, t)))(ts)
    loads = (np.linalg.norm(f_b, axis=1), np.linalg.norm(f_c, axis=1))
    hard = min(float(np.min(m / np.sqrt(np.mean(m**2)))) for m in loads)
    value_and_grad = jax.jit(
        jax.value_and_grad(lambda m: ideal.contact_margin(set_parameter(paper, "rod_mass", m), n, s))
    )
    margin, grad = (float(v) for v in value_and_grad(m0))
    assert 0.0 < hard <= margin <= hard + s * math.log(n)
    assert math.isfinite(grad)
    fd = (float(value_and_grad(m0 + h)[0]) - float(value_and_grad(m0 - h)[0])) / (2 * h)
    np.testing.assert_allclose(grad, fd, rtol=1e-5)
    with pytest.raises(ValueError, match="samples"):
        ideal.contact_margin(paper, samples=4)
