"""Design problems as data: problem files, derived length variables, kinematic quantities and
the augmented Lagrangian's arithmetic. Fast tests (no steady-state solve); the end-to-end run
of the docs page's problem file is in tests/test_design_your_own.py (slow)."""

from __future__ import annotations

import math
from pathlib import Path

import jax
import numpy as np
import pytest

import jaxcrank as jc
from jaxcrank.analysis.kinematic_summary import grashof_loops, kinematic_summary
from jaxcrank.physics.parameters import get_parameter
from optim import constrained, quantities, spec

ROOT = Path(__file__).resolve().parents[1]
ROCKER = ROOT / "docs" / "linkages" / "crank-rocker.toml"
DOCS_PROBLEM = ROOT / "docs" / "problems" / "crank-rocker-pin-force.toml"


def _problem(**changes):
    data = {
        "mechanism": {"file": str(ROCKER)},
        "variables": {
            "coupler_length": {
                "kind": "length",
                "body": "coupler",
                "from": "A",
                "to": "B",
                "carry": "uniform_bar",
                "lower": 0.32,
                "upper": 0.38,
            },
            "rocker_length": {
                "kind": "length",
                "body": "rocker",
                "from": "O4",
                "to": "B",
                "carry": "scale",
                "lower": 0.27,
                "upper": 0.33,
            },
            "frame_length": {
                "kind": "length",
                "body": "ground",
                "from": "O2",
                "to": "O4",
                "lower": 0.38,
                "upper": 0.42,
            },
            "clearance_B": {"lower": 2e-4, "upper": 5e-4},
        },
        "objective": {"terms": [{"quantity": "peak_contact_force_B_N", "weight": 1.0}]},
        "constraints": [
            {"quantity": "kinematics.output.swing_deg", "lower": 38.0, "upper": 42.0},
            {"quantity": "rms_rocker_angle_deviation_deg", "upper": 0.07},
            {"linear": {"coupler_length": 1.0, "rocker_length": -1.0}, "lower": 0.0},
        ],
    }
    data.update(changes)
    return spec.from_dict(data)[0]


@pytest.mark.parametrize("mech", [jc.paper(), jc.four_bar(), jc.config.load(ROCKER)], ids=["paper", "four-bar", "own"])
def test_kinematic_quantities_are_the_kinematic_summary(mech):
    """The traceable kinematics (720 samples) agree with the kinematic summary (3600 samples,
    parabola vertices) to 1e-7 relative, and the Grashof margin is p + q - (s + l)."""
    names = quantities.kinematic_names(mech)
    values = jax.jit(lambda m: quantities.kinematic_values(m, names))(mech)
    s = kinematic_summary(mech)
    for name, v in values.items():
        if name == "kinematics.grashof.margin_m":
            loop = grashof_loops(mech)[0]
            assert float(v) == pytest.approx(loop["p_plus_q_m"] - loop["s_plus_l_m"], rel=1e-12)
            continue
        _, part, key = name.split(".")
        assert float(v) == pytest.approx(s[part][key], rel=1e-7), name


def test_a_length_variable_moves_its_point_and_carries_the_mass_properties():
    """At its base length a length variable reproduces the base; at another length the moved point
    lies on the same line at that distance, a uniform bar's centre is midway with inertia
    m L^2 / 12, a scaled bar's mass grows with the length and its inertia with its cube, and the
    ground's point moves alone."""
    p = _problem()
    base = p.base
    x0 = np.asarray(p.default_start())
    assert x0[:3] == pytest.approx([0.35, 0.30, 0.40], rel=1e-12)
    m0 = p.mechanism(x0)
    for name in ("bodies.coupler.points.B.x", "bodies.rocker.mass", "ground.O4.x", "bodies.rocker.inertia"):
        assert get_parameter(m0, name) == pytest.approx(get_parameter(base, name), rel=1e-12)
    m = p.mechanism(np.array([0.36, 0.33, 0.41, 4e-4]))
    pts = m.bodies["coupler"].points
    assert math.hypot(pts["B"].x - pts["A"].x, pts["B"].y - pts["A"].y) == pytest.approx(0.36, rel=1e-12)
    coupler = m.bodies["coupler"]
    assert float(coupler.centre_of_mass.x) == pytest.approx(0.18, rel=1e-12)
    assert float(coupler.inertia) == pytest.approx(float(coupler.mass) * 0.36**2 / 12.0, rel=1e-12)
    r = 0.33 / 0.30
    rocker, rocker0 = m.bodies["rocker"], base.bodies["rocker"]
    assert float(rocker.mass) == pytest.approx(float(rocker0.mass) * r, rel=1e-12)
    assert float(rocker.inertia) == pytest.approx(float(rocker0.inertia) * r**3, rel=1e-12)
    assert float(rocker.centre_of_mass.x) == pytest.approx(float(rocker0.centre_of_mass.x) * r, rel=1e-12)
    assert float(m.ground["O4"].x) == pytest.approx(0.41, rel=1e-12)
    assert get_parameter(m, "clearance_B") == pytest.approx(4e-4, rel=1e-12)


