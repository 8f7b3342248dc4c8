"""Loops of ideal joints closed in the dynamics: a Watt and a Stephenson six-bar with
clearance at exactly one joint (docs/linkages), and the all-ideal Watt six-bar.

The bodies a loop of ideal joints slaves follow the bodies they hang from through the
dyads' closed forms applied to the actual poses; the state keeps the independent
coordinates only. Checked against facts: every ideal joint stays closed, the motion tends
to the ideal mechanism's as the clearance goes to zero within the first-order bound of
the pin's play, the work-energy balance closes, gradients equal central differences, and
the steady state's Floquet multipliers are the eigenvalues of the one-revolution map."""

from pathlib import Path

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcrank as jc
from jaxcrank import model, outputs
from jaxcrank.runs import config

LINKAGES = Path(__file__).resolve().parents[1] / "docs" / "linkages"
SIX_BARS = ("watt-six-bar", "stephenson-six-bar")


def _load(name):
    return config.load(LINKAGES / f"{name}.toml")


def _all_ideal(mech):
    return jc.Linkage(**{**_fields(mech), "joints": {j: jc.Ideal() for j in mech.joints}})


def _fields(lk):
    return {k: getattr(lk, k) for k in ("bodies", "ground", "connections", "joints", "driver", "gravity", "outputs")}


@pytest.mark.parametrize("name", SIX_BARS)
def test_the_ideal_loop_is_closed_by_a_dyad_and_two_coordinates_are_left(name):
    """Five bodies, seven joints, one with clearance: 3 x 5 - 2 x 6 - 1 = 2 coordinates,
    and the loop of ideal joints closed by an RRR dyad of the tree."""
    compiled = model.compile_model(_load(name))
    assert compiled.tree.n == 2 and len(compiled.tree.cut) == 1
    (dyad,) = compiled.tree.closures
    assert dyad.kind == "RRR"


@pytest.mark.parametrize("name", SIX_BARS)
def test_ideal_joints_stay_closed_and_the_solve_is_short(name):
    """50 ms (the first impacts included): every ideal joint's two sides within 1e-12 m
    of each other at every sample (measured: about 3e-16 m)."""
    sim = jc.simulate(_load(name), 0.05, n_samples=101)
    residual = np.asarray(outputs.frames(sim).closure_residual)
    assert residual.shape == (101, 6) and residual.max() < 1e-12, residual.max()


def test_the_all_ideal_six_bar_moves_as_its_ideal_mechanism():
    """Every joint ideal: two dyads close both loops, no coordinate is left; the motion is
    the ideal mechanism's (1e-12 m and rad) and every joint's reaction and the driving
    moment equal the ideal mechanism's inverse dynamics (1e-9 of the largest)."""
    mech = _all_ideal(_load("watt-six-bar"))
    compiled = model.compile_model(mech)
    assert compiled.tree.n == 0 and len(compiled.tree.closures) == 2
    sim = jc.simulate(mech, 0.05, n_samples=26)
    frames = outputs.frames(sim)
    np.testing.assert_allclose(np.asarray(frames.q), np.asarray(frames.ideal_q), rtol=0, atol=1e-12)
    forces, torques = jax.vmap(lambda t: jc.ideal.joint_reactions(mech, t))(sim.ts)
    expected = np.stack([np.linalg.norm(np.asarray(forces[j]), axis=-1) for j in compiled.tree.joints], axis=1)
    scale = np.max(expected)
    np.testing.assert_allclose(np.asarray(frames.normal_force), expected, rtol=0, atol=1e-9 * scale)
    np.testing.assert_allclose(np.asarray(frames.driving_moment), np.asarray(torques), rtol=0, atol=1e-9 * scale)


# --------------------------------------------------------------------------- the zero-clearance limit


def _stiff(name, clearance):
    """The six-bar with ``clearance`` (m) at its clearance joint and contact 1000 times
    stiffer (E = 207 TPa)."""
    mech = _load(name)
    (joint,) = model.compile_model(mech).tree.cut
    mech = jc.set_parameter(mech, f"clearance_{joint}", clearance)
    for part in ("pin_material", "hole_material"):
        mech = jc.set_parameter(mech, f"{part}.youngs_modulus", 207e12)
    return mech, joint


