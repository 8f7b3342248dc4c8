"""Projected L-BFGS (optim.quasi_newton, optim.optimizers.ProjectedLBFGS) on smooth problems
with known minima, and in optim.optimize's loop with stand-ins for the steady-state
evaluator: no mechanism is solved.

``python -m tests.test_quasi_newton`` prints the iterations and evaluations of projected
L-BFGS and projected Adam to a tolerance on the smooth problems."""

import jax.numpy as jnp
import numpy as np
import pytest

from jaxcrank import paper
from jaxcrank.physics.params import ParameterError
from optim import quasi_newton as qn
from optim.design import DesignProblem
from optim.optimize import Settings, optimize
from optim.optimizers import ProjectedLBFGS, adam, from_settings
from optim.problem import FeasibleSet
from optim.steady import NOT_PERIODIC, PERIODIC, RegimeGuard, Steady


def quadratic(n=9, condition=1e4, seed=0):
    """``(Q, c)``: a Hessian with eigenvalues log-spaced over ``[1, condition]`` in random
    axes and a minimum ``c`` inside the unit box (every coordinate in [0.3, 0.7])."""
    rng = np.random.default_rng(seed)
    axes, _ = np.linalg.qr(rng.standard_normal((n, n)))
    return axes @ np.diag(np.logspace(0, np.log10(condition), n)) @ axes.T, 0.3 + 0.4 * rng.random(n)


def rosenbrock(u):
    """The chained Rosenbrock function of ``x = -2 + 4 u`` (x in [-2, 2]^n, minimum 0 at
    x = 1, u = 0.75) and its gradient with respect to ``u``."""
    x = -2.0 + 4.0 * np.asarray(u)
    r = x[1:] - x[:-1] ** 2
    g = np.zeros_like(x)
    g[:-1] += -400.0 * x[:-1] * r - 2.0 * (1.0 - x[:-1])
    g[1:] += 200.0 * r
    return float(np.sum(100.0 * r**2 + (1.0 - x[:-1]) ** 2)), 4.0 * g


def box(n):
    return FeasibleSet(np.zeros((0, n)), np.zeros(0))


def test_quadratic_with_condition_1e4_in_9_variables_converges_in_at_most_80_iterations():
    """A strictly convex quadratic, Hessian condition 1e4, minimum inside the box, from the
    box's corner region (the first steps reach the bounds, which the working set then
    releases). The bound: L-BFGS with unit quasi-Newton steps converges superlinearly on a
    quadratic; measured 56 iterations (58 evaluations) from this start and 54 from the centre
    with 20 pairs (scipy's L-BFGS-B, 10 pairs and a Wolfe line search: 90 iterations from this
    start); 80 leaves room for rounding, not for a linearly converging method (projected Adam
    needs thousands of iterations, python -m tests.test_quasi_newton)."""
    Q, c = quadratic()
    res = qn.minimize(
        lambda u: (0.5 * (u - c) @ Q @ (u - c), Q @ (u - c)),
        np.full(9, 0.95),
        box(9),
        ProjectedLBFGS(ftol=0.0),
        gtol=1e-9,
        max_iterations=200,
    )
    assert res["converged"] and res["converged"].startswith("projected gradient"), res["stop_reason"]
    assert res["iterations"] <= 80, res["iterations"]
    assert res["evaluations"] <= res["iterations"] + 20  # unit steps are accepted nearly always
    np.testing.assert_allclose(res["u"], c, atol=1e-10)


def test_rosenbrock_in_9_variables_converges_in_at_most_100_iterations():
    """Chained Rosenbrock in 9 variables from the classic start (x = -1.2, 1, -1.2, ...), the
    minimum x = 1 inside the box [-2, 2]^9. The bound: measured 77 iterations (83 evaluations);
    scipy's L-BFGS-B (Wolfe line search) takes 65 on the same scaled problem; 100 is the usual
    budget of a quasi-Newton method on this function, well short of a first-order method's."""
    x0 = np.tile([-1.2, 1.0], 5)[:9]
    res = qn.minimize(rosenbrock, (x0 + 2.0) / 4.0, box(9), ProjectedLBFGS(ftol=0.0), gtol=1e-8, max_iterations=300)
    assert res["converged"] and res["converged"].startswith("projected gradient"), res["stop_reason"]
    assert res["iterations"] <= 100, res["iterations"]
    np.testing.assert_allclose(-2.0 + 4.0 * res["u"], np.ones(9), atol=1e-6)


