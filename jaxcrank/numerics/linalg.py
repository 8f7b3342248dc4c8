"""Small dense linear algebra in plain array operations, for the solver loop.

XLA never compiles a while loop that contains a custom call (LAPACK's ``getrf``
behind ``jnp.linalg.inv`` and ``jax.scipy.linalg.lu_factor``) into one kernel
([`jaxcrank.numerics.runtime`][]), so an implicit solver that factorises its 10 x 10
iteration matrix with LAPACK keeps the whole solver loop on XLA's slower thunk
runtime. For matrices this small, elimination written as array operations costs
less than the call did; the 2 x 2 systems of the equations of motion and the
ideal-joint reactions are solved in closed form.
"""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx


def inverse(m):
    """Inverse of a small square matrix by Gauss-Jordan elimination with partial
    pivoting (plain array operations)."""
    n = m.shape[0]
    rows = jnp.arange(n)

    def eliminate(j, a):
        column = jax.lax.dynamic_index_in_dim(a, j, axis=1, keepdims=False)
        pivot = jnp.argmax(jnp.where(rows >= j, jnp.abs(column), -1.0))
        row_j = jax.lax.dynamic_index_in_dim(a, j, keepdims=False)
        row_p = jax.lax.dynamic_index_in_dim(a, pivot, keepdims=False)
        a = jax.lax.dynamic_update_index_in_dim(a, row_j, pivot, 0)  # swap rows j and pivot
        normalised = row_p / row_p[j]
        a = jax.lax.dynamic_update_index_in_dim(a, normalised, j, 0)
        factors = jnp.where(rows == j, 0.0, jax.lax.dynamic_index_in_dim(a, j, axis=1, keepdims=False))
        return a - factors[:, None] * normalised[None, :]

    augmented = jnp.concatenate([m, jnp.eye(n, dtype=m.dtype)], axis=1)
    return jax.lax.fori_loop(0, n, eliminate, augmented)[:, n:]


def solve_2x2(a, b):
    """a^-1 b for a 2 x 2 matrix a, in closed form."""
    det = a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]
    return jnp.stack([a[1, 1] * b[0] - a[0, 1] * b[1], a[0, 0] * b[1] - a[1, 0] * b[0]]) / det


class _Transposed(eqx.Module):
    """Whether a [`DenseInverse`][jaxcrank.numerics.linalg.DenseInverse] state solves with the transposed operator
    (static)."""

    value: bool = eqx.field(static=True)


class DenseInverse(lx.AbstractLinearSolver):
    """A lineax solver for small square systems whose vectors are 1-D arrays: the
    operator is inverted once ([`inverse`][jaxcrank.numerics.linalg.inverse]) and every solve is a product with
    the inverse. Use it where lineax's LU would be a LAPACK call inside a solver loop
    (e.g. the chord Newton iterations of diffrax's implicit Runge-Kutta solvers)."""

    def init(self, operator, options: dict[str, Any]):
        del options
        if operator.in_size() != operator.out_size():
            raise ValueError("DenseInverse needs a square operator")
        return inverse(operator.as_matrix()), _Transposed(False)

    def compute(self, state, vector, options: dict[str, Any]):
        del options
        inv, transposed = state
        if jnp.ndim(vector) != 1:
            raise ValueError(f"DenseInverse needs a 1-D vector, got shape {jnp.shape(vector)}")
        solution = (inv.T if transposed.value else inv) @ vector
        return solution, lx.RESULTS.successful, {}

    def transpose(self, state, options: dict[str, Any]):
        inv, transposed = state
        return (inv, _Transposed(not transposed.value)), {}

    def conj(self, state, options: dict[str, Any]):
        inv, transposed = state
        return (inv.conj(), transposed), {}

    def assume_full_rank(self):
        return True
