"""Many-variable design problems (optim/design.py): the constraint reparametrisation,
the preset and its config round trip, the objective terms' gradients against
central differences, constraints along an optimisation path, and the gradient-free
baselines of bench/bench_design.py."""

import dataclasses
import math
import tomllib

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import tomli_w

from jaxcrank import SolveOptions
from jaxcrank.physics.params import ParameterError
from optim import cli
from optim.design import TERMS, DesignProblem
from optim.ensemble import Ensemble
from optim.geometry import CrankRocker, SliderCrankStroke, ideal_stroke
from optim.geometry import crank_and_offset as geometry
from optim.objective import EQ19, AbstractObjective, Pathwise
from optim.optimize import Settings, optimize
from optim.optimizers import adam
from optim.presets import design_problem, design_variables
from optim.search import pathwise_of

DESIGN_VARIABLES = design_variables()

# A non-chaotic window for exact-gradient checks (as tests/test_objectives.py's EXACT):
# the first 1.2 ms, tight tolerances, pathwise derivative.
EXACT = Pathwise(t_start=0.0, t_end=1.2e-3, options=SolveOptions(rtol=1e-10, atol=1e-10, max_steps=100_000))


def test_geometry_holds_the_stroke_transmission_and_assembly_over_the_box():
    """Every (L2, alpha_min) of the preset's box, corners included: stroke within
    0.1 mm (to rounding in fact), min transmission angle = its variable >= 40 deg,
    L2 - L1 - e > 0, e >= 0, checked in closed form from the derived L1, e."""
    prob = design_problem()
    rng = np.random.default_rng(0)
    u = np.concatenate(
        [rng.uniform(size=(200, prob.n)), np.array(np.meshgrid([0, 1], [0, 1])).reshape(2, -1).T @ np.eye(2, prob.n)]
    )
    x = np.asarray(prob.from_unit(u))
    c = prob.constraints(x)
    assert np.max(np.abs(c["stroke_error_m"])) < 1e-12
    assert np.all(c["min_transmission_angle_deg"] >= 40.0 - 1e-9)
    np.testing.assert_allclose(c["min_transmission_angle_deg"], np.degrees(x[:, 1]), atol=1e-9)
    assert np.all(c["assembly_margin_m"] > 0.05)
    assert np.all(c["offset_m"] >= 0.0) and np.all(c["crank_length_m"] > 0.0)
    assert prob.feasible(x).all()
    # an independent check of the stroke: the slider's travel between its dead centres
    # from the ideal kinematics (x3 over a fine crank-angle grid)
    from jaxcrank import ideal

    mech = prob.mechanism(jnp.asarray(x[0]))
    th = jnp.linspace(0.0, 2 * math.pi, 20_001)
    slider = ideal.body_index(mech, "slider")
    x3 = jax.vmap(lambda t: ideal.positions(mech, t)[slider, 0])(th / float(mech.driver.speed))
    assert float(jnp.max(x3) - jnp.min(x3)) == pytest.approx(prob.derived.stroke, abs=1e-7)


def test_geometry_derivatives_are_the_implicit_functions():
    """dL1/dL2, dL1/dalpha, de/d... of the bisection + Newton step against central
    differences of the same solve (the bisection itself has zero derivative)."""
    f = lambda p: jnp.stack(geometry(p[0], p[1], p[2]))  # noqa: E731
    p = np.array([0.41, math.radians(55.0), 0.24])
    jac = np.asarray(jax.jacrev(f)(jnp.asarray(p)))
    for j in range(3):
        h = 1e-6 * max(1.0, abs(p[j]))
        e = np.zeros(3)
        e[j] = h
        fd = (np.asarray(f(jnp.asarray(p + e))) - np.asarray(f(jnp.asarray(p - e)))) / (2 * h)
        np.testing.assert_allclose(jac[:, j], fd, rtol=1e-6, atol=1e-9)

    # the stroke stays put along the derivative: dS = 0 for any change of L2, alpha
    def stroke_of(q):
        l1, e = geometry(q[0], q[1], 0.24)
        return ideal_stroke(l1, q[0], e)

    assert np.max(np.abs(np.asarray(jax.grad(stroke_of)(jnp.asarray(p[:2]))))) < 1e-12
    l1, e = geometry(p[0], p[1], p[2])
    assert float(ideal_stroke(l1, p[0], e)) == pytest.approx(0.24, abs=1e-14)


