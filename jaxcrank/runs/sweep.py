"""Sweeps: many designs of one mechanism, one at a time or in ``vmap`` batches.

A sweep is a table of designs over named parameters (any name
[`jaxcrank.physics.parameters.set_parameter`][] accepts: ``rod_length``,
``contact.restitution``, ``clearance_B``, ...), built by a sampler
([`full_factorial`][jaxcrank.runs.sampling.full_factorial], [`latin_hypercube`][jaxcrank.runs.sampling.latin_hypercube]
, [`random_uniform`][jaxcrank.runs.sampling.random_uniform] ,
[`one_at_a_time`][jaxcrank.runs.sampling.one_at_a_time] , [`monte_carlo`][jaxcrank.runs.sampling.monte_carlo] ) and run
by [`run`][jaxcrank.runs.sweep.run] :

- each design is checked on the host first (an invalid one, e.g. a
  non-assemblable geometry, gets ``status = "invalid"`` and the parameter error as
  its message) and then solved with ``throw=False``, ``chunk`` designs at a time: a
  device given one design solves it alone, a device given several solves them in a
  ``vmap`` batch (memory stays bounded either way); a failed solve is reported in the
  ``status`` column (``max_steps``, ``solver_failed``, ``non_finite``) and its
  metric cells are left empty, never NaN;
- the table (``table.csv``, one row per design: index, parameters, status,
  headline metrics with their units in the column names) is appended after every
  batch, each batch in one ``write`` (a killed process leaves whole batches), so a
  killed sweep resumed with ``resume=True`` only solves what is missing; a table or
  ``designs.npy`` that is truncated, corrupted or from another sweep raises
  [`CorruptFileError`][jaxcrank.errors.CorruptFileError] naming the file, never a silent restart;
- a chunk is a ``jax.Array`` sharded over every device of every process of a
  ``jax.distributed`` job; each device solves its shard with its own compiled solve
  (no per-step collective; see [`jaxcrank.runs.sweep_dispatch.evaluate`][]);
- ``workers = N`` solves chunks in N local processes (one per CPU core), the way to
  use several cores of one machine: XLA compiles the solver loop into one
  single-threaded kernel ([`jaxcrank.numerics.runtime`][]), and several host devices in one
  process do not run at the same time.

Which chunk is fastest depends on the device (``bench/bench_sweep.py``): on a CPU a
design solved alone (``chunk = 1`` per device, the default there) beats any ``vmap``
batch, which steps every member until the slowest one finishes and selects each
update per member; a GPU needs batches of thousands (default: the largest batch that fits
in its free memory, [`default_chunk`][jaxcrank.runs.sweep_dispatch.default_chunk]).

Reproducibility: a design's numbers do not depend on its batch mates, its position
in the batch, the batch size (>= 2), the number of devices, processes or workers
(with [`jaxcrank.numerics.runtime`][]'s XLA options: no FMA contraction, which otherwise
rounds differently per lane and batch size). Solving alone (one design per device)
and in a batch are two compiled programs that round differently in the last bit,
which impact chaos amplifies (1e-5..1e-3 relative after 3 ms): a resumed sweep must
keep its chunk per device on the same side of that line.

The headline metrics are the base mechanism's
([`metric_names`][jaxcrank.runs.sweep_design.metric_names]: named from its description, e.g.
``max_abs_slider_x_deviation_m`` for the slider-crank, ``max_abs_rocker_angle_deviation_deg``
for the four-bar), after the first revolution by default: the same numbers
``jaxcrank simulate`` writes to ``summary.json``.

This module runs a sweep ([`run`][jaxcrank.runs.sweep.run], [`summarize`][jaxcrank.runs.sweep.summarize] ); its parts
live beside it and
their public names are re-exported here: one design's settings and solve
([`jaxcrank.runs.sweep_design`][]), memory planning and sharded dispatch
([`jaxcrank.runs.sweep_dispatch`][]), the table and atomic I/O
([`jaxcrank.runs.sweep_table`][]) and worker processes ([`jaxcrank.runs.sweep_workers`][]).
"""

from __future__ import annotations

import dataclasses  # noqa: F401  (sweep.dataclasses.fields(sweep.Settings) lists the settings)
from collections.abc import Mapping, Sequence
from pathlib import Path

