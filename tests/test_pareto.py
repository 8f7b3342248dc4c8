"""Pareto fronts by the epsilon-constraint method (optim.pareto): the non-dominated filter, the
hypervolume, the [pareto] table's checks, one compiled program for every bound, the files and the
resume of a killed run (a stand-in solve, no steady state); one end-to-end front (slow)."""

from __future__ import annotations

import csv
import dataclasses
import json
import math
import re
import tomllib
from pathlib import Path

import numpy as np
import pytest

from jaxcrank.physics.params import ParameterError
from optim import constrained, pareto, spec

FORCE, EQ19 = "peak_contact_force_B_N", "rms_transmission_angle_error_deg"


def _data(**changes):
    data = {
        "mechanism": {"preset": "four-bar"},
        "variables": {
            "coupler_length": {"lower": 0.33, "upper": 0.40},
            "rocker_length": {"lower": 0.28, "upper": 0.35},
        },
        "objective": {"terms": [{"quantity": EQ19, "weight": 1.0}]},
        "solver": {"settle_revolutions": 10},
        "pareto": {"quantity": FORCE, "points": 3},
    }
    data.update(changes)
    return data


@pytest.fixture(scope="module")
def problem():
    return spec.from_dict(_data())[0]


def test_nondominated_keeps_the_points_no_other_beats():
    v = np.array([[1.0, 3.0], [2.0, 2.0], [3.0, 1.0], [2.5, 2.5], [1.0, 3.0], [np.nan, 0.0], [0.5, 4.0]])
    assert pareto.nondominated(v).tolist() == [True, True, True, False, False, False, True]
    assert pareto.nondominated(np.array([[1.0, 1.0, 1.0], [1.0, 2.0, 0.5], [2.0, 2.0, 2.0]])).tolist() == [
        True,
        True,
        False,
    ]


def test_hypervolume_of_known_points():
    """Three staircase points against (4, 4): 3 + 2 + 1; a dominated point, a point beyond the
    reference and a NaN add nothing; a single point is its rectangle."""
    v = [[1.0, 3.0], [2.0, 2.0], [3.0, 1.0]]
    assert pareto.hypervolume(v, [4.0, 4.0]) == pytest.approx(6.0, abs=1e-15)
    more = v + [[2.5, 2.5], [5.0, 0.0], [math.nan, 0.5]]
    assert pareto.hypervolume(more, [4.0, 4.0]) == pytest.approx(6.0, abs=1e-15)
    assert pareto.hypervolume([[1.0, 1.0]], [3.0, 2.0]) == pytest.approx(2.0)
    assert pareto.hypervolume([], [1.0, 1.0]) == 0.0
    with pytest.raises(ParameterError, match="reference"):
        pareto.hypervolume(v, [4.0, math.inf])


def test_reference_point_is_the_nadir_plus_a_tenth_of_the_range():
    ref = pareto.reference_point(np.array([[1.0, 30.0], [3.0, 10.0], [5.0, 50.0]]))
    assert ref == pytest.approx([3.0 + 0.2, 30.0 + 2.0])
    assert pareto.reference_point(np.array([[2.0, 0.0]])) == pytest.approx([2.2, 0.1])
    assert pareto.levels(0.0, 1.0, 5) == pytest.approx([0.25, 0.5, 0.75])


@pytest.mark.parametrize(
    ("table", "match"),
    [
        ({"points": 3}, "quantity is missing"),
        ({"quantity": "peak_force_N"}, "unknown quantity 'peak_force_N'; valid for this mechanism: .*" + FORCE),
        ({"quantity": EQ19}, "only term"),
        ({"quantity": FORCE, "points": 2}, r"points = 2 must be an integer in \[3, 100\]"),
        ({"quantity": FORCE, "points": 4.0}, "points = 4.0 must be an integer"),
        ({"quantity": FORCE, "weight": 0.0}, "weight = 0.0 must be a finite nonzero number"),
        ({"quantity": FORCE, "scale": -1.0}, "scale = -1.0 must be a finite number > 0"),
        ({"quantity": FORCE, "step": 1}, r"unknown keys \['step'\]; valid: \['quantity', 'points', .*'scale'\]"),
    ],
)
def test_a_bad_pareto_table_names_the_key_and_the_valid_range(problem, table, match):
    with pytest.raises(ParameterError, match=r"\[pareto\].*" + match):
        pareto.front_settings(problem, table)


def test_the_command_refuses_a_bad_pareto_table_before_it_writes_anything(tmp_path, capsys):
    import tomli_w

    from jaxcrank.runs.cli import main

    file = tmp_path / "front.toml"
    file.write_text(tomli_w.dumps(_data(pareto={"quantity": FORCE, "points": 1})))
    out = tmp_path / "run"
    assert main(["optimize", "--problem", str(file), "--out", str(out), "--quiet", "--no-cache"]) == 2
    assert "[pareto] points = 1 must be an integer in [3, 100]" in capsys.readouterr().err
    assert not out.exists()


