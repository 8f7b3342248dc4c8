"""Where an optimisation starts (optim.starts): the way in for the steady-state objective
classifies candidate starts until one is periodic and the lowest so far, and hands its
evaluator to the optimiser.
The steady-state evaluator is the stand-in of test_quasi_newton: no mechanism is solved."""

import dataclasses
import math

import jax.numpy as jnp
import numpy as np
import pytest

from optim.optimize import Settings, optimize
from optim.optimizers import ProjectedLBFGS
from optim.starts import periodic_start, start_points
from optim.steady import NOT_PERIODIC, PERIODIC, RegimeGuard
from optim.way_in import LOCAL_STARTS
from tests.test_quasi_newton import _Evaluator, _patch, steady_problem


def _start(prob, u):
    return dataclasses.replace(prob, start=tuple(float(v) for v in np.asarray(prob.from_unit(jnp.asarray(u)))))


def test_a_periodic_start_is_kept_after_one_classification():
    prob = steady_problem()  # start u = (0.1, 0.1, 0.1): periodic (u_2 < 0.6)
    ev = _Evaluator(prob)
    found = periodic_start(prob, evaluator=ev, progress=False)
    assert found.periodic and found.chosen == 0 and len(found.classified) == 1
    assert found.problem is prob and found.evaluator is ev
    assert found.describe()["classified"][0]["regime"] == PERIODIC


def test_a_not_periodic_start_is_replaced_by_the_first_periodic_candidate():
    """From u_2 = 0.9 (not periodic) the Sobol candidates are classified in order until the
    first periodic one, here also the lowest value so far, which becomes the start; nothing
    after it is classified."""
    prob = _start(steady_problem(), [0.1, 0.1, 0.9])
    ev = _Evaluator(prob)
    found = periodic_start(prob, count=8, seed=3, evaluator=ev, progress=False)
    candidates = start_points(prob, 8, seed=3)
    k = next(i for i, u in enumerate(candidates) if u[2] < 0.6)
    assert k > 0 and found.periodic and found.chosen == k == len(found.classified) - 1
    assert [c["regime"] for c in found.classified] == [NOT_PERIODIC] * k + [PERIODIC]
    np.testing.assert_allclose(np.asarray(found.problem.start_unit()), candidates[k], atol=1e-12)
    np.testing.assert_allclose(np.asarray(ev.classified), candidates[: k + 1], atol=1e-12)


def test_a_periodic_candidate_above_a_value_already_seen_is_passed_over():
    """From u_2 = 0.9 with seed 1 the stand-in's candidates are (value, periodic): (6.70, no),
    (3.62, no), (6.32, yes), (3.28, no), (4.45, yes), (2.82, yes), ...: the periodic candidates 2
    and 4 lie above a value already seen, and the search stops at 5, the first periodic one that
    is the lowest so far. Each periodic candidate lower than every periodic one before it is kept
    by the evaluator as it is classified (2, 4, 5), and the chosen one is the warm start at the end."""
    prob = _start(steady_problem(), [0.1, 0.1, 0.9])
    ev = _Evaluator(prob)
    found = periodic_start(prob, count=8, seed=1, evaluator=ev, progress=False)
    values = [c["value_deg"] for c in found.classified]
    assert found.periodic and found.chosen == 5 == len(found.classified) - 1
    assert [c["regime"] == PERIODIC for c in found.classified] == [False, False, True, False, True, True]
    assert values[5] < min(values[:5]) and values[2] > values[1] and values[4] > values[3]
    candidates = start_points(prob, 8, seed=1)
    np.testing.assert_allclose(np.asarray(found.problem.start_unit()), candidates[5], atol=1e-12)
    np.testing.assert_allclose(np.asarray(ev.warmed), candidates[[2, 4, 5, 5]], atol=1e-9)