def _output_angle_and_bound(name, clearance, t1=0.02):
    """Largest |output angle - ideal| over ``t1`` (s), and the first-order bound the pin's
    play allows: |d theta / d e| (|e| <= clearance + largest penetration), with d theta / d e
    the output angle's change per eccentricity of the clearance joint at each sample (the
    two coordinates through the pin's eccentricity: (d theta / ds) (d e / ds)^-1)."""
    mech, joint = _stiff(name, clearance)
    compiled = model.compile_model(mech)
    sim = jc.simulate(mech, t1, n_samples=201)
    frames = outputs.frames(sim)
    i = compiled.tree.bodies.index("output")
    deviation = np.abs(np.asarray(frames.q[:, i, 2] - frames.ideal_q[:, i, 2]))
    play = clearance + max(float(np.max(frames.penetration[:, compiled.tree.joints.index(joint)])), 0.0)
    n = compiled.tree.n

    def angle_and_eccentricity(s, t):
        q = model.positions(compiled, s, t)
        kin, _ = model.joint_motion(compiled, joint, q, jnp.zeros_like(q))
        return jnp.concatenate([q[3 * i + 2 : 3 * i + 3], kin.pin_position - kin.hole_position])

    @jax.jit
    def gain(t, y):
        s = model.unpack(compiled, y).deviation
        jac = jax.jacfwd(angle_and_eccentricity)(s, t)
        return jnp.linalg.norm(jnp.linalg.solve(jac[1:, :n].T, jac[0, :n]))

    bound = np.asarray(jax.vmap(gain)(sim.ts, sim.ys)) * play
    return float(np.max(deviation / (1.0 + 1e-3) / bound)), float(deviation.max())


@pytest.mark.slow
@pytest.mark.parametrize("name", SIX_BARS)
def test_zero_clearance_limit_is_the_ideal_mechanism(name):
    """With 1 um of clearance and contact 1000 times stiffer, over 20 ms (impacts
    included) the output link's angle stays within the first-order bound of the pin's play
    (clearance + largest penetration) at every sample; with 10 um its deviation is about
    ten times larger (more than five): the motion tends to the ideal one linearly in the
    play."""
    ratio, deviation = _output_angle_and_bound(name, 1e-6)
    assert ratio <= 1.0 and deviation < 1e-4, (ratio, deviation)
    ratio10, deviation10 = _output_angle_and_bound(name, 1e-5)
    assert ratio10 <= 1.0 and deviation10 > 5.0 * deviation, (ratio10, deviation10, deviation)


# --------------------------------------------------------------------------- work and energy


@pytest.mark.slow
@pytest.mark.parametrize("name", SIX_BARS)
def test_work_energy_balance_closes_over_four_revolutions(name):
    """0.4 s at the default tolerances: the change of kinetic, potential and contact
    energy equals the driver's work less the dissipated work to 1e-4 of the driver's work
    (of the largest of the driver's and the dissipated work where the driver's nearly
    cancels: the Stephenson six-bar, whose driver takes back what gravity gives)."""
    sim = jc.simulate(_load(name), 0.4, n_samples=401, options=jc.SolveOptions(max_steps=2_000_000))
    balance = outputs.energy_balance(outputs.trajectory(sim))
    scale = max(abs(balance["driver_work_J"]), abs(balance["dissipated_work_J"]))
    assert abs(balance["residual_J"]) < 1e-4 * scale, balance
    assert float(np.max(outputs.frames(sim).closure_residual)) < 1e-10


# --------------------------------------------------------------------------- gradients


#: a window holding the first contact of each six-bar's pin
WINDOWS = {"watt-six-bar": 3.6e-3, "stephenson-six-bar": 4.0e-3}


