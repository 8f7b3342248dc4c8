"""Gradient-free evaluation of a problem's objective over many designs at once:
the ``vmap`` grid search (ground truth for the optimiser and its gradient-free
baseline) and the batched evaluations the 1-D scans use.

Each design is one forward solve from the pins-centred start (the ``pathwise``
Eq. 19 value, which is the objective itself) plus the cost term. Designs are
solved ``chunk`` at a time under ``vmap`` so memory stays bounded; a design whose
solve fails is reported in ``status`` (never a silent NaN).
"""

from __future__ import annotations

import dataclasses
import functools
import itertools

import jax
import jax.numpy as jnp
import numpy as np
from tqdm.auto import tqdm

from .objective import pathwise_errors
from .problem import Problem


@functools.partial(jax.jit, static_argnums=0)
def _batch(problem: Problem, xs):
    def one(x):
        sq, ok = pathwise_errors(problem.mechanism(x), problem.objective)
        return jnp.sqrt(jnp.mean(sq)) + problem.cost(x), ok

    return jax.vmap(one)(xs)


def evaluate(problem: Problem, xs, chunk: int = 16, progress: bool = True):
    """Objective (degrees, incl. cost) and status at SI designs ``xs`` (N, n).

    Returns ``(values, ok)``: ``values[i]`` is NaN exactly where ``ok[i]`` is False
    (the solve failed; see ``jaxcrank.simulate(..., throw=False)``).
    """
    xs = np.atleast_2d(np.asarray(xs, dtype=float))
    values, oks = [], []
    with tqdm(total=len(xs), desc="designs", unit="design", disable=not progress) as bar:
        for i in range(0, len(xs), chunk):
            block = xs[i:i + chunk]
            pad = chunk - len(block) if len(xs) > chunk else 0  # one compiled shape
            padded = np.concatenate([block, np.repeat(block[-1:], pad, axis=0)]) if pad else block
            v, ok = _batch(problem, jnp.asarray(padded))
            v, ok = np.asarray(v)[:len(block)], np.asarray(ok)[:len(block)]
            values.append(np.where(ok, v, np.nan))
            oks.append(ok)
            bar.update(len(block))
    return np.concatenate(values), np.concatenate(oks)


@dataclasses.dataclass
class Grid:
    """Result of :func:`grid_search` over two variables.

    Attributes: axes (2 arrays, SI), values (n0, n1) degrees (NaN where infeasible or
    failed), feasible and ok masks, best (SI design) and best_value (degrees).
    """

    axes: tuple[np.ndarray, np.ndarray]
    values: np.ndarray
    feasible: np.ndarray
    ok: np.ndarray
    best: np.ndarray
    best_value: float


def grid_search(problem: Problem, n: int = 21, chunk: int = 21, progress: bool = True) -> Grid:
    """Evaluate an ``n`` x ``n`` grid over the box of a two-variable problem."""
    if problem.n != 2:
        raise ValueError("grid_search needs a two-variable problem")
    axes = tuple(np.linspace(lo, hi, n) for lo, hi in zip(problem.lower, problem.upper))
    pts = np.array(list(itertools.product(*axes)))
    feasible = problem.feasible(pts)
    values = np.full(len(pts), np.nan)
    ok = np.zeros(len(pts), bool)
    if feasible.any():
        v, o = evaluate(problem, pts[feasible], chunk=chunk, progress=progress)
        values[feasible], ok[feasible] = v, o
    i = int(np.nanargmin(values))
    return Grid(axes, values.reshape(n, n), feasible.reshape(n, n), ok.reshape(n, n), pts[i], float(values[i]))

