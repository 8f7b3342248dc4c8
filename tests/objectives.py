"""Objectives and a finite difference shared by the optimiser tests."""

import jax.numpy as jnp
import numpy as np

from jaxcrank import SolveOptions
from optim.ensemble import Ensemble
from optim.objective import Pathwise

# Short ensemble objective: evaluation window (0.02, 0.03] s (impacts from the first
# milliseconds on, chaotic by 20 ms), five 2 ms windows. The default suite solves the
# windows with tsit5 (compiles in seconds, where the default implicit kvaerno5 takes
# minutes); the ``slow`` tests check the default solver.
SHORT = Ensemble(t_start=0.02, t_end=0.03, window_options=SolveOptions.from_text("tsit5", max_steps=5_000))
# A non-chaotic window for exact-gradient checks: the first 1.2 ms (see test_gradients).
EXACT = Pathwise(t_start=0.0, t_end=1.2e-3, options=SolveOptions(rtol=1e-10, atol=1e-10, max_steps=100_000))


def central_difference(f, x, i, h):
    """``(f(x + h e_i) - f(x - h e_i)) / 2h``."""
    e = np.zeros(len(x))
    e[i] = h
    return (float(f(jnp.asarray(x + e))) - float(f(jnp.asarray(x - e)))) / (2 * h)
