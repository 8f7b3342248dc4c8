"""Facts that hold for any linkage, checked on the four-bar (clearance at B and C) and on
the slider-crank with clearance at its ground pivot (``slider-crank-A``): the ideal
mechanism's closed form against Newton's loop closure and its rates against finite
differences, the zero-clearance limit, the work-energy balance, the restitution of an
isolated impact in the mechanism, and gradients against central differences."""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcrank as jc
from jaxcrank import ideal, laws, model, outputs
from jaxcrank.analysis.validation import wall_impact
from jaxcrank.physics.dynamics import mass_vector

MECHANISMS = ("four-bar", "slider-crank-A")


def _wrap(angle):
    return np.angle(np.exp(1j * np.asarray(angle)))


# --------------------------------------------------------------------------- the ideal mechanism


def _none(x):
    return x is None


def _with_guesses(mech, shift=2e-3, turn=0.05):
    """The mechanism's linkage with every body's ``guess``: its frame pose at the start
    moved by (shift, -shift) m and turned by ``turn`` rad, so that Newton's method starts
    away from the answer (the dyads pick their branch by the guesses too)."""
    lk = mech.linkage()
    poses = np.asarray(model.ideal_poses(mech, lk.driver.initial_angle))
    guesses = {b: jc.Pose(*(poses[i] + [shift, -shift, turn])) for i, b in enumerate(sorted(lk.bodies))}
    bodies = {b: eqx.tree_at(lambda x: x.guess, lk.bodies[b], g, is_leaf=_none) for b, g in guesses.items()}
    return eqx.tree_at(lambda x: x.bodies, lk, bodies)


@jax.jit
def _closure_pair(lk, phis):
    dyads = jax.vmap(lambda p: model.ideal_poses(lk, p))(phis)
    newton = jax.vmap(lambda p: model.newton_poses(lk, p))(phis)
    return dyads, newton


@pytest.mark.slow
@pytest.mark.parametrize("name", MECHANISMS)
def test_dyads_in_closed_form_equal_newtons_loop_closure(name):
    """Every body's frame pose at 72 driver angles over a revolution: the RRR / RRP dyads
    in closed form and the loop-closure Newton solve (every body placed by Newton from
    guesses 2.8 mm and 0.05 rad off) agree to 1e-12 (m and rad; measured: 4.4e-16). The
    guesses pick the same assembly as the preset's default branch."""
    mech = jc.preset(name)
    lk = _with_guesses(mech)
    phis = lk.driver.initial_angle + jnp.linspace(0.0, 2.0 * np.pi, 73)[:-1]
    dyads, newton = (np.array(x) for x in _closure_pair(lk, phis))
    plain = np.array(jax.vmap(lambda p: model.ideal_poses(mech, p))(phis))
    for other in (newton, plain):
        diff = dyads - other
        diff[..., 2] = _wrap(diff[..., 2])
        assert np.abs(diff).max() < 1e-12


@pytest.mark.parametrize("name", MECHANISMS)
def test_ideal_rates_equal_finite_differences_of_the_positions(name):
    """``ideal.kinematics``' velocities and accelerations (forward-mode derivatives)
    against central differences of ``ideal.positions`` at 36 times over a revolution,
    relative to the largest rate of each kind. Velocities at h = 1e-6 s: the truncation
    error (h d/dt)^2 / 6 of the third derivative is about (3 w h)^2 / 6 = 6e-9 relative
    for harmonics up to 3 w (w = 62.8 rad/s), the rounding error eps |q| / h about 1e-10:
    tolerance 1e-8 (measured: 5.4e-10 four-bar, 2.3e-10 slider-crank). Accelerations at
    h = 1e-5 s: truncation (3 w h)^2 / 12 = 3e-7, rounding 4 eps |q| / h^2 / |qdd| about
    1e-7: tolerance 1e-6 (measured 1.1e-7 and 5.7e-8)."""
    mech = jc.preset(name)
    ts = jnp.linspace(0.0, float(mech.period), 37)[:-1]

    @jax.jit
    def check(ts):
        q, qd, qdd = jax.vmap(lambda t: ideal.kinematics(mech, t))(ts)

        def at(dt):
            return jax.vmap(lambda t: ideal.positions(mech, t))(ts + dt)

        fd1 = (at(1e-6) - at(-1e-6)) / 2e-6
        fd2 = (at(1e-5) - 2.0 * at(0.0) + at(-1e-5)) / 1e-10
        return jnp.max(jnp.abs(fd1 - qd)) / jnp.max(jnp.abs(qd)), jnp.max(jnp.abs(fd2 - qdd)) / jnp.max(jnp.abs(qdd))

    velocity, acceleration = (float(x) for x in check(ts))
    assert velocity < 1e-8 and acceleration < 1e-6, (velocity, acceleration)


