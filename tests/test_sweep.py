"""Sweeps (jaxcrank.runs.sweep): vmap equals a loop, failures are reported, a killed
sweep resumes to the same table, several devices and processes give the same
numbers as one, and a sweep runs on the four-bar as on the slider-crank. Short simulations
(3 ms); the slider-crank tests share one compiled batch."""

import dataclasses
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import jaxcrank as jc
from jaxcrank import cli, outputs, sampling, sweep
from jaxcrank import spec as sweep_spec
from jaxcrank.physics.params import ParameterError
from jaxcrank.runs import engines

ROOT = Path(__file__).resolve().parents[1]
SHORT = sweep.Settings(
    revolutions=0.03,
    samples_per_revolution=1200,
    metrics_from_revolution=0.01,
    options=jc.DEFAULTS.replace(max_steps=20_000),
)
NAMES = ["clearance_C", "memory.memory_time"]
# design 1: a 0.1 ns impact memory makes the solve too stiff for its step budget;
# design 3: a clearance larger than the hole (invalid, caught before any solve)
DESIGNS = np.array([[2.5e-4, 1e-5], [2.5e-4, 1e-10], [3e-4, 1e-5], [9e-3, 1e-5], [1.5e-4, 2e-5]])
METRICS = sweep.metric_names(jc.paper())


@pytest.fixture(scope="module")
def table():
    return sweep.run(jc.paper(), NAMES, DESIGNS, SHORT, chunk=2, progress=False, engine="xla")


def test_vmap_equals_python_loop_before_impacts():
    """Over the first 1 ms (pins still in free flight, no contact) a vmap batch
    equals a Python loop of the public API (simulate -> trajectory -> metrics) to
    1e-9 relative."""
    first_ms = sweep.Settings(revolutions=0.01, samples_per_revolution=1200, metrics_from_revolution=0.0)
    tab = sweep.run(jc.paper(), NAMES, DESIGNS[[0, 2, 4]], first_ms, chunk=4, progress=False, engine="xla")
    for row, i in enumerate((0, 2, 4)):
        mech = jc.paper()
        for n, v in zip(NAMES, DESIGNS[i]):
            mech = jc.set_parameter(mech, n, float(v))
        period = float(mech.period)
        sim = jc.simulate(
            mech, ts=np.linspace(0.0, first_ms.revolutions, first_ms.n_samples) * period, metrics_start=0.0
        )
        ref = outputs.summary_metrics(sim)
        assert ref["peak_contact_force_C_N"] == 0.0 and ref["peak_contact_force_B_N"] == 0.0
        for key in set(ref) & set(METRICS):
            np.testing.assert_allclose(tab[key][row], ref[key], rtol=1e-9, atol=1e-300, err_msg=key)
        assert tab["steps"][row] == int(sim.num_steps)


def test_vmap_equals_python_loop_through_impacts(table):
    """Over 3 ms with impacts, a Python loop of one design at a time gives the
    batch's numbers exactly: batch mates do not influence each other. (The loop
    uses the same compiled batch shape: an unbatched compile rounds differently in
    the last bit, and impact chaos amplifies that to 1e-5..1e-3 relative in 3 ms.)"""
    for i in range(len(DESIGNS)):
        one = sweep.run(jc.paper(), NAMES, DESIGNS[i : i + 1], SHORT, chunk=2, progress=False, engine="xla")
        assert one["status"][0] == table["status"][i]
        for k in list(METRICS) + ["steps"]:
            np.testing.assert_array_equal(one[k][0], table[k][i], err_msg=k)


def test_batch_size_does_not_change_a_design(table):
    """Batches of 2 and 3 designs give the same numbers for every design, wherever it
    sits in its batch (no FMA contraction, jaxcrank.numerics.runtime: with it the same design
    rounded differently per lane and per batch size)."""
    three = sweep.run(jc.paper(), NAMES, DESIGNS, SHORT, chunk=3, progress=False, engine="xla")
    assert list(three["status"]) == list(table["status"])
    for k in list(METRICS) + ["steps"]:
        np.testing.assert_array_equal(three[k], table[k], err_msg=k)


