"""Design for life: a problem file's ``[life]`` table, and the evaluator that reads the
quantities after N cycles (its plumbing, on stand-in life runs: the runs' own gradients are
checked in tests/test_life.py and bench/life_gradients.py, the evaluator's against central
differences in bench/life_design.py)."""

from __future__ import annotations

import dataclasses
import json
import math
import types
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest

import jaxcrank as jc
from jaxcrank.analysis import life as lf
from jaxcrank.physics.wear import Worn
from optim import life_design, spec
from optim.steady import SteadyEvaluator

ROOT = Path(__file__).resolve().parents[1]
FILE = ROOT / "docs" / "problems" / "four-bar-life.toml"
METRIC = "rms_rocker_angle_deviation_deg"


def _data(**changes):
    data = {
        "mechanism": {"preset": "four-bar", "joints": {"B": {"wear": {"hole_coefficient": 1e-3}}}},
        "life": {"cycles": 150, "rtol": 0.2, "wear": ["B"]},
        "variables": {
            "joints.B.wear.hole_hardness": {"lower": 0.5e9, "upper": 2e9},
            "coupler_mass": {"lower": 0.8, "upper": 1.6},
        },
        "objective": {"terms": [{"quantity": METRIC, "weight": 1.0}]},
    }
    data.update(changes)
    return data


def test_the_life_table_makes_the_joints_worn_before_the_mechanism_table_sets_their_wear():
    problem, tables = spec.from_dict(_data())
    life = tables["life"]
    assert (life.cycles, life.rtol, life.wear, life.average_revolutions) == (150.0, 0.2, ("B",), 10)
    assert life.start_from_new is True
    mech = problem.mechanism(jnp.asarray(problem.default_start()))
    assert isinstance(mech.joints["B"], Worn) and not isinstance(mech.joints["C"], Worn)
    assert float(mech.joints["B"].wear.hole_coefficient) == 1e-3
    assert problem.default_start() == pytest.approx([0.64e9, float(jc.four_bar().coupler_mass)])
    plain = {k: v for k, v in _data().items() if k != "life"}
    plain.update(mechanism={"preset": "four-bar"}, variables={"coupler_mass": {"lower": 0.8, "upper": 1.6}})
    assert spec.from_dict(plain)[1]["life"] is None


def test_the_docs_life_problem_file_parses():
    problem, tables = spec.load(FILE)
    assert tables["life"] is not None and tables["life"].cycles > 0
    assert METRIC in problem.quantities


@pytest.mark.parametrize(
    ("life", "match"),
    [
        ({"rtol": 0.1}, "cycles is missing"),
        ({"cycles": -5}, "cycles = -5.0 must be a finite number > 0"),
        ({"cycles": 100, "rtol": 0.0}, "rtol = 0.0 must be"),
        ({"cycles": 100, "average_revolutions": 1}, "average_revolutions = 1 must be an integer >= 2"),
        ({"cycles": 100, "wear": ["Z"]}, "\\[life\\] wear: unknown joint 'Z'"),
        ({"cycles": 100, "wear": ["A"]}, "joint 'A'"),
        ({"cycles": 100, "wear": []}, "no worn joint"),
        ({"cycles": 100, "cycle": 3}, "unknown keys \\['cycle'\\]"),
        ({"cycles": 100, "start_from_new": "yes"}, "start_from_new = 'yes' must be true or false"),
    ],
)
def test_a_bad_life_table_names_what_is_wrong(life, match):
    data = _data(life=life)
    if life.get("wear") is not None and "cycle" not in life:
        data["mechanism"] = {"preset": "four-bar"}
        data["variables"] = {"coupler_mass": {"lower": 0.8, "upper": 1.6}}
    with pytest.raises(jc.ParameterError, match=match):
        spec.from_dict(data)


def test_a_life_problem_takes_no_pareto_front():
    with pytest.raises(jc.ParameterError, match="no \\[pareto\\]"):
        spec.from_dict(_data(pareto={"quantity": "peak_contact_force_B_N", "points": 3}))


# --------------------------------------------------------------------------- the evaluator on stand-ins


def _steady(metric, periodic=True):
    return types.SimpleNamespace(
        periodic=periodic, ok=True, regime="periodic" if periodic else "not periodic", period_revolutions=1,
        metrics={METRIC: metric}, statistics=None if periodic else {METRIC: {"value": metric}},
        multiplier_moduli=np.array([0.5]), lyapunov_exponent_per_s=-1.0, revolutions={}, note="",
    )  # fmt: skip


@pytest.fixture
def stand_in(monkeypatch):
    """Life runs whose metric after N cycles is hardness [GPa] x coupler mass [kg] (the new
    mechanism's is zero); a coupler heavier than 1.5 kg fails, one of exactly 1.4 kg is not
    periodic at its last point. Records each run's schedule argument."""
    calls = []

    def new_steady(self, x):
        return _steady(0.0)

    def fake_life(mech, cycles, options, schedule=None, warm_start=None):
        mass, hardness = float(mech.coupler_mass), float(mech.joints["B"].wear.hole_hardness)
        calls.append(schedule)
        if mass > 1.5:
            raise lf.LifeError("the step in cycles fell below one cycle: lower the wear coefficients")
        steps = list(schedule) if schedule is not None else [50.0, 100.0]
        first = lf.WearPoint({}, {}, {METRIC: 0.0}, "periodic", {}, _steady(0.0))
        last = lf.WearPoint({}, {}, {METRIC: hardness * 1e-9 * mass}, "periodic", {}, _steady(hardness * 1e-9 * mass))
        if mass == 1.4:
            last = lf.WearPoint({}, {}, {}, "not periodic", {}, _steady(hardness * 1e-9 * mass, periodic=False))
        return lf.Life(mech, [0.0, cycles], [{}, {}], [first, last], [first], steps, 0, options)

    def fake_replay(build, x, run):
        mech = build(x)
        value = mech.joints["B"].wear.hole_hardness * 1e-9 * mech.coupler_mass
        return types.SimpleNamespace(metrics={METRIC: jnp.stack([jnp.zeros(()), value])})

    monkeypatch.setattr(SteadyEvaluator, "steady_at", new_steady)
    monkeypatch.setattr(life_design, "life", fake_life)
    monkeypatch.setattr(life_design, "replay", fake_replay)
    return calls


