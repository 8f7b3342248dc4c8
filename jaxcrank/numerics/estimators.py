"""Gradient estimators: a value from one computation with the derivative of another."""

from __future__ import annotations

import jax
from jaxtyping import Array, ArrayLike, Float


def straight_through(
    value: Float[ArrayLike, "*shape"], surrogate: Float[ArrayLike, "*shape"]
) -> Float[Array, "*shape"]:
    """``value`` with the derivative of ``surrogate``: ``sg(value) + (surrogate -
    sg(surrogate))``, sg the stop-gradient. Forward: exactly ``value`` wherever
    ``surrogate`` is finite; derivatives (any mode, first order only: the second
    derivative of the difference is not the surrogate's): those of ``surrogate``.
    Used where a quantity is computed exactly by one solve and its gradient is
    estimated by another (the ensemble-sensitivity objectives)."""
    sg = jax.lax.stop_gradient
    return sg(value) + (surrogate - sg(surrogate))
