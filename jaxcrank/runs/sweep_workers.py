"""Solving a sweep's chunks in local worker processes (``workers = N``).

Each task carries what it needs (the base mechanism as a parameter dict, the
parameter names, the settings and the chunk's designs), so a worker keeps no module
state: the mechanism is rebuilt per chunk (microseconds), and the compiled solve is
reused from [`jaxcrank.runs.sweep_dispatch.evaluate`][]'s cache.
"""

from __future__ import annotations

import dataclasses
import itertools
import multiprocessing
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

import numpy as np
from jaxtyping import Float

from . import config
from .sweep_design import Settings
from .sweep_dispatch import evaluate


@dataclasses.dataclass(frozen=True)
class _Job:
    """What every chunk of one sweep shares, sent with each chunk to a worker."""

    base: dict  # config.to_dict of the base mechanism
    names: tuple[str, ...]
    settings: Settings


def _solve_chunk(job: _Job, xs):
    # a fresh (spawned) process: importing jaxcrank applies jaxcrank.numerics.runtime's XLA options
    return evaluate(config.from_dict(job.base), list(job.names), job.settings, xs)


def run_in_workers(
    base,
    names,
    settings,
    chunks: Sequence[tuple[Sequence[int], Float[np.ndarray, "chunk params"]]],
    workers: int,
    record: Callable,
):
    """Solve ``chunks`` (pairs of design indices and their (chunk, params) values) in
    ``workers`` spawned processes, at most two chunks queued per worker, and call
    ``record(indices, result)`` for each as it finishes (the table is sorted when read)."""
    job = _Job(config.to_dict(base), tuple(names), settings)
    ctx = multiprocessing.get_context("spawn")  # a forked JAX runtime is not safe
    with ProcessPoolExecutor(workers, mp_context=ctx) as pool:
        pending, queue = {}, iter(chunks)
        for idx, xs in itertools.islice(queue, 2 * workers):
            pending[pool.submit(_solve_chunk, job, xs)] = idx
        while pending:
            finished, _ = wait(pending, return_when=FIRST_COMPLETED)
            for future in finished:
                record(pending.pop(future), future.result())
                for idx, xs in itertools.islice(queue, 1):
                    pending[pool.submit(_solve_chunk, job, xs)] = idx
