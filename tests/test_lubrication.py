"""The lubricated revolute joint (jaxcrank.physics.lubrication) against the facts of
model.md, "Lubricated revolute joint": the short bearing's steady load and attitude
angle, its Sommerfeld number against Butenschoen's tables, the film force with squeeze
and whirl against a quadrature of the short-bearing pressure of this file's own, the
dissipation and the energy balance of the wrench, the dry law at zero viscosity, the
hand-over blend, finite gradients and the parameter checks."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxcrank.physics import joints, lubrication
from jaxcrank.physics.joints import Clearance, JointAccelerations, JointKinematics
from jaxcrank.physics.lubrication import Lubricated
from jaxcrank.physics.params import ParameterError

ETA = 0.05  # Pa s
PIN_RADIUS = 20e-3  # m
CLEARANCE = 0.1e-3  # m
LENGTH = 10e-3  # m (L/D = 1/4)
HOLE = np.array([0.1, -0.2])  # m, where the hole's centre is
HOLE_VELOCITY = np.array([0.3, 0.1])  # m/s


def law(**kw):
    args = dict(hole_radius=PIN_RADIUS + CLEARANCE, pin_radius=PIN_RADIUS, viscosity=ETA, length=LENGTH)
    return Lubricated(**{**args, **kw})


def kinematics(d, v, pin_speed, hole_speed):
    """A joint whose pin centre is at ``d`` (m) from the hole's and moves at ``v`` (m/s)
    relative to it; the hole's body moves and turns too."""
    d, v = np.asarray(d, dtype=float), np.asarray(v, dtype=float)
    f = lambda x: jnp.asarray(x, dtype=jnp.float64)
    return JointKinematics(
        hole_position=f(HOLE),
        hole_velocity=f(HOLE_VELOCITY),
        hole_angle=f(0.3),
        hole_angular_velocity=f(hole_speed),
        pin_position=f(HOLE + d),
        pin_velocity=f(HOLE_VELOCITY + v),
        pin_angle=f(-1.1),
        pin_angular_velocity=f(pin_speed),
    )


def line_of_centres(eps, phi, eps_dot, phi_dot):
    """Eccentricity (m) and relative velocity (m/s) from eps, phi (rad) and their rates."""
    n, t = np.array([math.cos(phi), math.sin(phi)]), np.array([-math.sin(phi), math.cos(phi)])
    return eps * CLEARANCE * n, CLEARANCE * (eps_dot * n + eps * phi_dot * t), n, t


STATE = jnp.array([0.2, 1e-3])  # the default memory law's: approach-speed memory, m/s; dwell clock, s


@pytest.mark.parametrize("eps", [0.05, 0.3, 0.5, 0.8, 0.94])
def test_steady_load_and_attitude_angle_are_the_closed_forms(eps):
    omega, phi = 120.0, 2.2  # rad/s, rad
    d, v, n, t = line_of_centres(eps, phi, 0.0, 0.0)
    f = law().forces(kinematics(d, v, omega, 0.0), STATE).force
    load = (
        ETA * omega * PIN_RADIUS * LENGTH**3 / (4 * CLEARANCE**2)
        * eps / (1 - eps**2) ** 2 * math.sqrt(16 * eps**2 + math.pi**2 * (1 - eps**2))
    )  # fmt: skip
    attitude = math.atan(math.pi * math.sqrt(1 - eps**2) / (4 * eps))
    assert float(jnp.linalg.norm(f)) == pytest.approx(load, rel=1e-10)
    # the load that the film carries is -f: along n, lagging the rotation by the attitude angle
    assert math.atan2(float(f @ t), float(-f @ n)) == pytest.approx(attitude, rel=1e-10)


