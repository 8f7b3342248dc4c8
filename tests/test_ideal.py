"""The ideal mechanism: the closed-form closure, its time derivatives, its inverse
dynamics and the contact margin, against facts (loop closure at every joint, finite
differences, the power balance, Newton's laws body by body)."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcrank as jc
from jaxcrank import ideal
from jaxcrank.physics import model
from jaxcrank.physics.dynamics import mass_vector
from jaxcrank.physics.linkage import GROUND, Prismatic, world_point

MECHANISMS = {"paper": jc.paper, "four-bar": jc.four_bar}


def _sites(mech, t):
    """World positions of every joint's two sites at time t, by joint name, and the poses."""
    lk, tree = model.compile_model(mech).linkage, model.compile_model(mech).tree
    frames = model.ideal_poses(mech, ideal.driver_angle(mech, t))
    poses = {b: frames[i] for i, b in enumerate(tree.bodies)}
    poses[GROUND] = jnp.zeros(3)

    def world(site):
        local = (lk.ground if site.body == GROUND else lk.bodies[site.body].points)[site.point].vector()
        return np.asarray(world_point(poses[site.body], local))

    return {j: tuple(world(s) for s in lk.connections[j].sites()) for j in tree.joints}, poses


@pytest.mark.parametrize("name", MECHANISMS)
def test_positions_satisfy_loop_closure(name):
    """Every revolute joint's hole and pin points coincide; a prismatic joint's slider
    point lies on its guide's axis at the joint's angle (1e-15 m, 1e-15 rad)."""
    mech = MECHANISMS[name]()
    lk, _ = model.compile_model(mech).linkage, model.compile_model(mech).tree
    for t in np.linspace(0, 0.1, 7):
        sites, poses = _sites(mech, t)
        for j, (a, b) in sites.items():
            conn = lk.connections[j]
            if isinstance(conn, Prismatic):
                angle = float(poses[conn.guide.body][2]) + float(conn.direction)
                normal = np.array([-math.sin(angle), math.cos(angle)])
                assert abs(np.dot(b - a, normal)) < 1e-15, (j, t)
                turn = float(poses[conn.slider.body][2] - poses[conn.guide.body][2]) - float(conn.angle)
                assert abs(turn) < 1e-15, (j, t)
            else:
                np.testing.assert_allclose(b, a, atol=1e-15, err_msg=f"{j} at t = {t}")


def test_positions_are_the_centres_of_mass_and_the_slider_runs_on_its_line(paper):
    """The paper's bodies: the crank's centre at L1/2 along it, the slider at y = e."""
    for t in np.linspace(0, 0.1, 7):
        q = np.asarray(ideal.positions(paper, t))
        th1 = float(ideal.driver_angle(paper, t))
        crank, slider = ideal.body_index(paper, "crank"), ideal.body_index(paper, "slider")
        np.testing.assert_allclose(q[crank], [0.075 * math.cos(th1), 0.075 * math.sin(th1), th1], atol=1e-15)
        assert q[slider, 1] == pytest.approx(paper.offset, abs=1e-15) and abs(q[slider, 2]) < 1e-15