def test_kinematic_gradients_through_length_variables_equal_central_differences():
    """d(swing, transmission extremes, Grashof margin)/d(lengths) by forward mode equal central
    differences (step 1e-6 m) to 1e-5 relative: the derived variables are differentiable."""
    p = _problem()
    names = quantities.kinematic_names(p.base)
    f = jax.jit(lambda x: jax.numpy.stack(list(quantities.kinematic_values(p.mechanism(x), names).values())))
    x = np.array([0.35, 0.30, 0.40, 5e-4])
    jac = np.asarray(jax.jacfwd(f)(x))
    h = 1e-6
    for i in range(3):
        e = np.zeros(4)
        e[i] = h
        fd = (np.asarray(f(x + e)) - np.asarray(f(x - e))) / (2 * h)
        np.testing.assert_allclose(jac[:, i], fd, rtol=1e-5, atol=1e-6 * np.abs(jac).max())


def test_the_problem_file_reads_bounds_linear_constraints_and_defaults():
    """Starts default to the base's values (a length's distance); a linear constraint with a lower
    bound becomes a row of A x <= b with the signs flipped; quantities keep file order."""
    p = _problem()
    assert p.names == ("coupler_length", "rocker_length", "frame_length", "clearance_B")
    assert p.A == ((-1.0, 1.0, 0.0, 0.0),) and p.b == (-0.0,)
    assert p.quantities == ("peak_contact_force_B_N", "kinematics.output.swing_deg", "rms_rocker_angle_deviation_deg")
    assert type(p.objective).__name__ == "Steady"


@pytest.mark.parametrize(
    "changes, match",
    [
        ({"objective": {"terms": [{"quantity": "peak_force_Q_N"}]}}, "unknown quantity 'peak_force_Q_N'"),
        ({"objective": {"terms": []}}, "at least one term"),
        ({"constraints": [{"quantity": "kinematics.output.swing_deg", "lower": 40.0, "upper": 38.0}]}, "lower = 40"),
        ({"constraints": [{"quantity": "kinematics.output.stroke_m", "upper": 1.0}]}, "valid for this mechanism"),
        ({"constraints": [{"linear": {"crank": 1.0}, "upper": 1.0}]}, "not variables"),
        (
            {"variables": {"mass_of_it": {"lower": 0.0, "upper": 1.0}}, "constraints": []},
            "unknown design variable 'mass_of_it'",
        ),
        (
            {
                "variables": {
                    "L": {"kind": "length", "body": "coupler", "from": "A", "to": "Q", "lower": 0.3, "upper": 0.4}
                }
            },
            "no point 'Q'",
        ),
        (
            {
                "variables": {
                    "L": {
                        "kind": "length",
                        "body": "coupler",
                        "from": "A",
                        "to": "B",
                        "carry": "heavy",
                        "lower": 0.3,
                        "upper": 0.4,
                    }
                }
            },
            "carry = 'heavy'",
        ),
        (
            {
                "mechanism": {"preset": "paper"},
                "variables": {
                    "L": {"kind": "length", "body": "rod", "from": "B", "to": "C", "lower": 0.3, "upper": 0.4}
                },
            },
            "written-out linkage",
        ),
        (
            {"variables": {"clearance_B": {"lower": 1e-4, "upper": 4e-4, "start": 5e-4}}},
            "start of 'clearance_B': 0.0005 is outside its bounds \\[lower, upper\\] = \\[0.0001, 0.0004\\]",
        ),
        (
            {"scatter": {"parts": [["clearance_B", 1e-5, "normal"]], "samples": 2}},
            "samples = 2: the steady-state objective does not average over manufactured parts; set samples = 0",
        ),
        ({"objectives": {}}, "unknown keys \\['objectives'\\]"),
        ({"solver": {"method": "ensemble"}}, "windowed objective measures the RMS metrics only"),
    ],
)
def test_a_bad_problem_file_names_what_is_wrong(changes, match):
    if "variables" in changes:
        changes = {"constraints": [], **changes}
    with pytest.raises(jc.ParameterError, match=match):
        _problem(**changes)


