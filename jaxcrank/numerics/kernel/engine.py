"""Running batches of designs through the compiled kernel (CPU, OpenMP).

[`solve`][jaxcrank.numerics.kernel.engine.solve] is the kernel's counterpart of the JAX path's
[`jaxcrank.runs.sweep.simulate_design`][jaxcrank.runs.sweep_design.simulate_design] over many designs: each design's
adaptive
tsit5 solve from the pins-centred start, with the headline metrics accumulated in the
kernel, and the same status codes ([`jaxcrank.numerics.results.RESULTS`][]: ``successful``,
``max_steps_reached``, ``non_finite``). Designs are independent: one per thread, each with its
own steps, so a design's numbers do not depend on its batch mates, the batch size or
the thread count.
"""

from __future__ import annotations

import functools
import os
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from ...physics.linkage import AbstractMechanism as Mechanism
from ...physics.parameters import set_parameters
from ...physics.params import ParameterError
from ..results import RESULTS, code
from . import build, source

#: the status codes the kernel returns (codes of [`jaxcrank.numerics.results.RESULTS`][])
OK, MAX_STEPS, NON_FINITE = (int(code(i)) for i in (RESULTS.successful, RESULTS.max_steps_reached, RESULTS.non_finite))


class Batch(NamedTuple):
    """What the kernel returns for a batch of n designs.

    Attributes:
        metrics: (n, metrics) in the order of the structure's metrics
            ([`jaxcrank.numerics.kernel.source.names`][]), units in the names.
        status: (n,) status codes (`OK`, `MAX_STEPS` or `NON_FINITE`).
        steps: (n,) accepted steps. rejected: (n,) rejected steps.
        y: (n, state) scaled state at the end (where the solve stopped).
        whole_run_peaks: (n, peak metrics) peaks over the whole run, not only the window.
    """

    metrics: np.ndarray
    status: np.ndarray
    steps: np.ndarray
    rejected: np.ndarray
    y: np.ndarray
    whole_run_peaks: np.ndarray


def available() -> bool:
    """Whether the CPU kernel can be built here (a C compiler is on the PATH)."""
    return build.compiler() is not None


@functools.lru_cache(maxsize=16)
def library(st: source.Structure) -> build.Compiled:
    """The compiled kernel of a mechanism structure (generated, compiled or loaded from the cache)."""
    return build.compile_source(source.kernel_source(st))


