"""Metrics tracked during a solve (jaxcrank.numerics.tracking): the same numbers as stored
samples where they should be, peaks independent of the sampling, memory
independent of the number of samples."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcrank as jc
from jaxcrank import metrics, outputs
from jaxcrank.physics import model, signals
from jaxcrank.physics.parameters import set_parameters


def test_tracked_rms_equals_the_rms_of_stored_samples_and_peaks_do_not_depend_on_sampling():
    """Tracked metrics (no sample stored) against today's metrics of the same solve:
    RMS metrics equal the RMS over the stored samples, each sample evaluated by the
    one-state program the solve tracks with, to 1e-13 relative (summation order only).
    (The batched program of ``outputs.frames`` rounds differently: measured, the driving
    moment's deviation, a difference of large terms, differs by up to 2.6e-12 of its
    largest value per sample and 2.8e-13 in its RMS.) The peaks over the solve are the same
    bits at 1 and 100 samples per degree, and not below the peaks over the samples by more than 1e-3 relative (a
    sample can fall nearer a maximum inside a step than either step end: measured
    3e-5 for the penetration at C here). 10 ms of the paper run."""
    mech = jc.paper()
    t1, start = 0.01, 0.0025
    dense = jc.simulate(mech, t1, n_samples=3601, metrics_start=start)  # 10 samples per degree
    coarse = jc.simulate(mech, t1, n_samples=37, metrics_start=start, save_samples=False)
    fine = jc.simulate(mech, t1, n_samples=36001, metrics_start=start, save_samples=False)
    assert coarse.ys.shape[0] == fine.ys.shape[0] == 1  # nothing stored per sample
    samples = outputs.sample_metrics(dense, start)
    ts, ys = dense.ts, dense.ys
    assert samples["peak_contact_force_C_N"] > 0.0
    one_state = jax.lax.map(lambda a: signals.rms_signals(mech, model.evaluate(mech, a[0], a[1:])), jnp.c_[ts, ys])
    window = np.asarray(ts) > start
    for i, name in enumerate(metrics.rms_metrics(mech)):
        rms = np.sqrt(np.mean(np.asarray(one_state)[window, i] ** 2))
        np.testing.assert_allclose(float(dense.metrics[name]), rms, rtol=1e-13, err_msg=name)
    for name in metrics.peak_metrics(mech):
        assert float(coarse.metrics[name]) == float(fine.metrics[name]) == float(dense.metrics[name]), name
        assert float(dense.metrics[name]) >= samples[name] - 1e-3 * abs(samples[name]), name


def _sweep_program_bytes(samples_per_revolution):
    from jaxcrank import sweep

    settings = sweep.Settings(
        revolutions=0.05, samples_per_revolution=samples_per_revolution, metrics_from_revolution=0.01
    )
    base = jc.paper()
    program = jax.jit(lambda x: sweep.simulate_design(base, ("rod_length",), x, settings))
    memory = program.lower(jnp.array([0.403])).compile().memory_analysis()
    return memory.temp_size_in_bytes + memory.output_size_in_bytes


def test_memory_of_a_metrics_only_sweep_does_not_grow_with_samples():
    """XLA's memory plan of one sweep design: the same bytes at 360 and at 36 000
    samples per revolution (before tracking it grew by ~40 bytes per sample)."""
    assert _sweep_program_bytes(360) == _sweep_program_bytes(36_000)


def test_tracking_needs_equally_spaced_samples():
    with pytest.raises(jc.ParameterError, match="equally spaced"):
        jc.simulate(jc.paper(), ts=jnp.array([0.0, 1e-4, 3e-4]), metrics_start=0.0)


@pytest.mark.slow  # compiles sweep programs for several batch sizes (about 25 s)
def test_chunk_that_fits_and_the_error_for_one_that_does_not():
    """The memory arithmetic of GPU sweeps, on this machine's XLA plan: a batch's bytes
    grow linearly with its size, the chunk that fits a budget fits it, and a chunk that
    does not raises an error naming chunk and the size that would fit."""
    from jaxcrank import sweep

    base, names = jc.paper(), ("rod_length",)
    settings = sweep.Settings(revolutions=0.002, samples_per_revolution=3600, metrics_from_revolution=0.0)
    b2, b8 = sweep.batch_bytes(base, names, settings, 2), sweep.batch_bytes(base, names, settings, 8)
    assert b8 > b2 > 0
    budget = 10 * b8
    fits = sweep.chunk_that_fits(base, names, settings, budget)
    assert sweep.batch_bytes(base, names, settings, fits) <= budget
    with pytest.raises(jc.ParameterError, match=rf"chunk = {4 * fits} .* use chunk <= {fits} per device"):
        sweep.check_chunk_fits(base, names, settings, 4 * fits, budget)
    sweep.check_chunk_fits(base, names, settings, fits, budget)  # fits: no error


def _reference_program_bytes(samples_per_degree):
    from optim import ensemble as W
    from optim.ensemble import Ensemble

    obj = Ensemble(t_start=0.002, t_end=0.004, window=5e-4, windows=4, samples_per_degree=samples_per_degree)
    grid = obj.grid(jc.paper())
    base = jc.paper()

    def solve(length):
        return W.tracked_solve(set_parameters(base, ["rod_length"], length), grid, obj.windows, obj.options, False)

    program = jax.jit(solve)
    memory = program.lower(jnp.array([0.403])).compile().memory_analysis()
    return memory.temp_size_in_bytes + memory.output_size_in_bytes


def test_objective_solve_stores_only_the_window_starts():
    """The design objective's forward solve (optim.ensemble.tracked_solve, behind the
    Eq. 19 value, sensitivities and design terms) tracks its metrics and stores the
    K window starts only: the same bytes at 1 and 100 samples per degree, and the
    same value and start states as a solve that stores every sample (to rounding)."""
    from optim import ensemble as W
    from optim.ensemble import Ensemble

    assert _reference_program_bytes(1) == _reference_program_bytes(100)
    obj = Ensemble(t_start=0.002, t_end=0.004, window=5e-4, windows=4)
    mech = jc.paper()
    grid = obj.grid(mech)
    n_start, n_eval, _, dt = grid
    sim = W.tracked_solve(mech, grid, obj.windows, obj.options, True)
    assert sim.ys.shape[0] == 4
    stored = jc.simulate(mech, ts=dt * np.arange(n_start + n_eval + 1))
    idx = W.window_start_indices(grid, obj.windows)
    np.testing.assert_allclose(np.asarray(sim.ys), np.asarray(stored.ys)[idx], rtol=1e-12, atol=1e-12)
    err = outputs.transmission_angle_error(mech, stored.ts[n_start + 1 :], stored.ys[n_start + 1 :])
    rms = float(jnp.sqrt(jnp.mean(err**2)))
    assert float(sim.metrics["rms_transmission_angle_error_deg"]) == pytest.approx(rms, rel=1e-12)
