"""The headline metric definitions (jaxcrank.analysis.metrics): named fields, vectors
built and read by name, and objective values that do not depend on the order in which
the metrics are defined."""

import json
import subprocess
import sys

import jax.numpy as jnp
import numpy as np
import pytest

import jaxcrank as jc
from jaxcrank import metrics
from jaxcrank.physics.presets import paper_guide

# Computes, in a fresh process, every objective value and tracked metric by name, after
# permuting the metric definitions (the order of metric_definitions, and of the RMS and
# peak tuples) before anything else reads them. Short windows: the pathwise design terms and objective over
# the first 1.2 ms, the ensemble design objective over 2 ms in two windows, the paper
# problem's objective (Eq. 19), the sensitivity metric values and summary of a 5 ms run.
_PERMUTED = """
import json, sys
import numpy as np
import jaxcrank.analysis.metrics as M
import jaxcrank.physics.signals as S

order = sys.argv[1]
if order == "reversed":
    definitions, peaks, rms = S.metric_definitions, S.peak_metrics, S.rms_metrics
    S.metric_definitions = lambda mech: dict(list(definitions(mech).items())[::-1])
    S.peak_metrics = lambda mech: peaks(mech)[::-1]
    S.rms_metrics = lambda mech: rms(mech)[::-1]
    M.metric_definitions, M.peak_metrics, M.rms_metrics = S.metric_definitions, S.peak_metrics, S.rms_metrics

import jax.numpy as jnp
import jaxcrank as jc
from jaxcrank import outputs
from optim import ensemble as E, objective as O, sensitivity
from optim.presets import design_problem
from optim.presets import paper_problem

out = {}
exact = O.Pathwise(t_start=0.0, t_end=1.2e-3, options=jc.SolveOptions(rtol=1e-10, atol=1e-10, max_steps=100_000))
prob = design_problem(exact)
x = jnp.asarray(prob.from_unit(prob.start_unit()))
out["design_terms"] = {k: float(v).hex() for k, v in prob.term_values(x).items()}
out["design_pathwise"] = float(prob.objective_value(x)).hex()
tsit5 = jc.SolveOptions.from_text("tsit5", max_steps=5_000)
tiny = E.Ensemble(t_start=0.0, t_end=2e-3, window=1e-3, windows=2, window_options=tsit5)
out["design_ensemble"] = float(design_problem(tiny).objective_value(x)).hex()
paper = paper_problem(tiny, start=None)
out["paper_objective"] = float(paper.objective_value(jnp.asarray(paper.from_unit(paper.start_unit())))).hex()
sim = jc.simulate(jc.paper(), 0.005, n_samples=181, metrics_start=0.001)
summary = outputs.summary_metrics(sim)
out["summary"] = {k: float(v).hex() for k, v in summary.items()}
values = np.asarray(sensitivity.metric_values(sim))
out["sensitivity"] = {k: float(v).hex() for k, v in zip(sensitivity.metric_names(jc.paper()), values)}
print(json.dumps(out))
"""


def _objective_values(order: str) -> dict:
    out = subprocess.run([sys.executable, "-c", _PERMUTED, order], capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


# the paper's metric names, as they were before mechanisms were described as data
PAPER_METRICS = (
    "max_abs_rod_x_deviation_m",
    "max_abs_slider_x_deviation_m",
    "max_abs_slider_ax_deviation_m_s2",
    "peak_contact_force_B_N",
    "peak_contact_force_C_N",
    "max_penetration_B_m",
    "max_penetration_C_m",
    "peak_driving_moment_N_m",
    "rms_driving_moment_deviation_N_m",
    "rms_rod_x_deviation_m",
    "rms_slider_x_deviation_m",
    "rms_transmission_angle_error_deg",
    "max_abs_transmission_angle_error_deg",
    "rms_contact_force_B_N",
    "rms_contact_force_C_N",
)
MECHANISMS = {"paper": jc.paper, "paper-guide": paper_guide, "four-bar": jc.four_bar}


@pytest.mark.parametrize("name", MECHANISMS)
def test_every_metric_is_a_named_definition(name):
    mech = MECHANISMS[name]()
    defs = metrics.metric_definitions(mech)
    signals = metrics.signal_meanings(mech)
    for key, m in defs.items():
        assert isinstance(m, metrics.Metric), key
        assert m.reduction in ("max_abs", "max", "rms") and m.signal in signals and m.meaning, key
    assert set(metrics.rms_metrics(mech)) | set(metrics.peak_metrics(mech)) == set(defs)
    assert set(metrics.meanings(mech)) == set(defs)
    assert set(metrics.force_metrics(mech)) <= set(metrics.peak_metrics(mech))


def test_metric_names_come_from_the_description():
    """The paper keeps its names (and gains joints A and guide); the four-bar's name its
    rocker; the guide with clearance has a penetration."""
    paper = set(metrics.metric_definitions(jc.paper()))
    assert set(PAPER_METRICS) <= paper
    assert paper - set(PAPER_METRICS) == {f"{k}_contact_force_{j}_N" for k in ("peak", "rms") for j in ("A", "guide")}
    four_bar = set(metrics.metric_definitions(jc.four_bar()))
    assert {
        "max_abs_rocker_angle_deviation_deg",
        "rms_rocker_angle_deviation_deg",
        "max_abs_rocker_angular_acceleration_deviation_rad_s2",
        "rms_transmission_angle_error_deg",
        "peak_contact_force_D_N",
    } <= four_bar
    assert not any("slider" in k or "rod_" in k for k in four_bar)
    assert "max_penetration_guide_m" in metrics.metric_definitions(paper_guide())


def test_a_vector_of_metrics_is_built_and_read_by_name():
    rms, peaks = metrics.rms_metrics(jc.paper()), metrics.peak_metrics(jc.paper())
    values = {k: jnp.asarray(float(i)) for i, k in enumerate(rms)}
    named = metrics.by_name(rms, metrics.stack(rms, values))
    assert {k: float(v) for k, v in named.items()} == {k: float(v) for k, v in values.items()}
    batch = metrics.by_name(peaks, jnp.ones((3, len(peaks))))
    assert all(v.shape == (3,) for v in batch.values())
    with pytest.raises(ValueError, match="cannot hold"):
        metrics.by_name(rms, jnp.zeros(len(rms) - 1))


def test_reduce_signal_names_an_unknown_reduction():
    with pytest.raises(ValueError, match="unknown reduction 'median'"):
        metrics.reduce_signal("median", jnp.zeros(3), jnp.ones(3, bool))


def test_reductions_against_hand_computed_values():
    x = jnp.array([3.0, -4.0, 1.0, -9.0])
    window = jnp.array([True, True, True, False])
    assert float(metrics.reduce_signal("max_abs", x, window)) == 4.0
    assert float(metrics.reduce_signal("max", x, window)) == 3.0
    np.testing.assert_allclose(float(metrics.reduce_signal("rms", x, window)), np.sqrt(26.0 / 3.0), rtol=1e-15)


@pytest.mark.slow  # two processes, each compiling short solves and objectives
def test_permuting_the_metric_definitions_changes_no_objective_value():
    """Reversing the order of the metric definitions (and of the RMS and peak tuples)
    changes no objective value, term, tracked metric or sensitivity value, bit for bit:
    every vector of metrics is built and read by name."""
    assert _objective_values("reversed") == _objective_values("defined")