@pytest.mark.slow  # two worker processes
def test_workers_give_the_single_process_table():
    """Two local worker processes, each design solved alone (one per chunk), give the
    table of one process exactly, failures and invalid designs included."""
    alone = sweep.run(jc.paper(), NAMES, DESIGNS, SHORT, chunk=1, progress=False, engine="xla")
    pooled = sweep.run(jc.paper(), NAMES, DESIGNS, SHORT, chunk=1, workers=2, progress=False, engine="xla")
    assert list(alone["status"]) == list(pooled["status"]) == ["ok", "max_steps", "ok", "invalid", "ok"]
    for k in ["index", "steps"] + list(METRICS):
        np.testing.assert_array_equal(pooled[k], alone[k], err_msg=k)
    assert list(pooled["message"]) == list(alone["message"])


@pytest.mark.parametrize("kwargs, match", [({"chunk": 0}, "chunk"), ({"workers": 0}, "workers")])
def test_bad_chunk_or_workers_raise(kwargs, match):
    with pytest.raises(ParameterError, match=match):
        sweep.run(jc.paper(), NAMES, DESIGNS[:1], SHORT, progress=False, engine="xla", **kwargs)


def test_failures_are_reported_and_the_rest_completes(table):
    assert list(table["status"]) == ["ok", "max_steps", "ok", "invalid", "ok"]
    assert "max_steps" in table["message"][1] and "clearance_C = 0.009" in table["message"][3]
    assert "pin_radius" in table["message"][3] and "valid range" in table["message"][3]
    ok = table["status"] == "ok"
    for k in METRICS:
        assert np.all(np.isfinite(table[k][ok])) and np.all(np.isnan(table[k][~ok]))  # empty cells, not values
    # geometric bound of the zero-clearance reading: slider deviation stays within a few clearances
    assert np.all(table["max_abs_slider_x_deviation_m"][ok] < 0.01)


def test_killed_sweep_resumes_to_the_same_table(tmp_path, table, monkeypatch):
    calls = {"n": 0}
    real = sweep._evaluate

    def dies_after_first_batch(*a):
        if calls["n"] == 1:
            raise KeyboardInterrupt("killed")
        calls["n"] += 1
        return real(*a)

    monkeypatch.setattr(sweep, "_evaluate", dies_after_first_batch)
    with pytest.raises(KeyboardInterrupt):
        sweep.run(jc.paper(), NAMES, DESIGNS, SHORT, out=tmp_path, chunk=2, progress=False, engine="xla")
    partial = sweep.read_table(tmp_path / "table.csv")
    assert sorted(partial["index"]) == [0, 1, 3]  # first batch + the invalid design
    with pytest.raises(ParameterError, match="resume"):
        sweep.run(jc.paper(), NAMES, DESIGNS, SHORT, out=tmp_path, chunk=2, progress=False, engine="xla")
    with pytest.raises(ParameterError, match="other designs"):
        sweep.run(
            jc.paper(), NAMES, DESIGNS[:4], SHORT, out=tmp_path, chunk=2, resume=True, progress=False, engine="xla"
        )
    no_gravity, longer = jc.set_parameter(jc.paper(), "gravity", 0.0), dataclasses.replace(SHORT, revolutions=0.5)
    for base, settings, what in ((no_gravity, SHORT, "mechanism"), (jc.paper(), longer, "settings")):
        with pytest.raises(ParameterError, match=f"another {what}"):  # their rows would mix with these: refused
            sweep.run(base, NAMES, DESIGNS, settings, out=tmp_path, chunk=2, resume=True, progress=False, engine="xla")
    monkeypatch.setattr(sweep, "_evaluate", real)
    resumed = sweep.run(
        jc.paper(), NAMES, DESIGNS, SHORT, out=tmp_path, chunk=2, resume=True, progress=False, engine="xla"
    )
    assert list(resumed["status"]) == list(table["status"])
    for k in list(METRICS) + ["steps"]:
        np.testing.assert_array_equal(resumed[k], table[k], err_msg=k)


_SUBPROCESS = """
import json, sys, numpy as np, jax
import jaxcrank as jc
from jaxcrank import sweep
sys.path.insert(0, {tests!r})
from test_sweep import NAMES, DESIGNS, METRICS, SHORT
tab = sweep.run(jc.paper(), NAMES, DESIGNS, SHORT, chunk=8, progress=False, engine="xla")  # 2 per device
print(json.dumps({{"devices": jax.device_count(), "status": list(tab["status"]),
                  **{{k: [None if np.isnan(v) else v for v in tab[k]] for k in METRICS}}}}))
"""


