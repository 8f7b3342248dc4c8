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