def test_preset_has_nine_variables_within_physical_bounds():
    prob = design_problem()
    assert prob.n >= 8
    assert {
        "rod_length",
        "min_transmission_angle",
        "clearance_B",
        "clearance_C",
        "rod_mass",
        "rod_inertia_ratio",
        "slider_mass",
        "friction.coefficient",
    } <= set(prob.names)
    x = np.asarray(prob.from_unit(prob.start_unit()))
    mech = prob.mechanism(jnp.asarray(x))
    i = prob.names.index
    assert float(mech.rod_inertia) == pytest.approx(
        x[i("rod_inertia_ratio")] * x[i("rod_mass")] * x[i("rod_length")] ** 2
    )
    assert float(mech.joints["B"].clearance) == pytest.approx(x[i("clearance_B")])
    for joint in ("B", "C"):  # the tied friction coefficient of both clearance joints
        assert float(mech.joints[joint].friction.coefficient) == pytest.approx(x[i("friction.coefficient")])
    lo, hi = prob.lower[i("rod_inertia_ratio")], prob.upper[i("rod_inertia_ratio")]
    assert lo < 1 / 12 < hi < 0.25  # a uniform bar inside, below the dumbbell's 1/4


def test_preset_round_trips_through_the_config(tmp_path):
    prob, settings = cli.build({"problem": "design", "design": {"weights": [["rms_contact_force_N", 3e-5]]}})
    assert isinstance(prob, DesignProblem) and dict(prob.terms) == {EQ19: 1.0, "rms_contact_force_N": 3e-5}
    path = tmp_path / "optimize.toml"
    path.write_text(tomli_w.dumps(cli._drop_none(cli.resolved(prob, settings, "design"))))
    again, settings2 = cli.build(tomllib.loads(path.read_text()))
    assert again == prob and cli.settings_config(settings2) == cli.settings_config(settings)


@pytest.mark.parametrize(
    "change, match",
    [
        (dict(lower=(0.30,) + tuple(v[1] for v in DESIGN_VARIABLES[1:])), "out of reach"),
        (dict(lower=(0.36, math.radians(35.0)) + tuple(v[1] for v in DESIGN_VARIABLES[2:])), "min_transmission_angle"),
        (dict(names=("crank_length",) + tuple(v[0] for v in DESIGN_VARIABLES[1:])), "rod_length"),
        (dict(terms=((EQ19, 1.0), ("peak_contact_force_N", 1.0))), "unknown quantity"),
        (dict(derived=SliderCrankStroke(stroke=-0.1)), "stroke"),
    ],
)
def test_bad_design_problems_raise(change, match):
    with pytest.raises(ParameterError, match=match):
        dataclasses.replace(design_problem(), **change)


@pytest.fixture(scope="module")
def exact_problem():
    return design_problem(EXACT)


@pytest.fixture(scope="module")
def term_gradients(exact_problem):
    """Each term of the objective (Eq. 19, rod and slider deviation, driving-moment
    deviation, contact force) and the cost at a start design with 0.12 mm
    clearances (the preset's 0.4 mm has no contact yet in the first 1.2 ms):
    values, reverse-mode Jacobian with respect to the nine scaled variables, and
    central differences (h = 1e-5 scaled; converged: h = 1e-6 agrees to ~1e-5)."""
    prob = exact_problem
    u0 = np.array(prob.start_unit())
    u0[prob.names.index("clearance_B")] = u0[prob.names.index("clearance_C")] = 0.05

    def all_terms(u):
        x = prob.from_unit(u)
        t = prob.term_values(x)
        return jnp.append(jnp.stack([t[k] for k in TERMS]), prob.cost(x))

    terms = jax.jit(all_terms)
    jac = np.asarray(jax.jit(jax.jacrev(all_terms))(u0))
    h = 1e-5
    fd = np.zeros_like(jac)
    for j in range(prob.n):
        e = np.zeros(prob.n)
        e[j] = h
        fd[:, j] = (np.asarray(terms(u0 + e)) - np.asarray(terms(u0 - e))) / (2 * h)
    return np.asarray(terms(u0)), jac, fd