import jax
import numpy as np
from jaxtyping import ArrayLike, Float, Shaped

from ..numerics import results
from ..physics.linkage import AbstractMechanism as Mechanism
from ..physics.params import ParameterError
from . import programs
from .sweep_design import (
    SOLVE_KEYS,
    STATUSES,
    Settings,
    SweepSettings,
    metric_names,
    simulate_design,
    split_valid,
    validate,
)
from .sweep_dispatch import (
    batch_bytes,
    check_chunk_fits,
    chunk_that_fits,
    default_chunk,
    free_device_bytes,
    resolve_chunk,
)
from .sweep_dispatch import evaluate as _evaluate
from .sweep_table import (
    append,
    atomic_write,
    columns,
    csv_text,
    metric_columns,
    open_table,
    parameter_columns,
    read_table,
    run_identity,
    table_from_rows,
)
from .sweep_workers import run_in_workers

__all__ = [
    "SOLVE_KEYS",
    "STATUSES",
    "Settings",
    "SweepSettings",
    "batch_bytes",
    "check_chunk_fits",
    "chunk_that_fits",
    "columns",
    "default_chunk",
    "free_device_bytes",
    "metric_columns",
    "metric_names",
    "parameter_columns",
    "read_table",
    "resolve_chunk",
    "run",
    "run_in_workers",
    "simulate_design",
    "summarize",
    "validate",
]


