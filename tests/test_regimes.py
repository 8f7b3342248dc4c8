"""Regime classification of batches (jaxcrank.runs.regimes) against facts it does not
compute itself: synthetic section sequences of known period, a longer kernel run, the
JAX path's settle, and steady_state's classification of the same designs; a four-bar grid on
both engines.

The designs: CMA-ES's best of the nine-variable design problem
(bench/results/steady_gradient.json, ``cma_best``) is periodic (period 1: its section
settles within a few revolutions); the design below (``CHAOTIC_SI``, the scrambled Sobol
point 9 of seed 1 of bench/steady_from_rest.py, not periodic there) keeps its last
section point O(1) from the earlier ones (scaled units) after 8, 20 and 40 revolutions
(measured, kernel: 1.8, 1.4 and 2.6; XLA after 8: 1.8)."""

import json
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest

import jaxcrank as jc
from jaxcrank.numerics import shooting
from jaxcrank.physics import model
from jaxcrank.runs import regimes

ROOT = Path(__file__).resolve().parent.parent
NAMES = ["rod_mass", "clearance_B"]

CHAOTIC_SI = [
    0.4158353626728058,
    0.9153809262523709,
    0.0004894240312278271,
    0.0003019675347954035,
    2.1942555252462626,
    0.11227750438265502,
    1.4723818730562925,
    0.0386046856828034,
    192407793626.18924,
]

kernel_only = pytest.mark.skipif(not regimes.resolve_engine(None) == "kernel", reason="no C compiler")


def _design(x):
    from optim.presets import design_problem

    return design_problem().mechanism(jnp.asarray(x))


@pytest.fixture(scope="module")
def periodic():
    d = json.loads((ROOT / "bench" / "results" / "steady_gradient.json").read_text())["designs"]
    return _design(next(e for e in d if e["design"] == "cma_best")["design_SI"])


@pytest.fixture(scope="module")
def chaotic():
    return _design(CHAOTIC_SI)


def _x(mech, names=NAMES):
    return [float(jc.get_parameter(mech, n)) for n in names]


def test_recurrence_on_synthetic_sections():
    rng = np.random.default_rng(0)
    m, n = 4, 10
    tail = np.ones((n + 1, 2)) * np.arange(n + 1)[:, None]  # works: growing, never compared
    fixed = np.concatenate([np.tile(rng.normal(size=m), (n + 1, 1)), tail], axis=1)
    two = np.concatenate([np.array([rng.normal(size=m), rng.normal(size=m)] * 6)[: n + 1], tail], axis=1)
    none = np.concatenate([rng.normal(size=(n + 1, m)), tail], axis=1)
    k, d = shooting.recurrence(fixed, m, 4, 1e-3)
    assert k == 1 and d.shape == (4,) and np.all(d == 0.0)
    k, d = shooting.recurrence(two, m, 4, 1e-3)
    assert k == 2 and d[0] > 1e-3 and d[1] == 0.0 and d[3] == 0.0
    k, d = shooting.recurrence(none, m, 4, 1e-3)
    assert k == 0 and np.all(d > 1e-3)
    # a period longer than max_period is not one; a noisy recurrence within tol is
    assert shooting.recurrence(two, m, 1, 1e-3)[0] == 0
    noisy = fixed + np.concatenate([1e-4 * rng.normal(size=(n + 1, m)), np.zeros((n + 1, 2))], axis=1)
    assert shooting.recurrence(noisy, m, 4, 1e-3)[0] == 1 and shooting.recurrence(noisy, m, 4, 1e-6)[0] == 0
    # batched over designs, a NaN section never recurs, fewer points than max_period
    batch = np.stack([fixed, two, none, np.full_like(fixed, np.nan)])
    k, d = shooting.recurrence(batch, m, 4, 1e-3)
    assert k.tolist() == [1, 2, 0, 0] and d.shape == (4, 4)
    assert shooting.recurrence(two[:3], m, 4, 1e-3)[1].shape == (2,)