def test_a_problem_files_history_names_the_merit_without_a_unit():
    """The optimiser's columns of a problem file's run are the augmented Lagrangian's
    (dimensionless), not degrees: ``merit``, ``grad_merit_<variable>_per_SI``; the way in's
    candidates carry ``merit`` too."""
    from optim.file_cli import _merit_named, _search_merit_named

    row = {"objective_deg": 1.0, "cost_deg": 0.0, "grad_L_deg_per_SI": 2.0, "L_SI": 0.3, "f": 3000.0}
    assert _merit_named(row) == {"merit": 1.0, "cost": 0.0, "grad_merit_L_per_SI": 2.0, "L_SI": 0.3, "f": 3000.0}
    search = {"classified": [{"value_deg": 1.0, "regime": "periodic"}], "chosen": 0}
    assert _search_merit_named(search) == {"classified": [{"merit": 1.0, "regime": "periodic"}], "chosen": 0}
    assert _search_merit_named(None) is None


def test_a_windowed_problem_file_with_length_variables_is_recorded_for_its_run():
    """A problem file with the windowed objective runs as a preset problem does, whose run folder
    records the problem (optimize.toml): its length variables are written as tables, not refused."""
    import tomli_w

    from optim.cli import _drop_none, resolved
    from optim.optimize import Settings

    p = _problem(
        objective={"terms": [{"quantity": "rms_rocker_angle_deviation_deg"}]},
        constraints=[],
        solver={"method": "ensemble", "t_start": 0.2, "t_end": 0.25},
    )
    record = resolved(p, Settings(), "windowed")
    lengths = record["design"]["lengths"]
    assert [(v["name"], v["body"], v["carry"]) for v in lengths][:2] == [
        ("coupler_length", "coupler", "uniform_bar"),
        ("rocker_length", "rocker", "scale"),
    ]
    assert "lengths" in tomli_w.dumps(_drop_none(record))  # as the run writes it


def test_the_augmented_lagrangian_gradient_is_its_derivative():
    """On outputs that are linear in the design (values o0 + J x), the evaluator's augmented
    Lagrangian gradient from (outputs, J) equals central differences of its value, active and
    inactive constraints alike, and each bound gives one scaled inequality."""
    p = _problem()
    ev = constrained.QuantityEvaluator(p)
    ev.f_ref, ev.mu = 3000.0, 10.0
    ev.lam = np.array([0.5, 0.0, 2.0])
    rng = np.random.default_rng(0)
    o0 = np.array([3100.0, 0.0, 41.5, 0.075])
    jac = rng.normal(size=(4, 4)) * np.array([[1000.0], [0.0], [10.0], [0.1]])
    x = np.array([0.35, 0.30, 0.40, 5e-4])
    value, grad = ev.lagrangian(o0 + jac @ x, jac)
    for i in range(4):
        e = np.zeros(4)
        e[i] = 1e-7
        fd = (ev.lagrangian(o0 + jac @ (x + e)) - ev.lagrangian(o0 + jac @ (x - e))) / 2e-7
        assert grad[i] == pytest.approx(fd, rel=1e-6, abs=1e-9)
    g, rows = constrained.inequalities(p, np.array([41.5, 0.075]))
    assert g == pytest.approx([(41.5 - 42.0) / 42.0, (38.0 - 41.5) / 42.0, (0.075 - 0.07) / 0.07])
    assert rows[:, 0].tolist() == [0, 0, 1]
    assert constrained.satisfied(p, np.array([41.5, 0.075])) == [True, False]