def sommerfeld(length_to_diameter, eps):
    """So = W psi^2 / (L D eta omega) of the law, at its steady load."""
    length, omega = length_to_diameter * 2 * PIN_RADIUS, 50.0
    d, v, _, _ = line_of_centres(eps, 0.4, 0.0, 0.0)
    f = law(length=length).forces(kinematics(d, v, omega, 0.0), STATE).force
    psi = CLEARANCE / PIN_RADIUS
    return float(jnp.linalg.norm(f)) * psi**2 / (length * 2 * PIN_RADIUS * ETA * omega)


def test_sommerfeld_number_at_one_eighth_width_is_butenschoens():
    so = sommerfeld(1 / 8, 0.5)
    assert so == pytest.approx(0.02345, abs=5e-6)
    assert so == pytest.approx(0.0231, rel=0.02)  # Butenschoen's finite-width table


def test_sommerfeld_number_at_unit_width_overshoots_the_finite_bearing():
    # the short bearing is for L/D up to about 1/2: at L/D = 1 it gives 1.50 where
    # Butenschoen's tables give 0.89
    so = sommerfeld(1.0, 0.5)
    assert so == pytest.approx(1.50, abs=0.005)
    assert so > 1.5 * 0.89


def quadrature_force(d, v, pin_speed, hole_speed, n_angle=2**18):
    """Force on the pin from the short-bearing pressure, integrated here over the film
    where it is positive: world angle alpha on a periodic grid (trapezoid), the axial
    coordinate z by 3-point Gauss-Legendre. The short-bearing Reynolds equation
    ``h^3 p_zz = 6 eta ((w_pin + w_hole) dh/dalpha + 2 dh/dt)`` with
    ``h = c - d.u(alpha)``, p = 0 at z = +-L/2."""
    alpha = np.linspace(0.0, 2 * np.pi, n_angle, endpoint=False)
    u = np.stack([np.cos(alpha), np.sin(alpha)], axis=-1)
    du = np.stack([-np.sin(alpha), np.cos(alpha)], axis=-1)
    h = CLEARANCE - u @ d
    rhs = 6 * ETA * ((pin_speed + hole_speed) * -(du @ d) + 2 * -(u @ v))
    nodes, weights = np.polynomial.legendre.leggauss(3)
    z, wz = 0.5 * LENGTH * nodes, 0.5 * LENGTH * weights
    p = rhs[:, None] / (2 * h[:, None] ** 3) * (z[None, :] ** 2 - LENGTH**2 / 4)
    p_axial = np.maximum(p, 0.0) @ wz
    return -PIN_RADIUS * (2 * np.pi / n_angle) * (p_axial @ u)


CASES = [  # eps, eps_dot (1/s), phi_dot (rad/s), pin speed, hole speed (rad/s)
    (0.3, 20.0, 0.0, 0.0, 0.0),  # pure squeeze towards the wall
    (0.3, -20.0, 0.0, 0.0, 0.0),  # pure squeeze away from it
    (0.6, 15.0, 30.0, 100.0, 0.0),
    (0.6, -15.0, 30.0, 100.0, 0.0),
    (0.6, 15.0, 70.0, 100.0, 0.0),  # whirl faster than half the spin: the wedge turns over
    (0.85, -8.0, -40.0, 60.0, -90.0),  # both surfaces turning, opposite ways
    (0.85, 8.0, 25.0, -60.0, 140.0),
    (0.93, 3.0, -10.0, 80.0, 30.0),
    (0.1, -50.0, 200.0, -30.0, 20.0),
]


@pytest.mark.parametrize("eps, eps_dot, phi_dot, pin_speed, hole_speed", CASES)
def test_film_force_with_squeeze_and_whirl_is_the_integral_of_the_positive_pressure(
    eps, eps_dot, phi_dot, pin_speed, hole_speed
):
    d, v, _, _ = line_of_centres(eps, -0.7, eps_dot, phi_dot)
    f = np.asarray(law().forces(kinematics(d, v, pin_speed, hole_speed), STATE).force)
    ref = quadrature_force(d, v, pin_speed, hole_speed)
    assert np.linalg.norm(f - ref) <= 1e-6 * np.linalg.norm(ref)