def constrained_quadratic():
    """A quadratic in 5 variables (condition 1e3) whose unconstrained minimum lies outside
    the set ``[0, 1]^5`` and ``u_1 + u_2 + 0.5 u_3 <= 1.2``, built from its constrained
    minimum ``u*`` (on the bound u_0 = 1 and on the half-space) and positive multipliers
    (2 and 3): ``c = u* + Q^-1 (2 e_0 + 3 a)`` satisfies the KKT conditions at ``u*``,
    which is therefore the minimum (strictly convex). Returns ``(Q, c, a, beta, u*)``."""
    Q, _ = quadratic(5, 1e3, seed=1)
    a, beta = np.array([0.0, 1.0, 1.0, 0.5, 0.0]), 1.2
    ustar = np.array([1.0, 0.5, 0.45, 0.5, 0.3])
    c = ustar + np.linalg.solve(Q, 2.0 * np.eye(5)[0] + 3.0 * a)
    return Q, c, a, beta, ustar


@pytest.mark.parametrize("u0", [np.full(5, 0.2), np.zeros(5), np.array([0.0, 1.0, 0.2, 0.0, 1.0])])
def test_constrained_minimum_is_reached_with_every_trial_point_feasible(u0):
    Q, c, a, beta, ustar = constrained_quadratic()
    assert a @ ustar == pytest.approx(beta) and np.all((ustar[1:] > 0) & (ustar[1:] < 1))
    assert a @ c > beta and c[0] > 1.0  # the unconstrained minimum violates both constraints
    points = []

    def fun(u):
        points.append(np.array(u))
        return 0.5 * (u - c) @ Q @ (u - c), Q @ (u - c)

    res = qn.minimize(fun, u0, FeasibleSet(a[None], np.array([beta])), ProjectedLBFGS(ftol=0.0), gtol=1e-8)
    assert res["converged"], res["stop_reason"]
    np.testing.assert_allclose(res["u"], ustar, atol=1e-8)
    assert res["iterations"] <= 40, res["iterations"]  # measured 21-23
    points = np.array(points)
    assert len(points) == res["evaluations"]
    # every evaluated point (iterates and line-search trials) is in the set, to rounding
    assert points.min() >= 0.0 and points.max() <= 1.0
    assert np.max(points @ a) <= beta + 1e-12


def test_two_loop_recursion_is_the_bfgs_inverse_hessian_and_bad_pairs_are_skipped():
    rng = np.random.default_rng(2)
    Q, _ = quadratic(6, 1e3, seed=2)
    s = rng.standard_normal((4, 6))
    y = s @ Q
    gamma = float(s[-1] @ y[-1] / (y[-1] @ y[-1]))
    H = gamma * np.eye(6)
    for si, yi in zip(s, y):  # BFGS update of the inverse, oldest pair first (Nocedal & Wright, Eq. 6.17)
        V = np.eye(6) - np.outer(yi, si) / (yi @ si)
        H = V.T @ H @ V + np.outer(si, si) / (yi @ si)
    v = rng.standard_normal(6)
    np.testing.assert_allclose(qn.two_loop(v, s, y, gamma), H @ v, rtol=1e-12, atol=1e-14 * np.abs(H @ v).max())
    state = qn.init_state(np.zeros(6), 3)
    state = qn.add_pair(state, s[0], y[0], 1e-10)
    assert int(state.pairs) == 1
    assert int(qn.add_pair(state, s[1], -y[1], 1e-10).pairs) == 1  # negative curvature: skipped
    assert int(qn.add_pair(state, s[1], np.zeros(6), 1e-10).pairs) == 1  # no gradient change: skipped
    for k in range(1, 4):
        state = qn.add_pair(state, s[k], y[k], 1e-10)
    assert int(state.pairs) == 3 and np.array_equal(qn.pairs_of(state)[0], s[1:])  # the oldest dropped


