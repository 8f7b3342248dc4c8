"""The headline metric definitions (jaxcrank.analysis.metrics): named fields, vectors
built and read by name, and objective values that do not depend on the order in which
the metrics are defined."""

import json
import subprocess
import sys

import jax.numpy as jnp
import numpy as np
import pytest

from jaxcrank import metrics

# Computes, in a fresh process, every objective value and tracked metric by name, after
# permuting the metric definitions (METRICS' order, and the RMS and peak tuples) before
# anything else reads them. Short windows: the pathwise design terms and objective over
# the first 1.2 ms, the ensemble design objective over 2 ms in two windows, the paper
# problem's objective (Eq. 19), the sensitivity metric values and summary of a 5 ms run.
_PERMUTED = """
import json, sys
import numpy as np
import jaxcrank.analysis.metrics as M

order = sys.argv[1]
if order == "reversed":
    items = list(M.METRICS.items())[::-1]
    M.METRICS.clear()
    M.METRICS.update(items)
    M.PEAK_METRICS = M.PEAK_METRICS[::-1]
    M.RMS_METRICS = M.RMS_METRICS[::-1]

import jax.numpy as jnp
import jaxcrank as jc
from jaxcrank import outputs
from optim import objective as O, sensitivity
from optim.design import design_problem
from optim.problem import paper_problem

out = {}
exact = O.Pathwise(t_start=0.0, t_end=1.2e-3, rtol=1e-10, atol=1e-10, max_steps=100_000)
prob = design_problem(exact)
x = jnp.asarray(prob.from_unit(prob.start_unit()))
out["design_terms"] = {k: float(v).hex() for k, v in prob.terms(x).items()}
out["design_pathwise"] = float(prob.objective_value(x)).hex()
tiny = O.Ensemble(t_start=0.0, t_end=2e-3, window=1e-3, windows=2, window_solver="tsit5")
out["design_ensemble"] = float(design_problem(tiny).objective_value(x)).hex()
paper = paper_problem(tiny, start=None)
out["paper_objective"] = float(paper.objective_value(jnp.asarray(paper.from_unit(paper.start_unit())))).hex()
sim = jc.simulate(jc.paper(), 0.005, n_samples=181, metrics_start=0.001)
summary = outputs.summary_metrics(sim)
out["summary"] = {k: float(v).hex() for k, v in summary.items()}
values = np.asarray(sensitivity.metric_values(sim))
out["sensitivity"] = {k: float(v).hex() for k, v in zip(sensitivity.METRICS, values)}
print(json.dumps(out))
"""


def _objective_values(order: str) -> dict:
    out = subprocess.run([sys.executable, "-c", _PERMUTED, order], capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_every_metric_is_a_named_definition():
    for name, m in metrics.METRICS.items():
        assert isinstance(m, metrics.Metric), name
        assert m.reduction in ("max_abs", "max", "rms") and m.signal in metrics.SIGNALS and m.meaning, name
    assert set(metrics.RMS_METRICS) | set(metrics.PEAK_METRICS) == set(metrics.METRICS)
    assert set(metrics.meanings()) == set(metrics.METRICS)


def test_a_vector_of_metrics_is_built_and_read_by_name():
    values = {k: jnp.asarray(float(i)) for i, k in enumerate(metrics.RMS_METRICS)}
    named = metrics.by_name(metrics.RMS_METRICS, metrics.stack(metrics.RMS_METRICS, values))
    assert {k: float(v) for k, v in named.items()} == {k: float(v) for k, v in values.items()}
    batch = metrics.by_name(metrics.PEAK_METRICS, jnp.ones((3, len(metrics.PEAK_METRICS))))
    assert all(v.shape == (3,) for v in batch.values())
    with pytest.raises(ValueError, match="cannot hold"):
        metrics.by_name(metrics.RMS_METRICS, jnp.zeros(len(metrics.RMS_METRICS) - 1))


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
