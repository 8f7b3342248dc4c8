"""Time budgets hold in every phase of a steady-state run (optim.budget): the way in, the gradient
steps, the regime guard's halvings and the line search's trial points each check the budget before
their next solve, so a run overshoots it by at most one solve and returns what it has.

The clock here counts the stand-in evaluator's solves (test_quasi_newton's ``_Evaluator``: no
mechanism is solved), so "at most one solve past the budget" is an exact count."""

import dataclasses

import jax.numpy as jnp
import numpy as np
import pytest

from jaxcrank.physics.params import ParameterError
from optim.budget import Budget, BudgetSpent
from optim.optimize import Settings, optimize
from optim.optimizers import ProjectedLBFGS, adam
from optim.starts import periodic_start
from optim.steady import RegimeGuard, SteadyEvaluator
from tests.test_quasi_newton import _Evaluator, steady_problem


def _counted(ev, seconds):
    """A budget of ``seconds`` solves of ``ev``, counted from now."""
    return Budget(seconds, clock=lambda: float(len(ev.solved)))


def _start(prob, u):
    return dataclasses.replace(prob, start=tuple(float(v) for v in np.asarray(prob.from_unit(jnp.asarray(u)))))


def test_the_way_in_stops_at_the_budget_and_starts_from_the_best_so_far():
    """Nothing is periodic: the way in would classify 8 + 4 candidates; with a budget of 3 solves
    it classifies 4 (the fourth starts while 3 have been spent: one past), says why it stopped and
    starts from the lowest value among those 4."""
    prob = steady_problem()
    ev = _Evaluator(prob, periodic=lambda u: False)
    ev.budget = _counted(ev, 3)
    found = periodic_start(prob, count=8, evaluator=ev, progress=False)
    values = [c["value_deg"] for c in found.classified]
    assert len(ev.solved) == 4 == len(found.classified)
    assert found.stopped and "max_seconds = 3" in found.stopped and "steady-state solve" in found.stopped
    assert values[found.chosen] == min(values) and found.describe()["stopped"] == found.stopped


@pytest.mark.parametrize("seconds", [2, 5, 9])
def test_the_regime_guard_halvings_stop_at_the_budget(seconds):
    """Adam with large steps from u_2 = 0.55 (the stand-in is periodic below 0.6): most steps leave
    the periodic region and the guard halves them, each halving a new solve. The run stops within
    one solve of the budget, in whatever phase it is, keeps the iterates it finished and says why."""
    prob = _start(steady_problem(), [0.1, 0.1, 0.55])
    ev = _Evaluator(prob)
    ev.budget = _counted(ev, seconds)
    settings = Settings(optimizer=adam(0.5), max_iterations=100, gtol=0.0, xtol=0.0, guard=RegimeGuard(3))
    res = optimize(prob, settings, progress=False, evaluator=ev)
    assert len(ev.solved) <= seconds + 1
    assert "max_seconds" in res["stop_reason"]
    assert len(ev.asked) > 0  # the guard ran
    assert res["final_objective"] == min(h["objective_deg"] for h in res["history"])


@pytest.mark.parametrize("seconds", [3, 6])
def test_the_line_search_trial_points_stop_at_the_budget(seconds):
    """Projected L-BFGS with an initial step of 2 from u_2 = 0.1: its first trial points leave the
    periodic region and are refused by the guard, shortened by the line search; the budget ends the
    run within one solve of it."""
    prob = steady_problem()
    ev = _Evaluator(prob)
    ev.budget = _counted(ev, seconds)
    settings = Settings(optimizer=ProjectedLBFGS(initial_step=2.0), max_iterations=100, gtol=0.0, xtol=0.0,
                        guard=RegimeGuard())  # fmt: skip
    res = optimize(prob, settings, progress=False, evaluator=ev)
    assert len(ev.solved) <= seconds + 1 and "max_seconds" in res["stop_reason"]


def test_a_budget_spent_by_the_way_in_returns_its_start_with_no_iteration():
    """The way in spends the budget on its one (periodic) candidate: the run solves and compiles
    nothing more; the result is the way in's design with its classified value, no history, and the
    reason."""
    prob = steady_problem()
    ev = _Evaluator(prob)
    ev.budget = _counted(ev, 0.5)
    found = periodic_start(prob, count=8, evaluator=ev, progress=False)
    assert found.periodic and len(ev.solved) == 1
    res = optimize(found.problem, Settings(max_iterations=5), progress=False, evaluator=ev)
    assert res["history"] == [] and "max_seconds = 0.5" in res["stop_reason"] and "compiling" in res["stop_reason"]
    assert len(ev.solved) == 1 and not ev.evaluated
    assert res["final_objective"] == found.classified[found.chosen]["value_deg"]
    np.testing.assert_allclose(res["final"], found.problem.start, rtol=1e-12)


def test_optimize_makes_a_budget_from_max_seconds_and_gives_it_back():
    """Without a budget of the caller's, max_seconds makes the run's own, on the evaluator while the
    run lasts and removed after it."""
    prob = steady_problem()
    ev = _Evaluator(prob)
    seen = []
    value_and_grad = ev.value_and_grad
    ev.value_and_grad = lambda x: seen.append(ev.budget) or value_and_grad(x)
    optimize(prob, Settings(max_iterations=2, max_seconds=3600.0), progress=False, evaluator=ev)
    assert seen and all(isinstance(b, Budget) and b.seconds == 3600.0 for b in seen)
    assert ev.budget is None


def test_the_steady_state_evaluator_checks_the_budget_before_a_solve():
    """The library's evaluator: a spent budget raises before any steady-state solve, naming the phase."""
    prob = steady_problem()
    ev = SteadyEvaluator(prob)
    ev.budget = Budget(1e-9)
    with pytest.raises(BudgetSpent, match="before|steady-state solve"):
        ev.steady_at(np.asarray(prob.start))
    assert not ev._steady


@pytest.mark.parametrize("seconds", [0, -1.0, float("nan"), "10"])
def test_a_budget_that_is_not_positive_is_refused(seconds):
    with pytest.raises(ParameterError, match="max_seconds"):
        Budget(seconds)