def test_settings_are_checked_and_selectable_by_name():
    assert from_settings("projected_lbfgs", memory_size=5).memory_size == 5
    assert ProjectedLBFGS().settings()["method"] == "projected_lbfgs"
    with pytest.raises(ParameterError, match="armijo"):
        ProjectedLBFGS(armijo=0.7)
    with pytest.raises(ParameterError, match="takes"):
        from_settings("projected_lbfgs", learning_rate=0.1)


# ---------------------------------------------------------------- optimize()'s loop, stand-in evaluators

NAMES = ("crank_length", "rod_length", "rod_mass")


def steady_problem():
    """Three mechanism parameters with a binding half-space ``L1 + L2 <= 0.525 m`` (scaled:
    ``u_0 + u_1 <= 1.25``), measured by a Steady objective (its evaluator replaced below)."""
    return DesignProblem(
        base=paper(),
        names=NAMES,
        lower=(0.110, 0.390, 1.0),
        upper=(0.130, 0.410, 2.0),
        A=((1.0, 1.0, 0.0),),
        b=(0.525,),
        start=(0.112, 0.392, 1.1),
        objective=Steady(),
    )


class _Evaluator:
    """Stands in for optim.steady.SteadyEvaluator: ``1 + (u - c)^T D (u - c) / 2`` on the scaled
    design, ``D = diag(1, 4, 10)``, ``c = (1.5, 1.5, 0.5)``, periodic where ``u_2 < 0.6``;
    outside, the long-run value with a zero gradient (no trend estimate), like the steady-state
    objective. Records every design it evaluates or classifies. Its constrained minimum is
    ``u* = (0.25, 1, 0.5)``: on the bound ``u_1 = 1`` and the half-space, with multipliers 0.75
    and 1.25 (KKT: ``-D (u* - c) = (1.25, 2, 0) = 1.25 (1, 1, 0) + 0.75 (0, 1, 0)``)."""

    c, D = np.array([1.5, 1.5, 0.5]), np.array([1.0, 4.0, 10.0])

    def __init__(self, problem, periodic=lambda u: u[2] < 0.6):
        self.problem, self.periodic, self.evaluated, self.asked = problem, periodic, [], []
        self.last_report, self.compile_seconds, self.classified, self.warmed = {}, 0.0, [], []
        self.budget, self.first_gradient, self.solved = None, None, []

    def unit(self, x):
        return np.asarray(self.problem.to_unit(jnp.asarray(x)))

    def _solve(self, x):
        """A new design is solved (recorded in ``solved``) after the budget is checked, as the
        steady-state evaluator does; a design solved before is not solved again."""
        u = self.unit(x)
        if not any(np.array_equal(u, v) for v in self.solved):
            if self.budget is not None:
                self.budget.check("a steady-state solve")
            self.solved.append(u)
        return u

    def prepare(self, x):
        return False

    def regime_at(self, x):
        self.asked.append(self._solve(x))
        return PERIODIC if self.periodic(self.unit(x)) else NOT_PERIODIC

    def value_and_grad(self, x, gradient=True):
        u = self._solve(x)
        periodic = self.periodic(u)
        if gradient and periodic and not self.compile_seconds:  # the first gradient compiles: checked
            if self.budget is not None:
                self.budget.check("compiling the gradient program")
            self.compile_seconds = 1e-9
        self.evaluated.append(u)
        self.last_report = {"regime": PERIODIC if periodic else NOT_PERIODIC, "leading_multiplier": 0.5}
        grad_u = self.D * (u - self.c) if periodic else np.zeros(3)
        value = 1.0 + 0.5 * float((u - self.c) @ (self.D * (u - self.c)))
        return value, grad_u / np.asarray(self.problem.span), self.last_report

    def value(self, x):
        """The value and regime without a gradient, as a classification of a start."""
        self.classified.append(self.unit(x))
        value, _, report = self.value_and_grad(x, gradient=False)
        self.evaluated.pop()
        return value, {**report, "ok": True}

    def warm_from(self, x):
        """Records each design a solve would be told to warm-start from (nothing is solved here)."""
        self.warmed.append(self.unit(x))


