"""Headline metrics accumulated during a solve, with memory that does not grow
with the number of samples or steps.

[`MetricsTracking`][jaxcrank.numerics.tracking.MetricsTracking] wraps a diffrax solver. After each step it

- evaluates the signals of the mechanism's peak metrics
  ([`jaxcrank.physics.signals.peak_metrics`][]) at the step's end
  and keeps their running maxima: the peaks over the solution, independent of the
  output sample times (a step a few microseconds long resolves an impact, an
  output sample every 0.1 deg of crank angle does not);
- evaluates the signals of its RMS metrics ([`jaxcrank.physics.signals.rms_metrics`][]) at the sample times
  that fall in the step, from the step's dense output (the values ``SaveAt(ts=...)``
  would store), and adds their squares: the RMS over the samples, the numbers of the
  RMS of stored samples (to rounding). The sample times are equally spaced and
  generated one at a time, so nothing is kept per sample.

diffrax keeps a solver's state only for accepted steps, so rejected steps leave
no trace. The window of every metric is ``t > t_start``; the peaks of the contact
forces are also kept over the whole run. Forward mode only: the sample loop is a
``while_loop``, which reverse-mode autodiff does not go through (gradients of RMS
metrics use stored samples of short windows, [`optim.objective`][]).
"""

from __future__ import annotations

from typing import NamedTuple

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, Int

from ..physics import model, signals


class Running(NamedTuple):
    """The accumulators (a solver-state entry): peaks over step ends in the window
    and over the whole run (in the order of the mechanism's
    [`peak_metrics`][jaxcrank.physics.signals.peak_metrics]), sums of squares over the window's samples and
    their count (order of its [`rms_metrics`][jaxcrank.physics.signals.rms_metrics]), and the index of the
    next sample time."""

    peaks: Float[Array, " peaks"]
    whole_run_peaks: Float[Array, " peaks"]
    sums: Float[Array, " rms"]
    count: Int[Array, ""]
    next_sample: Int[Array, ""]


class MetricsTracking(diffrax.AbstractAdaptiveSolver):
    """A diffrax solver that steps like ``solver`` and accumulates the headline
    metrics ([`Running`][jaxcrank.numerics.tracking.Running]) in its state. ``args`` of the solve must be the
    mechanism ([`AbstractMechanism`][jaxcrank.physics.linkage.AbstractMechanism]).

    Attributes:
        solver: the solver that takes the steps (its steps, error estimates and dense
            output are passed through unchanged).
        first_sample: the first of the equally spaced sample times of the RMS metrics, s.
        last_sample: the last of those sample times, s.
        n_samples: number of sample times, >= 2 (static).
        t_start: the metrics cover t > t_start, s.
    """

    solver: diffrax.AbstractSolver
    first_sample: Float[Array, ""]
    last_sample: Float[Array, ""]
    n_samples: int = eqx.field(static=True)
    t_start: Float[Array, ""] = eqx.field(kw_only=True)

    def sample_time(self, k):
        """The k-th sample time, s (the last one exactly ``last_sample``)."""
        n = self.n_samples
        step = (self.last_sample - self.first_sample) / (n - 1)
        return jnp.where(k >= n - 1, self.last_sample, self.first_sample + jnp.asarray(k, dtype=step.dtype) * step)

    @property
    def term_structure(self):
        return self.solver.term_structure

    @property
    def interpolation_cls(self):  # pyright: ignore
        return self.solver.interpolation_cls

    def order(self, terms):
        return self.solver.order(terms)

    def strong_order(self, terms):
        return self.solver.strong_order(terms)

    def error_order(self, terms):
        return self.solver.error_order(terms)

    def init(self, terms, t0, t1, y0, args):
        running = Running(
            signals.initial_peaks(args),
            signals.initial_peaks(args),
            jnp.zeros(len(signals.rms_metrics(args))),
            jnp.zeros((), dtype=int),
            jnp.zeros((), dtype=int),
        )
        return self.solver.init(terms, t0, t1, y0, args), running

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        inner, run = solver_state
        y1, y_error, dense_info, inner, result = self.solver.step(terms, t0, t1, y0, args, inner, made_jump)
        mech = args
        interpolation = self.solver.interpolation_cls(t0=t0, t1=t1, **dense_info)
        n = self.n_samples

        def visit(carry):
            """One output frame: at the next sample time within the step (its RMS signals),
            else at the step's end (its peaks, and the loop ends); one frame in the program
            serves both."""
            i, sums, count, peaks, whole, _ = carry
            sample = (i < n) & (self.sample_time(i) <= t1)
            t = jnp.where(sample, self.sample_time(i), t1)
            frame = model.evaluate(mech, t, jnp.where(sample, interpolation.evaluate(t), y1))
            sig, value = signals.rms_signals(mech, frame), signals.peak_values(mech, frame)
            inside = sample & (t > self.t_start)
            sums = sums + jnp.where(inside, sig**2, 0.0)
            peaks = jnp.where(~sample & (t1 > self.t_start), jnp.maximum(peaks, value), peaks)
            whole = jnp.where(sample, whole, jnp.maximum(whole, value))
            return i + sample.astype(i.dtype), sums, count + inside.astype(count.dtype), peaks, whole, ~sample

        carry = (run.next_sample, run.sums, run.count, run.peaks, run.whole_run_peaks, jnp.asarray(False))
        i, sums, count, peaks, whole, _ = jax.lax.while_loop(lambda c: ~c[-1], visit, carry)
        return y1, y_error, dense_info, (inner, Running(peaks, whole, sums, count, i)), result

    def func(self, terms, t0, y0, args):
        return self.solver.func(terms, t0, y0, args)


def finish(running: Running, mech) -> dict[str, Array]:
    """The metrics of ``mech`` ([`jaxcrank.physics.signals.metric_definitions`][], in that
    order) from the accumulators of a finished solve, plus the whole run's peak contact
    forces (``peak_contact_force_<joint>_whole_run_N``); units as in the names. A window
    without samples gives an RMS of 0."""
    peak_names, rms_names = signals.peak_metrics(mech), signals.rms_metrics(mech)
    out = dict(zip(peak_names, jnp.moveaxis(running.peaks, -1, 0)))
    n = jnp.maximum(running.count, 1)[..., None].astype(running.sums.dtype)
    out.update(zip(rms_names, jnp.moveaxis(jnp.sqrt(running.sums / n), -1, 0)))
    whole_run = dict(zip(peak_names, jnp.moveaxis(running.whole_run_peaks, -1, 0)))
    ordered = {k: out[k] for k in signals.metric_definitions(mech)}
    for name in signals.force_metrics(mech):
        ordered[whole_run_name(name)] = whole_run[name]
    return ordered


def whole_run_name(name: str) -> str:
    """``peak_contact_force_B_N`` -> ``peak_contact_force_B_whole_run_N``."""
    return name[: -len("_N")] + "_whole_run_N"
