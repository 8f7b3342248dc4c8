"""The solve (jaxcrank.numerics.solve): the one solver-settings object, solver names only
at the text boundary, and the same solve whichever way the settings are given."""

import diffrax
import numpy as np
import pytest

import jaxcrank as jc
from jaxcrank.numerics import solve
from jaxcrank.physics.params import ParameterError
from tests.helpers import tree_allclose


def test_options_hold_a_solver_instance_with_one_default_each():
    assert isinstance(solve.DEFAULTS.solver, diffrax.Tsit5)
    assert solve.DEFAULTS.solver_name == "tsit5"
    assert (solve.DEFAULTS.rtol, solve.DEFAULTS.atol, solve.DEFAULTS.max_steps) == (1e-6, 1e-6, 500_000)


@pytest.mark.parametrize("name", list(solve.SOLVERS))
def test_names_map_to_instances_and_back(name):
    solver = solve.solver_from_name(name)
    assert isinstance(solver, solve.SOLVERS[name]) and solve.solver_name(solver) == name
    assert solve.SolveOptions.from_text(solver=name).solver == solver  # equal instances: one compiled program


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"solver": "tsit5"}, "is a name: pass solver_from_name"),
        ({"solver": 3}, "must be a diffrax adaptive solver instance"),
        ({"rtol": 0.0}, "rtol = 0.0 must be a finite number > 0"),
        ({"atol": True}, "atol = True must be a finite number > 0"),
        ({"dt0": float("nan")}, "dt0 = nan"),
        ({"max_steps": 1.5}, "max_steps = 1.5 must be an integer >= 1"),
        ({"max_steps": True}, "max_steps = True must be an integer >= 1"),
    ],
)
def test_bad_options_raise_a_named_error(kwargs, match):
    with pytest.raises(ParameterError, match=match):
        solve.SolveOptions(**kwargs)


def test_unknown_solver_name_lists_the_valid_ones():
    with pytest.raises(ParameterError, match="solver 'rk45' is unknown; valid: kvaerno5, .*dopri8"):
        solve.solver_from_name("rk45")


def test_implicit_solver_gets_the_controllers_tolerances_also_as_a_copy():
    import pickle

    solver = solve.solver_from_name("kvaerno5")
    controller = solve.step_size_controller(solver, 1e-7, 1e-9)
    for s in (solver, pickle.loads(pickle.dumps(solver))):  # a worker process gets a copy
        finder = solve._with_tolerances(s, controller).root_finder
        assert (finder.rtol, finder.atol, finder.norm) == (1e-7, 1e-9, controller.norm)


def test_the_same_solve_by_default_by_instance_and_by_name(paper):
    t1, n = 2e-3, 21
    by_default = jc.simulate(paper, t1, n_samples=n)
    by_instance = jc.simulate(paper, t1, n_samples=n, options=solve.SolveOptions(solver=diffrax.Tsit5()))
    by_name = jc.simulate(paper, t1, n_samples=n, options=solve.SolveOptions.from_text("tsit5"))
    assert tree_allclose(by_default.ys, by_instance.ys, rtol=0.0, atol=0.0)
    assert tree_allclose(by_default.ys, by_name.ys, rtol=0.0, atol=0.0)
    np.testing.assert_array_equal(np.asarray(by_default.ts), np.asarray(by_instance.ts))


def test_simulate_takes_its_settings_in_one_options_object(paper):
    with pytest.raises(TypeError, match="rtol"):
        jc.simulate(paper, 1e-3, n_samples=3, rtol=1e-8)
    with pytest.raises(ParameterError, match="options = .* must be a SolveOptions"):
        jc.simulate(paper, 1e-3, n_samples=3, options={"rtol": 1e-8})


def test_tree_allclose_compares_structure_shapes_and_values():
    a = {"x": np.ones(3), "y": (1, "s")}
    assert tree_allclose(a, {"x": np.ones(3) + 1e-12, "y": (1, "s")})
    assert not tree_allclose(a, {"x": np.ones(3) + 1e-3, "y": (1, "s")})
    assert not tree_allclose(a, {"x": np.ones(4), "y": (1, "s")})
    assert not tree_allclose(a, {"x": np.ones(3), "y": (2, "s")})
    assert not tree_allclose(a, {"x": np.ones(3)})