@kernel_only
def test_kernel_continuation_equals_a_longer_run(periodic):
    """One revolution continued from the last section state (t restarting at 0) against
    one solve over two revolutions. The step-size controller restarts at dt0 in the
    continued run, so the two step sequences differ and the states agree to the solve's
    noise (about 100 x rtol = 1e-8 scaled units), not to rounding; the works accumulate."""
    from jaxcrank.numerics.kernel import engine, source

    o = shooting.STEADY_DEFAULTS
    st, xs, T = source.structure(periodic, NAMES), np.array([_x(periodic)]), float(periodic.period)

    def run(t_end, y0=None):
        return engine._run(st, xs, [t_end], [0.0], 2, o.rtol, o.atol, o.dt0, o.max_steps, y0, 1)

    two = run(2 * T)
    one = run(T)
    more = run(T, one.y)
    m = shooting.dynamic_size(periodic)
    assert two.status[0] == one.status[0] == more.status[0] == 0
    assert np.max(np.abs(more.y[0, :m] - two.y[0, :m])) <= 1e-6
    np.testing.assert_allclose(more.y[0, m:], two.y[0, m:], rtol=1e-7)  # works (J, scaled)
    assert np.all(more.y[0, m:] > 1.5 * one.y[0, m:])  # they accumulated over both revolutions
    # the fact behind it: the field is periodic in t with the crank period (the crank
    # angle is not a state entry), here at section states and mid-revolution
    for y, t in ((one.y[0], 0.0), (more.y[0], 0.0), (one.y[0], 0.37 * T)):
        f0 = np.asarray(model.vector_field(t, jnp.asarray(y), periodic))
        f1 = np.asarray(model.vector_field(t + T, jnp.asarray(y), periodic))
        np.testing.assert_allclose(f1, f0, rtol=1e-9, atol=1e-9 * np.max(np.abs(f0)))


@kernel_only
def test_known_designs_with_the_default_settings(periodic, chaotic):
    for mech, regime, period in ((periodic, "periodic", 1), (chaotic, "not periodic", 0)):
        t = regimes.classify(mech, NAMES, [_x(mech)], progress=False)
        assert t["status"].tolist() == ["ok"] and t["regime"].tolist() == [regime]
        assert t["period_revolutions"].tolist() == [period]
        d = t["recurrence_distance_scaled"][0]
        assert d <= 1e-6 if period else d > 0.1  # far from the 1e-3 tolerance either way
        assert t["steps"][0] > 0


@kernel_only
def test_kernel_and_xla_classify_alike(periodic, chaotic):
    """Both engines on designs whose classification is robust (no chaotic transient
    that rounding could steer onto another attractor: see the module docstring)."""
    xs = [_x(periodic), [_x(periodic)[0], 1.2 * _x(periodic)[1]]]
    for mech, x in ((periodic, xs), (chaotic, [_x(chaotic)])):
        k = regimes.classify(mech, NAMES, x, settle_revolutions=8, engine="kernel", progress=False)
        x_ = regimes.classify(mech, NAMES, x, settle_revolutions=8, engine="xla", chunk=len(x), progress=False)
        for col in ("status", "regime", "period_revolutions"):
            assert k[col].tolist() == x_[col].tolist(), col
        per = k["regime"] == "periodic"
        assert np.all(k["recurrence_distance_scaled"][per] <= 1e-6)
        assert np.all(x_["recurrence_distance_scaled"][per] <= 1e-6)
        assert np.all(x_["recurrence_distance_scaled"][~per] > 0.1)


@kernel_only
def test_failing_and_invalid_designs_do_not_disturb_the_others(periodic):
    """Half ``periodic``'s rod mass needs about 1.4 x the steps of the nominal design (5 % heavier
    than ``periodic``'s, periodic after 3 settle revolutions): with a budget between the
    two, it gets max_steps, and the nominal design's row is the one it has alone."""
    x = [1.05 * _x(periodic)[0], _x(periodic)[1]]
    light = [0.5 * _x(periodic)[0], x[1]]
    opts = dict(settle_revolutions=3, max_period=2, progress=False)
    alone = regimes.classify(periodic, NAMES, [x], **opts)
    more = regimes.classify(periodic, NAMES, [light], **opts)
    assert more["steps"][0] > 1.3 * alone["steps"][0]
    options = shooting.STEADY_DEFAULTS.replace(max_steps=int(1.2 * alone["steps"][0]))
    t = regimes.classify(periodic, NAMES, [light, x, [-1.0, x[1]]], options=options, **opts)
    assert t["status"].tolist() == ["max_steps", "ok", "invalid"]
    assert "max_steps" in t["message"][0] and "rod_mass" in t["message"][2]
    assert t["regime"].tolist() == ["", "periodic", ""] and np.isnan(t["period_revolutions"][[0, 2]]).all()
    for col in ("period_revolutions", "recurrence_distance_scaled", "steps"):
        assert t[col][1] == alone[col][0], col


