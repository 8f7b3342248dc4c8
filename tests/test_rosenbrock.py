"""The Rodas4 solver checked against facts: its convergence order, its dense
output, L-stability on a stiff problem, agreement with tsit5 on the paper
mechanism, and reverse mode against central differences."""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest

import jaxcrank as jc
from jaxcrank import model, outputs
from jaxcrank.numerics.rosenbrock import Rodas4


def _forced_pendulum(t, y, args):
    return jnp.array([y[1], -jnp.sin(y[0]) + 0.3 * jnp.cos(2.0 * t)])


def _solve(vf, solver, t1, y0, ts, dt0=None, tol=None, max_steps=100_000):
    controller = (
        diffrax.ConstantStepSize() if tol is None else diffrax.PIDController(rtol=tol, atol=tol, norm=optx.rms_norm)
    )
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(vf),
        solver,
        0.0,
        t1,
        dt0 if dt0 else 1e-3,
        jnp.asarray(y0),
        stepsize_controller=controller,
        saveat=diffrax.SaveAt(ts=ts),
        max_steps=max_steps,
    )
    return np.asarray(sol.ys), sol


def test_order_four_and_dense_output():
    """Fixed steps on a forced pendulum (non-autonomous, so the df/dt terms count):
    the error at the step ends falls as h^4 (observed order within 0.2 of 4), and
    the dense output between steps as at least h^3 (its design order)."""
    t1, y0 = 3.0, [1.0, 0.0]
    ends = jnp.linspace(0.0, t1, 13)  # step ends for every n below
    inside = jnp.linspace(0.0, t1, 13)[:-1] + 0.37 * t1 / 12  # inside the coarsest steps' intervals
    ts = jnp.sort(jnp.concatenate([ends, inside]))
    ref, _ = _solve(_forced_pendulum, diffrax.Dopri8(), t1, y0, ts, tol=1e-14)
    at_end = np.isin(np.asarray(ts), np.asarray(ends))
    err_end, err_in = [], []
    for n in (24, 48, 96):
        ys, _ = _solve(_forced_pendulum, Rodas4(), t1, y0, ts, dt0=t1 / n)
        err_end.append(np.abs(ys - ref)[at_end].max())
        err_in.append(np.abs(ys - ref)[~at_end].max())
    order_end = np.log2(np.array(err_end[:-1]) / np.array(err_end[1:]))
    order_in = np.log2(np.array(err_in[:-1]) / np.array(err_in[1:]))
    assert np.all(np.abs(order_end - 4.0) < 0.2), order_end
    assert np.all(order_in > 2.8), order_in


def test_l_stable_on_a_stiff_problem():
    """Prothero-Robinson y' = lam (y - sin t) + cos t, lam = -1e8, exact solution sin t:
    with steps ~1e7 times the explicit stability limit (~3 / |lam|) the solution at
    t = 2 s is right to the tolerance, in a handful of steps."""
    lam = -1e8

    def vf(t, y, args):
        return lam * (y - jnp.sin(t)) + jnp.cos(t)

    ys, sol = _solve(vf, Rodas4(), 2.0, jnp.array([0.0]), jnp.array([2.0]), tol=1e-8, max_steps=10_000)
    assert abs(ys[0, 0] - np.sin(2.0)) < 1e-8
    assert int(sol.stats["num_steps"]) < 50


def test_agrees_with_tsit5_on_the_paper_mechanism(paper):
    """First 5 ms of the paper run (the start-up impacts at both pins): Rodas4 and
    tsit5 at rtol = atol = 1e-9 give the same slider and rod motion to within
    1e-9 m (2e-6 of the 0.5 mm clearance). At 1e-8 tsit5 alone is 2.1e-9 m off a
    tsit5 solve at 1e-11 (rodas4 3e-11 m): the approach-speed memory's fast reset after
    each separation is resolved less accurately by the explicit solver; at 1e-9 both are
    within 1.1e-11 m of it."""
    cols = [
        outputs.trajectory(
            jc.simulate(paper, 0.005, n_samples=181, options=jc.SolveOptions.from_text(s, rtol=1e-9, atol=1e-9))
        )
        for s in ("rodas4", "tsit5")
    ]
    for name in ("slider_x", "rod_x"):
        assert np.abs(cols[0][name] - cols[1][name]).max() < 1e-9, name


@pytest.mark.slow  # about a minute of compilation
def test_reverse_mode_is_the_derivative_of_the_fixed_step_solution(paper):
    """First 1.2 ms of the paper run (first impact at B), fixed steps of 0.2 us:
    reverse mode through Rodas4 (Jacobian, inverse, stages) matches central
    differences of the same discrete solution within 1e-7 (relative), w.r.t.
    L1 and L2. (With adaptive steps diffrax holds the step sizes fixed in reverse
    mode, so there the two differ by how much the solution moves with its step
    sequence.)"""
    t1 = 1.2e-3
    ts = jnp.linspace(0.0, t1, 121)

    def objective(x):
        mech = eqx.tree_at(lambda m: (m.crank_length, m.rod_length), paper, (x[0], x[1]))
        sol = diffrax.diffeqsolve(
            diffrax.ODETerm(model.vector_field),
            Rodas4(),
            0.0,
            t1,
            2e-7,
            model.initial_state(mech),
            args=mech,
            saveat=diffrax.SaveAt(ts=ts),
            stepsize_controller=diffrax.ConstantStepSize(),
            max_steps=10_000,
        )
        return jnp.sum(outputs.transmission_angle_error(mech, sol.ts, sol.ys) ** 2)

    x = jnp.array([0.12, 0.40])
    grad = np.asarray(jax.jit(jax.grad(objective))(x))
    f = jax.jit(objective)
    for i in range(2):
        e = np.zeros(2)
        e[i] = 1e-5
        fd = (float(f(x + e)) - float(f(x - e))) / 2e-5
        assert abs(grad[i] - fd) <= 1e-7 * abs(fd), (i, grad[i], fd)