@pytest.mark.slow  # the term_gradients fixture compiles a nine-variable reverse-mode Jacobian: 162-195 s
@pytest.mark.parametrize("k", range(len(TERMS) + 1), ids=list(TERMS) + ["cost"])
def test_objective_term_gradient_matches_central_differences(term_gradients, k):
    """Reverse-mode gradient of term ``k`` within 1e-4 of its largest entry of the
    central differences, on the non-chaotic first 1.2 ms. (With the frozen memory law the
    RMS contact force's derivatives with respect to the clearances missed the differences
    by 0.15 %; with the default memory law, whose dwell clock adds a state entry but acts
    only after 2 ms of contact, they agree within this bound.)"""
    vals, jac, fd = term_gradients
    assert np.all(np.isfinite(jac[k])) and vals[k] > 0
    scale = np.max(np.abs(fd[k]))
    assert scale > 0
    assert np.max(np.abs(jac[k] - fd[k])) <= 1e-4 * scale, (jac[k], fd[k])


@pytest.mark.slow  # the term_gradients fixture (162-195 s)
def test_contact_force_gradient_matches_central_differences_except_clearances(term_gradients):
    """The wear term (contact force, N) has contact in the window and its gradient
    along the seven variables other than the clearances matches within 1e-4."""
    vals, jac, fd = term_gradients
    k = list(TERMS).index("rms_contact_force_N")
    assert vals[k] > 100.0
    keep = [j for j in range(jac.shape[1]) if j not in (2, 3)]
    assert np.max(np.abs(jac[k, keep] - fd[k, keep])) <= 1e-4 * np.max(np.abs(fd[k])), (jac[k], fd[k])


@pytest.mark.slow  # six Adam iterations on the nine-variable pathwise objective, compiled: 118 s
def test_constraints_hold_at_every_iterate_of_an_optimisation_path(exact_problem):
    """Adam with large steps (iterates pushed onto the box's faces), on the exact short
    objective: every iterate has the stroke within 0.1 mm, alpha_min >= 40 deg and
    L2 > L1 + e."""
    prob = exact_problem
    res = optimize(prob, Settings(optimizer=adam(0.5), max_iterations=6, gtol=0.0, xtol=0.0), progress=False)
    xs = np.array([[h[f"{n}_SI"] for n in prob.names] for h in res["history"]])
    assert len(xs) == 6
    c = prob.constraints(xs)
    assert np.max(np.abs(c["stroke_error_m"])) <= prob.derived.stroke_tolerance
    assert np.min(c["min_transmission_angle_deg"]) >= 40.0 - 1e-9
    assert np.min(c["assembly_margin_m"]) > 0.0
    assert prob.feasible(xs).all()
    us = np.asarray(prob.to_unit(xs))
    assert np.any((us <= 1e-12) | (us >= 1 - 1e-12))  # some iterate sits on a face of the box
    assert res["final_objective"] < res["history"][0]["objective_deg"]


def _bench():
    """bench/bench_design.py as the module ``bench_design`` (on sys.path, so that its
    spawned pool workers import it too)."""
    import importlib
    import sys
    from pathlib import Path

    bench = str(Path(__file__).resolve().parents[1] / "bench")
    if bench not in sys.path:
        sys.path.insert(0, bench)
    return importlib.import_module("bench_design")


def test_bench_best_so_far_and_checkpoints():
    """The head-to-head's bookkeeping: the best-so-far value never rises, and each
    checkpoint holds the best design evaluated by its time (none before the first)."""
    B = _bench()
    trace = [(1.0, 3.0, [0.1], "not periodic"), (2.0, 2.0, [0.2], "periodic"), (5.0, 2.5, [0.3], "periodic")]
    assert [b[1] for b in B.best_so_far(trace)] == [3.0, 2.0, 2.0]
    cps = B.checkpoints(trace, 8.0, (0.1, 0.25, 1.0))
    assert cps[0]["unit_design"] is None and cps[0]["objective_deg"] == float("inf")
    assert cps[1]["unit_design"] == [0.2] and cps[2]["objective_deg"] == 2.0