def _rms_deviation_mrad(name, p, adjoint):
    base = _load(name)
    (joint,) = model.compile_model(base).tree.cut
    mech = jc.set_parameters(base, ["bodies.crank.points.B.x", f"clearance_{joint}"], p)
    sim = jc.simulate(
        mech,
        ts=jnp.linspace(0.0, WINDOWS[name], 51),
        options=jc.SolveOptions(rtol=1e-10, atol=1e-10, max_steps=200_000),
        adjoint=adjoint,
    )
    f = jax.vmap(lambda t, y: model.evaluate(mech, t, y))(sim.ts, sim.ys)
    return 1e3 * jnp.sqrt(jnp.mean((f.q[..., 2] - f.ideal_q[..., 2]) ** 2))


@pytest.mark.slow
@pytest.mark.parametrize("name", SIX_BARS)
def test_gradients_equal_central_differences(name):
    """d(RMS angle deviation of every body, mrad) / d(crank length, clearance) by forward
    mode through the solve and the closures, against central differences (h = 1e-6 m,
    1e-8 m), to 1e-4 relative."""
    p0 = jnp.array([0.10, 5e-4])
    grad = np.asarray(jax.jacfwd(lambda p: _rms_deviation_mrad(name, p, diffrax.ForwardMode()))(p0))
    assert np.all(np.isfinite(grad))
    f = jax.jit(lambda p: _rms_deviation_mrad(name, p, None))
    for i, h in enumerate((1e-6, 1e-8)):
        e = jnp.zeros(2).at[i].set(h)
        fd = float((f(p0 + e) - f(p0 - e)) / (2 * h))
        assert abs(grad[i] - fd) <= 1e-4 * abs(fd), (i, grad[i], fd)


# --------------------------------------------------------------------------- the steady state


def _plain_map(mech, y, revolutions, tol=1e-12):
    """The map over ``revolutions`` by plain simulate (no shooting code), works zeroed."""
    sim = jc.simulate(
        mech,
        ts=jnp.array([0.0, revolutions * float(mech.period)]),
        y0=y.at[-2:].set(0.0),
        options=jc.SolveOptions(rtol=tol, atol=tol, max_steps=2_000_000),
    )
    return sim.ys[-1]


@pytest.mark.slow
@pytest.mark.long  # 1.5 to 3 minutes each: the shooting, then 12 solves over the period at rtol 1e-12
@pytest.mark.parametrize("name", SIX_BARS)
def test_the_steady_state_is_an_orbit_whose_multipliers_are_the_maps_eigenvalues(name):
    """``steady_state`` finds a periodic orbit (the Watt six-bar's: period 4 revolutions;
    the Stephenson six-bar's: period 1); every Floquet multiplier is within 1e-4 of an
    eigenvalue of the central-difference Jacobian of the map over one period (plain
    simulate, rtol = atol = 1e-12, h = 3e-4 scaled units) on the dynamic subspace, and the
    other way round (measured on the Watt six-bar: 8.4e-6; at rtol = 1e-10 the map's noise
    over four revolutions moves the differences' eigenvalue by up to 5e-4); one more
    period from the orbit's start returns to it within 1e-6."""
    mech = _load(name)
    steady = jc.steady_state(mech, jc.SteadyOptions(samples_per_revolution=360))
    assert steady.periodic and float(steady.residual) <= 1e-7, steady.regime
    k = steady.period_revolutions
    mu = np.asarray(steady.floquet_multipliers)
    y, active = steady.section_state, np.flatnonzero(np.asarray(steady.active))
    back = np.asarray(_plain_map(mech, y, k))
    assert np.max(np.abs(back - np.asarray(y))[active]) <= 1e-6
    h = 3e-4
    columns = [(np.asarray(_plain_map(mech, y.at[j].add(h), k)) - np.asarray(_plain_map(mech, y.at[j].add(-h), k)))
               / (2 * h) for j in active]  # fmt: skip
    ev = np.linalg.eigvals(np.stack(columns, axis=1)[active])
    gap = np.abs(mu[:, None] - ev[None, :])
    assert np.max(np.min(gap, axis=1)) <= 1e-4 and np.max(np.min(gap, axis=0)) <= 1e-4, (mu, ev)