# --------------------------------------------------------------------------- the zero-clearance limit


def _tiny(name, clearance):
    """The preset with ``clearance`` (m) at each of its clearance joints and contact 1000
    times stiffer (E = 207 TPa for pins and holes)."""
    mech = jc.preset(name)
    mech = jc.with_clearance(mech, **{j: clearance for j in model.compile_model(mech).tree.cut})
    for part in ("pin_material", "hole_material"):
        mech = jc.set_parameter(mech, f"{part}.youngs_modulus", 207e12)
    return mech


def _deviation_and_bound(name, clearance, t1=0.02):
    """The largest deviation of the output coordinate from the ideal motion over ``t1`` (s)
    and the loop-closure bound that the joints' play (clearance + largest penetration)
    allows, per sample; returns (deviation / bound).max(), deviation.max(), bound.max()."""
    mech = _tiny(name, clearance)
    sim = jc.simulate(mech, t1, n_samples=201)
    f = outputs.frames(sim)
    tree = model.compile_model(mech).tree
    rho = {j: clearance + max(float(jnp.max(f.penetration[:, tree.joints.index(j)])), 0.0) for j in tree.cut}
    if name == "four-bar":
        # first order in play / length: the loop a e1 + b e3 - c e4 - (D - A) = -u with
        # u = d_A - d_B + d_C - d_D gives c sin(gamma) d(theta4) = u . e3, |u| <= sum rho
        i = ideal.body_index(mech, "rocker")
        deviation = np.abs(np.asarray(f.q[:, i, 2] - f.ideal_q[:, i, 2]))
        sin_gamma = np.abs(np.sin(np.asarray(f.ideal_transmission_angle)))
        bound = (1.0 + 1e-3) * sum(rho.values()) / (float(mech.rocker_length) * sin_gamma)
    else:
        i = ideal.body_index(mech, "slider")
        deviation = np.abs(np.asarray(f.q[:, i, 0] - f.ideal_q[:, i, 0]))
        bound = np.full_like(deviation, mech.deviation_bounds(max(rho.values()) - clearance)["slider_x_m"])
    return float(np.max(deviation / bound)), float(deviation.max()), float(bound.max())


@pytest.mark.slow
@pytest.mark.parametrize("name", MECHANISMS)
def test_zero_clearance_limit_is_the_ideal_mechanism(name):
    """With 1 um of clearance and contact 1000 times stiffer, over 20 ms (a fifth of a
    turn, impacts included) the output coordinate (rocker angle; slider x) stays within
    the loop-closure bound of the joints' play (clearance + largest penetration: the
    only way the motion can leave the ideal one; the solver's error, 1e-6 of the
    clearance per step on the scaled state, is far below it). Measured: rocker 8.4e-6
    rad within 9.1e-6; slider 1.21 um within 1.44 um. With 10 um the deviation is about
    10 times larger (measured 9.9 and 8.8 times): the motion tends to the ideal one
    linearly in the play."""
    ratio, deviation, bound = _deviation_and_bound(name, 1e-6)
    assert ratio <= 1.0, (deviation, bound)
    assert bound < (1e-5 if name == "four-bar" else 2e-6)
    ratio10, deviation10, _ = _deviation_and_bound(name, 1e-5)
    assert ratio10 <= 1.0 and deviation10 > 5.0 * deviation


# --------------------------------------------------------------------------- work and energy


