"""One enumeration of outcomes (jaxcrank.numerics.results.RESULTS) and the regime
enumeration: how solves, steady states, sweeps and the kernel report them."""

import json

import diffrax
import jax
import numpy as np
import pytest

import jaxcrank as jc
from jaxcrank.numerics import results
from jaxcrank.numerics.kernel import engine
from jaxcrank.numerics.results import RESULTS, Regime
from jaxcrank.runs import sweep_design


def test_results_extends_diffrax_and_keeps_its_codes():
    for name in ("successful", "max_steps_reached", "dt_min_reached", "internal_error"):
        ours, theirs = getattr(RESULTS, name), getattr(diffrax.RESULTS, name)
        assert int(results.code(ours)) == int(theirs._value)
        assert bool(RESULTS.promote(theirs) == ours)
    assert len(RESULTS) == len(diffrax.RESULTS) + 6


def test_codes_labels_and_messages_round_trip():
    for value, name in results.NAMES.items():
        assert int(results.code(results.item(value))) == value
        assert results.status_label(value) in results.STATUSES
        assert results.message(value) == RESULTS[getattr(RESULTS, name)]
    labels = {results.status_label(results.code(getattr(RESULTS, n))) for n in results.LABELS}
    assert labels == {"ok", "max_steps", "non_finite", "invalid"}
    assert results.status_label(results.code(RESULTS.dt_min_reached)) == "solver_failed"
    assert results.message(0) == ""
    assert "max_steps" in results.message(results.code(RESULTS.max_steps_reached))
    with pytest.raises(ValueError, match="no item of RESULTS"):
        results.status_label(len(RESULTS))


def test_kernel_statuses_are_codes_of_the_enumeration():
    assert results.status_label(engine.OK) == "ok"
    assert results.status_label(engine.MAX_STEPS) == "max_steps"
    assert results.status_label(engine.NON_FINITE) == "non_finite"


def test_regime_is_a_string_enumeration():
    assert Regime.PERIODIC == "periodic" and Regime("not periodic") is Regime.NOT_PERIODIC
    assert json.dumps({"r": Regime.FAILED}) == '{"r": "failed"}'
    assert f"{Regime.NOT_PERIODIC}" == "not periodic"


def test_a_simulation_and_a_sweep_design_carry_the_enumeration():
    mech = jc.paper()
    sim = jc.simulate(mech, 0.002, n_samples=5, options=jc.SolveOptions(max_steps=3), throw=False)
    assert isinstance(sim.result, RESULTS) and not bool(sim.ok)
    assert bool(sim.result == RESULTS.max_steps_reached)
    settings = sweep_design.SweepSettings(revolutions=0.05, samples_per_revolution=40, metrics_from_revolution=0.0)
    names = ["clearance_B"]
    _, status, _ = jax.jit(lambda x: sweep_design.simulate_design(mech, names, x, settings))(np.array([2.5e-4]))
    assert results.status_label(status) == "ok"
    tight = sweep_design.SweepSettings(
        revolutions=0.05, samples_per_revolution=40, metrics_from_revolution=0.0, options=jc.SolveOptions(max_steps=3)
    )
    _, status, _ = sweep_design.simulate_design(mech, names, np.array([2.5e-4]), tight)
    assert results.status_label(status) == "max_steps"
    assert "max_steps" in results.message(status)