@kernel_only
def test_checkpoint_and_resume(periodic, tmp_path):
    x = _x(periodic)
    xs = [x, [x[0], 1.1 * x[1]], [1.1 * x[0], x[1]]]
    opts = dict(settle_revolutions=2, max_period=1, chunk=1, progress=False)
    full = regimes.classify(periodic, NAMES, xs, out=tmp_path, **opts)
    lines = (tmp_path / "table.csv").read_text().splitlines()
    assert len(lines) == 4
    (tmp_path / "table.csv").write_text("\n".join(lines[:2]) + "\n")  # the last two designs lost
    with pytest.raises(jc.ParameterError, match="resume"):
        regimes.classify(periodic, NAMES, xs, out=tmp_path, **opts)
    resumed = regimes.classify(periodic, NAMES, xs, out=tmp_path, resume=True, **opts)
    for col in full:
        assert full[col].tolist() == resumed[col].tolist(), col
    with pytest.raises(jc.ParameterError, match="other designs"):
        regimes.classify(periodic, NAMES, xs[:2], out=tmp_path, resume=True, **opts)


def test_bad_arguments_name_the_parameter(paper):
    x = [[_x(paper)[0], _x(paper)[1]]]
    for kwargs, match in (
        (dict(settle_revolutions=0), "settle_revolutions"),
        (dict(max_period=0), "max_period"),
        (dict(recurrence_tol=-1.0), "recurrence_tol"),
        (dict(recurrence_tol=float("nan")), "recurrence_tol"),
        (dict(engine="gpu"), "engine"),
        (dict(chunk=0), "chunk"),
        (dict(options="tsit5"), "options"),
    ):
        with pytest.raises(jc.ParameterError, match=match):
            regimes.classify(paper, NAMES, x, progress=False, **kwargs)
    with pytest.raises(jc.ParameterError, match="one column per parameter"):
        regimes.classify(paper, NAMES, [[1.0, 2.0, 3.0]], progress=False)
    if regimes.resolve_engine(None) == "kernel":
        kv = shooting.STEADY_DEFAULTS.replace(solver=jc.solver_from_name("kvaerno5"))
        with pytest.raises(jc.ParameterError, match="tsit5"):
            regimes.classify(paper, NAMES, x, engine="kernel", options=kv, progress=False)
        assert regimes.resolve_engine(None, kv) == "xla"


@kernel_only
def test_cli_writes_table_summary_and_regime_map(periodic, tmp_path):
    import tomli_w

    from jaxcrank.runs import cli

    x = _x(periodic)
    spec = {
        "sampling": "grid",
        # four designs that are periodic after 3 settle revolutions at rtol 1e-9
        "parameters": {
            "rod_mass": {"values": [1.02 * x[0], 1.05 * x[0]]},
            "clearance_B": {"values": [0.95 * x[1], x[1]]},
        },
        "simulation": {"rtol": 1e-9, "revolutions": 4},
        "mechanism": jc.config.to_dict(periodic),
    }
    (tmp_path / "spec.toml").write_text(tomli_w.dumps(spec))
    out = tmp_path / "run"
    args = ["regimes", "--spec", str(tmp_path / "spec.toml"), "--out", str(out), "--settle-revolutions", "3", "--quiet"]
    assert cli.main(args) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["designs"] == 4 and summary["regime_counts"]["periodic"] == 4 and summary["engine"] == "kernel"
    assert summary["solver"]["rtol"] == 1e-9 and summary["solver"]["atol"] == shooting.STEADY_DEFAULTS.atol
    assert (out / "regime_map.png").stat().st_size > 0 and (out / "table.csv").exists()
    assert cli.main(args) == 2  # the table exists: --resume needed
    assert cli.main(args + ["--resume"]) == 0
    assert cli.main(args + ["--resume", "--max-period", "0"]) == 2