def test_the_evaluator_reads_the_last_point_and_its_exact_gradient(stand_in, tmp_path):
    problem, tables = spec.from_dict(_data())
    ev = life_design.LifeEvaluator(problem, tables["life"], folder=tmp_path)
    x = np.array([1e9, 1.2])
    out, jac, info = ev.outputs_and_jacobian(x)
    assert out[0] == pytest.approx(1.2) and info["regime"] == "periodic"
    np.testing.assert_allclose(jac[0], [1.2e-9, 1.0], rtol=1e-12)
    assert ev.outputs_at(x)[0] == pytest.approx(1.2) and ev.regime_at(x) == "periodic"


def test_every_design_takes_the_first_designs_steps_and_a_resumed_run_keeps_them(stand_in, tmp_path):
    problem, tables = spec.from_dict(_data())
    ev = life_design.LifeEvaluator(problem, tables["life"], folder=tmp_path)
    ev.outputs_at(np.array([1e9, 1.2]))
    ev.outputs_at(np.array([1.1e9, 1.2]))
    assert stand_in == [None, [50.0, 100.0]]
    kept = json.loads((tmp_path / life_design.SCHEDULE_FILE).read_text())
    assert kept["steps_cycles"] == [50.0, 100.0] and kept["cycles"] == 150.0
    again = life_design.LifeEvaluator(problem, tables["life"], folder=tmp_path)
    again.outputs_at(np.array([0.9e9, 1.0]))
    assert stand_in[-1] == [50.0, 100.0]


def test_a_failed_run_is_nan_and_a_run_that_is_not_periodic_has_no_metric_gradient(stand_in):
    problem, tables = spec.from_dict(_data())
    ev = life_design.LifeEvaluator(problem, tables["life"])
    value, info = ev.value(np.array([1e9, 1.55]))
    assert math.isnan(value) and info["regime"] == "failed" and "lower the wear" in info["note"]
    assert ev.regime_at(np.array([1e9, 1.55])) == "failed"
    out, jac, info = ev.outputs_and_jacobian(np.array([1e9, 1.4]))
    assert info["regime"] == "not periodic" and out[0] == pytest.approx(1.4)
    np.testing.assert_array_equal(jac[0], [0.0, 0.0])


# --------------------------------------------------------------------------- the real thing, slow


@pytest.mark.slow
def test_the_docs_life_problem_runs_from_the_command_line(tmp_path):
    """``jaxcrank optimize --problem docs/problems/four-bar-life.toml`` with one iteration per
    run: a design for a new clearance, then for life from it (the quantities after the cycles of
    wear), the steps in cycles kept in the run folder and in result.json."""
    import subprocess
    import sys

    out = tmp_path / "four-bar-life"
    run = subprocess.run(
        [sys.executable, "-m", "jaxcrank.runs.cli", "optimize", "--problem", str(FILE.relative_to(ROOT)),
         "--out", str(out), "--quiet", "--no-cache", "--iterations", "1"],
        cwd=ROOT, capture_output=True, text=True, timeout=1800,
    )  # fmt: skip
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-3000:]
    res = json.loads((out / "result.json").read_text())
    kept = json.loads((out / life_design.SCHEDULE_FILE).read_text())
    assert res["life"]["cycles"] == 150 and res["life"]["steps_cycles"] == kept["steps_cycles"]
    assert res["life"]["new_clearance_design_SI"] == res["start_design_SI"]  # designed for new, then for life
    assert (out / "new_clearance" / "rounds.json").exists()
    assert sum(kept["steps_cycles"]) == pytest.approx(150.0)
    force = res["objectives"][0]
    assert force["quantity"] == "rms_contact_force_B_N" and math.isfinite(force["value"]) and force["start"] > 0
    assert res["iterations"] >= 1


def test_design_for_life_starts_from_the_new_clearance_design_unless_told_not_to(monkeypatch, tmp_path):
    """``solve_for_life``: a run for a new clearance (the plain evaluator, into new_clearance/),
    then the life run from its final design with the life evaluator; with start_from_new =
    false, the life run alone from the problem's start."""
    from optim import constrained

    calls = []

    def fake_solve(problem, settings, rounds, out=None, resume=False, progress=True, evaluator=None):
        calls.append((problem.start, out, type(evaluator).__name__))
        return {"final_design": [1.1e9, 1.0]}

    monkeypatch.setattr(constrained, "solve", fake_solve)
    problem, tables = spec.from_dict(_data())
    res = life_design.solve_for_life(problem, tables["life"], None, None, out=tmp_path)
    assert calls == [(None, tmp_path / "new_clearance", "NoneType"), ((1.1e9, 1.0), tmp_path, "LifeEvaluator")]
    assert res["new_clearance"] == {"final_design": [1.1e9, 1.0]}
    calls.clear()
    alone = dataclasses.replace(tables["life"], start_from_new=False)
    res = life_design.solve_for_life(problem, alone, None, None)
    assert calls == [(None, None, "LifeEvaluator")] and res["new_clearance"] is None
