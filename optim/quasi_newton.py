"""Projected L-BFGS on a scaled feasible set: the algorithm of
[`optim.optimizers.ProjectedLBFGS`][], as functions of arrays on the host.

For objectives whose evaluations are expensive (a steady-state value and its exact
gradient cost seconds), each evaluation gives value and gradient together, and the
constraints are the unit box and a few half-spaces
([`optim.problem.FeasibleSet`][]). One iteration at ``u`` (value ``f``, gradient ``g``):

1. **Working set.** The constraints active at ``u`` (slack <= ``active_tol``), a linearly
   independent subset, from which the one with the most negative multiplier is dropped
   until every multiplier is >= 0: the constraints the model's minimiser pushes against.
   With ``N`` their outward normals (columns) and ``H`` the L-BFGS inverse Hessian (two-loop
   recursion on the last ``memory_size`` pairs ``(s, y)``, ``H_0 = (s.y / y.y) I`` of the
   newest pair), the multipliers are ``lambda = -(N^T H N)^-1 N^T H g``.
2. **Direction.** The quasi-Newton step on the face the working set spans,
   ``d = -H (g + N lambda)``: the minimiser of the quadratic model with ``N^T d = 0``
   (L-BFGS-B's subspace step for general linear constraints). Without a stored pair,
   the projected-gradient arc ``d = -g * initial_step / |g|_inf``.
3. **Line search** along the projection arc ``u(t) = P(u + t d)``, ``t = 1, ...``: every
   trial point is projected, hence feasible; it is accepted by the Armijo condition
   ``f(u(t)) <= f + armijo * g . (u(t) - u)``. A trial whose value or gradient is not
   finite, or that the evaluation refuses (the regime guard: a design outside the
   periodic regime), fails the test; ``t`` shrinks by safeguarded quadratic interpolation
   (a factor in [0.1, 0.5]; 0.5 after a refusal). When the quasi-Newton arc finds no
   decrease in ``max_linesearch_steps`` trials, the memory is cleared and the projected-
   gradient arc is searched; if that fails too, the iteration fails.
4. **Memory.** The pair ``s = u_new - u``, ``y = g_new - g`` is stored when its
   curvature ``s . y > curvature_eps * y . y`` (else skipped), the oldest dropped after
   ``memory_size``.

Convergence (the caller's tests): the projected-gradient step ``|P(u - g) - u|_inf``
(scaled variables) and the relative value change of an accepted step,
``|f_k - f_k+1| <= ftol * max(|f_k|, |f_k+1|, 1)``
([`value_change_converged`][optim.quasi_newton.value_change_converged]).
[`minimize`][optim.quasi_newton.minimize] runs the iteration on a callable;
[`optim.optimize.optimize`][] runs it on a design problem with checkpoints and the
regime guard.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from jaxcrank.physics.params import ParameterError

#: an evaluation: scaled design (n,) -> (value, gradient (n,)), or None when it refuses the design
Evaluation = Callable[[np.ndarray], "tuple[float, np.ndarray] | None"]


class LBFGSState(NamedTuple):
    """The L-BFGS memory: the last pairs, oldest first, in the last ``pairs`` rows.

    Attributes:
        s: design differences ``u_new - u``, (memory_size, n), scaled units.
        y: gradient differences ``g_new - g``, (memory_size, n), scaled objective per scaled unit.
        pairs: how many rows hold pairs (0 ... memory_size), int.
    """

    s: np.ndarray
    y: np.ndarray
    pairs: np.ndarray


class Step(NamedTuple):
    """One iteration's outcome ([`step`][optim.quasi_newton.step]).

    Attributes:
        u: the new iterate (the old one when ``ok`` is False), scaled.
        value: its value. Same for grad (its gradient).
        grad: its gradient.
        state: the updated memory.
        ok: whether a trial point passed the Armijo test.
        evaluations: value-and-gradient evaluations made.
        refused: trial points the evaluation refused (not evaluated).
        trials: trial points tried (evaluated or refused).
        t: the accepted (or last tried) step along the arc.
        direction: ``"quasi-newton"`` or ``"gradient"``: the arc of the accepted (or last) search.
    """

    u: np.ndarray
    value: float
    grad: np.ndarray
    state: LBFGSState
    ok: bool
    evaluations: int
    refused: int
    trials: int
    t: float
    direction: str


def init_state(u, memory_size: int) -> LBFGSState:
    """An empty memory for designs shaped like ``u``."""
    n = np.shape(u)[-1]
    return LBFGSState(np.zeros((memory_size, n)), np.zeros((memory_size, n)), np.asarray(0))


def pairs_of(state: LBFGSState) -> tuple[np.ndarray, np.ndarray]:
    """The stored pairs ``(s, y)``, oldest first, each (pairs, n)."""
    k = int(state.pairs)
    s, y = np.asarray(state.s, dtype=float), np.asarray(state.y, dtype=float)
    return s[len(s) - k :], y[len(y) - k :]


def add_pair(state: LBFGSState, s, y, curvature_eps: float) -> LBFGSState:
    """``state`` with the pair ``(s, y)`` appended (the oldest dropped when full), or
    unchanged when its curvature ``s . y <= curvature_eps * y . y`` (or ``y = 0``)."""
    s, y = np.asarray(s, dtype=float), np.asarray(y, dtype=float)
    sy, yy = float(s @ y), float(y @ y)
    if not (yy > 0.0 and sy > curvature_eps * yy and np.isfinite(sy)):
        return state
    mem_s = np.concatenate([np.asarray(state.s, dtype=float)[1:], s[None]])
    mem_y = np.concatenate([np.asarray(state.y, dtype=float)[1:], y[None]])
    return LBFGSState(mem_s, mem_y, np.asarray(min(int(state.pairs) + 1, len(mem_s))))


def two_loop(v, s, y, gamma: float) -> np.ndarray:
    """``H v`` for the L-BFGS inverse Hessian of the pairs ``s, y`` (k, n), oldest first,
    with ``H_0 = gamma I`` (Nocedal & Wright, Numerical Optimization, Algorithm 7.4)."""
    q = np.array(v, dtype=float)
    rho = 1.0 / np.einsum("ij,ij->i", s, y)
    alpha = np.zeros(len(s))
    for i in range(len(s) - 1, -1, -1):
        alpha[i] = rho[i] * (s[i] @ q)
        q -= alpha[i] * y[i]
    r = gamma * q
    for i in range(len(s)):
        r += s[i] * (alpha[i] - rho[i] * (y[i] @ r))
    return r


def working_set(G, h, u, grad, apply_h, active_tol: float) -> tuple[list[int], np.ndarray]:
    """The rows of ``G u <= h`` the quasi-Newton step keeps active (module docstring, step 1)
    and their multipliers (>= 0); ``apply_h(v) = H v``."""
    slack = h - G @ u
    unit = G / np.linalg.norm(G, axis=1, keepdims=True)
    chosen: list[int] = []
    for j in np.flatnonzero(slack <= active_tol):
        if np.linalg.matrix_rank(unit[chosen + [j]], tol=1e-10) == len(chosen) + 1:
            chosen.append(int(j))
    hg = apply_h(grad)
    while chosen:
        N = G[chosen].T
        hn = np.stack([apply_h(N[:, k]) for k in range(N.shape[1])], axis=1)
        lam = -np.linalg.solve(N.T @ hn, N.T @ hg)
        if lam.min() >= 0.0:
            return chosen, lam
        chosen.pop(int(np.argmin(lam)))
    return chosen, np.zeros(0)


def direction(state: LBFGSState, G, h, u, grad, active_tol: float) -> np.ndarray | None:
    """The quasi-Newton direction on the working set's face, ``-H (g + N lambda)``
    (module docstring, step 2), or None without a stored pair."""
    s, y = pairs_of(state)
    if not len(s):
        return None
    gamma = float(s[-1] @ y[-1]) / float(y[-1] @ y[-1])
    apply_h = lambda v: two_loop(v, s, y, gamma)
    chosen, lam = working_set(G, h, u, grad, apply_h, active_tol)
    d = -apply_h(grad + (G[chosen].T @ lam if chosen else 0.0))
    n = len(u)
    for j in chosen:  # exactly still along the bounds it keeps (rounding would leave them by 1e-17)
        if j < 2 * n:
            d[j % n] = 0.0
    return d


def line_search(opt, fun: Evaluation, project, u, value: float, grad, d) -> Step:
    """Backtracking Armijo search along ``P(u + t d)`` from ``t = 1`` (module docstring,
    step 3); the returned Step has ``state = None`` (the caller updates the memory)."""
    t, evaluations, refused = 1.0, 0, 0
    for trial in range(1, opt.max_linesearch_steps + 1):
        point = np.asarray(project(u + t * d), dtype=float)
        move = point - u
        slope = float(grad @ move)
        if not np.any(move):  # the arc does not leave u: no step can decrease f
            return Step(u, value, grad, None, False, evaluations, refused, trial, t, "")
        out = fun(point) if slope < 0.0 else None  # an ascent arc (never the gradient's) shrinks unevaluated
        refused += out is None and slope < 0.0
        v, g = (float(out[0]), np.asarray(out[1], dtype=float)) if out is not None else (np.nan, None)
        evaluations += out is not None
        if np.isfinite(v) and np.all(np.isfinite(g)) and v <= value + opt.armijo * slope:
            return Step(point, v, g, None, True, evaluations, refused, trial, t, "")
        if trial < opt.max_linesearch_steps:  # the next t: the quadratic's minimiser through f, slope, f(t)
            shrink = -slope / (2.0 * (v - value - slope)) if np.isfinite(v) else 0.5
            t *= float(np.clip(shrink, 0.1, 0.5))
    return Step(u, value, grad, None, False, evaluations, refused, opt.max_linesearch_steps, t, "")


def step(opt, fun: Evaluation, feasible, u, value: float, grad, state: LBFGSState) -> Step:
    """One projected L-BFGS iteration from ``u`` with its ``value`` and ``grad``
    (module docstring): the quasi-Newton arc, or the projected-gradient arc without
    memory or after the quasi-Newton arc failed (the memory then cleared).

    Args:
        opt: the settings ([`optim.optimizers.ProjectedLBFGS`][]).
        fun: the evaluation, ``u -> (value, gradient)`` or None to refuse ``u``.
        feasible: the scaled feasible set ([`optim.problem.FeasibleSet`][]); ``u`` lies in it.
        state: the memory ([`init_state`][optim.quasi_newton.init_state]).

    Returns:
        [`Step`][optim.quasi_newton.Step]: the accepted point, or ``u`` with ``ok = False``.
    """
    u, grad = np.asarray(u, dtype=float), np.asarray(grad, dtype=float)
    G, h = feasible.rows()
    d = direction(state, G, h, u, grad, opt.active_tol)
    spent = (0, 0, 0)
    if d is not None:
        out = line_search(opt, fun, feasible.project, u, value, grad, d)
        if out.ok:
            return out._replace(
                state=add_pair(state, out.u - u, out.grad - grad, opt.curvature_eps), direction="quasi-newton"
            )
        spent = (out.evaluations, out.refused, out.trials)
        state = init_state(u, opt.memory_size)  # its curvature misled the search: start afresh
    scale = opt.initial_step / max(float(np.max(np.abs(grad))), np.finfo(float).tiny)
    out = line_search(opt, fun, feasible.project, u, value, grad, -scale * grad)
    new_state = add_pair(state, out.u - u, out.grad - grad, opt.curvature_eps) if out.ok else state
    return out._replace(
        state=new_state,
        evaluations=out.evaluations + spent[0],
        refused=out.refused + spent[1],
        trials=out.trials + spent[2],
        direction="gradient",
    )


def projected_gradient(feasible, u, grad) -> float:
    """``|P(u - g) - u|_inf``: zero exactly at a stationary point of the constrained problem."""
    return float(np.max(np.abs(feasible.project(np.asarray(u) - np.asarray(grad)) - np.asarray(u))))


def value_change_converged(previous: float, value: float, ftol: float) -> str | None:
    """The stopping reason when an accepted step changed the value by at most
    ``ftol * max(|previous|, |value|, 1)`` (the 1: values scaled to the start's), else None."""
    change = abs(previous - value)
    if change <= ftol * max(abs(previous), abs(value), 1.0):
        return f"relative value change {change / max(abs(previous), abs(value), 1.0):.2e} <= ftol {ftol:g}"
    return None


def failure_reason(out: Step) -> str:
    """What a failed iteration did, and what to do."""
    return (
        f"line search failed: no decrease along the projected quasi-Newton or gradient arc in {out.trials} "
        f"trials ({out.evaluations} evaluated, {out.refused} refused by the regime guard; smallest step "
        f"t = {out.t:.2e}): the gradient does not predict the values here (a kink, noise or chaos, the edge "
        "of the periodic regime, or values resolved no finer than gtol asks); keep the iterate, or raise "
        "max_linesearch_steps / lower initial_step"
    )


def minimize(fun: Evaluation, u0, feasible, opt, *, gtol: float = 1e-8, max_iterations: int = 100) -> dict:
    """Minimise ``fun`` over the scaled feasible set from ``u0`` (projected first) by
    projected L-BFGS ([`step`][optim.quasi_newton.step]).

    Args:
        fun: ``u -> (value, gradient)`` (None refuses ``u``: a failed trial).
        u0: start, (n,), scaled.
        feasible: the set ([`optim.problem.FeasibleSet`][]).
        opt: the settings ([`optim.optimizers.ProjectedLBFGS`][]; its ``ftol`` is the value-change test).
        gtol: stop when [`projected_gradient`][optim.quasi_newton.projected_gradient] is at most this.
        max_iterations: iterations (steps) at most.

    Returns:
        dict: ``u``, ``value``, ``grad`` (the last iterate), ``iterations`` (accepted steps),
        ``evaluations`` (value-and-gradient evaluations, the start's included),
        ``converged`` (the reason, or None), ``stop_reason`` (always a sentence) and
        ``history`` (per iterate: ``u``, ``value``, ``projected_gradient``, ``evaluations`` so far,
        ``trials`` of the line search from it).

    Raises:
        ParameterError: the start's value or gradient is not finite, or it is refused.
    """
    u = np.asarray(feasible.project(np.asarray(u0, dtype=float)), dtype=float)
    out = fun(u)
    if out is None or not (np.isfinite(float(out[0])) and np.all(np.isfinite(np.asarray(out[1])))):
        raise ParameterError(f"the start u0 = {u.tolist()} has no finite value and gradient: start elsewhere")
    value, grad = float(out[0]), np.asarray(out[1], dtype=float)
    state, evaluations, history = opt.init(u), 1, []
    converged = stop = None
    for _ in range(max_iterations + 1):
        pg = projected_gradient(feasible, u, grad)
        history.append({"u": u, "value": value, "projected_gradient": pg, "evaluations": evaluations, "trials": 0})
        if pg <= gtol:
            converged = f"projected gradient {pg:.2e} <= gtol {gtol:g}"
        elif len(history) > 1:
            converged = value_change_converged(history[-2]["value"], value, opt.ftol)
        if converged or len(history) > max_iterations:
            break
        res = opt.step(fun, feasible, u, value, grad, state)
        evaluations += res.evaluations
        history[-1]["trials"] = res.trials
        if not res.ok:
            stop = failure_reason(res)
            break
        u, value, grad, state = res.u, res.value, res.grad, res.state
    reason = converged or stop or f"iteration limit: max_iterations = {max_iterations}"
    return {
        "u": u,
        "value": value,
        "grad": grad,
        "iterations": len(history) - 1,
        "evaluations": evaluations,
        "converged": converged,
        "stop_reason": reason,
        "history": history,
    }


def trial_function(problem, vg, f0: float, guard, evaluator) -> Evaluation:
    """The evaluation of trial points of a design problem on the scaled design:
    ``u -> (value / f0, gradient)`` from ``vg(u, f0)`` ([`optim.optimize.programs`][]; not finite
    where the solve failed), or None where the regime ``guard`` ([`optim.steady.RegimeGuard`][],
    with the steady-state ``evaluator``) refuses the design; no guard: every design is evaluated."""

    def trial(u):
        if guard is not None and not guard.accept(evaluator, np.asarray(problem.from_unit(u))):
            return None
        value, grad = vg(u, f0)
        return float(value), np.asarray(grad, dtype=float)

    return trial
