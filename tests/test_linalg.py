"""Small dense linear algebra of the implicit solvers (jaxcrank.numerics.linalg) against
numpy's LAPACK-backed solves."""

import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
import pytest

from jaxcrank.numerics.linalg import DenseInverse, inverse


def _matrices():
    rng = np.random.default_rng(0)
    yield "random", rng.normal(size=(10, 10))
    # a zero leading pivot: elimination without row exchanges would divide by zero
    permuted = np.eye(10)[rng.permutation(10)] + 1e-3 * rng.normal(size=(10, 10))
    yield "needs pivoting", permuted
    # an implicit solver's iteration matrix I - h*gamma*J with a stiff J (cond ~1e8)
    jac = rng.normal(size=(10, 10)) @ np.diag(np.logspace(0, 8, 10)) @ rng.normal(size=(10, 10))
    yield "stiff iteration matrix", np.eye(10) - 0.25 * 1e-4 * jac


@pytest.mark.parametrize("name, m", list(_matrices()), ids=lambda v: v if isinstance(v, str) else "")
def test_inverse_and_solves_match_lapack(name, m):
    """inverse(m) @ m = I and solves (plain and transposed) agree with numpy's within
    1e3 * machine epsilon * cond(m), the accuracy backward-stable elimination gives."""
    inv = np.asarray(jax.jit(inverse)(jnp.asarray(m)))
    tol = 1e3 * np.finfo(float).eps * np.linalg.cond(m)
    assert np.abs(inv @ m - np.eye(10)).max() < tol
    b = np.arange(1.0, 11.0)
    op = lx.MatrixLinearOperator(jnp.asarray(m))
    x = lx.linear_solve(op, jnp.asarray(b), DenseInverse()).value
    xt = lx.linear_solve(op.T, jnp.asarray(b), DenseInverse()).value
    for got, want in ((x, np.linalg.solve(m, b)), (xt, np.linalg.solve(m.T, b))):
        assert np.linalg.norm(np.asarray(got) - want) <= tol * np.linalg.norm(want)


def test_gradient_through_a_dense_inverse_solve_matches_lapack():
    """Reverse mode through lx.linear_solve with DenseInverse (lineax differentiates
    the solve through the transposed solver) equals the same with LU."""
    rng = np.random.default_rng(1)
    m, b = jnp.asarray(rng.normal(size=(6, 6)) + 6 * np.eye(6)), jnp.asarray(rng.normal(size=6))

    def loss(m, b, solver):
        return jnp.sum(jnp.sin(lx.linear_solve(lx.MatrixLinearOperator(m), b, solver).value))

    ours = jax.grad(loss, argnums=(0, 1))(m, b, DenseInverse())
    lapack = jax.grad(loss, argnums=(0, 1))(m, b, lx.LU())
    for a, c in zip(ours, lapack):
        np.testing.assert_allclose(np.asarray(a), np.asarray(c), rtol=1e-10, atol=1e-12)


def test_rejects_what_it_cannot_solve():
    with pytest.raises(ValueError, match="square"):
        DenseInverse().init(lx.MatrixLinearOperator(jnp.ones((3, 4))), {})
