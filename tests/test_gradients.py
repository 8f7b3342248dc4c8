"""Reverse-mode gradients through the whole solve, against central finite differences;
forward mode against reverse mode."""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcrank as jc
from jaxcrank import ideal, model

# The paper preset's first impacts: pin B from ~1 ms, both pins with tens of kN by
# 1.8 ms. By 2.5 ms central differences no longer converge in h (impact chaos), so
# the comparison window contains the first impact at B.
WINDOW = 1.2e-3
PARAMS = ["crank_length", "rod_length", "clearance_B", "clearance_C"]


ROD, SLIDER = ideal.body_index(jc.paper(), "rod"), ideal.body_index(jc.paper(), "slider")


def _mechanism(p):
    base = jc.paper()
    l1, l2, cb, cc = p
    return eqx.tree_at(
        lambda m: (m.crank_length, m.rod_length, m.joints["B"].pin_radius, m.joints["C"].pin_radius),
        base,
        (l1, l2, base.joints["B"].hole_radius - cb, base.joints["C"].hole_radius - cc),
    )


def rms_slider_deviation_mm(p, t1=WINDOW, adjoint=None):
    mech = _mechanism(p)
    sim = jc.simulate(
        mech,
        ts=jnp.linspace(0.0, t1, 51),
        options=jc.SolveOptions(rtol=1e-10, atol=1e-10, max_steps=100_000),
        adjoint=adjoint,
    )
    q = jax.vmap(lambda t, y: model.evaluate(mech, t, y).q)(sim.ts, sim.ys)
    qi = jax.vmap(lambda t: ideal.positions(mech, t))(sim.ts)
    rod = q[:, ROD, :2] - qi[:, ROD, :2]
    return 1e3 * jnp.sqrt(jnp.mean((q[:, SLIDER, 0] - qi[:, SLIDER, 0]) ** 2) + jnp.mean(rod**2))


P0 = jnp.array([0.150, 0.403, 5e-4, 5e-4])


@pytest.fixture(scope="module")
def reverse_gradient():
    return jax.grad(rms_slider_deviation_mm)(P0)


def test_gradient_finite_from_pins_centred_start(reverse_gradient):
    assert np.all(np.isfinite(np.asarray(reverse_gradient)))
    # at t = 0 the pins sit exactly at the bearing centres (eccentricity 0)
    g0 = jax.grad(lambda p: rms_slider_deviation_mm(p, t1=1e-5))(P0)
    assert np.all(np.isfinite(np.asarray(g0)))


def test_forward_mode_equals_reverse_mode(reverse_gradient):
    """``jax.jacfwd`` through ``diffrax.ForwardMode`` (one pass for all four
    parameters; 3.2x the forward solve against 7.4x for reverse mode in
    bench/bench_solvers.py) gives the reverse-mode gradient to 1e-8 of the largest
    component (measured 3.9e-9, in d/dc_B: the two modes treat the adaptive step
    sequence alike only to within that)."""
    fwd = jax.jacfwd(lambda p: rms_slider_deviation_mm(p, adjoint=diffrax.ForwardMode()))(P0)
    rev = np.asarray(reverse_gradient)
    np.testing.assert_allclose(np.asarray(fwd), rev, rtol=0, atol=1e-8 * np.abs(rev).max())


@pytest.mark.parametrize("i", range(4), ids=PARAMS)
def test_gradient_matches_central_differences(reverse_gradient, i):
    h = 1e-6 if i < 2 else 1e-8
    e = jnp.zeros(4).at[i].set(h)
    f_plus, f_minus = rms_slider_deviation_mm(P0 + e), rms_slider_deviation_mm(P0 - e)
    fd = (f_plus - f_minus) / (2 * h)
    g = float(reverse_gradient[i])
    # the difference quotient's own rounding: each value is the end of a solve of about 500
    # steps whose rounding adds up like a random walk, so two runs differ by about
    # sqrt(2 x 500) ~ 32 ulp; three times that is the floor. Measured: 17 ulp between the
    # two runs at clearance_C, whose pin does not touch within the window (its exact
    # derivative is zero), where a step of c_C moves the state's length scale
    rounding = 100 * np.finfo(float).eps * max(abs(float(f_plus)), abs(float(f_minus))) / (2 * h)
    tol = 1e-4 * max(abs(float(fd)), 1e-6 * np.abs(np.asarray(reverse_gradient)).max()) + rounding
    assert abs(g - float(fd)) <= tol
