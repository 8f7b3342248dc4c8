"""Life by cycle averaging: the error-controlled steps in cycles against an exact slow
map (a stand-in wear rate linear in the profile), replayed schedules, the life to a
limit; and (slow) the command line, its checkpoint and resume."""

from __future__ import annotations

import csv
import json
import math
import subprocess
import sys

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcrank as jc
from jaxcrank.analysis import life as lf
from jaxcrank.numerics import wear_run as nw
from jaxcrank.physics.params import ParameterError
from jaxcrank.physics.wear import profile_on_grid
from jaxcrank.runs import config
from jaxcrank.runs.life_cli import life_columns

#: the stand-in slow map dP/dN = A + B P, per coefficient (m per cycle, 1 per cycle)
A, B = 2e-9, -2e-6


class _Steady:
    periodic = True
    regime = "periodic"


def _stand_in(mech, options=lf.LIFE_OPTIONS, warm_start=None):
    """A WearPoint whose rate is A + B P on every coefficient of both profiles."""
    rate, vol = {}, {}
    for j, (hole, pin) in nw.profiles_of(mech).items():
        rate[j] = (A + B * hole, 0.1 * (A + B * pin))
        vol[j] = (float(rate[j][0][0]), float(rate[j][1][0]))
    metrics = {"deepest_hole_B_m": float(jnp.max(jnp.abs(nw.profiles_of(mech)["B"][0])))}
    ci = {"B": (0.9 * vol["B"][0], 1.1 * vol["B"][0])}  # as if B's rate were averaged; C's is exact
    return lf.WearPoint(rate, vol, metrics, "periodic", ci, _Steady())


def _exact(n):
    return (A / B) * (math.exp(B * n) - 1.0)


@pytest.fixture
def stand_in(monkeypatch):
    monkeypatch.setattr(lf, "wear_per_cycle", _stand_in)
    return jc.preset("paper-wear")


def test_steps_in_cycles_converge_to_the_exact_slow_map(stand_in):
    """Every coefficient follows dP/dN = A + B P, solved exactly: after 1e6 cycles the
    largest error is within rtol of the deepest wear and shrinks with rtol (measured 5.9e-3,
    1.6e-3, 3.2e-4 of it at rtol 0.05, 0.01, 0.002, in 14, 23 and 46 steps: the error
    follows rtol), and on this smooth slow map every step is longer than the last."""
    errors = []
    for rtol in (0.05, 0.01, 0.002):
        run = lf.life(stand_in, 1e6, lf.LifeOptions(rtol=rtol))
        assert run.cycles[-1] == pytest.approx(1e6, rel=1e-12)
        hole = np.asarray(run.profiles[-1]["B"][0])
        errors.append(np.max(np.abs(hole - _exact(1e6))) / abs(_exact(1e6)))
        assert errors[-1] < rtol
    assert errors[0] > errors[1] > errors[2]
    assert np.all(np.diff(run.schedule[:-1]) > 0.0)  # a smooth slow map: every step longer than the last


def test_a_schedule_replays_the_run_and_the_life_is_interpolated(stand_in):
    run = lf.life(stand_in, 2e5, lf.LifeOptions(rtol=0.02))
    again = lf.life(stand_in, 2e5, lf.LifeOptions(rtol=0.5), schedule=run.schedule)
    np.testing.assert_array_equal(np.asarray(again.profiles[-1]["B"][0]), np.asarray(run.profiles[-1]["B"][0]))
    values = [p.metrics["deepest_hole_B_m"] for p in run.points]
    limit = 0.5 * values[-1]
    n = float(lf.cycles_to_limit(run.cycles, values, limit))
    i = lf.crossing_index(values, limit)
    assert run.cycles[i - 1] < n <= run.cycles[i]
    assert abs(_exact(n) - limit) / limit < 0.02  # linear between points of a smooth curve
    assert math.isinf(float(lf.cycles_to_limit(run.cycles, values, 10.0)))