@pytest.mark.slow
@pytest.mark.parametrize("name", MECHANISMS)
def test_work_energy_balance_closes_over_four_revolutions(name):
    """0.4 s at the default tolerances (rtol = atol = 1e-6): the change of kinetic,
    potential and contact energy equals the driver's work less the dissipated work to
    1e-4 of the driver's work (measured: 1.1e-6 four-bar, 1.8e-6 slider-crank-A)."""
    mech = jc.preset(name)
    sim = jc.simulate(mech, 0.4, n_samples=401, options=jc.SolveOptions(max_steps=2_000_000))
    balance = outputs.energy_balance(outputs.trajectory(sim))
    assert abs(balance["residual_J"]) < 1e-4 * abs(balance["driver_work_J"]), balance


# --------------------------------------------------------------------------- an isolated impact


@jax.jit
def _inverse_mass(mech):
    """The inverse mass W of the clearance joints' eccentricities (d'' = W F for forces F
    on their pins, the mechanism at its start), from the tree's mass matrix M and the
    eccentricities' Jacobian J: W = J M^-1 J^T, (2 cut joints, 2 cut joints)."""
    tree = model.compile_model(mech).tree
    n = tree.n
    y0 = model.initial_state(mech)
    scale = model.state_scales(mech)

    def rates(sd):
        y = jnp.concatenate([y0[:n], sd / scale[n : 2 * n], y0[2 * n :]])
        return model.joint_eccentricities(mech, 0.0, y)[1].ravel()

    def kinetic(sd):
        _, qd, _ = model.coordinates(mech, jnp.zeros(n), sd, 0.0)
        return 0.5 * jnp.sum(mass_vector(mech) * qd**2)

    zero = jnp.zeros(n)
    jac = jax.jacfwd(rates)(zero)
    return jac @ jnp.linalg.solve(jax.hessian(kinetic)(zero), jac.T)


_start_state = jax.jit(model.state_from_eccentricities)
_eccentricities = jax.jit(jax.vmap(model.joint_eccentricities, in_axes=(None, 0, 0)))


IMPACTS = [("slider-crank-A", "A", 0), ("slider-crank-A", "A", 1), ("four-bar", "B", 0), ("four-bar", "C", 1)]


@pytest.mark.slow
@pytest.mark.parametrize(("name", "joint", "axis"), IMPACTS)
def test_isolated_impact_in_the_mechanism_keeps_the_restitution_relation(name, joint, axis):
    """A pin 1 um from its bearing's wall hits it at 0.5 m/s inside the mechanism: no
    gravity, no friction, the crank turning at 1 rad/s (the mechanism's own inertial loads
    are 1/4000 of those at 600 rpm), every other pin centred and at rest relative to its
    hole. The approach is along a principal axis of the joint's inverse mass W (W n = n /
    m_eff): along any other direction the mechanism's constraints turn part of the normal
    impulse into tangential sliding and the impact is not a central one. The rebound speed
    / approach speed is the restitution e of chi (1 + e) = ln((1 + chi) / (1 - chi e))
    (model.md) for the joint's own contact law, to 1 % as for the free pin
    (tests/test_wall_impact.py; measured here: 9.8e-5 and 7.7e-6 at the pivot A, 2.5e-4 at B, 2.2e-4 at C)."""
    mech = jc.preset(name)
    mech = jc.set_parameters(mech, ["gravity", "friction.coefficient", "driver.speed"], jnp.array([0.0, 0.0, 1.0]))
    tree = model.compile_model(mech).tree
    law = mech.joints[joint]
    speed, gap, c = 0.5, 1e-6, float(law.clearance)
    k = tree.cut.index(joint)
    normal = np.linalg.eigh(np.asarray(_inverse_mass(mech))[2 * k : 2 * k + 2, 2 * k : 2 * k + 2])[1][:, axis]
    d = np.zeros((len(tree.cut), 2))
    d_rate = np.zeros((len(tree.cut), 2))
    d[k], d_rate[k] = (c - gap) * normal, speed * normal
    rest = [np.array(mech.joints[j].initial_state(), dtype=float) for j in tree.cut]
    rest[k][0] = speed  # the approach-speed memory has tracked the approach
    y0 = _start_state(mech, 0.0, d, d_rate, np.concatenate([*rest, np.zeros(2)]))
    t1 = 0.5 * c / speed  # the rebounding pin is still inside its clearance
    sim = jc.simulate(
        mech, ts=jnp.linspace(0.0, t1, 101), y0=y0, options=jc.SolveOptions(rtol=1e-10, atol=1e-10, max_steps=1_000_000)
    )
    ecc, rate = (np.asarray(x[:, k]) for x in _eccentricities(mech, sim.ts, sim.ys))
    assert np.max(np.linalg.norm(ecc, axis=1)) > c  # it hit the wall
    assert np.linalg.norm(ecc[-1]) < c  # and left it
    rebound = -float(np.dot(rate[-1], normal)) / speed
    exact = laws.achieved_restitution(float(law.contact.law.hysteresis_factor(law.contact.restitution)))
    assert abs(rebound / exact - 1.0) < 0.01, (rebound, exact)


