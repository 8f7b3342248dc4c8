"""The problems (optim.problem): projections, validation, the robust mean over
manufactured parts, the configuration round trip, batched evaluation."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxcrank import SolveOptions, paper
from jaxcrank.physics.params import ParameterError
from optim import search
from optim.design import DesignProblem
from optim.objective import Pathwise, eq19
from optim.presets import paper_problem, robust_problem
from tests.objectives import EXACT, central_difference


@pytest.mark.parametrize(
    "u, expect",
    [
        ((0.5, 0.5), (0.5, 0.5)),
        ((1.5, -0.3), (1.0, 0.0)),
        ((-1.0, 2.0), (0.0, 1.0)),
    ],
)
def test_projection_onto_the_box(u, expect):
    np.testing.assert_allclose(paper_problem().project(jnp.array(u)), expect, atol=1e-12)


def test_projection_with_an_active_linear_constraint():
    # L2 >= L1 + 0.27 cuts the box's corner: (1, 0) scaled projects onto the line
    prob = DesignProblem(
        paper(), ("crank_length", "rod_length"), (0.11, 0.39), (0.13, 0.41), A=((1.0, -1.0),), b=(-0.27,)
    )
    u = prob.project(jnp.array([1.0, 0.0]))
    x = np.asarray(prob.from_unit(u))
    np.testing.assert_allclose(x, [0.125, 0.395], atol=1e-9)
    assert prob.feasible(x, tol=1e-9)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(names=("bogus",), lower=(0.0,), upper=(1.0,)), "unknown design variable"),
        (dict(names=("rod_length",), lower=(0.41,), upper=(0.39,)), "lower"),
        (dict(names=("rod_length",), lower=(0.39,), upper=(0.41,), cost_weight=1.0), "clearance"),
        (dict(names=("rod_length",), lower=(0.39,), upper=(0.41,), samples=2), "needs a scatter"),
        (
            dict(
                names=("rod_length",),
                lower=(0.39,),
                upper=(0.41,),
                samples=2,
                scatter=(("driver.speed", 1.0, "uniform"),),
            ),
            "driver.speed",
        ),
        (
            dict(
                names=("rod_length",),
                lower=(0.39,),
                upper=(0.41,),
                samples=2,
                scatter=(("rod_length", 1e-4, "triangular"),),
            ),
            "distribution",
        ),
        (
            dict(
                names=("clearance_C",),
                lower=(1e-4,),
                upper=(5e-4,),
                samples=4,
                scatter=(("clearance_C", 2e-4, "uniform"),),
            ),
            "clearance <= 0",
        ),
        (
            dict(names=("rod_length",), lower=(0.39,), upper=(0.41,), samples=2, scatter=(("bogus", 1e-4, "normal"),)),
            "unknown design variable",
        ),
    ],
)
def test_bad_problems_raise(kwargs, match):
    from jaxcrank import ParameterError

    with pytest.raises(ParameterError, match=match):
        DesignProblem(base=paper(), **kwargs)


@pytest.mark.slow  # eight parts, value and gradient against central differences (about 40 s)
def test_robust_objective_is_the_parts_mean_with_a_verified_gradient():
    """Sample-average of Eq. 19 over manufactured parts (common random numbers): value
    = mean of the parts' values, gradient = central differences of that mean (short,
    non-chaotic window), and the grid's evaluator gives the same mean."""
    prob = robust_problem(EXACT, samples=3)
    x = np.array([0.12, 0.40])
    dev = prob.draws()
    assert dev.shape == (3, 4) and np.all(np.abs(dev[:, 2:]) <= 5e-5)  # uniform clearance band
    f = jax.jit(prob.objective_value)
    value, g = jax.jit(jax.value_and_grad(prob.objective_value))(jnp.asarray(x))
    parts = jax.jit(jax.vmap(lambda d: eq19(EXACT, prob.part(jnp.asarray(x), d))))(jnp.asarray(dev))
    assert float(value) == pytest.approx(float(np.mean(parts)), rel=1e-12)
    assert len(set(np.round(np.asarray(parts), 12))) == 3  # the parts differ
    for i in range(2):
        fd = central_difference(f, x, i, 1e-6)
        assert abs(g[i] - fd) <= 1e-4 * abs(fd), (i, g[i], fd)
    grid_value, ok = search.evaluate(prob, [x], chunk=1, progress=False)
    assert ok[0] and grid_value[0] == pytest.approx(float(value), rel=1e-9)