def test_film_force_at_the_centre_is_the_integral_of_the_positive_pressure():
    v = np.array([-2e-3, 1.5e-3])  # m/s
    f = np.asarray(law().forces(kinematics([0.0, 0.0], v, 70.0, -20.0), STATE).force)
    ref = quadrature_force(np.zeros(2), v, 70.0, -20.0)
    assert np.linalg.norm(f - ref) <= 1e-6 * np.linalg.norm(ref)


def test_literature_variables_give_the_same_film_force():
    eps, eps_dot, phi_dot, w_pin, w_hole = CASES[5]
    d, v, n, t = line_of_centres(eps, 1.3, eps_dot, phi_dot)
    f = np.asarray(law().forces(kinematics(d, v, w_pin, w_hole), STATE).force)
    geometry = dict(viscosity=ETA, length=LENGTH, radius=PIN_RADIUS, clearance=CLEARANCE)
    f_r, f_t = lubrication.short_bearing_force(eps, eps_dot, phi_dot, w_pin, w_hole, **geometry)
    np.testing.assert_allclose([f @ n, f @ t], [float(f_r), float(f_t)], rtol=1e-12)


def random_states(rng, count, max_eps):
    for _ in range(count):
        eps = rng.uniform(0.0, max_eps)
        phi = rng.uniform(-math.pi, math.pi)
        d, v, _, _ = line_of_centres(eps, phi, rng.normal(0.0, 30.0), rng.normal(0.0, 100.0))
        yield d, v, rng.normal(0.0, 100.0), rng.normal(0.0, 100.0)


def test_dissipation_is_never_negative():
    rng = np.random.default_rng(1)
    joint = law()
    forces = jax.jit(joint.forces)
    for d, v, w_pin, w_hole in random_states(rng, 300, 1.02):
        assert float(forces(kinematics(d, v, w_pin, w_hole), STATE).dissipation) >= 0.0


def wrench_power(kin, out):
    """Power the law's wrench delivers to the two bodies, W (rigid-body point velocities)."""

    def point_velocity(centre, velocity, omega, point):
        r = point - centre
        return velocity + omega * jnp.array([-r[1], r[0]])

    v_pin = point_velocity(kin.pin_position, kin.pin_velocity, kin.pin_angular_velocity, out.pin_point)
    v_hole = point_velocity(kin.hole_position, kin.hole_velocity, kin.hole_angular_velocity, out.hole_point)
    return float(
        out.force @ v_pin
        - out.force @ v_hole
        + out.pin_moment * kin.pin_angular_velocity
        + out.hole_moment * kin.hole_angular_velocity
    )


def test_film_wrench_dissipates_what_it_reports_and_has_no_net_moment():
    rng = np.random.default_rng(2)
    joint = law()
    for d, v, w_pin, w_hole in random_states(rng, 50, 0.97):
        kin = kinematics(d, v, w_pin, w_hole)
        out = joint.forces(kin, STATE)
        assert -wrench_power(kin, out) == pytest.approx(float(out.dissipation), rel=1e-9, abs=1e-12)
        moment = (
            float(jnp.cross(out.pin_point, out.force) - jnp.cross(out.hole_point, out.force))
            + float(out.pin_moment + out.hole_moment)
        )  # fmt: skip
        scale = float(jnp.linalg.norm(out.force)) * float(jnp.linalg.norm(out.pin_point))
        assert abs(moment) <= 1e-12 * scale


