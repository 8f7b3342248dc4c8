"""Calibration against a measured trace (optim.trace, optim.least_squares, optim.calibrate,
optim.fit, ``jaxcrank fit``).

Without the simulator: Levenberg-Marquardt and its intervals against closed forms (a linear
model is ordinary least squares), the identifiability flags, the trace file and its phases,
the signal names against the frame they read, and every bad input named in its
ParameterError. With it, on a cheap periodic design (one clearance joint, short settle): the
exact Jacobian of the residuals against central differences of steady states, a noise-free
trace recovered from a start a few % off, and the command writing its files."""

import json
import tomllib
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats

import jaxcrank as jc
from jaxcrank.physics import model
from jaxcrank.physics.params import ParameterError
from optim.calibrate import FIT_STEADY, Calibration, FitParameter, model_trace
from optim.fit import fit
from optim.least_squares import LMSettings, intervals, levenberg_marquardt
from optim.trace import Trace, model_signal, phase_times, read_trace, signal_columns, write_trace

# ----------------------------------------------------------------------------- least squares


def test_lm_on_a_linear_model_is_ordinary_least_squares_with_its_intervals():
    rng = np.random.default_rng(0)
    X = np.stack([np.ones(40), np.linspace(0.0, 1.0, 40)], axis=1)
    y = X @ np.array([2.0, -1.0]) + 0.1 * rng.standard_normal(40)
    exact = LMSettings(ftol=1e-15)
    res = levenberg_marquardt(lambda u, _: (X @ u - y, X, {}), np.zeros(2), [-10.0, -10.0], [10.0, 10.0], exact)
    ols = np.linalg.lstsq(X, y, rcond=None)[0]
    np.testing.assert_allclose(res.u, ols, rtol=1e-9)
    assert res.converged
    iv = intervals(res.jacobian, res.residuals, res.u, ["a", "b"])
    s2 = float(np.sum((X @ ols - y) ** 2)) / (40 - 2)
    se = np.sqrt(s2 * np.diag(np.linalg.inv(X.T @ X)))
    np.testing.assert_allclose(iv.standard_error, se, rtol=1e-9)
    np.testing.assert_allclose(iv.ci95[:, 1] - ols, stats.t.ppf(0.975, 38) * se, rtol=1e-9)
    assert iv.rank == 2 and all(iv.identifiable) and iv.condition_number > 1.0


def test_lm_recovers_a_nonlinear_model_and_holds_a_bound():
    t = np.linspace(0.0, 2.0, 30)
    truth = np.array([3.0, 1.5])

    def fun(u, _):
        e = np.exp(-u[1] * t)
        return u[0] * e - truth[0] * np.exp(-truth[1] * t), np.stack([e, -u[0] * t * e], axis=1), {}

    res = levenberg_marquardt(fun, truth * [1.3, 0.7], [0.0, 0.0], [10.0, 10.0], LMSettings(max_iterations=100))
    np.testing.assert_allclose(res.u, truth, rtol=1e-7)
    held = levenberg_marquardt(fun, [2.0, 1.0], [0.0, 0.0], [10.0, 1.2], LMSettings(max_iterations=100))
    assert held.u[1] == 1.2 and held.misfit > 0.0
    iv = intervals(held.jacobian, held.residuals, held.u, ["a", "k"], at_bound=[False, True])
    assert not iv.identifiable[1] and "bound" in iv.reasons[1]


def test_intervals_flag_what_the_data_do_not_determine():
    rng = np.random.default_rng(1)
    a = rng.standard_normal(20)
    r = 0.1 * rng.standard_normal(20)
    unseen = intervals(np.stack([a, np.zeros(20)], axis=1), r, [1.0, 1.0], ["a", "z"])
    assert unseen.identifiable == [True, False] and np.isfinite(unseen.standard_error[0])
    assert "does not depend" in unseen.reasons[1]
    twins = intervals(np.stack([a, 2.0 * a], axis=1), r, [1.0, 1.0], ["a", "b"])
    assert twins.rank == 1 and twins.identifiable == [False, False]
    assert "combination with b" in twins.reasons[0] and not np.isfinite(twins.condition_number)
    wide = intervals(np.stack([a, a + 1e-3 * rng.standard_normal(20)], axis=1), r, [1.0, 1.0], ["a", "b"])
    assert wide.rank == 2 and wide.identifiable == [False, False] and "interval" in wide.reasons[0]


