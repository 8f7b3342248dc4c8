"""Gradient-free evaluation of a problem's objective over many designs at once:
the ``vmap`` grid search (ground truth for the optimiser and its gradient-free
baseline) and the batched evaluations the 1-D scans use.

Each design is one forward solve from the pins-centred start (the
[`Pathwise`][optim.objective.Pathwise] value over the objective's window, which is the
windowed objectives' value) plus the cost term; for a robust
problem (``Problem.samples > 0``) the mean over its manufactured parts. Designs are
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
from jaxtyping import ArrayLike, Bool, Float
from tqdm.auto import tqdm

from jaxcrank.physics.params import ParameterError

from .ensemble import Ensemble
from .objective import AbstractObjective, Pathwise
from .problem import AbstractProblem as Problem


def pathwise_of(objective: AbstractObjective) -> Pathwise:
    """The [`Pathwise`][optim.objective.Pathwise] objective over the same window and
    tolerances as ``objective`` (a windowed one: pathwise or ensemble), whose value is
    the objective's value.

    Raises:
        ParameterError: ``objective`` has no evaluation window (the steady state: evaluate
            its designs with [`optim.steady`][]).
    """
    if isinstance(objective, Pathwise):
        return objective
    if isinstance(objective, Ensemble):
        keep = ("t_start", "t_end", "samples_per_degree", "options")
        return Pathwise(**{k: getattr(objective, k) for k in keep})
    raise ParameterError(
        f"the grid search evaluates windowed objectives (Pathwise, Ensemble), not {type(objective).__name__}"
    )


@functools.partial(jax.jit, static_argnums=0)
def _batch(problem: Problem, xs):
    objective = pathwise_of(problem.objective)

    def value(mech):
        rms, ok = objective.evaluate(mech)
        return problem.loss(rms), ok

    def one(x):
        if not getattr(problem, "samples", 0):
            return value(problem.mechanism(x))
        # robust problem: the mean over the same manufactured parts as the objective
        values, ok = jax.vmap(lambda d: value(problem.part(x, d)))(jnp.asarray(problem.draws()))
        return jnp.mean(values), jnp.all(ok)

    return jax.vmap(one)(xs)


def evaluate(
    problem: Problem, xs: Float[ArrayLike, "designs n"], chunk: int = 16, progress: bool = True
) -> tuple[Float[np.ndarray, " designs"], Bool[np.ndarray, " designs"]]:
    """Objective (degrees, incl. cost) and status at SI designs ``xs`` (N, n).

    Returns ``(values, ok)``: ``values[i]`` is NaN exactly where ``ok[i]`` is False
    (the solve failed; see ``jaxcrank.simulate(..., throw=False)``).
    """
    xs = np.atleast_2d(np.asarray(xs, dtype=float))
    errors, ok = rms_errors(problem, xs, chunk, progress)
    return _with_cost(problem, xs, errors, ok), ok


def _with_cost(problem: Problem, xs, errors, ok):
    """Eq. 19 errors plus the problem's cost at designs ``xs``; NaN where not ``ok``."""
    cost = np.array([float(problem.cost(x)) for x in xs])
    return np.where(ok, errors + cost, np.nan)


def rms_errors(
    problem: Problem, xs: Float[ArrayLike, "designs n"], chunk: int = 16, progress: bool = True
) -> tuple[Float[np.ndarray, " designs"], Bool[np.ndarray, " designs"]]:
    """The problem's values without the cost term (degrees; Eq. 19 for a parameter problem)
    and status at SI designs ``xs``."""
    xs = np.atleast_2d(np.asarray(xs, dtype=float))
    values, oks = [], []
    with tqdm(total=len(xs), desc="designs", unit="design", disable=not progress) as bar:
        for i in range(0, len(xs), chunk):
            block = xs[i : i + chunk]
            pad = chunk - len(block)  # one compiled shape per chunk size, also for a single design
            padded = np.concatenate([block, np.repeat(block[-1:], pad, axis=0)]) if pad else block
            v, ok = _batch(problem, jnp.asarray(padded))
            v, ok = np.asarray(v)[: len(block)], np.asarray(ok)[: len(block)]
            values.append(np.where(ok, v, np.nan))
            oks.append(ok)
            bar.update(len(block))
    return np.concatenate(values), np.concatenate(oks)