@pytest.mark.slow  # a subprocess with four host devices
def test_sharded_over_four_host_devices_equals_one_device(table):
    env = dict(os.environ, JAX_NUM_CPU_DEVICES="4", JAX_PLATFORMS="cpu")
    res = subprocess.run(
        [sys.executable, "-c", _SUBPROCESS.format(tests=str(ROOT / "tests"))],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
        cwd=ROOT,
    )
    assert res.returncode == 0, res.stderr[-2000:]
    got = json.loads(res.stdout.strip().splitlines()[-1])
    assert got["devices"] == 4
    assert got["status"] == list(table["status"])
    ok = table["status"] == "ok"
    for k in METRICS:
        np.testing.assert_array_equal(np.array(got[k], float)[ok], table[k][ok], err_msg=k)


_WORKER = """
import json, sys, jax
jax.config.update("jax_num_cpu_devices", 1)
jax.distributed.initialize(coordinator_address=sys.argv[1], num_processes=2, process_id=int(sys.argv[2]),
                           initialization_timeout=120, heartbeat_timeout_seconds=30)
import numpy as np, jaxcrank as jc
from jaxcrank import sampling, sweep
sys.path.insert(0, {tests!r})
from test_sweep import NAMES, SHORT, TOLERANCES
names, x = sampling.monte_carlo(TOLERANCES, 6, seed=0)
tab = sweep.run(jc.paper(), names, x, SHORT, chunk=4, progress=False, engine="xla")
ok = tab["status"] == "ok"
print(json.dumps({{"processes": jax.process_count(), "devices": jax.device_count(), "ok": int(ok.sum()),
                  "mean": float(np.mean(tab["rms_transmission_angle_error_deg"][ok]))}}))
jax.distributed.shutdown()
"""
TOLERANCES = {"clearance_C": sampling.Tolerance(2.5e-4, 5e-5), "memory.memory_time": sampling.Tolerance(1e-5, 2e-6)}


@pytest.mark.slow  # two processes
def test_two_processes_with_jax_distributed_give_the_one_process_monte_carlo_mean():
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    env.pop("JAX_NUM_CPU_DEVICES", None)
    code = _WORKER.format(tests=str(ROOT / "tests"))
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", code, f"127.0.0.1:{port}", str(i)],
            env=env,
            cwd=ROOT,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for i in range(2)
    ]
    try:
        outs = [p.communicate(timeout=600) for p in procs]
    finally:
        for p in procs:
            p.kill()
    for p, (_, err) in zip(procs, outs):
        assert p.returncode == 0, err[-2000:]
    got = [json.loads([ln for ln in o.splitlines() if ln.startswith("{")][-1]) for o, _ in outs]
    names, x = sampling.monte_carlo(TOLERANCES, 6, seed=0)
    one = sweep.run(jc.paper(), names, x, SHORT, chunk=4, progress=False, engine="xla")
    ok = one["status"] == "ok"
    mean = float(np.mean(one["rms_transmission_angle_error_deg"][ok]))
    for g in got:
        assert g["processes"] == 2 and g["devices"] == 2 and g["ok"] == int(ok.sum())
        assert g["mean"] == mean


def test_samplers():
    names, x = sampling.latin_hypercube({"a": (0.0, 1.0), "b": (10.0, 20.0)}, 8, seed=3)
    assert names == ["a", "b"] and x.shape == (8, 2)
    for j, (lo, hi) in enumerate([(0.0, 1.0), (10.0, 20.0)]):  # one sample per stratum
        assert sorted(np.floor((x[:, j] - lo) / (hi - lo) * 8).astype(int)) == list(range(8))
    names, x = sampling.full_factorial({"a": [1, 2], "b": [3, 4, 5]})
    assert x.shape == (6, 2) and {tuple(r) for r in x} == {(a, b) for a in (1, 2) for b in (3, 4, 5)}
    base = jc.paper()
    names, x = sampling.one_at_a_time(base, {"rod_length": (0.40, 0.41), "offset": (0.0, 0.06)}, points=3)
    assert x.shape == (6, 2)
    assert np.all(x[:3, 1] == base.offset) and np.all(x[3:, 0] == base.rod_length)
    tol = {
        "clearance_B": sampling.Tolerance(2.5e-4, 5e-5, "uniform"),
        "rod_length": sampling.Tolerance(0.403, 1e-4, "normal"),
    }
    names, x = sampling.monte_carlo(tol, 4000, seed=1)
    assert np.all(np.abs(x[:, 0] - 2.5e-4) <= 5e-5)
    np.testing.assert_allclose(x[:, 1].std(), tol["rod_length"].sigma, rtol=0.05)
    np.testing.assert_allclose(x[:, 0].std(), tol["clearance_B"].sigma, rtol=0.05)