def test_every_bound_shares_one_compiled_program_and_an_infinite_bound_is_no_bound(problem):
    """The first anchor (infinite bound) and every epsilon point have one structure (the key of
    the compiled outputs programs); the infinite bound adds nothing to the augmented Lagrangian,
    and a negative weight bounds the quantity from below."""
    front = pareto.front_settings(problem, {"quantity": FORCE})
    loose = pareto.bounded(problem, front, math.inf, 1.0)
    tight = pareto.bounded(dataclasses.replace(problem, start=(0.35, 0.3)), front, 4800.0, 250.0)
    assert constrained.structure(loose) == constrained.structure(tight)
    assert constrained.structure(pareto.second_problem(problem, front)) != constrained.structure(loose)
    assert tight.limits[-1] == (FORCE, None, 4800.0, 250.0)
    ev = constrained.QuantityEvaluator(loose)
    ev.f_ref = 1.0
    value, grad = ev.lagrangian(np.array([0.5, 0.0, 5000.0]), np.array([[1.0, 2.0], [0.0, 0.0], [3.0, 4.0]]))
    assert value == pytest.approx(0.5) and grad == pytest.approx([1.0, 2.0])
    maximise = pareto.front_settings(problem, {"quantity": FORCE, "weight": -1.0})
    assert pareto.bounded(problem, maximise, math.inf, 1.0).limits[-1] == (FORCE, -math.inf, None, 1.0)
    assert pareto.bounded(problem, maximise, 4000.0, 1.0).limits[-1] == (FORCE, 4000.0, None, 1.0)


class _Killed(Exception):
    pass


def _stand_in(monkeypatch, calls, kill_at=None):
    """A solve whose exact front is f1 = s, q2 = 1 - s (s in [0, 1], the coupler length's place
    in its bounds [0.33, 0.40] m): the first anchor at 0, the second at 1, the point of bound b
    at 1 - b; a measure that reads it."""

    class Evaluator:
        def __init__(self, problem):
            self.problem = problem

    def solve(problem, settings, rounds, out=None, resume=False, progress=True, evaluator=None):
        calls.append((problem.terms[0][0], problem.limits[-1] if problem.limits else None, problem.start, resume))
        if kill_at is not None and len(calls) == kill_at:
            raise _Killed
        if problem.terms[0][0] == FORCE:
            x0 = 1.0
        else:
            x0 = 0.0 if math.isinf(problem.limits[-1][2]) else 1.0 - problem.limits[-1][2]
        return {"final_design": [0.33 + 0.07 * x0, 0.3], "history": [], "rounds": [{}]}

    def measure(ev, problem, front, x):
        x = [(x[0] - 0.33) / 0.07]
        return {
            "objective": x[0],
            "terms": [x[0]],
            "quantity": 1.0 - x[0],
            "second": 1.0 - x[0],
            "constraints": [],
            "satisfied": [],
            "feasible": True,
        }

    monkeypatch.setattr(pareto.constrained, "solve", solve)
    monkeypatch.setattr(pareto.constrained, "QuantityEvaluator", Evaluator)
    monkeypatch.setattr(pareto, "measure", measure)


def test_a_killed_front_resumes_without_solving_its_finished_points_again(problem, tmp_path, monkeypatch):
    """Killed in its fourth point, the run keeps three in pareto.json; --resume solves the fourth
    (resumed) and the fifth only, each warm-started from the previous point's design; the levels
    are evenly spaced between the anchors, every point is on the front, and the hypervolume is
    the staircase's against the nadir + 10 %. Without --resume a second run is refused."""
    calls = []
    _stand_in(monkeypatch, calls, kill_at=4)
    tables = {"optimizer": {"max_iterations": 2, "rounds": 1}, "pareto": {"quantity": FORCE, "points": 5}}
    with pytest.raises(_Killed):
        pareto.run_front(problem, tables, tmp_path, progress=False)
    saved = json.loads((tmp_path / "pareto.json").read_text())
    assert [p["kind"] for p in saved["points"]] == ["first", "second", "epsilon"]
    assert saved["levels"] == pytest.approx([0.25, 0.5, 0.75]) and saved["scale"] == 1.0
    with pytest.raises(ParameterError, match="already holds a front"):
        pareto.run_front(problem, tables, tmp_path, progress=False)
    calls.clear()
    res = pareto.run_front(problem, tables, tmp_path, progress=False, resume=True)
    assert [c[1][2] for c in calls] == [0.5, 0.75] and all(c[3] for c in calls)
    assert calls[0][2] == pytest.approx((0.33 + 0.07 * 0.75, 0.3))  # from the previous point's design
    assert [p["objective"] for p in res["points"]] == pytest.approx([0.0, 1.0, 0.75, 0.5, 0.25])
    assert all(p["nondominated"] for p in res["points"])
    assert res["reference"] == pytest.approx([1.1, 1.1])
    staircase = 1.1 * 0.1 + sum((1.1 - f) * 0.25 for f in (0.25, 0.5, 0.75, 1.0))
    assert res["hypervolume"] == pytest.approx(staircase)
    with open(tmp_path / "pareto.csv") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 5
    assert {"coupler_length_m", "rocker_length_m", "objective_deg", f"second:{FORCE}", f"bound:{FORCE}"} <= set(rows[0])
    assert {"feasible", "nondominated", "cpu_s", "wall_s"} <= set(rows[0])
    assert (tmp_path / "pareto.png").stat().st_size > 0
    other = {**tables, "pareto": {"quantity": FORCE, "points": 4}}
    with pytest.raises(ParameterError, match="other settings"):
        pareto.run_front(problem, other, tmp_path, progress=False, resume=True)