@dataclasses.dataclass
class Grid:
    """Result of [`grid_search`][optim.search.grid_search] over two variables.

    Attributes: axes (2 arrays, SI), values (n0, n1) objective incl. cost, degrees
    (NaN where infeasible or failed), errors (n0, n1) the Eq. 19 part alone, feasible
    and ok masks, best (SI design) and best_value (degrees).
    """

    axes: tuple[np.ndarray, np.ndarray]
    values: np.ndarray
    errors: np.ndarray
    feasible: np.ndarray
    ok: np.ndarray
    best: np.ndarray
    best_value: float


def grid_axes(problem: Problem, n: int) -> tuple[Float[np.ndarray, " points"], ...]:
    """The ``n`` points per axis of the grid over the box, SI."""
    return tuple(np.linspace(lo, hi, n) for lo, hi in zip(problem.lower, problem.upper))


def grid_search(
    problem: Problem,
    n: int = 21,
    chunk: int = 21,
    progress: bool = True,
    errors: Float[ArrayLike, "points points"] | None = None,
) -> Grid:
    """Evaluate an ``n`` x ``n`` grid over the box of a two-variable problem.

    ``errors``: the (n, n) Eq. 19 values of the same grid from an earlier run of
    the same objective ([`read_grid`][optim.search.read_grid]); the cost term is then recomputed, so a
    landscape can be reused with another ``cost_weight``."""
    if problem.n != 2:
        raise ValueError("grid_search needs a two-variable problem")
    axes = grid_axes(problem, n)
    pts = np.array(list(itertools.product(*axes)))
    feasible = problem.feasible(pts)
    values = np.full(len(pts), np.nan)
    errs = np.full(len(pts), np.nan)
    ok = np.zeros(len(pts), bool)
    if feasible.any():
        if errors is None:
            e, o = rms_errors(problem, pts[feasible], chunk=chunk, progress=progress)
        else:
            e = np.asarray(errors, float).reshape(-1)[feasible]
            o = np.isfinite(e)
        errs[feasible], ok[feasible] = e, o
        values[feasible] = _with_cost(problem, pts[feasible], e, o)
    i = int(np.nanargmin(values))
    return Grid(
        axes,
        values.reshape(n, n),
        errs.reshape(n, n),
        feasible.reshape(n, n),
        ok.reshape(n, n),
        pts[i],
        float(values[i]),
    )


def write_grid(path, problem: Problem, grid: Grid):
    """``grid.csv``: one row per grid point; SI variables, the Eq. 19 error, the
    cost and their sum (degrees), feasibility and solve status."""
    import csv

    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(
            [f"{n}_SI" for n in problem.names] + ["rms_error_deg", "cost_deg", "objective_deg", "feasible", "ok"]
        )
        for (i, a), (j, b) in itertools.product(enumerate(grid.axes[0]), enumerate(grid.axes[1])):
            v, e = grid.values[i, j], grid.errors[i, j]
            w.writerow(
                [
                    repr(float(a)),
                    repr(float(b)),
                    repr(float(e)),
                    repr(float(v - e)),
                    repr(float(v)),
                    bool(grid.feasible[i, j]),
                    bool(grid.ok[i, j]),
                ]
            )


def read_grid(path, problem: Problem, n: int) -> Float[np.ndarray, "points points"]:
    """The (n, n) Eq. 19 errors of a ``grid.csv`` written by [`write_grid`][optim.search.write_grid] for
    the same variables and box (checked); NaN where infeasible or failed."""
    import csv

    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    cols = [f"{nm}_SI" for nm in problem.names]
    if len(rows) != n * n or any(c not in rows[0] for c in cols + ["rms_error_deg"]):
        raise ParameterError(
            f"--grid-from {path} is not a grid.csv of an {n} x {n} grid over "
            f"{list(problem.names)}: give the grid.csv of a run with the same variables and --grid {n}"
        )
    try:
        pts = np.array([[float(r[c]) for c in cols] for r in rows])
        errors = np.array([float(r["rms_error_deg"]) if r["rms_error_deg"] != "" else np.nan for r in rows])
    except (TypeError, ValueError):
        raise ParameterError(f"--grid-from {path}: a cell is not a number (a damaged grid.csv?)") from None
    expect = np.array(list(itertools.product(*grid_axes(problem, n))))
    if not np.allclose(pts, expect, rtol=1e-12, atol=0.0):
        raise ParameterError(
            f"--grid-from {path}: its grid points are not the {n} x {n} grid over this "
            "problem's box: give the grid.csv of a run with the same box and --grid"
        )
    return errors.reshape(n, n)