# ----------------------------------------------------------------------------- traces and signals


def test_trace_file_round_trip_and_phases(tmp_path, paper):
    T = float(paper.period)
    by_time = Trace("slider_ax_m_s2", np.arange(4.0), time_s=np.array([0.0, 0.25, 1.25, 2.5]) * T)
    write_trace(tmp_path / "t.csv", by_time)
    back = read_trace(tmp_path / "t.csv")
    np.testing.assert_array_equal(back.values, by_time.values)
    np.testing.assert_allclose(back.time_s, by_time.time_s, rtol=1e-15)
    phase, turns = phase_times(paper, back)
    np.testing.assert_allclose(phase / T, [0.0, 0.25, 0.25, 0.5], atol=1e-12)
    assert turns.tolist() == [0, 0, 1, 2]
    by_angle = Trace("slider_ax_m_s2", np.arange(3.0), angle_deg=np.array([90.0, 450.0, 719.0]))
    phase, turns = phase_times(paper, by_angle)
    np.testing.assert_allclose(phase / T, [0.25, 0.25, 359.0 / 360.0], rtol=1e-12)
    assert turns.tolist() == [0, 1, 1]
    (tmp_path / "traj.csv").write_text("t,crank_angle,slider_ax\n0.0,0.0,1.5\n0.01,36.0,2.5\n")
    assert read_trace(tmp_path / "traj.csv", "slider_ax").signal == "slider_ax"  # a trajectory.csv's columns


def test_signal_names_read_the_frame(paper):
    names = signal_columns(paper)
    for name in ("slider_ax", "slider_ax_m_s2", "rod_omega_rad_s", "force_C_normal_N", "slider_x_deviation_m"):
        assert name in names
    assert names["slider_ax_m_s2"] == "m_s2" and names["contact_force_B_N"] == "N"
    bodies = model.compile_model(paper).tree.bodies
    rng = np.random.default_rng(2)
    f = jax.eval_shape(model.evaluate, paper, 0.0, model.initial_state(paper))
    frames = type(f)(*(jnp.asarray(rng.standard_normal((3, *v.shape))) for v in f))
    i = bodies.index("slider")
    np.testing.assert_array_equal(model_signal(paper, frames, "slider_ax_m_s2"), frames.qdd[:, i, 0])
    np.testing.assert_array_equal(model_signal(paper, frames, "slider_ax"), frames.qdd[:, i, 0])
    deviation = model_signal(paper, frames, "slider_ax_deviation_m_s2")
    np.testing.assert_array_equal(deviation, frames.qdd[:, i, 0] - frames.ideal_qdd[:, i, 0])
    np.testing.assert_allclose(model_signal(paper, frames, "rod_angle_deg"), np.degrees(frames.q[:, 1, 2]))


# ----------------------------------------------------------------------------- bad inputs


def _p(name="clearance_B", start=3e-4, lower=1e-4, upper=6e-4):
    return FitParameter(name, start, lower, upper)


@pytest.mark.parametrize(
    "make, words",
    [
        (lambda m, tr: Calibration(m, [_p()], Trace("slider_jerk_m_s3", tr.values, angle_deg=tr.angle_deg)),
         ["slider_jerk_m_s3", "slider_ax_m_s2"]),
        (lambda m, tr: Calibration(m, [_p("clearance_Z")], tr), ["clearance_Z", "joints"]),
        (lambda m, tr: Calibration(m, [_p("contact.stifness")], tr), ["contact.stifness"]),
        (lambda m, tr: Calibration(m, [_p(upper=0.02)], tr), ["clearance_B", "0.02"]),
        (lambda m, tr: Calibration(m, [_p("driver.speed", 60.0, 50.0, 70.0)], tr), ["driver.speed"]),
        (lambda m, tr: Calibration(m, [_p(), _p()], tr), ["twice"]),
        (lambda m, tr: _p(start=7e-4), ["clearance_B", "0.0007", "0.0001", "0.0006"]),
        (lambda m, tr: _p(lower=6e-4, upper=1e-4), ["clearance_B", "lower"]),
        (lambda m, tr: Calibration(m, [_p(), _p("clearance_C"), _p("contact.restitution", 0.7, 0.3, 1.0)],
                                   Trace("slider_ax_m_s2", tr.values[:3], angle_deg=tr.angle_deg[:3])),
         ["3 samples", "3 parameters", "at least 4"]),
        (lambda m, tr: Calibration(m, [_p()], tr, noise=0.0), ["noise"]),
        (lambda m, tr: Trace("slider_ax_m_s2", tr.values), ["time_s", "crank_angle_deg"]),
        (lambda m, tr: Trace("slider_ax_m_s2", [1.0, np.nan], angle_deg=[0.0, 1.0]), ["slider_ax_m_s2", "finite"]),
    ],
)  # fmt: skip
def test_bad_inputs_raise_parameter_errors_that_name_them(paper, make, words):
    trace = Trace("slider_ax_m_s2", np.ones(10), angle_deg=np.arange(10.0))
    with pytest.raises(ParameterError) as err:
        make(paper, trace)
    for word in words:
        assert word in str(err.value)