def _patch(monkeypatch, **kwargs):
    made = []

    def make(problem):
        made.append(_Evaluator(problem, **kwargs))
        return made[-1]

    monkeypatch.setattr("optim.optimize.SteadyEvaluator", make)
    return made


def test_steady_loop_converges_to_the_constrained_minimum_with_the_guard_shortening_steps(monkeypatch):
    """In optimize()'s loop with the regime guard: the first trial points (initial_step 2, from
    u = (0.1, 0.1, 0.1): u_2 = 1 and 0.81) leave the periodic region and are refused, the line
    search shortens the step; every evaluated design is periodic and feasible, the evaluations
    are counted, the run converges to u*."""
    made = _patch(monkeypatch)
    prob = steady_problem()
    opt = ProjectedLBFGS(initial_step=2.0)
    settings = Settings(optimizer=opt, max_iterations=30, gtol=1e-9, xtol=0.0, guard=RegimeGuard())
    res = optimize(prob, settings, progress=False)
    ev = made[-1]
    assert res["converged"] and res["converged"] == res["stop_reason"], res["stop_reason"]
    u_final = np.asarray(prob.to_unit(jnp.asarray(res["last"])))
    np.testing.assert_allclose(u_final, [0.25, 1.0, 0.5], atol=1e-8)
    assert res["history"][0]["halvings"] == 2  # the two refused trial points
    assert all(ev.periodic(u) for u in ev.evaluated)
    designs = np.array(ev.evaluated + ev.asked)
    assert designs.min() >= 0.0 and designs.max() <= 1.0 and np.max(designs[:, 0] + designs[:, 1]) <= 1.25 + 1e-12
    assert res["evaluations"] == len(ev.evaluated) == res["history"][-1]["evaluations"]


def test_steady_loop_resume_reproduces_the_uninterrupted_history(monkeypatch, tmp_path):
    _patch(monkeypatch)
    prob = steady_problem()
    settings = Settings(optimizer=ProjectedLBFGS(ftol=0.0), max_iterations=8, gtol=1e-9, xtol=0.0)
    full = optimize(prob, settings, out=tmp_path / "full", progress=False)
    optimize(prob, settings, out=tmp_path / "cut", progress=False, stop_after=3)
    resumed = optimize(prob, settings, out=tmp_path / "cut", resume=True, progress=False)
    assert len(resumed["history"]) == len(full["history"]) >= 5
    assert resumed["stop_reason"] == full["stop_reason"] and resumed["evaluations"] == full["evaluations"]
    for a, b in zip(full["history"], resumed["history"]):
        assert {k: v for k, v in a.items() if k != "seconds"} == {k: v for k, v in b.items() if k != "seconds"}


@pytest.mark.parametrize("method", ["projected_lbfgs", "adam"])
def test_a_not_periodic_start_with_a_zero_gradient_is_not_reported_as_converged(monkeypatch, tmp_path, method):
    """The whole box is not periodic: the start's steady-state gradient is exactly zero
    (no trend estimate). The run stops at once, not converged, and says why and what to do;
    a resume does not run it again."""
    _patch(monkeypatch, periodic=lambda u: False)
    prob = steady_problem()
    settings = Settings(optimizer=from_settings(method), max_iterations=5)
    res = optimize(prob, settings, out=tmp_path, progress=False)
    assert res["converged"] is None
    assert res["stop_reason"].startswith("not periodic at crank_length = 0.112")
    assert "start from a periodic design" in res["stop_reason"]
    assert len(res["history"]) == 1 and res["history"][0]["regime"] == NOT_PERIODIC
    again = optimize(prob, settings, out=tmp_path, resume=True, progress=False)
    assert again["stop_reason"] == res["stop_reason"] and len(again["history"]) == 1


