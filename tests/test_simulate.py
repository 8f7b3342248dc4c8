"""Simulations checked against facts: zero-clearance limit, energy balance, geometry."""

import jax.numpy as jnp
import numpy as np
import pytest

import jaxcrank as jc
from jaxcrank import outputs

from .helpers import frictionless, with_ideal, with_law

REV = 0.1  # one crank revolution at 600 rpm, s


@pytest.fixture(scope="module")
def paper_rev2():
    """Paper preset over two revolutions (the second is past the start transient)."""
    sim = jc.simulate(jc.paper(), 2 * REV, n_samples=4001)
    return outputs.trajectory(sim)


def _dev(cols, name):
    return cols[name] - cols[f"ideal_{name}"]


def test_zero_clearance_limit():
    """1 um clearance: positions within 5e-6 m of the closed form over a revolution
    (after the 10 ms start transient of the pins-centred start), and deviations
    shrink with the clearance. Lankarani-Nikravesh: its stiffness grows as c -> 0
    (conformal contact), so the clearance limit is the rigid mechanism."""
    peaks = []
    for c in [1e-4, 1e-5, 1e-6]:
        mech = with_law(jc.with_clearance(jc.paper(), B=c, C=c), "lankarani_nikravesh")
        cols = outputs.trajectory(jc.simulate(mech, REV, n_samples=2001))
        late = cols["t"] >= 0.01
        peaks.append(max(np.abs(_dev(cols, "slider_x")[late]).max(), np.abs(_dev(cols, "rod_x")[late]).max()))
    assert peaks[0] > peaks[1] > peaks[2]
    assert np.abs(_dev(cols, "slider_x")[late]).max() < 5e-6
    assert np.abs(_dev(cols, "rod_x")[late]).max() < 5e-6
    assert np.abs(_dev(cols, "rod_y")[late]).max() < 5e-6


def test_exact_kinematic_closure(paper_rev2):
    """Slider deviation = -d_Bx + d_Cx + L2 (cos theta2 - cos theta2_ideal), exactly."""
    c, m = paper_rev2, jc.paper()
    lhs = _dev(c, "slider_x")
    rhs = (
        -c["ecc_B_x"]
        + c["ecc_C_x"]
        + m.rod_length * (np.cos(np.radians(c["rod_angle"])) - np.cos(np.radians(c["ideal_rod_angle"])))
    )
    np.testing.assert_allclose(lhs, rhs, atol=1e-12)


def test_paper_deviation_within_geometric_bound(paper_rev2):
    """After the first revolution the deviations obey the bound the loop closure
    implies (SliderCrank.deviation_bounds; c_B + c_C + max penetration alone is not a bound)."""
    c, m = paper_rev2, jc.paper()
    late = c["t"] > REV
    pen = max(c["penetration_B"][late].max(), c["penetration_C"][late].max())
    bounds = m.deviation_bounds(pen)
    assert np.abs(_dev(c, "slider_x")[late]).max() <= bounds["slider_x_m"]
    assert np.abs(_dev(c, "rod_x")[late]).max() <= bounds["rod_x_m"]
    for j in "BC":
        ecc = np.hypot(c[f"ecc_{j}_x"], c[f"ecc_{j}_y"])
        assert np.all(ecc <= m.joints[j].clearance + c[f"penetration_{j}"].max() + 1e-12)
    # the paper's envelopes (ADAMS): rod +-0.5 mm, slider +-1.0 mm; ours are reported, not asserted
    assert np.abs(_dev(c, "slider_x")[late]).max() < 1.3e-3


def test_work_energy_balance_paper(paper_rev2):
    """Second revolution: delta(kinetic + potential + contact) = driver work - dissipated work
    within 0.5 % of the driver work."""
    c = paper_rev2
    i0 = int(np.searchsorted(c["t"], REV))
    bal = outputs.energy_balance(c, i0=i0)
    assert bal["dissipated_work_J"] > 0.0
    assert abs(bal["residual_J"]) < 5e-3 * abs(bal["driver_work_J"])


def test_work_energy_balance_frictionless_elastic():
    # Undamped contacts ring at ~40 kHz on the light rod ends; at rtol = atol = 1e-6
    # the energy residual is 1.8e-3 J (integration error: 1.3e-4 J at 1e-7, 1.8e-7 J
    # at 1e-8), so this check runs at 1e-8.
    mech = frictionless(jc.set_parameter(jc.paper(), "contact.restitution", 1.0))
    cols = outputs.trajectory(jc.simulate(mech, REV, n_samples=1001, options=jc.SolveOptions(rtol=1e-8, atol=1e-8)))
    bal = outputs.energy_balance(cols)
    assert abs(bal["dissipated_work_J"]) < 1e-9
    assert abs(bal["residual_J"]) < 5e-3 * abs(bal["driver_work_J"])