@pytest.mark.parametrize(
    "spec, match",
    [
        ({"sampling": "sobol", "parameters": {"offset": {"values": [0.0]}}}, "sampling"),
        ({"parameters": {}}, "at least one"),
        ({"parameters": {"rod_lenght": {"values": [0.4]}}}, "rod_lenght"),
        ({"sampling": "lhs", "parameters": {"offset": {"lower": 0.0}}}, "lower and upper"),
        ({"sampling": "monte_carlo", "parameters": {"offset": {"nominal": 0.05}}}, "tolerance"),
        ({"parameters": {"offset": {"values": [0.0]}}, "simulation": {"revolution": 2}}, "simulation"),
        ({"parameters": {"offset": {"values": [0.0]}}, "metrics": ["peak_force"]}, "metrics"),
        ({"parameters": {"offset": {"values": [0.0]}}, "colour": "red"}, "colour"),
        ({"parameters": {"offset": {"values": [0.0]}}, "simulation": {"revolutions": -1}}, "revolutions"),
        ({"parameters": {"offset": {"values": [0.0]}}, "mechanism": "five-bar"}, "five-bar"),
        ({"parameters": {"offset": {"values": [0.0]}}, "mechanism": 3}, "preset"),
        ({"parameters": {"offset": {"values": [0.0]}}, "mechanism": "four-bar"}, "offset"),  # not a four-bar's
    ],
)
def test_bad_specs_raise(spec, match):
    with pytest.raises(ParameterError, match=match):
        sweep_spec.spec_from_dict(spec)


def test_spec_mechanism_is_a_preset_name_or_a_table():
    """``mechanism = "four-bar"`` names a preset; a ``[mechanism]`` table is a config
    file's (its kind, joints and shorthands); without one, the paper's slider-crank."""
    params = {"parameters": {"clearance_B": {"values": [2e-4]}}}
    assert isinstance(sweep_spec.spec_from_dict(params).base, jc.SliderCrank)
    assert isinstance(sweep_spec.spec_from_dict({**params, "mechanism": "four-bar"}).base, jc.FourBar)
    table = {"mechanism": "four-bar", "crank_length": 0.09, "clearance_C": 3e-4, "contact": {"restitution": 0.5}}
    base = sweep_spec.spec_from_dict({**params, "mechanism": table}).base
    assert isinstance(base, jc.FourBar) and base.crank_length == 0.09
    assert jc.get_parameter(base, "clearance_C") == pytest.approx(3e-4)
    assert jc.get_parameter(base, "joints.B.contact.restitution") == 0.5


def test_cli_sweep_writes_table_summary_figures_and_resumes(tmp_path, table):
    spec = tmp_path / "spec.toml"
    spec.write_text(
        'sampling = "grid"\nchunk = 2\nmetrics = ["max_abs_slider_x_deviation_m"]\n'
        "[parameters.clearance_C]\nvalues = [2.5e-4, 3e-4]\n"
        '[parameters."memory.memory_time"]\nvalues = [1e-5]\n'
        "[simulation]\nrevolutions = 0.03\nsamples_per_revolution = 1200\nmetrics_from_revolution = 0.01\n"
        "max_steps = 20000\n"
    )
    out = tmp_path / "run"
    assert cli.main(["sweep", "--spec", str(spec), "--out", str(out), "--quiet", "--workers", "2"]) == 0
    tab = sweep.read_table(out / "table.csv")
    np.testing.assert_array_equal(tab["max_abs_slider_x_deviation_m"], table["max_abs_slider_x_deviation_m"][[0, 2]])
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status_counts"]["ok"] == 2 and summary["workers"] == 2 and summary["chunk"] == 2
    assert (out / "figures" / "heatmap_max_abs_slider_x_deviation_m.png").exists()
    assert cli.main(["sweep", "--spec", str(spec), "--out", str(out), "--quiet"]) == 2  # would overwrite
    assert cli.main(["sweep", "--spec", str(spec), "--out", str(out), "--quiet", "--resume"]) == 0


