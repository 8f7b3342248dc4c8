"""A design problem's numbers as a compiled program's inputs: problems that differ only in
them (a speed, a stroke) share one key and one program, the program rebuilds each problem's
mechanism exactly, and a problem whose numbers are read at trace time is refused under a
trace (its program compiles them in instead)."""

import dataclasses

import jax
import numpy as np
import pytest

import jaxcrank as jc
from optim import presets, spec
from optim.problem import problem_values, values_key, with_values
from optim.programs import TRACE_ERRORS


def _variant(problem, speed_factor: float, stroke: float):
    speed = float(jc.get_parameter(problem.base, "driver.speed")) * speed_factor
    base = jc.set_parameter(problem.base, "driver.speed", speed)
    return dataclasses.replace(problem, base=base, derived=dataclasses.replace(problem.derived, stroke=stroke))


def _leaves(mech):
    return [np.asarray(v, dtype=float) for v in jax.tree.leaves(mech)]


def test_problems_that_differ_only_in_numbers_share_a_key_and_rebuild_exactly():
    p = presets.problem("design")
    q = _variant(p, 0.9, 0.230)  # a slower crank and a shorter stroke
    assert values_key(p) == values_key(q) and p != q
    i = p.names.index("rod_mass")
    wider = dataclasses.replace(p, upper=p.upper[:i] + (3.0,) + p.upper[i + 1 :])  # a program takes the design itself
    assert values_key(wider) == values_key(p)
    heavier = dataclasses.replace(p, terms=tuple((name, 2.0 * w) for name, w in p.terms))
    assert values_key(heavier) != values_key(p)  # a weight is compiled in: its own key
    x = np.asarray(q.start)
    expected = _leaves(q.mechanism(x))
    for got in (
        with_values(p, problem_values(q)).mechanism(x),  # p's structure, q's numbers
        jax.jit(lambda v: with_values(p, v).mechanism(x))(problem_values(q)),  # as a program's inputs
    ):
        assert len(_leaves(got)) == len(expected)
        for a, b in zip(_leaves(got), expected):
            np.testing.assert_allclose(a, b, rtol=1e-15, atol=0.0)
    assert float(q.mechanism(x).crank_length) != float(p.mechanism(x).crank_length)  # the stroke reached it


def test_a_number_read_at_trace_time_is_refused_under_a_trace():
    """The crank-rocker reparametrisation reads the base's lengths as Python numbers: its numbers
    cannot be inputs, and tracing them raises one of the errors the evaluator falls back on."""
    problem, _ = spec.load("docs/problems/crank-rocker-pin-force.toml")
    x = np.asarray(problem.start if problem.start is not None else problem.default_start())
    with pytest.raises(TRACE_ERRORS):
        jax.jit(lambda v: with_values(problem, v).mechanism(x))(problem_values(problem))
    concrete = with_values(problem, problem_values(problem)).mechanism(x)  # concrete values: the same mechanism
    for a, b in zip(_leaves(concrete), _leaves(problem.mechanism(x))):
        np.testing.assert_array_equal(a, b)


@pytest.mark.slow
def test_a_variant_in_numbers_reuses_the_compiled_gradient_program():
    """Two evaluators in one process, the design problem and its variant with a slower crank and
    a shorter stroke, at a periodic design: the variant compiles no gradient program, and its
    value and gradient are those of a program with its numbers compiled in."""
    from optim.programs import PROGRAMS, forget_programs
    from optim.steady import SteadyEvaluator

    p = presets.problem("design")
    q = _variant(p, 0.9, 0.230)
    unit = np.array([0.0658, 0.634, 0.167, 0.157, 0.893, 0.0753, 0.049, 0.5625, 0.7557])  # periodic in both
    x = np.asarray(p.lower) + unit * (np.asarray(p.upper) - np.asarray(p.lower))
    forget_programs()
    first = SteadyEvaluator(p)
    first.value_and_grad(x)
    assert first.compile_seconds > 0.0 and len(PROGRAMS) == 1
    shared = SteadyEvaluator(q)
    value, grad, info = shared.value_and_grad(x)
    assert info["regime"] == "periodic" and shared.compile_seconds == 0.0 and len(PROGRAMS) == 1
    own = SteadyEvaluator(q)  # the variant's own program, its numbers as constants
    steady = own.steady_at(x)
    args = own._args(x, steady)
    folded = jax.jit(own._program_fun(steady, folded=True))(*args)
    # the two programs compute the same function but round differently (the constants folded or not), and
    # each runs adaptive solves at a relative tolerance of 1e-10: they agree to that accuracy, not to the
    # last bit (measured 1.2e-11 in the value); the gradient of the orbit amplifies it (measured 3e-6)
    np.testing.assert_allclose(value, float(folded[0]), rtol=1e-9)
    np.testing.assert_allclose(grad, np.asarray(folded[1]), rtol=1e-5, atol=1e-8 * np.max(np.abs(grad)))