@pytest.mark.parametrize("ideal_joints", [("B",), ("C",)])
def test_ideal_joint_layouts(ideal_joints):
    # (with B and C both ideal the loop has no clearance joint: refused, tests/test_model.py)
    mech = with_ideal(jc.paper(), *ideal_joints)
    cols = outputs.trajectory(jc.simulate(mech, 0.02, n_samples=201))
    for j in ideal_joints:
        assert np.all(cols[f"ecc_{j}_x"] == 0.0)
    bal = outputs.energy_balance(cols)
    assert abs(bal["residual_J"]) < 5e-3 * max(abs(bal["driver_work_J"]), 1e-3)


def test_solver_failure_raises_with_advice():
    with pytest.raises(jc.SimulationError, match="max_steps"):
        jc.simulate(jc.paper(), 0.01, n_samples=11, options=jc.SolveOptions(max_steps=10))


def test_accelerations_come_from_the_vector_field():
    sim = jc.simulate(
        jc.paper(), 0.002, ts=jnp.linspace(0.0, 0.002, 2001), options=jc.SolveOptions(rtol=1e-9, atol=1e-9)
    )
    c = outputs.trajectory(sim)
    # away from impacts, finite differences of the velocity agree with the model's acceleration
    fd = np.gradient(c["slider_vx"], c["t"])
    quiet = (c["force_C_normal"] == 0) & (c["t"] < 1e-3)
    np.testing.assert_allclose(c["slider_ax"][quiet][5:-5], fd[quiet][5:-5], rtol=1e-3, atol=1e-2)


def test_the_driver_speed_can_be_traced_when_the_samples_are_given():
    """``jax.grad`` with respect to the driver's speed through ``simulate(t1=..., n_samples=...)``
    equals the same through explicit ``ts`` (the default sample times are not read from the traced
    period), matches a central difference (relative step 1e-6) to 1e-4 over the first millisecond
    (before the first impact: docs/numerics.md), and a default that needs the period is refused by
    name."""
    import jax

    def rms(speed, **kw):
        mech = jc.set_parameter(jc.paper(), "driver.speed", speed)
        return outputs.rms_transmission_error(jc.simulate(mech, **kw), t_start=0.0)

    given = dict(t1=1e-3, n_samples=21)
    g = jax.grad(rms)(62.8, **given)
    assert g == jax.grad(rms)(62.8, ts=jnp.linspace(0.0, 1e-3, 21))
    h = 62.8e-6
    fd = (rms(62.8 + h, **given) - rms(62.8 - h, **given)) / (2 * h)
    assert np.isfinite(g) and abs(g - fd) <= 1e-4 * abs(fd)
    with pytest.raises(jc.ParameterError, match="driver's speed is traced"):
        jax.grad(rms)(62.8, t1=2e-3)


def test_tracked_metrics_take_forward_mode_as_documented():
    """``simulate(metrics_start=..., adjoint=diffrax.ForwardMode())`` under ``jax.jvp`` (the
    tracking wrapper hides the solver from ForwardMode; simulate gives it its lax loop): the
    tangent of a tracked RMS metric matches a central difference (relative step 1e-6) to 1e-4
    over the first millisecond (before the first impact)."""
    import diffrax
    import jax

    def rms(mass):
        mech = jc.set_parameter(jc.paper(), "rod_mass", mass)
        sim = jc.simulate(mech, t1=1e-3, n_samples=21, metrics_start=0.0, adjoint=diffrax.ForwardMode())
        return sim.metrics["rms_transmission_angle_error_deg"]

    value, tangent = jax.jvp(rms, (1.2,), (1.0,))
    h = 1.2e-6
    fd = (rms(1.2 + h) - rms(1.2 - h)) / (2 * h)
    assert np.isfinite(tangent) and abs(tangent - fd) <= 1e-4 * abs(fd) and value > 0


def test_a_value_set_with_eqx_tree_at_is_checked_by_simulate():
    """``eqx.tree_at`` skips a module's checks; simulate runs them on the concrete mechanism it is
    given, naming the parameter by its path, before any solve (a traced value is not checked)."""
    import equinox as eqx
    import jax

    bad = eqx.tree_at(lambda m: m.joints["B"].contact.restitution, jc.paper(), 1.2)
    with pytest.raises(jc.ParameterError, match=r"joints\.B\.contact: restitution = 1.2 is outside"):
        jc.simulate(bad, t1=1e-4)
    with pytest.raises(jc.ParameterError, match="rod_mass = -1 kg"):
        jc.simulate(eqx.tree_at(lambda m: m.rod_mass, jc.paper(), -1.0), t1=1e-4)
    speed = jax.jit(lambda r: jc.simulate(eqx.tree_at(lambda m: m.rod_mass, jc.paper(), r), t1=1e-4).ys[-1, 0])
    assert np.isfinite(speed(1.2))