def test_a_periodic_candidate_worse_than_a_value_seen_is_not_the_start():
    """Only candidate 2 (6.32) is periodic among 5 and lies above the 3.62 of candidate 1 (not
    periodic): the search classifies LOCAL_STARTS candidates around the lowest value seen (none is
    periodic here), and the start is the lowest value seen, not periodic; candidate 2 is not chosen."""
    prob = _start(steady_problem(), [0.1, 0.1, 0.9])
    periodic_one = start_points(prob, 5, seed=1)[2]
    ev = _Evaluator(prob, periodic=lambda u: bool(np.allclose(u, periodic_one, atol=1e-9)))
    found = periodic_start(prob, count=5, seed=1, evaluator=ev, progress=False)
    phases = [c["phase"] for c in found.classified]
    assert phases == ["start"] + ["sobol"] * 4 + ["local"] * LOCAL_STARTS
    values = [c["value_deg"] for c in found.classified]
    assert not found.periodic and found.chosen != 2 and values[found.chosen] == min(values) < values[2]
    np.testing.assert_allclose(
        np.asarray(found.problem.start_unit()), found.classified[found.chosen]["unit_design"], atol=1e-12
    )
    np.testing.assert_allclose(ev.warmed[-1], found.classified[found.chosen]["unit_design"], atol=1e-9)


def test_around_a_best_design_that_is_not_periodic_a_periodic_neighbour_no_worse_is_the_start():
    """No Sobol candidate is periodic; the local candidates around the lowest value seen are
    (the stand-in's region u_2 < 0.6 moved: periodic wherever the design is not a Sobol candidate).
    The first local candidate that is periodic and the lowest so far is the start."""
    prob = _start(steady_problem(), [0.1, 0.1, 0.9])
    sobol = start_points(prob, 8, seed=2)
    ev = _Evaluator(prob, periodic=lambda u: not any(np.allclose(u, c, atol=1e-12) for c in sobol))
    found = periodic_start(prob, count=8, seed=2, evaluator=ev, progress=False, local=40)
    values = [c["value_deg"] for c in found.classified]
    assert found.periodic and found.classified[found.chosen]["phase"] == "local"
    assert found.chosen == len(found.classified) - 1 and values[found.chosen] == min(values)


@pytest.mark.parametrize("seed", range(12))
def test_the_start_is_never_a_periodic_design_worse_than_a_value_seen(seed):
    """Random regime maps, values and failed solves: the chosen start has the lowest value classified,
    a failed candidate (no value) is never chosen, and ``periodic`` says the chosen design's regime."""
    rng = np.random.default_rng(seed)
    prob = _start(steady_problem(), rng.uniform(0.0, 1.0, 3) * [0.5, 0.5, 1.0])
    bits = rng.integers(0, 2**16)

    def regime(u):  # a pseudo-random map of the box into regimes
        return int(np.floor(np.sum(u * [7.0, 11.0, 13.0])) + bits) % 3  # 0 periodic, 1 not, 2 failed

    ev = _Evaluator(prob, periodic=lambda u: regime(u) == 0)
    value = ev.value
    ev.value = lambda x: (math.nan, value(x)[1]) if regime(ev.unit(x)) == 2 else value(x)
    found = periodic_start(prob, count=6, seed=seed, evaluator=ev, progress=False)
    values = [c["value_deg"] for c in found.classified if c["value_deg"] is not None]
    if values:
        chosen = found.classified[found.chosen]
        assert chosen["value_deg"] == min(values)
        assert found.periodic == (chosen["regime"] == PERIODIC)
    else:
        assert not found.periodic and found.problem is prob


def test_a_periodic_candidate_without_a_finite_value_is_never_chosen():
    """A periodic candidate whose value is not finite neither stops the search nor sets a bar:
    the next periodic one is chosen."""
    prob = _start(steady_problem(), [0.1, 0.1, 0.9])
    first = start_points(prob, 8, seed=3)[1]  # the first periodic candidate of seed 3 (3.22)
    ev = _Evaluator(prob)
    value = ev.value
    ev.value = lambda x: (math.nan, value(x)[1]) if np.allclose(ev.unit(x), first, atol=1e-9) else value(x)
    found = periodic_start(prob, count=8, seed=3, evaluator=ev, progress=False)
    assert found.periodic and found.chosen == 3 == len(found.classified) - 1
    assert found.classified[1]["regime"] == PERIODIC and found.classified[1]["value_deg"] is None