@pytest.mark.slow
def test_agrees_with_steady_state(periodic, chaotic):
    """steady_state (settle, shoot, Floquet) and the batch classification (settle and
    recurrence only, on the kernel) on the same designs, with the same defaults."""
    from jaxcrank.numerics.steady import steady_state

    for mech in (periodic, chaotic):
        steady = steady_state(mech, jc.SteadyOptions(statistics_revolutions=4, samples_per_revolution=360))
        t = regimes.classify(mech, NAMES, [_x(mech)], progress=False)
        assert t["regime"][0] == steady.regime and t["period_revolutions"][0] == steady.period_revolutions
        if steady.regime == "not periodic":
            assert t["recurrence_distance_scaled"][0] > 1e-3 and float(steady.residual) > 1e-3


def _four_bar_one_clearance():
    """The four-bar preset with C ideal: clearance at B only."""
    import dataclasses

    mech = jc.four_bar()
    return dataclasses.replace(mech, joints={**mech.joints, "C": jc.Ideal()})


#: driver speed (150 or 600 rpm, rad/s) x restitution: at 150 rpm and 0.9 the pin at B
#: settles into contact (period 1, section recurring to 9e-7 scaled units in 10
#: revolutions), the other three keep impacting (section points 0.5 to 12 units apart)
FOUR_BAR_NAMES = ["driver.speed", "contact.restitution"]
FOUR_BAR_GRID = [[w * 2.0 * np.pi / 60.0, e] for w in (150.0, 600.0) for e in (0.9, 1.0)]


@pytest.mark.slow  # one XLA compilation of the four-bar's settle (about a minute in all)
@kernel_only
def test_four_bar_regimes_on_both_engines():
    """A grid on the four-bar (clearance at B only) classifies alike on the kernel and the
    JAX path, one design periodic and three not, each far from the tolerance on its side."""
    mech = _four_bar_one_clearance()
    tables = {
        engine: regimes.classify(
            mech, FOUR_BAR_NAMES, FOUR_BAR_GRID, settle_revolutions=10, engine=engine, chunk=4, progress=False
        )
        for engine in ("kernel", "xla")
    }
    for t in tables.values():
        assert list(t)[1:3] == ["driver.speed_rad_s", "contact.restitution_1"]
        assert t["status"].tolist() == ["ok"] * 4
        assert t["regime"].tolist() == ["periodic", "not periodic", "not periodic", "not periodic"]
        assert t["period_revolutions"].tolist() == [1, 0, 0, 0]
        assert t["recurrence_distance_scaled"][0] <= 1e-5 and np.all(t["recurrence_distance_scaled"][1:] > 0.1)


@kernel_only
def test_cli_regime_map_of_the_four_bar(tmp_path):
    """``jaxcrank regimes --mechanism four-bar --set joints.C.law=ideal`` on a spec without a
    mechanism: the four-bar's table, summary and regime map."""
    from jaxcrank.runs import cli

    spec = tmp_path / "spec.toml"
    levels = ", ".join(repr(w) for w in sorted({x[0] for x in FOUR_BAR_GRID}))
    spec.write_text(
        f'sampling = "grid"\n[parameters."driver.speed"]\nvalues = [{levels}]\n'
        '[parameters."contact.restitution"]\nvalues = [0.9, 1.0]\n'
    )
    out = tmp_path / "run"
    args = ["regimes", "--spec", str(spec), "--out", str(out), "--quiet", "--engine", "kernel"]
    assert cli.main([*args, "--mechanism", "four-bar", "--set", "joints.C.law=ideal", "--settle-revolutions", "4"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["mechanism"] == "four-bar" and summary["designs"] == 4 and summary["status_counts"]["ok"] == 4
    assert sum(summary["regime_counts"].values()) == 4
    assert (out / "regime_map.png").stat().st_size > 0
    table = regimes.read_table(out / "table.csv", regimes.TEXT_COLUMNS)
    assert "driver.speed_rad_s" in table and set(table["regime"]) <= set(regimes.REGIMES)