def test_bench_extended_budgets_checkpoints_and_speedups(tmp_path):
    """A gradient-free method rerun with a longer budget than its part's is scored at the
    part's checkpoints, then at the extension multiples up to its own budget; the merge
    bounds the speedup by the shortest budget of a method that never got within 1 %, and
    calls it exact only where the first method within 1 % got there before that budget."""
    import json

    B = _bench()
    assert B.checkpoint_times(240.0) == [f * 240.0 for f in B.CHECKPOINTS]
    assert B.checkpoint_times(450.0, base=240.0)[-3:] == [240.0, 360.0, 450.0]
    assert B.checkpoint_times(1200.0, base=240.0)[-6:] == [360.0, 480.0, 600.0, 720.0, 960.0, 1200.0]

    def method(budget, hit_at, base=240.0):
        """Held-out 1.0 (the best) from ``hit_at`` on, 2.0 before; None: never."""
        times = B.checkpoint_times(budget, base=base)
        cps = [{"t_s": t, "heldout_deg": 1.0 if hit_at is not None and t >= hit_at else 2.0} for t in times]
        return {"checkpoints": cps, "budget_cpu_s": budget}

    # (ours at, (cma budget, cma hit), (tpe budget, tpe hit)) -> (speedup, lower bound?)
    cases = {
        0: ((60.0, (450.0, None), (450.0, None)), (7.5, True)),
        1: ((60.0, (450.0, 360.0), (450.0, None)), (6.0, False)),
        2: ((60.0, (450.0, 360.0), (240.0, None)), (4.0, True)),
        3: ((60.0, (240.0, 180.0), (240.0, 240.0)), (3.0, False)),
    }
    parts = tmp_path / "parts"
    parts.mkdir()
    for seed, ((ours, cma, tpe), _) in cases.items():
        part = {
            "problem": "preset",
            "stroke_m": 0.24,
            "crank_speed_rpm": 600.0,
            "seed": seed,
            "budget_cpu_s": 240.0,
            "names": [f"x{j}" for j in range(9)],
            "start_heldout_deg": 2.0,
            "methods": {"ours_adam": method(240.0, ours), "cma": method(*cma), "tpe": method(*tpe)},
        }
        (parts / f"preset_seed{seed}.json").write_text(json.dumps(part))
    data = B.merge(parts, tmp_path / "design.json")
    got = {c["seed"]: (c["speedup"], c["speedup_is_lower_bound"]) for c in data["summary"]["cases"]}
    for seed, (_, (speedup, bound)) in cases.items():
        assert got[seed][0] == pytest.approx(speedup) and got[seed][1] is bound
    assert data["summary"]["cases"][0]["gradient_free_budgets_cpu_s"] == {"cma": 450.0, "tpe": 450.0}


@pytest.mark.long
@pytest.mark.slow
def test_bench_design_writes_the_schema(tmp_path):
    """A short part of bench_design (5 CPU-s budgets, ours and CMA-ES on the preset problem,
    seed 0), then the merge: design.json has the keys the head-to-head documents, every
    checkpoint has a held-out value, the summary has the case, and the plot is written."""
    import json

    B = _bench()
    parts, out = tmp_path / "parts", tmp_path / "design.json"
    args = ["--problem", "preset", "--seed", "0", "--budget", "5", "--methods", "ours_adam", "cma"]
    B.main(["--parts", str(parts), *args])
    assert (parts / "preset_seed0.json").exists()
    B.main(["--merge", "--parts", str(parts), "--out", str(out)])
    data = json.loads(out.read_text())
    assert data["objective"] == "steady_state" and data["heldout"]["revolutions"] >= 20
    assert data["budget_cpu_s_per_method"] == 5.0 and data["seeds"] == [0]
    (p,) = data["problems"]
    assert p["name"] == "preset" and p["n_variables"] == 9 and len(p["names"]) == 9
    assert p["target_heldout_deg"] == pytest.approx(1.01 * p["best_heldout_any_method"])
    (run,) = p["runs"]
    assert run["seed"] == 0 and run["problem"] == "preset" and run["budget_cpu_s"] == 5.0
    assert {"start_regime", "start_heldout_deg", "compile_s", "machine"} <= set(run)
    assert "speedup_vs_best_gradient_free" in run and "speedup_lower_bound" in run
    assert set(run["methods"]) == {"ours_adam", "cma"}
    for m in run["methods"].values():
        assert {"evaluations", "periodic_evaluations", "best_objective", "time_to_1pct_s", "trace"} <= set(m)
        assert len(m["checkpoints"]) == len(data["checkpoint_fractions"])
        assert all(np.isfinite(c["heldout_deg"]) for c in m["checkpoints"])
    (case,) = data["summary"]["cases"]
    assert (case["problem"], case["seed"]) == ("preset", 0)
    assert {"ours_time_to_1pct_s", "best_gradient_free_time_to_1pct_s", "speedup", "speedup_is_lower_bound"} <= set(
        case
    )
    assert {"worst", "best", "ours_never_within_1pct"} <= set(data["summary"])
    assert out.with_suffix(".png").exists()