def test_no_periodic_candidate_starts_from_the_lowest_value_and_the_run_from_it_is_not_converged(monkeypatch):
    """Nothing in the box is periodic: every candidate is classified (and LOCAL_STARTS around the
    lowest), the start is the lowest value seen, and the optimiser run from it (with the search's
    evaluator: no new one is made) stops at once, not converged, saying why."""
    made = _patch(monkeypatch, periodic=lambda u: False)
    prob = steady_problem()
    ev = _Evaluator(prob, periodic=lambda u: False)
    found = periodic_start(prob, count=4, evaluator=ev, progress=False)
    values = [c["value_deg"] for c in found.classified]
    assert not found.periodic and len(found.classified) == 4 + LOCAL_STARTS
    assert values[found.chosen] == min(values)
    res = optimize(found.problem, Settings(optimizer=ProjectedLBFGS()), progress=False, evaluator=found.evaluator)
    assert not made  # the search's evaluator was used
    assert res["converged"] is None and res["stop_reason"].startswith("not periodic at")
    assert res["final_objective"] == pytest.approx(values[found.chosen], rel=1e-12)


def test_the_optimiser_continues_from_the_chosen_start_with_the_carried_evaluator(monkeypatch):
    """From a not-periodic start the way in finds a periodic candidate; the run from it uses the
    same evaluator (the start is not solved again: its first evaluation is the optimiser's),
    keeps every evaluated design periodic and in the box, and converges to the constrained
    minimum of the stand-in objective."""
    made = _patch(monkeypatch)
    prob = _start(steady_problem(), [0.1, 0.1, 0.9])
    ev = _Evaluator(prob)
    found = periodic_start(prob, seed=3, evaluator=ev, progress=False)
    settings = Settings(optimizer=ProjectedLBFGS(), max_iterations=40, gtol=1e-9, xtol=0.0, guard=RegimeGuard())
    res = optimize(found.problem, settings, progress=False, evaluator=found.evaluator)
    assert not made and res["converged"], res["stop_reason"]
    np.testing.assert_allclose(np.asarray(prob.to_unit(jnp.asarray(res["last"]))), [0.25, 1.0, 0.5], atol=1e-8)
    designs = np.asarray(ev.evaluated)
    assert all(ev.periodic(u) for u in designs)
    assert designs.min() >= 0.0 and designs.max() <= 1.0 and np.max(designs[:, 0] + designs[:, 1]) <= 1.25 + 1e-12
    assert set(res["seconds"]) == {"start", "iterations", "gradient_compile", "first_gradient"}


def test_count_below_one_is_refused():
    from jaxcrank.physics.params import ParameterError

    with pytest.raises(ParameterError, match="starts = 0"):
        periodic_start(steady_problem(), count=0, evaluator=_Evaluator(steady_problem()), progress=False)


def test_optimize_with_no_settings_finds_a_periodic_start_and_keeps_to_the_periodic_regime(monkeypatch):
    """The library's way in from the defaults: ``optimize(problem)`` with a steady-state objective
    and no settings classifies starts first (one evaluator, carried into the run), then runs Adam at
    STEADY_LEARNING_RATE with the regime guard; every design it evaluates is periodic and the result
    names the search."""
    from optim import optimize as O

    made = _patch(monkeypatch)
    monkeypatch.setattr("optim.way_in.SteadyEvaluator", lambda problem: made.append(_Evaluator(problem)) or made[-1])
    prob = _start(steady_problem(), [0.1, 0.1, 0.9])  # not periodic: a zero gradient there
    settings = O.default_settings(prob)
    assert settings.optimizer.label == "adam" and isinstance(settings.guard, RegimeGuard)
    res = optimize(prob, progress=False)
    assert len(made) == 1  # the search's evaluator is the run's
    search = res["start_search"]
    assert search["periodic"] and search["chosen"] > 0 and "start_search" in res["seconds"]
    ev = made[0]
    assert ev.evaluated and all(ev.periodic(u) for u in ev.evaluated)
    assert res["history"][-1]["objective_deg"] < res["f0"]


def test_given_settings_run_from_the_problem_start_as_given(monkeypatch):
    """Settings given: no start search (the caller chose), the problem's own start is evaluated first."""
    made = _patch(monkeypatch)
    prob = steady_problem()
    res = optimize(prob, Settings(max_iterations=2), progress=False)
    assert "start_search" not in res and len(made) == 1
    np.testing.assert_allclose(made[0].evaluated[0], np.asarray(prob.start_unit()), atol=1e-12)