@pytest.mark.slow
def test_a_small_front_traces_end_to_end_from_the_command_line(tmp_path):
    """``jaxcrank optimize --problem`` with a ``[pareto]`` table: three points of the four-bar's
    transmission-angle error against the peak force at B (two
    link lengths, two iterations a point): the anchors bracket the force, the epsilon point holds
    its bound (feasible), and the epsilon point compiles no program (it shares the first anchor's)."""
    import jax
    import tomli_w

    from jaxcrank.runs.cli import main
    from optim.programs import PROGRAMS

    file = tmp_path / "front.toml"
    file.write_text(tomli_w.dumps(_data(optimizer={"max_iterations": 2, "rounds": 1})))
    out = tmp_path / "run"
    with jax.numpy_dtype_promotion("standard"):  # optax's adam mixes int32 and float (tests/conftest.py)
        assert main(["optimize", "--problem", str(file), "--out", str(out), "--quiet", "--no-cache"]) == 0
    res = json.loads((out / "pareto.json").read_text())
    first, second, middle = res["points"]
    assert second["quantity"] < first["quantity"]
    assert middle["bound"] == pytest.approx(0.5 * (first["quantity"] + second["quantity"]))
    assert middle["feasible"] and middle["quantity"] <= middle["bound"] * (1 + 1e-3)
    assert middle["programs_compiled"] == 0 or middle["regime"] != first["regime"]
    structures = {k[1] for k in PROGRAMS if k[0] == "outputs"}
    assert len(structures) <= 2
    assert res["hypervolume"] > 0.0
    for name in ("pareto.json", "pareto.csv", "pareto.png", "problem.toml"):
        assert (out / name).exists()


def test_the_page_prints_the_benchmark_problem_and_its_numbers():
    """docs/pareto.md prints bench/pareto-four-bar.toml as it is, and quotes the benchmark's
    hypervolumes and CPU seconds as bench/results/pareto.json holds them."""
    root = Path(__file__).resolve().parents[1]
    page = (root / "docs" / "pareto.md").read_text()
    block = re.search(r"```toml\n(.*?)```", page, re.S).group(1)
    assert block == (root / "bench" / "pareto-four-bar.toml").read_text()
    res = json.loads((root / "bench" / "results" / "pareto.json").read_text())
    for method in ("gradient", "grid", "nsga2"):
        assert f"{res['hypervolume'][method]:.4g}" in page, method
        assert f"{res['cpu_seconds'][method]:.0f}" in page, method
    spec.from_dict(tomllib.loads(block))  # the printed file is a valid problem file


def test_anchors_that_coincide_give_a_one_design_front_and_say_so(problem, tmp_path, monkeypatch):
    """Where both anchors have the same bounded quantity, no level lies between them: the run
    stops after the anchors, one of the two equal points is on the front, and pareto.json's
    ``note`` says why fewer points than asked were solved."""
    calls = []
    _stand_in(monkeypatch, calls)

    def same(ev, problem, front, x):
        return {
            "objective": 0.5, "terms": [0.5], "quantity": 0.5, "second": 0.5,
            "constraints": [], "satisfied": [], "feasible": True,
        }  # fmt: skip

    monkeypatch.setattr(pareto, "measure", same)
    tables = {"optimizer": {"max_iterations": 2, "rounds": 1}, "pareto": {"quantity": FORCE, "points": 3}}
    res = pareto.run_front(problem, tables, tmp_path, progress=False)
    assert len(calls) == 2 and res["levels"] == [] and "the front is one design" in res["note"]
    assert [p["nondominated"] for p in res["points"]] == [True, False]
    assert json.loads((tmp_path / "pareto.json").read_text())["note"] == res["note"]
