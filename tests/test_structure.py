"""The package's structure: layering between jaxcrank and optim, and one
definition of the headline metrics for every caller."""

import subprocess
import sys

import jax.numpy as jnp
import numpy as np

import jaxcrank as jc
from jaxcrank import outputs, sweep
from jaxcrank.physics.parameters import set_parameters
from optim import sensitivity


def _modules_after(statement):
    code = f"import sys\n{statement}\nprint(' '.join(sorted(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return set(out.stdout.split())


def test_importing_jaxcrank_leaves_optim_out():
    loaded = _modules_after("import jaxcrank")
    assert "optim" not in loaded and not any(m.startswith("optim.") for m in loaded)


def test_optim_imports_sampling_not_the_sweep_runner():
    loaded = _modules_after(
        "import optim.problem, optim.objective, optim.optimize, optim.sensitivity, "
        "optim.search, optim.scans, optim.plots, optim.cli"
    )
    assert "jaxcrank.runs.sampling" in loaded
    assert "jaxcrank.runs.sweep" not in loaded and "jaxcrank.runs.spec" not in loaded


def test_summary_sweep_row_and_sensitivity_give_identical_metrics():
    """The same solve (a sweep's sample times and solver settings, 20 ms of the paper
    run, metrics after 5 ms so the start-up impacts are in the window) through
    ``jaxcrank simulate``'s summary, a sweep row and the sensitivity values: the very
    same numbers, bit for bit. The design's swept parameter is traced in both
    solves (a sweep compiles the base design's other parameters in as constants, and
    so does ``simulate`` for Python-float parameters)."""
    settings = sweep.Settings(revolutions=0.2, samples_per_revolution=720, metrics_from_revolution=0.05)
    base = jc.paper()
    row = sweep.run(base, ["rod_length"], [[float(base.rod_length)]], settings, chunk=1, progress=False, engine="xla")
    assert row["status"][0] == "ok"
    mech = set_parameters(base, ["rod_length"], jnp.array([float(base.rod_length)]))
    sim = jc.simulate(
        mech, ts=settings.sample_times(mech), options=settings.options, metrics_start=settings.metrics_start(mech)
    )
    assert int(sim.num_steps) == row["steps"][0]
    summary = outputs.summary_metrics(sim)
    assert summary["peak_contact_force_C_N"] > 0.0  # impacts in the window
    for name in sweep.metric_names(base):
        assert summary[name] == row[name][0], name
    for name, value in zip(sensitivity.metric_names(base), np.asarray(sensitivity.metric_values(sim))):
        assert value == summary[name], name