def test_bad_trace_files_raise_parameter_errors_that_name_them(tmp_path):
    cases = {
        "no_time.csv": ("angle,slider_ax_m_s2\n0,1\n1,2\n", None, ["time_s", "crank_angle_deg", "angle"]),
        "word.csv": ("time_s,slider_ax_m_s2\n0,1\n0.1,abc\n", None, ["line 3", "slider_ax_m_s2", "abc"]),
        "which.csv": ("time_s,a_m,b_m\n0,1,2\n0.1,2,3\n", None, ["a_m", "b_m", "signal"]),
        "absent.csv": ("time_s,a_m\n0,1\n0.1,2\n", "slider_ax_m_s2", ["slider_ax_m_s2", "a_m"]),
        "short.csv": ("time_s,a_m\n0,1\n", None, ["1 samples", "at least 2"]),
    }
    for name, (text, signal, words) in cases.items():
        (tmp_path / name).write_text(text)
        with pytest.raises(ParameterError) as err:
            read_trace(tmp_path / name, signal)
        for word in words + [name]:
            assert word in str(err.value), (name, word, str(err.value))


def test_fit_command_refuses_a_bad_config_naming_the_key(tmp_path, capsys):
    from jaxcrank.runs.cli import main

    (tmp_path / "trace.csv").write_text("crank_angle_deg,slider_ax_m_s2\n0,1\n1,2\n2,3\n")
    head = "[parameters.clearance_B]\nstart = 3e-4\nlower = 1e-4\nupper = 6e-4\n"
    bad = {
        "unknown section": (head + "[fitting]\n", "fitting"),
        "no bounds": ("[parameters.clearance_B]\nstart = 3e-4\n", "lower"),
        "fit key": (head + "[fit]\nmax_iter = 3\n", "max_iter"),
        "steady key": (head + "[steady]\nsettle = 3\n", "settle"),
        "start outside": ("[parameters.clearance_B]\nstart = 9e-4\nlower = 1e-4\nupper = 6e-4\n", "clearance_B"),
    }
    for label, (text, word) in bad.items():
        (tmp_path / "fit.toml").write_text(text)
        argv = ["fit", "--config", str(tmp_path / "fit.toml"), "--data", str(tmp_path / "trace.csv")]
        assert main(argv + ["--out", str(tmp_path / "out"), "--quiet"]) == 2, label
        assert word in capsys.readouterr().err, label


def test_fit_config_takes_a_linkage_file_beside_it_as_a_problem_file_does(tmp_path):
    """``[mechanism] file = "linkage.toml"`` (relative to the config) and ``preset = NAME``, with
    the table's other keys as changes, as in a design problem file."""
    from jaxcrank.runs import config
    from optim.fit_cli import build

    docs = Path(__file__).resolve().parents[1] / "docs" / "linkages"
    (tmp_path / "rocker.toml").write_text((docs / "crank-rocker.toml").read_text())
    params = "[parameters.gravity]\nstart = 9.8\nlower = 9\nupper = 10\n"
    cfg = tomllib.loads('[mechanism]\nfile = "rocker.toml"\ngravity = 1.5\n' + params)
    mech = build(cfg, tmp_path)["mechanism"]
    expected = config.apply_overrides(config.load(docs / "crank-rocker.toml"), ["gravity=1.5"])
    assert config.to_dict(mech) == config.to_dict(expected)
    cfg = tomllib.loads('[mechanism]\npreset = "paper"\nclearance_B = 2e-4\n' + params)
    assert jc.get_parameter(build(cfg)["mechanism"], "clearance_B") == pytest.approx(2e-4, rel=1e-12)
    with pytest.raises(ParameterError, match="nowhere.toml"):
        build(tomllib.loads('[mechanism]\nfile = "nowhere.toml"\n' + params), tmp_path)