#: a grid over the four-bar: two clearances at B (and one larger than the hole: invalid) and
#: two restitutions, over its first 1 ms (the pins in free flight)
FOUR_BAR = {
    "mechanism": "four-bar",
    "sampling": "grid",
    "parameters": {"clearance_B": {"values": [2.5e-4, 5e-4, 9e-3]}, "contact.restitution": {"values": [0.7, 0.9]}},
    "simulation": {"revolutions": 0.01, "samples_per_revolution": 1200, "metrics_from_revolution": 0.0},
}
kernel_only = pytest.mark.skipif(not engines.kernel_available(), reason="no C compiler")


@kernel_only
def test_four_bar_sweep_on_both_engines():
    """A spec with ``mechanism = "four-bar"``: the table's columns are the four-bar's
    (its parameters' units, the rocker's metrics, nothing of a slider); both engines give
    the same statuses (the clearance larger than the hole invalid), and over the first
    1 ms (no contact yet) the kernel takes the XLA engine's steps and gives its metrics to
    1e-9 relative (the same solver, controller and dense output, to rounding)."""
    spec = sweep_spec.spec_from_dict(FOUR_BAR)
    assert isinstance(spec.base, jc.FourBar) and spec.names == ["clearance_B", "contact.restitution"]
    cols = sweep.columns(spec.base, spec.names)
    assert cols[1:3] == ["clearance_B_m", "contact.restitution_1"] and "max_abs_rocker_angle_deviation_deg" in cols
    assert not any("slider" in c for c in cols)
    tabs = {
        engine: sweep.run(spec.base, spec.names, spec.designs, spec.settings, chunk=1, progress=False, engine=engine)
        for engine in ("xla", "kernel")
    }
    for tab in tabs.values():
        assert list(tab) == cols
        assert list(tab["status"]) == ["ok"] * 4 + ["invalid"] * 2
    ok = tabs["xla"]["status"] == "ok"
    assert np.all(tabs["xla"]["peak_contact_force_B_N"][ok] == 0.0)
    np.testing.assert_array_equal(tabs["kernel"]["steps"][ok], tabs["xla"]["steps"][ok])
    for key in sweep.metric_names(spec.base):
        np.testing.assert_allclose(tabs["kernel"][key][ok], tabs["xla"][key][ok], rtol=1e-9, atol=1e-300, err_msg=key)
    summary = sweep.summarize(tabs["kernel"])
    assert set(summary["metrics"]) == set(sweep.metric_names(spec.base)) and summary["status_counts"]["invalid"] == 2


@kernel_only
def test_cli_sweep_on_the_four_bar(tmp_path):
    """``jaxcrank sweep --mechanism four-bar`` runs a spec without a mechanism on the
    four-bar and plots its metrics; a spec that names a mechanism too is refused."""
    spec = tmp_path / "spec.toml"
    spec.write_text(
        'sampling = "grid"\nmetrics = ["max_abs_rocker_angle_deviation_deg"]\n'
        "[parameters.clearance_C]\nvalues = [2.5e-4, 5e-4]\n"
        '[parameters."contact.restitution"]\nvalues = [0.7, 0.9]\n'
        "[simulation]\nrevolutions = 0.01\nsamples_per_revolution = 1200\nmetrics_from_revolution = 0.0\n"
    )
    out = tmp_path / "run"
    args = ["sweep", "--spec", str(spec), "--out", str(out), "--quiet", "--engine", "kernel"]
    assert cli.main([*args, "--mechanism", "four-bar"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["mechanism"] == "four-bar" and summary["status_counts"]["ok"] == 4
    assert "max_abs_rocker_angle_deviation_deg" in summary["metric_meanings"]
    assert (out / "figures" / "heatmap_max_abs_rocker_angle_deviation_deg.png").exists()
    spec.write_text('mechanism = "four-bar"\n' + spec.read_text())
    assert cli.main([*args, "--mechanism", "paper", "--out", str(tmp_path / "both")]) == 2