def test_robust_problem_config_round_trip():
    from optim.cli import build, resolved

    problem, settings = build(
        {
            "problem": "robust",
            "design": {
                "samples": 2,
                "seed": 7,
                "scatter": [["rod_length", 1e-4, "normal"], ["clearance_B", 5e-5, "uniform"]],
            },
        }
    )
    assert problem.samples == 2 and problem.scatter[0] == ("rod_length", 1e-4, "normal")
    assert "over 2 manufactured parts" in problem.description
    again, _ = build(resolved(problem, settings, "robust"))
    assert again.scatter == problem.scatter and (again.samples, again.seed) == (2, 7)
    np.testing.assert_array_equal(again.draws(), problem.draws())


def test_grid_reports_failed_designs_without_nan_in_ok_rows():
    prob = paper_problem(Pathwise(t_start=0.0, t_end=2e-3, options=SolveOptions(max_steps=50)))
    values, ok = search.evaluate(prob, np.array([[0.12, 0.40], [0.11, 0.41]]), progress=False)
    assert not ok.any() and np.isnan(values).all()


def _implemented(cls):
    import inspect

    return {
        name
        for name, member in vars(cls).items()
        if not name.startswith("__")  # dataclass machinery (__eq__, __repr__, ...)
        and (inspect.isfunction(member) or isinstance(member, property))
        and not getattr(member, "__isabstractmethod__", False)
        and not (isinstance(member, property) and getattr(member.fget, "__isabstractmethod__", False))
    }


@pytest.mark.parametrize(
    "base, finals",
    [
        (
            "optim.problem.AbstractProblem",
            ("optim.design.DesignProblem",),
        ),
        ("optim.objective.AbstractObjective", ("optim.objective.Pathwise", "optim.ensemble.Ensemble")),
        ("optim.objective.AbstractObjective", ("optim.steady.Steady",)),
        (
            "optim.optimizers.AbstractOptimizer",
            ("optim.optimizers.Projected", "optim.optimizers.LBFGS", "optim.optimizers.ProjectedLBFGS"),
        ),
        ("optim.optimizers.AbstractUpdateOptimizer", ("optim.optimizers.Projected", "optim.optimizers.LBFGS")),
        ("optim.optimizers.AbstractLineSearchOptimizer", ("optim.optimizers.ProjectedLBFGS",)),
    ],
)
def test_abstract_or_final_no_implemented_method_is_overridden(base, finals):
    """An abstract base and final subclasses: the base cannot be instantiated, and no
    subclass overrides a method the base implements."""
    import importlib

    def get(path):
        module, name = path.rsplit(".", 1)
        return getattr(importlib.import_module(module), name)

    base_cls = get(base)
    with pytest.raises(TypeError):
        base_cls()
    inherited = _implemented(base_cls) - {"__init__", "__post_init__", "__check_init__"}
    for final in finals:
        cls = get(final)
        assert not (inherited & set(vars(cls))), (final, inherited & set(vars(cls)))


def test_optim_has_no_import_cycle():
    """The module-level imports between optim's modules form no cycle (problem.py no
    longer imports design.py; the presets live in presets.py)."""
    import ast
    from pathlib import Path

    root = Path(__file__).resolve().parents[1] / "optim"
    graph = {}
    for path in root.glob("*.py"):
        tree = ast.parse(path.read_text())
        deps = set()
        for node in tree.body:  # module level only: imports inside functions are deferred on purpose
            if isinstance(node, ast.ImportFrom) and node.level == 1:
                deps |= {node.module} if node.module else {a.name for a in node.names}
        graph[path.stem] = deps
    state = {}

    def visit(m, stack):
        state[m] = "open"
        for d in graph.get(m, ()):
            assert state.get(d) != "open", f"import cycle: {' -> '.join(stack + [m, d])}"
            if d not in state:
                visit(d, stack + [m])
        state[m] = "done"

    for m in graph:
        if m not in state:
            visit(m, [])


def test_the_steady_state_objective_has_its_own_default_optimiser_and_the_regime_guard():
    """With the steady-state objective: the optimiser the head-to-head chose (STEADY_OPTIMIZER) and
    every step kept in the periodic regime; an explicit method or setting is kept; windowed
    objectives keep Adam at 0.1 and no guard."""
    from optim.cli import STEADY_OPTIMIZER, build, resolved
    from optim.steady import RegimeGuard

    problem, settings = build({"problem": "design"})
    assert settings.optimizer.settings() == {**settings.optimizer.settings(), **STEADY_OPTIMIZER}
    assert isinstance(settings.guard, RegimeGuard)
    _, resumed = build(resolved(problem, settings, "design"))  # what --resume reads back
    assert resumed.optimizer.settings() == settings.optimizer.settings() and isinstance(resumed.guard, RegimeGuard)
    _, chosen = build({"problem": "design", "optimizer": {"method": "projected_lbfgs"}})
    assert chosen.optimizer.label == "projected_lbfgs" and isinstance(chosen.guard, RegimeGuard)
    _, rate = build({"problem": "design", "optimizer": {"learning_rate": 0.02}})
    assert rate.optimizer.settings()["learning_rate"] == 0.02
    _, windowed = build({"problem": "paper"})
    assert windowed.optimizer.settings() == {"method": "adam", "learning_rate": 0.1} and windowed.guard is None


