"""Rodas4: an L-stable, stiffly accurate Rosenbrock method as a diffrax solver.

A Rosenbrock method is linearly implicit: each step linearises the vector field
once (the Jacobian ``J = df/dy`` and ``df/dt`` by forward-mode AD) and solves
linear systems with ``I / (gamma h) - J`` instead of iterating Newton to
convergence. That suits this problem: the friction ramp makes it stiff (a real
eigenvalue up to ~5e7 1/s, see ``bench/stiffness.py``), and diffrax's implicit
Runge-Kutta solver Kvaerno5 takes more steps than the explicit tsit5 there
because its Newton iterations fail across the ramp, while a linearly implicit
stage has nothing to converge.

Method: Rodas4 of Hairer & Wanner (Solving ODEs II, 2nd ed., Sec. IV.7; the
coefficients of their code RODAS, in the transformed form with stage
increments ``k_i``), order 4 with an embedded order-3 solution (the error
estimate is the last stage), six stages, one Jacobian and one matrix inverse
per step ([`jaxcrank.numerics.linalg.inverse`][], plain array operations, so that XLA can
compile the solver loop into one kernel), L-stable and stiffly accurate, with the method's order-3 dense output
(like the stages, the dense output loses order on stiff components when a step
is much longer than their time constant; the step-end values do not).
Works for a state that is one 1-D array (jaxcrank's scaled state).
"""

from __future__ import annotations

from typing import ClassVar

import diffrax
import jax
import jax.numpy as jnp
import numpy as np

from .linalg import inverse

GAMMA = 0.25
# stage k_i starts from y0 + sum_j A[i][j] k_j (stage 6 from stage 5's point + k_5)
A = (
    (),
    (1.544,),
    (0.9466785280815826, 0.2557011698983284),
    (3.314825187068521, 2.896124015972201, 0.9986419139977817),
    (1.221224509226641, 6.019134481288629, 12.53708332932087, -0.6878860361058950),
)
# stage i's right-hand side adds sum_j C[i][j] k_j / h
C = (
    (),
    (-5.6688,),
    (-2.430093356833875, -0.2063599157091915),
    (-0.1073529058151375, -9.594562251023355, -20.47028614809616),
    (7.496443313967647, -10.24680431464352, -33.99990352819905, 11.70890893206160),
    (8.083246795921522, -7.981132988064893, -31.52159432874371, 16.31930543123136, -6.058818238834054),
)
NODES = (0.0, 0.386, 0.21, 0.63, 1.0, 1.0)  # stage times as fractions of h
D = (0.25, -0.1043, 0.1035, -0.0362, 0.0, 0.0)  # weights of h df/dt per stage
# dense output: y(theta) = (1 - theta) y0 + theta (y1 + (1 - theta) (q1 + theta q2)), q = H k[:5]
H = (
    (10.12623508344586, -7.487995877610167, -34.80091861555747, -7.992771707568823, 1.025137723295662),
    (-0.6762803392801253, 6.087714651680015, 16.43084320892478, 24.76722511418386, -6.594389125716872),
)


def _padded(rows, width=6):
    return np.array([list(r) + [0.0] * (width - len(r)) for r in rows])


# per stage 2..6: weights of k in the stage point and in the right-hand side, node, D, index
_A6 = _padded(A[1:] + (A[4] + (1.0,),))  # stage 6 starts from stage 5's point + k5
_STAGE_ROWS = (_A6, _padded(C[1:]), np.array(NODES[1:]), np.array(D[1:]), np.arange(1, 6))
_A_LAST = np.array(A[4] + (1.0, 1.0))  # y1 = stage 6's point + k6
_H = _padded(H)


def _combine(weights, ks):
    """sum_i weights[i] ks[i] for constant weights, as multiply-adds: XLA CPU makes a
    matrix product of these shapes a YNNPACK custom fusion, which (like a custom call)
    keeps the solver loop from being compiled into one kernel."""
    return sum(float(w) * ks[i] for i, w in enumerate(weights) if w != 0.0)


class RodasInterpolation(diffrax.AbstractLocalInterpolation):
    """Rodas4's dense output on one step (order 3 in theta)."""

    t0: jax.Array
    t1: jax.Array
    y0: jax.Array
    y1: jax.Array
    q: jax.Array  # (2, n): the two dense-output vectors

    def evaluate(self, t0, t1=None, left=True):
        del left
        if t1 is not None:
            return self.evaluate(t1) - self.evaluate(t0)
        # theta = (t - t0) / (t1 - t0), and 0 (with zero gradients) on an empty step
        empty = self.t1 == self.t0
        th = jnp.where(empty, 0.0, t0 - self.t0) / jnp.where(empty, 1.0, self.t1 - self.t0)
        return (1 - th) * self.y0 + th * (self.y1 + (1 - th) * (self.q[0] + th * self.q[1]))


class Rodas4(diffrax.AbstractAdaptiveSolver):
    """Rodas4 (Hairer & Wanner): L-stable linearly implicit solver of order 4(3).

    Use like any diffrax solver with an adaptive step-size controller; in
    jaxcrank, ``simulate(..., options=SolveOptions.from_text("rodas4"))``. Costs per step: the Jacobian
    (one batched forward-mode evaluation of the vector field), a matrix inverse
    of the state's size and five more vector-field evaluations; no Newton
    iteration, so a step never fails to converge (a poor linearisation shows up
    in the error estimate and the step is rejected).
    """

    term_structure: ClassVar = diffrax.AbstractTerm
    interpolation_cls: ClassVar = RodasInterpolation

    def order(self, terms):
        return 4

    def error_order(self, terms):
        return 4  # embedded order 3: the local error estimate is O(h^4)

    def init(self, terms, t0, t1, y0, args):
        if jnp.ndim(y0) != 1:
            raise ValueError(f"Rodas4 needs the state as one 1-D array, got shape {jnp.shape(y0)}")
        return None

    def func(self, terms, t0, y0, args):
        return terms.vf(t0, y0, args)

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        del solver_state, made_jump
        # Under vmap diffrax still steps batch members that have finished, with t1 = t0,
        # and discards the result. The reverse pass still differentiates that step, so it
        # must stay finite: a 1e-12 s step keeps the stages at y0 (h = 0 would divide by
        # zero; a long step would evaluate the contact forces far outside the bearing).
        h = jnp.where(t1 > t0, t1 - t0, 1e-12)

        def f(t, y):
            return terms.vf(t, y, args)

        def f_twice(t, y):
            out = f(t, y)
            return out, out

        (f_t, jac), f0 = jax.jacfwd(f_twice, argnums=(0, 1), has_aux=True)(t0, y0)
        w_inv = inverse(jnp.eye(y0.shape[0], dtype=jac.dtype) / (GAMMA * h) - jac)
        k1 = w_inv @ (f0 + (D[0] * h) * f_t)
        ks = jnp.zeros((6,) + y0.shape, y0.dtype).at[0].set(k1)

        # stages 2..6 share one compiled body (a scan), which keeps compilation short
        def stage(ks, row):
            a, c, node, d, i = row
            u = y0 + a @ ks
            k = w_inv @ (f(t0 + node * h, u) + (c @ ks) / h + (d * h) * f_t)
            return ks.at[i].set(k), None

        ks, _ = jax.lax.scan(stage, ks, _STAGE_ROWS)
        y1 = y0 + _combine(_A_LAST, ks)
        q = jnp.stack([_combine(row, ks) for row in _H])
        dense_info = dict(y0=y0, y1=y1, q=q)
        return y1, ks[5], dense_info, None, diffrax.RESULTS.successful