@pytest.mark.long
@pytest.mark.slow
def test_ensemble_terms_have_the_exact_values_and_finite_gradients():
    """The ensemble objective of the design problem (short window, tsit5 windows):
    values equal the forward solve's terms, gradients finite, and the objective's
    gradient is the weighted sum of the terms' gradients plus the cost's."""
    obj = Ensemble(
        t_start=0.02,
        t_end=0.03,
        window_options=SolveOptions.from_text("tsit5", max_steps=5_000),
        window_adjoint=diffrax.RecursiveCheckpointAdjoint(),
    )
    prob = design_problem(obj)
    x = jnp.asarray(prob.from_unit(prob.start_unit()))

    def stacked(x):
        t = prob.term_values(x)
        return jnp.stack([t[k] for k in TERMS])

    vals = np.asarray(stacked(x))
    exact = np.asarray(jnp.stack(list(prob.with_objective(pathwise_of(obj)).term_values(x).values())))
    np.testing.assert_allclose(vals, exact, rtol=1e-12)
    jac = np.asarray(jax.jacrev(stacked)(x))
    g = np.asarray(jax.grad(prob.objective_value)(x))
    assert np.all(np.isfinite(jac)) and np.all(np.isfinite(g))
    w = prob.weight_of()
    expect = np.array([w[k] for k in TERMS]) @ jac + np.asarray(jax.grad(prob.cost)(x))
    np.testing.assert_allclose(g, expect, rtol=1e-10, atol=1e-14 * np.max(np.abs(expect)))


# ---------------------------------------------------------------- the four-bar problem (optim/problems/four-bar.toml)


def _four_bar_box_designs(prob, count=200):
    """``count`` random designs of the problem's box and its corners, SI."""
    rng = np.random.default_rng(1)
    corners = np.array(np.meshgrid(*[[0.0, 1.0]] * prob.n)).reshape(prob.n, -1).T
    return np.asarray(prob.from_unit(np.concatenate([rng.uniform(size=(count, prob.n)), corners])))


def test_four_bar_geometry_holds_grashof_and_the_transmission_bound_over_the_box():
    """Every design of the preset's box, corners included: a crank-rocker (Grashof's three
    inequalities with a positive margin, the crank shortest), the closed-form transmission
    extremes equal to their variables and within [40, 140] deg; the preset's own lengths
    at the start; valid mechanisms (FourBar's own checks, through the config)."""
    from jaxcrank.physics.presets import grashof_crank_rocker
    from jaxcrank.runs import config
    from optim.presets import four_bar_problem

    prob = four_bar_problem()
    x = _four_bar_box_designs(prob)
    c = prob.constraints(x)
    assert np.all(c["grashof_margin_m"] > 0.0)
    lengths = np.stack([c[f"{k}_length_m"] for k in ("crank", "coupler", "rocker", "ground")], axis=1)
    assert all(grashof_crank_rocker(*row) for row in lengths)
    np.testing.assert_allclose(c["min_transmission_angle_deg"], np.degrees(x[:, 2]), atol=1e-9)
    np.testing.assert_allclose(c["max_transmission_angle_deg"], np.degrees(x[:, 3]), atol=1e-9)
    assert np.all(c["min_transmission_angle_deg"] >= 40.0 - 1e-9)
    assert np.all(c["max_transmission_angle_deg"] <= 140.0 + 1e-9)
    assert prob.feasible(x).all()
    start = np.asarray(prob.from_unit(prob.start_unit()))
    preset = prob.base
    mech = prob.mechanism(jnp.asarray(start))
    for field in ("crank_length", "coupler_length", "rocker_length", "ground_length", "crank_mass", "rocker_inertia"):
        assert float(getattr(mech, field)) == pytest.approx(float(getattr(preset, field)), rel=1e-12), field
    for row in x[::20]:
        mech = config.from_dict(config.to_dict(prob.mechanism(jnp.asarray(row))))  # FourBar's checks run
        assert float(mech.coupler_mass) / float(mech.coupler_length) == pytest.approx(1.2 / 0.35, rel=1e-12)
        assert float(mech.coupler_inertia) == pytest.approx(float(mech.coupler_mass) * row[0] ** 2 / 12, rel=1e-12)