def default_threads() -> int:
    """Threads the kernel uses by default: the CPUs this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def finish(st: source.Structure, peaks, sums, count) -> np.ndarray:
    """The metrics (n, metrics) of structure ``st`` from the kernel's accumulators, as
    [`jaxcrank.numerics.tracking.finish`][] computes them."""
    nm = source.names(st)
    out = {k: peaks[:, j] for j, k in enumerate(nm.peak)}
    rms = np.sqrt(sums / np.maximum(count, 1)[:, None])
    out.update({k: rms[:, j] for j, k in enumerate(nm.rms)})
    return np.stack([out[k] for k in nm.metrics], axis=1)


def solve_mechanisms(
    mechs: Sequence[Mechanism],
    t_end: Sequence[float],
    t_start: Sequence[float],
    n_samples: int,
    *,
    rtol: float = 1e-6,
    atol: float = 1e-6,
    dt0: float = 1e-6,
    max_steps: int = 500_000,
    y0: np.ndarray | None = None,
    threads: int | None = None,
    vector: bool = True,
) -> Batch:
    """Solve each mechanism from 0 to its ``t_end`` (s) with tsit5, tracking the
    headline metrics over ``t > t_start`` (s) with ``n_samples`` equally spaced RMS
    sample times from 0 to ``t_end`` (as [`jaxcrank.simulate`][jaxcrank.numerics.solve.simulate] with
    ``metrics_start``). All mechanisms must share one structure (laws, ideal joints).

    Args:
        mechs: the designs.
        t_end: end time per design, s.
        t_start: start of the metrics window per design, s.
        n_samples: RMS sample times per design, >= 2.
        rtol: relative tolerance, scaled state, > 0 (as [`jaxcrank.numerics.solve.SolveOptions`][]).
        atol: absolute tolerance, scaled units, > 0.
        dt0: initial step, s, > 0.
        max_steps: step budget per design (accepted and rejected steps), >= 1.
        y0: (n, state) scaled initial states (default pins centred, zeros).
        threads: OpenMP threads (default [`default_threads`][jaxcrank.numerics.kernel.engine.default_threads]).
        vector: solve four designs per thread, one per vector lane (the default; the
            numbers equal the one-design-per-thread loop's bit for bit, which
            ``vector=False`` runs).

    Raises:
        ParameterError: for mechanisms of different structures, ``n_samples < 2`` or bad settings.
    """
    if not mechs:
        raise ParameterError("solve_mechanisms needs at least one mechanism")
    st = source.structure(mechs[0])
    params = np.stack([source.parameter_vector(m) for m in mechs])
    for m in mechs[1:]:
        if source.structure(m) != st:
            raise ParameterError("all designs of a kernel batch must share laws and ideal joints (one structure)")
    return _run(st, params, t_end, t_start, n_samples, rtol, atol, dt0, max_steps, y0, threads, vector)


def _run(st, params, t_end, t_start, n_samples, rtol, atol, dt0, max_steps, y0, threads, vector=True) -> Batch:
    """Solve the designs whose run-time inputs (``st``'s layout) are the rows of ``params``."""
    if int(n_samples) < 2:
        raise ParameterError(f"n_samples = {n_samples} must be >= 2")
    if not (rtol > 0 and atol > 0 and dt0 > 0 and int(max_steps) >= 1):
        raise ParameterError("rtol, atol and dt0 must be > 0 and max_steps >= 1")
    lib = library(st)
    n_params, n_state, n_peak, n_rms = lib.layout
    n = len(params)
    params = np.ascontiguousarray(params, dtype=np.float64).reshape(n, n_params)
    y = np.zeros((n, n_state)) if y0 is None else np.array(y0, dtype=np.float64, order="C", copy=True)
    if y.shape != (n, n_state):
        raise ParameterError(f"y0 must have shape ({n}, {n_state}), got {y.shape}")
    t_end = np.ascontiguousarray(t_end, dtype=np.float64)
    t_start = np.ascontiguousarray(t_start, dtype=np.float64)
    peaks, whole = np.zeros((n, n_peak)), np.zeros((n, n_peak))
    sums = np.zeros((n, n_rms))
    count, accepted, rejected = (np.zeros(n, dtype=np.int64) for _ in range(3))
    result = np.zeros(n, dtype=np.int32)
    threads = default_threads() if threads is None else int(threads)
    (lib.lib.jk_solve_v if vector else lib.lib.jk_solve)(
        n, threads, params, t_end, t_start, int(n_samples), int(max_steps), float(rtol), float(atol), float(dt0),
        y, peaks, whole, sums, count, accepted, rejected, result,
    )  # fmt: skip
    values = finish(st, peaks, sums, count)
    finite = np.all(np.isfinite(y), axis=1) & np.all(np.isfinite(values), axis=1)
    status = np.where(result == 0, np.where(finite, OK, NON_FINITE), MAX_STEPS)
    return Batch(values, status.astype(np.int64), accepted, rejected, y, whole)


def initial_states(base: Mechanism, names: Sequence[str], xs: np.ndarray) -> np.ndarray:
    """The scaled pins-centred start ([`jaxcrank.physics.model.initial_state`][jaxcrank.physics.state.initial_state])
    of each design ``xs`` (n, len(names)) of ``base``, shape (n, state): zeros where the
    base's joint laws all start at zero (every law of jaxcrank does), else design by design."""
    from ...physics import model

    xs = np.atleast_2d(np.asarray(xs, dtype=np.float64))
    y0 = np.asarray(model.initial_state(base))
    if not np.any(y0):
        return np.zeros((len(xs), y0.size))
    return np.stack([np.asarray(model.initial_state(set_parameters(base, list(names), list(x)))) for x in xs])


def solve(
    base: Mechanism, names: Sequence[str], xs: np.ndarray, settings, threads: int | None = None, vector: bool = True
) -> Batch:
    """Designs ``xs`` (n, len(names)) of ``base`` (SI values of ``names``), simulated as
    a sweep's [`SweepSettings`][jaxcrank.runs.sweep_design.SweepSettings] ask (revolutions, samples,
    metrics window, tolerances, step budget).

    Raises:
        ParameterError: when ``settings.options.solver`` is not tsit5 (the kernel's only solver).
    """
    if settings.options.solver_name != "tsit5":
        raise ParameterError(
            f"the kernel engine solves with tsit5 only, not {settings.options.solver_name!r}: use engine='xla'"
        )
    xs = np.atleast_2d(np.asarray(xs, dtype=np.float64))
    periods = np.array([float(set_parameters(base, list(names), [float(v) for v in x]).period) for x in xs])
    o = settings.options
    st = source.structure(base, names)  # the parameters that do not vary are compile-time constants
    t_end, t_start = settings.revolutions * periods, settings.metrics_from_revolution * periods
    y0 = initial_states(base, names, xs)
    args = (settings.n_samples, o.rtol, o.atol, o.dt0, o.max_steps, y0, threads, vector)
    return _run(st, xs, t_end, t_start, *args)
