"""The optimiser Modules (optim.optimizers) on their own, without a mechanism: names and
settings at the TOML boundary, range checks, and their steps on a smooth quadratic whose
minimiser is known (projected Adam to the box-constrained minimiser; optax's L-BFGS to the
unconstrained one). ProjectedLBFGS's steps are tested in test_quasi_newton."""

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

from jaxcrank.physics.params import ParameterError
from optim.optimizers import LBFGS, OPTIMIZERS, Projected, ProjectedLBFGS, adam, from_settings

#: f(u) = (u - c)^T D (u - c) / 2 on the scaled design: unconstrained minimiser c; on the unit box
#: the minimiser is clip(c, 0, 1) = (1, 0.25, 0) (D is diagonal)
C, D = jnp.array([1.4, 0.25, -0.3]), jnp.array([1.0, 4.0, 10.0])


def f(u):
    return 0.5 * jnp.sum(D * (u - C) ** 2)


def extended(u, f0):
    value, grad = jax.value_and_grad(f)(u)
    return value / f0, grad / f0


@pytest.mark.parametrize("name", sorted(OPTIMIZERS))
def test_every_optimiser_round_trips_through_its_settings(name):
    opt = from_settings(name)
    settings = opt.settings()
    assert settings["method"] == name == opt.label
    again = from_settings(**settings)
    assert again.settings() == settings


@pytest.mark.parametrize(
    "make, match",
    [
        (lambda: from_settings("sgd"), "optimiser method 'sgd' is unknown; valid: adam, lbfgs, projected_lbfgs"),
        (lambda: from_settings("adam", memory_size=3), r"optimiser 'adam' takes \['learning_rate'\]"),
        (lambda: adam(0.0), "learning_rate = 0.0 must be > 0"),
        (lambda: LBFGS(penalty=-1.0), "penalty = -1.0 must be > 0"),
        (lambda: ProjectedLBFGS(armijo=0.5), r"armijo = 0.5 must be in \(0, 0.5\)"),
        (lambda: ProjectedLBFGS(memory_size=0), "memory_size = 0 must be >= 1"),
    ],
)
def test_bad_settings_are_refused_naming_the_setting(make, match):
    with pytest.raises(ParameterError, match=match):
        make()


def test_projected_adam_stays_in_the_box_and_reaches_the_constrained_minimiser():
    opt = adam(0.05)
    u = jnp.array([0.5, 0.5, 0.5])
    state = opt.init(u)
    for _ in range(400):
        value, grad = jax.value_and_grad(f)(u)
        updates, state = opt.update(grad, state, u, value, 1.0, None)
        u = jnp.clip(optax.apply_updates(u, updates), 0.0, 1.0)  # the problem's projection, here the box
        assert bool(jnp.all((u >= 0.0) & (u <= 1.0)))
    np.testing.assert_allclose(np.asarray(u), [1.0, 0.25, 0.0], atol=1e-3)


def test_projected_wraps_any_optax_transformation():
    opt = Projected(optax.sgd(0.1), "sgd", 0.1)
    u = jnp.zeros(3)
    updates, _ = opt.update(jax.grad(f)(u), opt.init(u), u, f(u), 1.0, None)
    np.testing.assert_allclose(np.asarray(updates), -0.1 * np.asarray(jax.grad(f)(u)), rtol=1e-15)


def test_lbfgs_minimises_a_quadratic_in_a_few_iterations():
    """Three variables, exact gradients: optax's L-BFGS with its zoom line search reaches the
    minimiser to 1e-8 within 10 iterations (a quasi-Newton method on a quadratic needs about
    as many as there are variables)."""
    opt = LBFGS()
    u = jnp.zeros(3)
    state = opt.init(u)
    iterations = 0
    while float(jnp.max(jnp.abs(u - C))) >= 1e-8 and iterations < 10:
        value, grad = extended(u, 1.0)
        updates, state = opt.update(grad, state, u, value, 1.0, extended)
        u = optax.apply_updates(u, updates)
        iterations += 1
    assert float(jnp.max(jnp.abs(u - C))) < 1e-8, (iterations, u)