def test_zero_viscosity_is_the_dry_law():
    rng = np.random.default_rng(3)
    lubricated, dry = law(viscosity=0.0), Clearance(hole_radius=PIN_RADIUS + CLEARANCE, pin_radius=PIN_RADIUS)
    states = list(random_states(rng, 40, 1.0))
    states += [(d * (1 + 2e-6 / CLEARANCE) / np.linalg.norm(d) * CLEARANCE, v, a, b) for d, v, a, b in states[:20]]
    in_contact = 0
    for d, v, w_pin, w_hole in states:
        kin = kinematics(d, v, w_pin, w_hole)
        ours, theirs = lubricated.forces(kin, STATE), joints.clearance_contact(dry, kin, STATE)
        in_contact += bool(theirs.penetration > 0)
        for field in ("force", "pin_moment", "hole_moment", "dissipation", "elastic_energy", "penetration"):
            np.testing.assert_array_equal(getattr(ours, field), getattr(theirs, field), err_msg=field)
        scale = float(jnp.linalg.norm(theirs.force))
        for field in ("normal_force", "friction_force"):
            assert abs(float(getattr(ours, field) - getattr(theirs, field))) <= 1e-14 * scale, field
        if theirs.penetration > 0:
            np.testing.assert_array_equal(ours.pin_point, theirs.pin_point)
            np.testing.assert_array_equal(ours.hole_point, theirs.hole_point)
    assert in_contact == 20


def smoothstep(x):
    x = min(max(x, 0.0), 1.0)
    return x**3 * (10 - 15 * x + 6 * x**2)


@pytest.mark.parametrize("eps", [0.95, 0.955, 0.965, 0.975, 0.98, 0.99])
def test_hand_over_blends_the_film_into_the_dry_law(eps):
    d, v, _, _ = line_of_centres(eps, 0.9, -3.0, 20.0)
    kin = kinematics(d, v, 90.0, -10.0)
    blended = law().forces(kin, STATE)
    film = law(film_start=0.995, film_end=0.999).forces(kin, STATE)  # the whole film up to 0.995
    # the eccentricity ratio as the law sees it: its clearance is R_h - R_p in floating point
    actual = float(np.linalg.norm(np.asarray(kin.pin_position) - np.asarray(kin.hole_position))) / float(
        law().clearance
    )
    share = 1 - smoothstep((actual - 0.95) / (0.98 - 0.95))
    np.testing.assert_allclose(blended.force, share * film.force, rtol=1e-13, atol=0.0)
    np.testing.assert_allclose(blended.dissipation, share * film.dissipation, rtol=1e-13, atol=0.0)
    assert float(jnp.linalg.norm(film.force)) > 0


def test_film_and_hand_over_are_smooth_in_the_eccentricity():
    # central differences of the force along the line of centres against jax.grad
    def force(e):
        n = jnp.array([math.cos(0.5), math.sin(0.5)])
        v = CLEARANCE * (-2.0 * n + 15.0 * jnp.array([-n[1], n[0]]))
        kin = kinematics(np.zeros(2), np.zeros(2), 80.0, 10.0)._replace(
            pin_position=jnp.asarray(HOLE) + e * CLEARANCE * n, pin_velocity=jnp.asarray(HOLE_VELOCITY) + v
        )
        return law().forces(kin, STATE).force

    force, slope = jax.jit(force), jax.jit(jax.jacfwd(force))
    for e in [0.2, 0.7, 0.96, 0.97]:
        h = 1e-6
        fd = (force(e + h) - force(e - h)) / (2 * h)
        np.testing.assert_allclose(slope(e), fd, rtol=1e-6, atol=1e-6 * float(jnp.linalg.norm(fd)))


@jax.jit
def _gradients(viscosity, eps, state, kin):
    """Jacobians of the force, the moments and the dissipation with respect to the
    viscosity, the eccentricity ratio along the line of centres, the state and the pin's
    velocity."""

    def out(viscosity, eps, state, pin_velocity):
        d = kin.pin_position - kin.hole_position
        moved = kin.hole_position + eps * CLEARANCE * d / jnp.linalg.norm(d)
        k = kin._replace(pin_position=moved, pin_velocity=pin_velocity)
        f = law(viscosity=viscosity).forces(k, state)
        return jnp.concatenate([f.force, jnp.stack([f.pin_moment, f.hole_moment, f.dissipation])])

    return jax.jacrev(out, argnums=(0, 1, 2, 3))(viscosity, eps, state, kin.pin_velocity)


