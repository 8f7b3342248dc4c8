"""The validation rigs' shared event location (jaxcrank.analysis.validation.events) and
the straight-through estimator (jaxcrank.numerics.estimators), against closed forms."""

import jax
import jax.numpy as jnp
import numpy as np

from jaxcrank.analysis.validation.events import crossings
from jaxcrank.numerics.estimators import straight_through


def test_crossings_of_a_sine_are_the_multiples_of_pi():
    ts = np.linspace(0.1, 10.0, 50)
    up_lo, up_hi = crossings(np.sin, ts, np.sin(ts), upward=True)
    down_lo, down_hi = crossings(np.sin, ts, np.sin(ts), upward=False)
    np.testing.assert_allclose(up_hi, [2 * np.pi], rtol=1e-15)  # sin rises through 0 at 2 pi
    np.testing.assert_allclose(down_lo, [np.pi, 3 * np.pi], rtol=1e-15)
    assert np.all(np.sin(up_lo) < 0.0) and np.all(np.sin(up_hi) >= 0.0)
    assert np.all(np.sin(down_lo) >= 0.0) and np.all(np.sin(down_hi) < 0.0)
    empty = crossings(np.cos, ts[:3], np.cos(ts[:3]))
    assert empty[0].size == 0 and empty[1].size == 0


def test_straight_through_has_the_value_of_one_and_the_gradient_of_the_other():
    def f(x):
        return straight_through(jnp.sin(x), x**2)

    x = jnp.asarray(0.7)
    assert float(f(x)) == float(jnp.sin(x))
    assert float(jax.grad(f)(x)) == 2 * 0.7
    assert float(jax.jvp(f, (x,), (jnp.asarray(1.0),))[1]) == 2 * 0.7