@pytest.mark.parametrize("name", MECHANISMS)
def test_velocity_and_acceleration_match_finite_differences(name):
    mech = MECHANISMS[name]()
    t, h = 0.0123, 1e-6
    q, qd, qdd = ideal.kinematics(mech, t)
    qp, qm = ideal.positions(mech, t + h), ideal.positions(mech, t - h)
    np.testing.assert_allclose(qd, (qp - qm) / (2 * h), rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(qdd, (qp - 2 * q + qm) / h**2, rtol=1e-4, atol=1e-3)


def test_transmission_angle_formula(paper):
    t = 0.037
    th1 = float(ideal.driver_angle(paper, t))
    expected = math.acos((paper.crank_length * math.sin(th1) - paper.offset) / paper.rod_length)
    assert float(ideal.transmission_angle(paper, t)) == pytest.approx(expected, rel=1e-12)


def test_four_bar_transmission_angle_is_the_coupler_rocker_angle():
    """The law of cosines in triangle B C D: cos mu = (b^2 + c^2 - |BD|^2) / (2 b c)."""
    fb = jc.four_bar()
    for t in (0.0, 0.021, 0.063):
        th = float(ideal.driver_angle(fb, t))
        bd2 = fb.crank_length**2 + fb.ground_length**2 - 2 * fb.crank_length * fb.ground_length * math.cos(th)
        b, c = fb.coupler_length, fb.rocker_length
        expected = math.acos((b**2 + c**2 - bd2) / (2 * b * c))
        assert float(ideal.transmission_angle(fb, t)) == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize("name", MECHANISMS)
def test_ideal_driving_moment_balances_power(name):
    # virtual power: M omega = d/dt(kinetic + potential) for the ideal mechanism, every body
    mech = MECHANISMS[name]()
    lk, tree = model.compile_model(mech).linkage, model.compile_model(mech).tree
    mass = mass_vector(mech)
    weights = jnp.array([lk.bodies[b].mass * lk.gravity for b in tree.bodies])

    def energy(t):
        q, qd, _ = ideal.kinematics(mech, t)
        return 0.5 * jnp.sum(mass * jnp.ravel(qd) ** 2) + jnp.sum(weights * q[:, 1])

    moment, rate = jax.jit(lambda t: ideal.driving_moment(mech, t)), jax.jit(jax.grad(energy))
    for t in np.linspace(0.001, 0.099, 9):
        power = float(moment(t)) * float(mech.speed)
        assert power == pytest.approx(float(rate(t)), rel=1e-9, abs=1e-9)


def test_joint_reactions_satisfy_newtons_laws(paper):
    """The rod, with F_B, F_C the forces on it (minus the forces on the pins):
    m2 a_G = F_B + F_C + m2 g and J2 theta2'' = r_BG x F_B + r_CG x F_C; the slider
    (pushed by -F_C, guided in y): m3 x3'' = -F_Cx. To 1e-9 of the force scale."""
    rod, slider = ideal.body_index(paper, "rod"), ideal.body_index(paper, "slider")
    for t in np.linspace(0.0, float(paper.period), 5):
        q, _, qdd = (np.asarray(a) for a in ideal.kinematics(paper, t))
        forces, _ = ideal.joint_reactions(paper, t)
        f_b, f_c = -np.asarray(forces["B"]), -np.asarray(forces["C"])
        sites, _ = _sites(paper, t)
        b_end, c_end = sites["B"][0], sites["C"][0]  # the holes, on the rod
        g = np.array([0.0, -paper.rod_mass * paper.gravity])
        scale = np.linalg.norm(f_b) + np.linalg.norm(f_c)
        np.testing.assert_allclose(paper.rod_mass * qdd[rod, :2], f_b + f_c + g, atol=1e-9 * scale)
        rb, rc = b_end - q[rod, :2], c_end - q[rod, :2]
        torque = rb[0] * f_b[1] - rb[1] * f_b[0] + rc[0] * f_c[1] - rc[1] * f_c[0]
        np.testing.assert_allclose(paper.rod_inertia * qdd[rod, 2], torque, atol=1e-9 * scale * paper.rod_length)
        np.testing.assert_allclose(paper.slider_mass * qdd[slider, 0], -f_c[0], atol=1e-9 * scale)


def test_contact_margin_is_a_soft_minimum_of_the_relative_load(paper):
    """Between the sampled minimum of |F_j| / rms |F_j| over the joints and that plus
    softness * ln(samples); differentiable, matching central differences to 1e-5."""
    from jaxcrank.physics.parameters import set_parameter

    n, s, m0, h = 360, 0.005, float(paper.rod_mass), 1e-4
    ts = np.arange(n) * float(paper.period) / n
    forces = jax.jit(jax.vmap(lambda t: ideal.joint_reactions(paper, t)[0]))(ts)
    loads = (np.linalg.norm(forces["B"], axis=1), np.linalg.norm(forces["C"], axis=1))
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