@pytest.mark.parametrize("eps", [0.0, 0.5, 0.95, 0.965, 0.98, 1.0, 1.0 + 1e-3])
@pytest.mark.parametrize("moving", [True, False])
def test_gradients_are_finite_at_the_centre_and_across_the_hand_over(eps, moving):
    d, v, _, _ = line_of_centres(eps, 0.3, 5.0 if moving else 0.0, 30.0 if moving else 0.0)
    # the direction of the line of centres (its length is the argument)
    kin = kinematics(d if eps else [1e-6, 0.0], v, 60.0 if moving else 0.0, 0.0)
    grads = _gradients(jnp.asarray(ETA), jnp.asarray(eps), STATE, kin)
    for grad in grads:
        assert bool(jnp.all(jnp.isfinite(grad)))
    assert float(jnp.max(jnp.abs(grads[0]))) > 0 or not moving or eps >= 0.98


def test_state_is_the_dry_laws_memory():
    joint, dry = law(), Clearance(hole_radius=PIN_RADIUS + CLEARANCE, pin_radius=PIN_RADIUS)
    assert joint.state_names() == dry.state_names() == ("approach_memory", "contact_dwell")
    assert joint.state_scales(2.0) == dry.state_scales(2.0)
    assert float(joint.clearance) == pytest.approx(CLEARANCE, rel=1e-12)
    d, v, _, _ = line_of_centres(0.99, 0.4, 30.0, 5.0)
    kin = kinematics(d, v, 10.0, 0.0)
    acc = JointAccelerations(*(jnp.asarray(x) for x in ([1.0, -2.0], 3.0, [0.5, 4.0], -1.0)))
    rate = joint.state_rate(kin, acc, STATE, joint.forces(kin, STATE))
    np.testing.assert_array_equal(rate, dry.state_rate(kin, acc, STATE, dry.forces(kin, STATE)))


def test_lubricated_is_registered_by_name():
    assert joints.JOINT_LAWS["lubricated"] is Lubricated
    assert Lubricated.kinds == ("revolute",)
    with pytest.raises(ParameterError, match="already taken"):
        joints.register_joint_law(type("Other", (Lubricated,), {}))


@pytest.mark.parametrize(
    "kw, match",
    [
        (dict(viscosity=-1e-3), r"viscosity = -0\.001 Pa s is outside its valid range \[0, inf\)"),
        (dict(viscosity=float("nan")), "viscosity"),
        (dict(length=0.0), r"length = 0 m is outside its valid range \(0, inf\)"),
        (dict(film_start=0.0), r"film_start = 0 is outside its valid range \(0, 1\)"),
        (dict(film_end=1.0), r"film_end = 1 is outside its valid range \(0, 1\)"),
        (dict(film_start=0.98, film_end=0.95), r"film_start = 0\.98 must be smaller than film_end = 0\.95"),
        (dict(pin_radius=PIN_RADIUS + 2 * CLEARANCE), "pin_radius"),
    ],
)
def test_bad_settings_name_the_parameter_and_its_range(kw, match):
    with pytest.raises(ParameterError, match=match):
        law(**kw)


def test_paper_lubricated_without_oil_is_the_dry_paper_run():
    """The ``paper-lubricated`` preset with zero viscosity at B and C runs the dry paper
    preset's 20 ms exactly (the same states at every sample, the same steps); with its oil
    the film changes the motion."""
    import equinox as eqx

    import jaxcrank as jc
    from jaxcrank.physics import presets

    oiled = presets.preset("paper-lubricated")
    dry_oil = eqx.tree_at(lambda m: (m.joints["B"].viscosity, m.joints["C"].viscosity), oiled, (0.0, 0.0))
    dry = jc.simulate(jc.paper(), 0.02, n_samples=201)
    without = jc.simulate(dry_oil, 0.02, n_samples=201)
    np.testing.assert_array_equal(np.asarray(without.ys), np.asarray(dry.ys))
    assert int(without.num_steps) == int(dry.num_steps)
    with_oil = jc.simulate(oiled, 0.02, n_samples=201)
    assert with_oil.ok and float(jnp.max(jnp.abs(with_oil.ys[:, :8] - dry.ys[:, :8]))) > 1.0