def test_a_failed_line_search_stops_the_run_without_reporting_convergence(monkeypatch):
    """Every trial point is refused (periodic only at the start itself): the run stops after
    its first iteration, not converged, at the start."""
    prob = steady_problem()
    start = np.asarray(prob.start_unit())
    _patch(monkeypatch, periodic=lambda u: bool(np.array_equal(u, start)))
    settings = Settings(optimizer=ProjectedLBFGS(max_linesearch_steps=3), guard=RegimeGuard())
    res = optimize(prob, settings, progress=False)
    assert res["converged"] is None and res["stop_reason"].startswith("line search failed")
    assert "3 refused" in res["stop_reason"] and res["evaluations"] == 1  # no pairs yet: the gradient arc alone
    np.testing.assert_allclose(res["last"], prob.start)


# ---------------------------------------------------------------- measurement (python -m tests.test_quasi_newton)


def _adam_run(fun, u0, feasible, learning_rate, targets, budget):
    """Projected Adam (optax.adam, each step projected) for ``budget`` evaluations (one per
    iteration): per target function, the evaluations before the iterate first meets it (None: never)."""
    import jax

    opt = adam(learning_rate).transformation
    update = jax.jit(opt.update)
    u = feasible.project(u0)
    state, hits = opt.init(jnp.asarray(u)), [None] * len(targets)
    for k in range(budget + 1):
        hits = [h if h is not None or not met(u) else k for h, met in zip(hits, targets)]
        if all(h is not None for h in hits) or k == budget:
            return hits
        upd, state = update(jnp.asarray(fun(u)[1]), state, jnp.asarray(u))
        u = feasible.project(u + np.asarray(upd))


def measure(tolerances=(1e-3, 1e-6), budget=20_000):
    """Iterations and evaluations of projected L-BFGS and of projected Adam (four step
    sizes) until ``|u - u*|_inf <= tol`` (scaled) on the smooth problems."""
    Q, c = quadratic()
    qc, cc, a, beta, ustar = constrained_quadratic()
    quad = lambda u: (0.5 * (u - c) @ Q @ (u - c), Q @ (u - c))
    constrained = lambda u: (0.5 * (u - cc) @ qc @ (u - cc), qc @ (u - cc))
    cases = [
        ("quadratic, 9 variables, condition 1e4", quad, np.full(9, 0.95), box(9), c),
        ("rosenbrock, 9 variables", rosenbrock, (np.tile([-1.2, 1.0], 5)[:9] + 2.0) / 4.0, box(9), np.full(9, 0.75)),
        ("quadratic, 5 variables, bound and half-space active", constrained, np.full(5, 0.2),
         FeasibleSet(a[None], np.array([beta])), ustar),
    ]  # fmt: skip
    print(f"evaluations (L-BFGS: iterations/evaluations) to |u - u*|_inf <= tol, scaled; Adam: {budget} at most")
    for name, fun, u0, feasible, target in cases:
        targets = [lambda u, tol=tol, target=target: float(np.max(np.abs(u - target))) <= tol for tol in tolerances]
        res = qn.minimize(fun, u0, feasible, ProjectedLBFGS(ftol=0.0), gtol=1e-12, max_iterations=1000)
        for tol, met in zip(tolerances, targets):
            k = next((k for k, h in enumerate(res["history"]) if met(h["u"])), None)
            print(
                f"{name}, tol {tol:g}: projected L-BFGS",
                None if k is None else f"{k}/{res['history'][k]['evaluations']}",
            )
        for lr in (0.003, 0.01, 0.03, 0.1):
            print(
                f"  projected Adam, step {lr:g}:",
                dict(zip(tolerances, _adam_run(fun, u0, feasible, lr, targets, budget))),
            )


if __name__ == "__main__":
    import jax

    jax.config.update("jax_enable_x64", True)
    measure()