def test_rows_have_units_and_every_point_is_reported(stand_in):
    seen = []
    run = lf.life(stand_in, 1e5, on_point=lambda r: seen.append(len(r.cycles)))
    assert seen == list(range(1, len(run.cycles) + 1))
    row = run.rows()[-1]
    for j in ("B", "C"):
        for key in ("hole_max_depth_m", "pin_max_depth_m", "hole_volume_m3", "pin_volume_m3", "clearance_m"):
            assert f"{j}_{key}" in row
        law = stand_in.joints[j]
        assert row[f"{j}_clearance_m"] == pytest.approx(
            float(law.clearance) + row[f"{j}_hole_max_depth_m"] + row[f"{j}_pin_max_depth_m"]
        )
        volume = 2 * math.pi * float(law.hole_radius) * float(law.wear.length) * _exact(1e5)
        assert row[f"{j}_hole_volume_m3"] == pytest.approx(volume, rel=0.01)
    rate = row["B_hole_wear_m3_per_cycle"]
    band = (row["B_hole_wear_m3_per_cycle_ci95_low"], row["B_hole_wear_m3_per_cycle_ci95_high"])
    assert band == (0.9 * rate, 1.1 * rate)
    rate = row["C_hole_wear_m3_per_cycle"]
    assert row["C_hole_wear_m3_per_cycle_ci95_low"] == row["C_hole_wear_m3_per_cycle_ci95_high"] == rate


def test_bad_life_arguments_name_the_parameter(stand_in):
    with pytest.raises(ParameterError, match="cycles"):
        lf.life(stand_in, 0.0)
    with pytest.raises(ParameterError, match="rtol"):
        lf.LifeOptions(rtol=0.0)
    with pytest.raises(ParameterError, match="average_revolutions"):
        lf.LifeOptions(average_revolutions=1)


def _nonlinear(mech, hole, pin, j):
    """A stand-in wear rate that depends on the design (each hole's wear coefficient) and
    nonlinearly on the profiles: kappa A + B P + G P^2 per coefficient (m per cycle)."""
    kappa = mech.joints[j].wear.hole_coefficient / 1e-6
    return kappa * A + B * hole - hole**2, 0.1 * (kappa * A + B * pin)


def _nonlinear_at(mech, steady):
    """``life_gradient._at``'s stand-in: the rates above and a metric of the profiles (traceable)."""
    profiles = nw.profiles_of(mech)
    rate = {j: _nonlinear(mech, h, p, j) for j, (h, p) in profiles.items()}
    metric = 1e12 * sum(jnp.sum(h**2) + jnp.sum(p**2) for h, p in profiles.values())
    return rate, {"wear_metric_um2": metric}


def _nonlinear_point(mech, options=lf.LIFE_OPTIONS, warm_start=None):
    rate, metrics = _nonlinear_at(mech, None)
    vol = {j: (float(r[0][0]), float(r[1][0])) for j, r in rate.items()}
    return lf.WearPoint(rate, vol, {k: float(v) for k, v in metrics.items()}, "periodic", {}, _Steady())


def test_the_life_gradient_chains_the_steps_as_central_differences_of_whole_runs(monkeypatch):
    """Through Heun's steps at a run's schedule, the forward-mode gradient of a metric after
    N cycles and of the cycles to its limit, with respect to both holes' wear coefficients,
    equals central differences of whole life runs at that schedule (a stand-in for each
    point's orbit, nonlinear in the profiles and the design; the orbits' own derivatives are
    checked in tests/test_wear.py and bench/life_gradients.py)."""
    from jaxcrank.analysis import life_gradient as lg

    monkeypatch.setattr(lf, "wear_per_cycle", _nonlinear_point)
    monkeypatch.setattr(lg, "_at", _nonlinear_at)
    base = jc.preset("paper-wear")
    k0 = jnp.asarray([1e-6, 1e-6])

    def build(u):
        mech = base
        for i, j in enumerate(("B", "C")):
            mech = eqx.tree_at(lambda m, j=j: m.joints[j].wear.hole_coefficient, mech, k0[i] * (1.0 + u[i]))
        return mech

    u0 = jnp.asarray([0.1, -0.2])
    run = lf.life(build(u0), 3e5, lf.LifeOptions(rtol=0.05))
    assert len(run.schedule) >= 3
    values = [p.metrics["wear_metric_um2"] for p in run.points]
    limit, index = 0.5 * values[-1], lf.crossing_index(values, 0.5 * values[-1])

    def both(tr):
        m = tr.metrics["wear_metric_um2"]
        return jnp.stack([m[-1], lf.cycles_to_limit(tr.cycles, m, limit, index=index)])

    value, jac = lg.life_value_and_grad(both, build, u0, run)
    assert float(value[0]) == pytest.approx(values[-1], rel=1e-12)
    h = 1e-5
    for k in range(2):
        pair = []
        for sign in (1.0, -1.0):
            r = lf.life(build(u0.at[k].add(sign * h)), 3e5, schedule=run.schedule)
            v = [p.metrics["wear_metric_um2"] for p in r.points]
            pair.append(np.array([v[-1], float(lf.cycles_to_limit(r.cycles, v, limit, index=index))]))
        fd = (pair[0] - pair[1]) / (2 * h)
        np.testing.assert_allclose(np.asarray(jac)[:, k], fd, rtol=1e-6)