@pytest.mark.slow
def test_steady_state_and_its_viscosity_gradient_on_the_lubricated_four_bar():
    """``four-bar-lubricated`` has a periodic steady state: one plain revolution from the
    orbit's start returns to it within 1e-7 scaled units. The exact steady-state gradient
    of Eq. 19 with respect to the viscosity at C equals central differences of
    warm-started steady states (h = 4e-4 Pa s: measured 6.5e-4 relative; 5e-5 at
    h = 4e-5); at B, where the pin stays beyond the film's range all period, both are
    zero."""
    import equinox as eqx

    import jaxcrank as jc
    from jaxcrank.numerics.steady import steady_value_and_grad
    from jaxcrank.physics import model, presets

    key = "rms_transmission_angle_error_deg"
    base = presets.preset("four-bar-lubricated")

    def build(p):
        return eqx.tree_at(lambda m: (m.joints["B"].viscosity, m.joints["C"].viscosity), base, (p[0], p[1]))

    steady = jc.steady_state(base)
    assert steady.periodic
    y, n = steady.section_state, 2 * model.n_dof(base)
    one = jc.simulate(
        base,
        ts=jnp.array([0.0, float(base.period)]),
        y0=y.at[-2:].set(0.0),
        options=jc.SolveOptions(rtol=1e-10, atol=1e-10),
    )
    assert float(jnp.max(jnp.abs(one.ys[-1][:n] - y[:n]))) <= 1e-7
    p0 = jnp.array([float(base.joints["B"].viscosity), float(base.joints["C"].viscosity)])
    _, grad = steady_value_and_grad(lambda sim: sim.metrics[key], build, p0, steady)
    h = 4e-4
    fd = []
    for i in range(2):
        e = jnp.zeros(2).at[i].set(h)
        up = jc.steady_state(build(p0 + e), warm_start=steady).metrics[key]
        down = jc.steady_state(build(p0 - e), warm_start=steady).metrics[key]
        fd.append((float(up) - float(down)) / (2 * h))
    assert fd[0] == 0.0 and float(grad[0]) == 0.0
    assert float(grad[1]) == pytest.approx(fd[1], rel=2e-3) and fd[1] != 0.0


def test_the_commands_take_the_lubricated_presets(tmp_path):
    """``jaxcrank simulate --mechanism paper-lubricated`` runs and writes its summary, and
    the batch regime map of ``four-bar-lubricated`` over the viscosity at C (with oil and
    without: 0 is the dry joint) finds the period-1 orbit ``steady_state`` finds (its
    section recurs within 1e-6 scaled units after the default 20 revolutions)."""
    import json

    from jaxcrank.physics import catalogue
    from jaxcrank.runs import cli, regimes

    out = tmp_path / "run"
    args = ["simulate", "--mechanism", "paper-lubricated", "--t1", "0.005", "--out", str(out)]
    args += ["--no-figures", "--quiet"]
    assert cli.main(args) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["metrics"]["max_penetration_B_m"] >= 0.0
    table = regimes.classify(catalogue.four_bar_lubricated(), ["joints.C.viscosity"], [[0.4], [0.0]], progress=False)
    assert table["status"].tolist() == ["ok", "ok"] and table["regime"].tolist() == ["periodic", "periodic"]
    assert table["period_revolutions"].tolist() == [1, 1] and np.all(table["recurrence_distance_scaled"] <= 1e-6)