def test_a_start_up_in_the_trace_is_noted():
    """Residuals whose first revolution is more than TRANSIENT_RATIO times its last in RMS (a
    trace that begins with the start-up of a run from rest) get a note; noise alike in every
    revolution, a one-revolution trace and non-finite residuals get none."""
    from optim.fit import TRANSIENT_RATIO, _transient

    rng = np.random.default_rng(0)
    turns = np.repeat(np.arange(3), 90)
    steady = np.tile(rng.standard_normal(90), 3)  # the same residuals in every revolution
    assert _transient(turns, steady) == []
    start_up = steady * np.where(turns == 0, 1.1 * TRANSIENT_RATIO, 1.0)
    (note,) = _transient(turns, start_up)
    assert "start-up" in note and "revolution 3" in note
    assert _transient(np.zeros(90, int), steady[:90]) == []
    assert _transient(turns, np.where(turns == 0, np.nan, steady)) == []


# ----------------------------------------------------------------------------- with the simulator

#: a cheap periodic case: the paper's mechanism with clearance at B only (its pin settles onto a
#: period-1 orbit within a few revolutions; leading multiplier 7e-3), a short settle, tight solves
CHEAP = FIT_STEADY.replace(settle_revolutions=8, rtol=1e-10, atol=1e-10, newton_tol=1e-8)
NAMES = ("clearance_B", "contact.restitution")
TRUE = np.array([2e-4, 0.6])
SIGNAL = "slider_ax_m_s2"
BOUNDS = {"clearance_B": (1e-4, 4e-4), "contact.restitution": (0.3, 0.95)}


def _one_clearance():
    return eqx.tree_at(lambda m: m.joints["C"], jc.paper(), jc.Ideal())


def _params(start):
    return [FitParameter(n, float(s), *BOUNDS[n]) for n, s in zip(NAMES, start)]


@pytest.fixture(scope="module")
def cheap():
    base = _one_clearance()
    trace, ev = model_trace(base, NAMES, TRUE, SIGNAL, angle_deg=np.arange(0.0, 360.0, 10.0), options=CHEAP)
    assert ev.regime == "periodic" and ev.period_revolutions == 1 and ev.source == "steady orbit"
    return base, trace


def test_exact_jacobian_of_the_residuals_equals_central_differences(cheap):
    """d residuals / d parameters through the orbit (forward mode and the implicit function
    theorem) against central differences of steady states solved anew at x +- h (relative step
    1e-4, warm-started): equal to 1e-4 of each column's largest entry."""
    base, trace = cheap
    x = TRUE * np.array([1.03, 0.97])
    cal = Calibration(base, _params(x), trace, options=CHEAP)
    ev = cal.evaluate(x)
    assert ev.regime == "periodic" and ev.jacobian.shape == (trace.n, 2)
    for i in range(2):
        h = 1e-4 * x[i]
        up, down = x.copy(), x.copy()
        up[i] += h
        down[i] -= h
        fd = (cal.evaluate(up, jacobian=False).residuals - cal.evaluate(down, jacobian=False).residuals) / (2 * h)
        scale = np.max(np.abs(ev.jacobian[:, i]))
        assert scale > 0 and np.max(np.abs(fd - ev.jacobian[:, i])) <= 1e-4 * scale, NAMES[i]


@pytest.mark.slow  # 40 s; the command's test recovers the trace from another start by default
def test_a_noise_free_trace_is_recovered_from_a_start_a_few_percent_off(cheap):
    """From 2 % above the clearance and 4 % below the restitution: inside the basin of the true
    design (the misfit of an acceleration trace grows like |clearance error| beyond about 2 %:
    its impact spikes stop overlapping; docs/calibration.md)."""
    base, trace = cheap
    result = fit(base, _params(TRUE * np.array([1.02, 0.96])), trace, options=CHEAP)
    np.testing.assert_allclose(result.fitted, TRUE, rtol=1e-6)
    assert result.converged and result.final.regime == "periodic" and result.final.misfit < 1e-10
    summary = result.summary()
    assert all(p["identifiable"] for p in summary["parameters"].values())
    assert summary["condition_number"] > 1.0 and summary["misfit_final"] < summary["misfit_start"]