def test_the_penalty_grows_when_a_round_leaves_too_much_violation_the_first_against_the_start():
    """The first round is measured against the start's violation: a start that violates a
    bound by 0.10 and a first round that leaves 0.04 (more than a quarter) raise the penalty
    for the second round; a round that holds every bound, or quarters the violation, keeps it."""
    assert constrained.next_penalty(10.0, 0.04, 0.10, 10.0) == 100.0
    assert constrained.next_penalty(10.0, 0.02, 0.10, 10.0) == 10.0
    assert constrained.next_penalty(10.0, -0.003, 0.10, 10.0) == 10.0
    assert constrained.next_penalty(10.0, 0.04, math.inf, 10.0) == 10.0  # a start without finite outputs


def test_the_docs_problem_file_parses():
    """The docs page's problem file (run end to end by the slow test) is a valid problem on a
    written-out linkage, with an objective other than Eq. 19, kinematic and metric constraints."""
    p, tables = spec.load(DOCS_PROBLEM)
    assert isinstance(p.base, jc.Linkage)
    assert [q for q, _ in p.terms] != ["rms_transmission_angle_error_deg"]
    assert any(c[0].startswith("kinematics.") for c in p.limits)
    assert any(not c[0].startswith("kinematics.") for c in p.limits)
    assert tables["optimizer"]["rounds"] >= 1


def test_the_statistics_over_parts_are_numpys_and_differentiable():
    """mean, std (population) and percentiles equal numpy's on the parts' values; their gradients
    are finite, the standard deviation's also at zero spread."""
    from optim.design import STATISTICS, statistic_of

    v = np.array([0.3, 0.1, 0.7, 0.2, 0.5])
    for s in STATISTICS:
        expect = {"mean": np.mean(v), "std": np.std(v)}.get(s) or np.percentile(v, float(s[1:]))
        assert float(statistic_of(v, s)) == pytest.approx(expect, rel=1e-12), s
        assert np.all(np.isfinite(np.asarray(jax.grad(lambda a, s=s: statistic_of(a, s))(v))))
    assert np.all(np.isfinite(np.asarray(jax.grad(lambda a: statistic_of(a, "std"))(np.ones(4)))))


def test_a_problem_file_with_scatter_is_a_statistic_over_its_parts():
    """With ``[scatter]`` the value is the statistic of the parts' values (the same draws at every
    design), with a finite gradient. The parts are solved by another compiled program than the
    value's, so they agree to 1e-6 relative, not to the last bit (impacts amplify rounding)."""
    from optim.objective import Pathwise

    data = {
        "mechanism": {"preset": "paper"},
        "variables": {"crank_length": {"lower": 0.11, "upper": 0.13}, "rod_length": {"lower": 0.39, "upper": 0.41}},
        "objective": {"terms": [{"quantity": "rms_transmission_angle_error_deg"}]},
        "scatter": {"samples": 4, "seed": 3, "statistic": "p90", "parts": [["clearance_B", 5e-5, "uniform"]]},
        "solver": {"method": "pathwise", "t_start": 0.0, "t_end": 0.002},
    }
    p = spec.from_dict(data)[0]
    assert isinstance(p.objective, Pathwise) and p.samples == 4 and "p90 over 4" in p.description
    x = jax.numpy.asarray([0.12, 0.40])
    parts = np.asarray(jax.jit(jax.vmap(lambda d: p.loss(p.objective.rms(p.part(x, d)))))(jax.numpy.asarray(p.draws())))
    value, grad = jax.jit(jax.value_and_grad(p.objective_value))(x)
    assert float(value) == pytest.approx(np.percentile(parts, 90.0), rel=1e-6)
    assert np.all(np.isfinite(np.asarray(grad)))


def test_the_preset_problems_are_their_files():
    """Each preset problem is its package file, and the library's functions give the same problem."""
    from optim import presets

    for name in presets.PROBLEMS:
        assert presets.problem(name) == spec.from_dict(__import__("tomllib").loads(presets.problem_text(name)))[0]
    assert presets.design_problem() == presets.problem("design")
    assert presets.four_bar_problem() == presets.problem("four-bar")
    assert presets.paper_problem() == presets.problem("paper")
    with pytest.raises(jc.ParameterError, match="unknown; valid: paper"):
        presets.problem("nine-bar")