@pytest.mark.parametrize("name", MECHANISMS)
def test_wall_rig_with_the_mechanisms_own_joint_law(name):
    """The free-pin rig driven by each clearance joint law of the mechanism (friction off:
    the rig's pin does not slide): the rebound follows the exact relation to 1 %."""
    mech = jc.preset(name)
    for j in model.compile_model(mech).tree.cut:
        law = eqx.tree_at(lambda x: x.friction.coefficient, mech.joints[j], 0.0)
        exact = laws.achieved_restitution(float(law.contact.law.hysteresis_factor(law.contact.restitution)))
        for speed in (0.01, 0.5):
            assert abs(float(wall_impact.rebound_ratio(law, speed)) / exact - 1.0) < 0.01, (j, speed)


# --------------------------------------------------------------------------- gradients

#: the first contact comes at 1.5 ms (four-bar, pin B) and 1.21 ms (slider-crank-A, pivot A):
#: each window holds it, and ends before central differences stop converging in h
WINDOWS = {"four-bar": 2.0e-3, "slider-crank-A": 1.6e-3}


def _rms_deviation_mm(name, p, adjoint):
    base = jc.preset(name)
    names = ["crank_length", f"clearance_{model.compile_model(base).tree.cut[0]}"]
    mech = jc.set_parameters(base, names, p)
    sim = jc.simulate(
        mech,
        ts=jnp.linspace(0.0, WINDOWS[name], 51),
        options=jc.SolveOptions(rtol=1e-10, atol=1e-10, max_steps=100_000),
        adjoint=adjoint,
    )
    q = jax.vmap(lambda t, y: model.evaluate(mech, t, y).q)(sim.ts, sim.ys)
    qi = jax.vmap(lambda t: ideal.positions(mech, t))(sim.ts)
    return 1e3 * jnp.sqrt(jnp.mean((q[..., :2] - qi[..., :2]) ** 2))


@pytest.mark.slow
@pytest.mark.parametrize("name", MECHANISMS)
def test_gradients_equal_central_differences(name):
    """d(RMS position deviation, mm) / d(crank length, first clearance) by forward mode
    (``jax.jacfwd`` through ``diffrax.ForwardMode``) over a window holding the first
    impact, against central differences (h = 1e-6 m for the length, 1e-8 m for the
    clearance), to 1e-4 relative as in tests/test_gradients.py (measured: 6.6e-6 and
    1.3e-5 four-bar, 1.3e-5 and 4.0e-6 slider-crank-A)."""
    base = jc.preset(name)
    p0 = jnp.array([float(base.crank_length), 5e-4])
    grad = np.asarray(jax.jacfwd(lambda p: _rms_deviation_mm(name, p, diffrax.ForwardMode()))(p0))
    assert np.all(np.isfinite(grad))
    f = jax.jit(lambda p: _rms_deviation_mm(name, p, None))
    for i, h in enumerate((1e-6, 1e-8)):
        e = jnp.zeros(2).at[i].set(h)
        fd = float((f(p0 + e) - f(p0 - e)) / (2 * h))
        assert abs(grad[i] - fd) <= 1e-4 * abs(fd), (i, grad[i], fd)