def test_four_bar_transmission_extremes_are_the_ideal_mechanisms():
    """The closed form against the ideal mechanism (loop closure of physics/closure.py): the
    transmission angle over a revolution (0.5 deg steps, crank angles 0 and 180 deg among
    them) has its smallest value at crank angle 0 and its largest at 180 deg, equal to the
    problem's variables within 1e-9 deg, at the preset and at two corners of the box."""
    from jaxcrank import ideal
    from optim.presets import four_bar_problem

    prob = four_bar_problem()
    for u in (prob.start_unit(), np.zeros(prob.n), np.ones(prob.n)):
        x = np.asarray(prob.from_unit(jnp.asarray(u)))
        mech = prob.mechanism(jnp.asarray(x))
        ts = jnp.linspace(0.0, float(mech.period), 721)
        mu = np.degrees(np.asarray(jax.vmap(lambda t, m=mech: ideal.transmission_angle(m, t))(ts)))
        assert mu.min() == pytest.approx(np.degrees(x[2]), abs=1e-9) and np.argmin(mu) in (0, 720)
        assert mu.max() == pytest.approx(np.degrees(x[3]), abs=1e-9) and np.argmax(mu) == 360


@pytest.mark.parametrize(
    "change, match",
    [
        (dict(lower=(0.25, 0.20, math.radians(35.0), math.radians(100.0))), "min_transmission_angle"),
        (dict(upper=(0.45, 0.40, math.radians(80.0), math.radians(150.0))), "max_transmission_angle"),
        (dict(upper=(0.45, 0.40, math.radians(110.0), math.radians(140.0))), "upper bound of the first"),
        (dict(names=("crank_length", "rocker_length", "min_transmission_angle", "max_transmission_angle")), "crank"),
        (dict(names=("coupler_length", "rocker_length", "min_transmission_angle", "coupler_mass")), "scale_links"),
        (dict(derived=CrankRocker(min_transmission_deg=95.0)), "min_transmission_deg"),
    ],
)
def test_bad_four_bar_problems_raise(change, match):
    from optim.presets import four_bar_problem

    with pytest.raises(ParameterError, match=match):
        dataclasses.replace(four_bar_problem(), **change)


def test_four_bar_problem_needs_a_four_bar_and_round_trips_through_the_config():
    from jaxcrank import paper
    from optim.presets import four_bar_problem

    with pytest.raises(ParameterError, match="FourBar"):
        dataclasses.replace(four_bar_problem(), base=paper())
    prob, settings = cli.build({"problem": "four-bar", "design": {"min_transmission_deg": 35.0}})
    assert isinstance(prob, DesignProblem) and prob.derived.min_transmission_deg == 35.0
    again, _ = cli.build(tomllib.loads(tomli_w.dumps(cli._drop_none(cli.resolved(prob, settings, "four-bar")))))
    assert again == prob and again.base == prob.base


class _IdealTransmission(AbstractObjective):
    """A kinematic stand-in objective (no clearance solve): the RMS deviation of the ideal
    mechanism's transmission angle from 90 deg over a revolution, degrees, reported as
    ``rms_transmission_angle_error_deg``. Its minimum pulls both transmission extremes to
    90 deg, onto the faces of the four-bar box."""

    throw: bool = eqx.field(static=True, default=True)

    def rms(self, mech):
        from jaxcrank import ideal
        from optim.objective import EQ19

        ts = jnp.linspace(0.0, float(mech.period), 73)[:-1]
        mu = jax.vmap(lambda t: ideal.transmission_angle(mech, t))(ts)
        return {EQ19: jnp.sqrt(jnp.mean(jnp.degrees(mu - 0.5 * math.pi) ** 2))}

    def forward_mode(self):
        return False

    def describe(self):
        return {"kind": "ideal_transmission"}


@pytest.mark.parametrize("method", ["adam", "projected_lbfgs"])
def test_four_bar_feasibility_is_kept_at_every_iterate(method):
    """Large steps towards a minimum outside the box (the transmission angle pulled to 90 deg):
    every iterate is a crank-rocker with its transmission angle within [40, 140] deg, some
    iterate sits on a face of the box, and the objective falls."""
    from optim.optimizers import from_settings
    from optim.presets import four_bar_problem

    prob = four_bar_problem(_IdealTransmission())
    opt = adam(0.5) if method == "adam" else from_settings(method)
    res = optimize(prob, Settings(optimizer=opt, max_iterations=6, gtol=0.0, xtol=0.0), progress=False)
    xs = np.array([[h[f"{n}_SI"] for n in prob.names] for h in res["history"]])
    c = prob.constraints(xs)
    assert np.all(c["grashof_margin_m"] > 0.0) and prob.feasible(xs).all()
    assert np.min(c["min_transmission_angle_deg"]) >= 40.0 - 1e-9
    assert np.max(c["max_transmission_angle_deg"]) <= 140.0 + 1e-9
    us = np.asarray(prob.to_unit(xs))
    assert np.any((us <= 1e-12) | (us >= 1 - 1e-12))
    assert res["final_objective"] < res["history"][0]["objective_deg"]