def test_steady_objective_config_round_trip():
    from optim.cli import build, resolved
    from optim.steady import Steady

    problem, settings = build({"problem": "design", "objective": {"method": "steady_state", "rtol": 1e-8}})
    assert isinstance(problem.objective, Steady) and problem.objective.options.solve.rtol == 1e-8
    again, _ = build(resolved(problem, settings, "design"))
    assert again.objective == problem.objective
    with pytest.raises(ParameterError, match="objective method 'bogus' is unknown"):
        build({"problem": "paper", "objective": {"method": "bogus"}})
    with pytest.raises(ParameterError, match="optimiser method 'sgd' is unknown"):
        build({"problem": "paper", "optimizer": {"method": "sgd"}})
    with pytest.raises(ParameterError, match=r"unknown \[optimizer\] keys \['learning_rate'\] for method 'lbfgs'"):
        build({"problem": "paper", "optimizer": {"method": "lbfgs", "learning_rate": 0.1}})


@pytest.mark.parametrize(
    "table",
    [
        {"method": "pathwise", "t_end": 0.2, "solver": "kvaerno5", "max_steps": 1000},
        {
            "method": "ensemble",
            "rtol": 1e-8,
            "window_solver": "tsit5",
            "window_max_steps": 200,
            "window_gradient": "reverse",
        },
        {"method": "steady_state", "settle_revolutions": 12, "newton_tol": 1e-6, "atol": 1e-9, "on_failure": "nan"},
    ],
)
def test_objective_tables_map_flat_keys_onto_the_options_objects_and_round_trip(table):
    """An [objective] table's flat keys set the objective's SolveOptions (an ensemble's windows
    through window_*, following the solve's rtol/atol unless given; a steady state's SteadyOptions),
    and objective_config writes a table that builds the same objective."""
    import diffrax

    from optim.objective_config import objective_config, objective_from_config

    obj = objective_from_config(table)
    assert objective_from_config(objective_config(obj)) == obj
    if table["method"] == "pathwise":
        assert isinstance(obj.options.solver, diffrax.Kvaerno5) and obj.options.max_steps == 1000
    elif table["method"] == "ensemble":
        assert obj.options.rtol == obj.window_options.rtol == 1e-8 and obj.window_options.max_steps == 200
        assert isinstance(obj.window_options.solver, diffrax.Tsit5) and not obj.forward_mode()
    else:
        o = obj.options
        assert (o.settle_revolutions, o.newton_tol, o.solve.atol, o.solve.rtol) == (12, 1e-6, 1e-9, 1e-10)
        assert o.max_period == 2 and not obj.throw  # the objective's defaults kept
    with pytest.raises(ParameterError, match=r"unknown \[objective\] keys \['bogus'\]; valid: \[.*'rtol'"):
        objective_from_config({**table, "bogus": 1})


def test_the_design_config_chooses_a_subset_of_its_variables_by_name():
    """``[design] variables``: the design problem with those variables at their default bounds
    (the others fixed at their start values); a resume reads the same problem back; a name it does
    not know, or another problem, is refused naming the key."""
    from optim.cli import build, resolved
    from optim.presets import design_problem

    chosen = ["rod_length", "min_transmission_angle", "clearance_C"]
    problem, settings = build({"problem": "design", "design": {"variables": chosen, "stroke": 0.22}})
    expect = design_problem(variables=chosen)
    assert problem.names == tuple(chosen) and problem.lower == expect.lower and problem.upper == expect.upper
    assert problem.derived.stroke == 0.22 and problem.description.startswith("design: 3 variables, stroke 220 mm")
    again, _ = build(resolved(problem, settings, "design"))
    assert again.names == problem.names and again.start == problem.start and again.base == problem.base
    with pytest.raises(ParameterError, match=r"unknown design variables \['rod_lenght'\]; valid: \['rod_length'"):
        build({"problem": "design", "design": {"variables": ["rod_lenght"]}})
    with pytest.raises(ParameterError, match=r"\[design\] variables: only the design problem takes it, not 'paper'"):
        build({"problem": "paper", "design": {"variables": ["rod_length"]}})