# --------------------------------------------------------------------------- the real thing, slow

FOUR_BAR = [
    "--mechanism", "four-bar", "--rpm", "300", "--wear", "B", "--set", "joints.B.wear.hole_coefficient=1e-3",
    "--samples-per-revolution", "360", "--rtol", "0.2", "--metric", "rms_rocker_angle_deviation_deg",
]  # fmt: skip


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "jaxcrank.runs.cli", "life", *args], capture_output=True, text=True)


@pytest.mark.slow
def test_cli_writes_the_life_and_resumes_a_run(tmp_path):
    """``jaxcrank life`` on the four-bar with a fast-wearing pin B: life.csv with a row per
    point (cycles, wear, clearance and metrics with units), profiles.csv, summary.json with
    the life to a limit, the figures; then --resume to more cycles keeps the done points."""
    out = tmp_path / "life"
    done = _cli(*FOUR_BAR, "--limit", "0.1781", "--cycles", "150", "--out", str(out))
    assert done.returncode == 0, done.stderr[-2000:]
    rows = list(csv.DictReader((out / "life.csv").open()))
    assert float(rows[0]["cycles"]) == 0.0 and float(rows[-1]["cycles"]) == pytest.approx(150.0)
    assert float(rows[-1]["B_hole_max_depth_m"]) > 0.0 and "rms_rocker_angle_deviation_deg" in rows[0]
    assert set(rows[0]) - {"regime"} == set(life_columns(config.load(out / "config.toml")))  # --metric's choices
    profiles = list(csv.DictReader((out / "profiles.csv").open()))
    assert len(profiles) == len(rows) * 2 * 360 and {"cycles", "joint", "surface", "angle_deg", "depth_m"} <= set(
        profiles[0]
    )
    summary = json.loads((out / "summary.json").read_text())
    assert summary["life"]["reached"] and 0.0 < summary["life"]["cycles_to_limit"] <= 150.0
    assert {p.name for p in (out / "figures").iterdir()} == {"profiles.png", "metrics.png", "contact_arcs.png"}
    worn = config.load(out / "worn.toml")  # the mechanism as the run left it: its holes as deep as the last row
    angles = jnp.linspace(0.0, 2.0 * math.pi, 720, endpoint=False)
    deepest = float(jnp.max(jnp.abs(profile_on_grid(nw.profiles_of(worn)["B"][0], angles))))
    assert deepest == pytest.approx(float(rows[-1]["B_hole_max_depth_m"]), rel=1e-12)
    more = _cli(*FOUR_BAR, "--limit", "0.1781", "--cycles", "250", "--out", str(out), "--resume")
    assert more.returncode == 0, more.stderr[-2000:]
    again = list(csv.DictReader((out / "life.csv").open()))
    assert float(again[-1]["cycles"]) == pytest.approx(250.0) and len(again) > len(rows)
    assert again[: len(rows) - 1] == rows[:-1]


@pytest.mark.slow
def test_cli_without_a_worn_joint_says_what_to_do(tmp_path):
    done = _cli("--mechanism", "paper", "--cycles", "10", "--out", str(tmp_path / "x"))
    assert done.returncode == 2 and "--wear" in done.stderr
    # a misspelt --metric is refused before the run, not after it
    done = _cli("--mechanism", "paper", "--wear", "B", "--cycles", "1e6", "--metric", "nosuch", "--limit", "1",
                "--out", str(tmp_path / "y"))  # fmt: skip
    assert done.returncode == 2 and "'nosuch' is not a column of life.csv" in done.stderr
    assert not (tmp_path / "y" / "checkpoint.json").exists()