@pytest.mark.slow  # a steady-state solve and the gradient program of the four-bar (minutes on 2 cores)
def test_four_bar_problem_takes_a_steady_state_step_from_the_cli(tmp_path):
    """``jaxcrank optimize --problem four-bar --iterations 2``: the preset's periodic orbit at
    the start, a finite exact gradient, a feasible second iterate evaluated;
    result.json's final_mechanism is a four-bar with the final design's lengths, and it has
    no paper entry."""
    import json

    from jaxcrank.runs import config
    from jaxcrank.runs.cli import main
    from optim.presets import four_bar_problem

    out = tmp_path / "run"
    assert (
        main(["optimize", "--problem", "four-bar", "--iterations", "2", "--out", str(out), "--no-cache", "--quiet"])
        == 0
    )
    result = json.loads((out / "result.json").read_text())
    assert result["iterations"] == 2 and "paper" not in result
    prob = four_bar_problem()
    history = list(csv_rows(out / "history.csv"))
    xs = np.array([[float(h[f"{n}_SI"]) for n in prob.names] for h in history])
    assert prob.feasible(xs).all() and not np.allclose(xs[0], xs[1])
    # the preset's periodic orbit (period 1) with a finite, nonzero exact gradient; every iterate
    # is periodic (the command keeps steps inside the periodic regime with the regime guard)
    for h in history:
        grad = np.array([float(h[f"grad_{n}_deg_per_SI"]) for n in prob.names])
        assert h["regime"] == "periodic" and np.isfinite(float(h["objective_deg"]))
        assert np.all(np.isfinite(grad)) and np.any(grad != 0.0)
    mech = config.from_dict(result["final_mechanism"])
    assert result["final_mechanism"]["mechanism"] == "four-bar"
    expect = prob.mechanism(jnp.asarray(result["final_design_SI"]))
    for field in ("crank_length", "coupler_length", "rocker_length", "ground_length"):
        assert float(getattr(mech, field)) == pytest.approx(float(getattr(expect, field)), rel=1e-12)


def csv_rows(path):
    import csv

    with open(path, newline="") as f:
        yield from csv.DictReader(f)


@pytest.mark.slow  # steady-state solves and the gradient program of the lubricated four-bar (minutes on 2 cores)
def test_the_four_bar_problem_optimises_a_lubricated_base_from_the_cli(tmp_path):
    """``jaxcrank optimize --problem four-bar`` on the lubricated four-bar (its config's
    ``[mechanism]``): a periodic start, two periodic iterates with a finite, nonzero exact
    gradient, and a final mechanism whose pins are still lubricated."""
    import json

    from jaxcrank.physics import catalogue
    from jaxcrank.runs import config
    from jaxcrank.runs.cli import main
    from optim.presets import four_bar_problem

    cfg = tmp_path / "lubricated.toml"
    cfg.write_text(tomli_w.dumps({"problem": "four-bar", "mechanism": config.to_dict(catalogue.four_bar_lubricated())}))
    out = tmp_path / "run"
    args = ["optimize", "--config", str(cfg), "--iterations", "2", "--out", str(out), "--no-cache", "--quiet"]
    assert main(args) == 0
    result = json.loads((out / "result.json").read_text())
    assert result["iterations"] == 2 and result["start_search"]["periodic"]
    prob = four_bar_problem()
    history = list(csv_rows(out / "history.csv"))
    for h in history:
        grad = np.array([float(h[f"grad_{n}_deg_per_SI"]) for n in prob.names])
        assert h["regime"] == "periodic" and np.isfinite(float(h["objective_deg"]))
        assert np.all(np.isfinite(grad)) and np.any(grad != 0.0)
    joints = result["final_mechanism"]["joints"]
    assert joints["B"]["law"] == joints["C"]["law"] == "lubricated" and joints["C"]["viscosity"] == 0.4