def run(
    base: Mechanism,
    names: Sequence[str],
    designs: Float[ArrayLike, "designs params"],
    settings: Settings | None = None,
    *,
    out=None,
    resume: bool = False,
    chunk: int | None = None,
    workers: int = 1,
    progress: bool = True,
    engine: str | None = None,
) -> dict[str, Shaped[np.ndarray, " designs"]]:
    """Simulate every design and return the table (as [`read_table`][jaxcrank.runs.sweep_table.read_table]).

    Args:
        base: the mechanism every design starts from.
        names: parameter names (see [`jaxcrank.physics.parameters.set_parameter`][]).
        designs: (N, len(names)) parameter values, SI.
        settings: how each design is simulated (default [`SweepSettings`][jaxcrank.runs.sweep_design.SweepSettings]).
        out: directory for ``table.csv`` and ``designs.npy``, appended after every
            batch; without it the table is only returned.
        resume: continue the sweep in ``out``: designs already in the table are
            not solved again (the designs must be the same, checked exactly).
        chunk: designs solved together (rounded up to a multiple of the device count;
            one per device: each solved alone, several: a ``vmap`` batch per device);
            bounds memory and is the checkpoint granularity. Default
            [`default_chunk`][jaxcrank.runs.sweep_dispatch.default_chunk].
        workers: local processes that solve chunks in parallel (one per CPU core is
            the fastest on a CPU); 1 solves in this process. Not with ``jax.distributed``.
        progress: show the progress on standard error
            ([`jaxcrank.runs.programs.progress`][]: a bar on a terminal, a line every 10 %
            of the designs in a log).
        engine: ``"xla"`` (the compiled JAX solve above) or ``"kernel"`` (the
            per-trajectory C kernel of [`jaxcrank.numerics.kernel`][]: tsit5 only, one
            design per CPU thread, ``workers`` must be 1; ``chunk`` is then the designs per
            kernel call and checkpoint, default [`jaxcrank.runs.engines.default_chunk`][]).
            Same table, statuses and resume. Default ``None``: the kernel where it can run
            the sweep, else xla ([`jaxcrank.runs.engines.default_engine`][]); resuming, the
            engine the sweep was started with, which ``out`` records (the two round
            differently, which impact chaos amplifies).

    Raises:
        ParameterError: bad designs shape, an existing sweep in ``out`` without
            ``resume``, a resumed sweep over other designs or with another engine, or an
            engine that cannot run these settings ([`jaxcrank.runs.engines.check`][]).
        CorruptFileError: a resumed sweep's files cannot be read.
    """
    from . import engines

    settings = SweepSettings() if settings is None else settings
    engine = engines.resolve(engine, settings, workers, jax.process_count() > 1, out, resume, base)
    engines.check(engine, settings, workers, base)
    names = list(names)
    designs = np.atleast_2d(np.asarray(designs, dtype=float))
    if designs.shape[1] != len(names):
        raise ParameterError(f"designs must have one column per parameter {names}, got shape {designs.shape}")
    cols = columns(base, names)
    n_metrics = len(metric_names(base))
    writer = jax.process_index() == 0
    identity = run_identity(base, settings.to_text())
    path, done = open_table(out, resume, designs, cols, names, writer=writer, identity=identity)
    if path is not None and writer:
        atomic_write(Path(out) / engines.ENGINE_FILE, lambda f: f.write(engine.encode()))
    rows: list[list] = []

    def emit(new_rows):
        rows.extend(new_rows)
        if path is not None and writer and new_rows:
            append(path, csv_text(new_rows))

    def row(i, status, message="", metrics=None, steps=""):
        vals = [repr(float(v)) for v in designs[i]]
        m = [repr(float(v)) for v in metrics] if metrics is not None else [""] * n_metrics
        return [i] + vals + [status, message] + m + [steps]

    todo, invalid = split_valid(base, names, designs, done)
    emit([row(i, "invalid", message) for i, message in invalid])

    # a multiple of the device count; one shape for every chunk (one compilation)
    n_dev = jax.device_count()
    given = chunk is not None
    chunk = engines.default_chunk() if engine == "kernel" and chunk is None else chunk
    chunk = resolve_chunk(base, names, settings, chunk)
    if given and todo and engine == "xla":
        check_chunk_fits(base, names, settings, chunk // n_dev, free_device_bytes())
    if int(workers) < 1:
        raise ParameterError(f"workers = {workers} must be >= 1")
    if workers > 1 and jax.process_count() > 1:
        raise ParameterError("workers > 1 cannot be combined with a jax.distributed job: use processes instead")
    chunks = []
    for s in range(0, len(todo), chunk):
        idx = todo[s : s + chunk]
        xs = designs[idx]
        if len(idx) < chunk and engine == "xla":  # one compiled shape: pad with copies of the last design
            xs = np.concatenate([xs, np.repeat(xs[-1:], chunk - len(idx), axis=0)])
        chunks.append((idx, xs))

    def record(idx, result):
        metrics, status, steps = result
        new = []
        for j, i in enumerate(idx):
            st = results.status_label(status[j])
            new.append(row(i, st, results.message(status[j]), metrics[j] if st == "ok" else None, int(steps[j])))
        emit(new)
        bar.update(len(idx))

    with programs.progress(
        len(designs), initial=len(done) + len(invalid), desc="designs", unit="design", disable=not (progress and writer)
    ) as bar:
        if workers > 1 and chunks:
            run_in_workers(base, names, settings, chunks, int(workers), record)
        else:
            evaluate = _evaluate if engine == "xla" else engines.kernel_evaluate
            for idx, xs in chunks:
                record(idx, evaluate(base, names, settings, xs))
    if path is not None:
        if jax.process_count() > 1:
            from jax.experimental import multihost_utils

            multihost_utils.sync_global_devices("jaxcrank sweep table written")
        return read_table(path)
    return table_from_rows([dict(zip(cols, map(str, r))) for r in rows])


def summarize(table: Mapping[str, Shaped[np.ndarray, " designs"]], quantiles=(0.05, 0.5, 0.95)) -> dict:
    """Per metric over the ``ok`` designs (the table's metric columns,
    [`metric_columns`][jaxcrank.runs.sweep_table.metric_columns]): mean, std, min, max and
    quantiles; and the count of each status. Units as in the metric names."""
    ok = np.asarray(table["status"]) == "ok"
    out = {
        "designs": int(len(ok)),
        "status_counts": {s: int(np.sum(table["status"] == s)) for s in STATUSES},
        "metrics": {},
    }
    for k in metric_columns(table):
        v = np.asarray(table[k])[ok]
        if v.size == 0:
            continue
        out["metrics"][k] = {
            "mean": float(v.mean()),
            "std": float(v.std(ddof=1)) if v.size > 1 else 0.0,
            "min": float(v.min()),
            "max": float(v.max()),
            **{f"q{int(round(q * 100)):02d}": float(np.quantile(v, q)) for q in quantiles},
        }
    return out