def test_a_fit_that_did_not_converge_claims_no_parameter_identified(cheap):
    """Stopped by its iteration limit, a fit's intervals are the last iterate's, not a minimum's:
    every parameter is flagged not identifiable with that reason, and the notes say so."""
    base, trace = cheap
    result = fit(
        base, _params(TRUE * np.array([1.02, 0.96])), trace, options=CHEAP, settings=LMSettings(max_iterations=1)
    )
    assert not result.converged and result.final.regime == "periodic"
    for p in result.summary()["parameters"].values():
        assert p["identifiable"] is False and "did not converge" in p["why_not"]
    assert any(note.startswith("not converged") for note in result.notes)


def test_fit_command_recovers_a_noise_free_trace_and_writes_fit_json_csv_and_figure(cheap, tmp_path):
    """``jaxcrank fit`` from 2 % below the clearance and 4 % above the restitution recovers
    the design the noise-free trace came from, to 1e-6."""
    from jaxcrank.runs.cli import main

    _, trace = cheap
    write_trace(tmp_path / "trace.csv", trace)
    start = TRUE * np.array([0.98, 1.04])
    (tmp_path / "fit.toml").write_text(
        '[mechanism]\nmechanism = "paper"\n[mechanism.joints.C]\nlaw = "ideal"\n'
        + "".join(f"[parameters.{n}]\nstart = {float(s)!r}\nlower = {BOUNDS[n][0]!r}\nupper = {BOUNDS[n][1]!r}\n"
                  for n, s in zip(NAMES, start))
        + f'[data]\nsignal = "{SIGNAL}"\n[fit]\nmax_iterations = 20\n'
        + "[steady]\nsettle_revolutions = 8\nrtol = 1e-10\natol = 1e-10\nnewton_tol = 1e-8\n"
    )  # fmt: skip
    out = tmp_path / "out"
    argv = ["fit", "--config", str(tmp_path / "fit.toml"), "--data", str(tmp_path / "trace.csv")]
    assert main(argv + ["--out", str(out), "--quiet"]) == 0
    for name in ("fit.json", "fit.csv", "fit.png"):
        assert (out / name).exists(), name
    result = json.loads((out / "fit.json").read_text())
    assert set(result["parameters"]) == set(NAMES) and result["regime"] == "periodic" and result["converged"]
    for (name, p), true in zip(result["parameters"].items(), TRUE):
        assert {"start", "fitted", "standard_error", "ci95", "identifiable"} <= set(p), name
        assert p["fitted"] == pytest.approx(true, rel=1e-6) and p["identifiable"], name
    assert result["misfit_final"] < 1e-10 < result["misfit_start"] and result["cpu_seconds"] > 0
    assert result["condition_number"] > 1.0 and len(result["singular_values"]) == 2
    assert len((out / "fit.csv").read_text().splitlines()) == 2 + result["iterations"]
    assert not any("start-up" in note for note in result["notes"])


def test_a_killed_fit_resumes_from_its_last_accepted_iterate(tmp_path):
    """``checkpoint.json`` moves the starts to the last accepted iterate (clipped to the bounds);
    without ``--resume`` a folder that holds one is refused, and one of other parameters too."""
    from optim.fit_cli import resume_parameters

    params = [FitParameter("clearance_B", 3e-4, 1e-4, 6e-4), FitParameter("contact.restitution", 0.7, 0.3, 1.0)]
    checkpoint = tmp_path / "checkpoint.json"
    assert resume_parameters(params, checkpoint, resume=True) == (params, None)
    checkpoint.write_text(
        json.dumps({"iteration": 4, "accepted": True, "misfit": 12.5,
                    "design": {"clearance_B": 3.3e-4, "contact.restitution": 1.2}})
    )  # fmt: skip
    with pytest.raises(ParameterError, match="already holds a fit"):
        resume_parameters(params, checkpoint, resume=False)
    moved, resumed = resume_parameters(params, checkpoint, resume=True)
    assert [p.start for p in moved] == [3.3e-4, 1.0] and [p.lower for p in moved] == [1e-4, 0.3]
    assert resumed["iteration"] == 4 and resumed["misfit"] == 12.5
    with pytest.raises(ParameterError, match="fits"):
        resume_parameters(params[:1], checkpoint, resume=True)
