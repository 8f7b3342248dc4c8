"""The way in: where a single optimisation run starts.

[`start_points`][optim.way_in.start_points] gives the problem's start and scrambled Sobol points
of the box. The steady-state gradient is exact on the periodic orbit and exactly zero outside the
periodic regime (without a trend estimate), so a gradient run from a design that is not periodic
has nowhere to go. [`periodic_start`][optim.way_in.periodic_start] classifies candidate starts by
their steady state, value only, until one is periodic and has the lowest value classified so far
(else it takes the lowest periodic one), and hands that steady state to the optimiser (its
evaluator warm-starts from it): the start is solved once.
"""

from __future__ import annotations

import dataclasses
import time

import jax.numpy as jnp
import numpy as np
from tqdm.auto import tqdm

from jaxcrank.physics.params import ParameterError

from .problem import AbstractProblem
from .steady import FAILED, PERIODIC, SteadyEvaluator

__all__ = ["CLASSIFY_STARTS", "StartSearch", "periodic_start", "start_points"]

#: candidate starts classified at most by `periodic_start` (the problem's start and 7 Sobol points)
CLASSIFY_STARTS = 8


def start_points(problem: AbstractProblem, count: int, seed: int = 0) -> np.ndarray:
    """``count`` scaled start designs, shape (count, n): the problem's own start
    (`Problem.start_unit`), then scrambled Sobol points of the unit box (``seed``)
    projected onto the feasible set (`Problem.project`).

    Raises:
        ParameterError: for ``count < 1``.
    """
    import warnings

    from scipy.stats import qmc

    if count < 1:
        raise ParameterError(f"starts = {count} must be >= 1")
    first = np.asarray(problem.start_unit(), dtype=float)[None]
    if count == 1:
        return first
    with warnings.catch_warnings():  # Sobol's balance warning for counts that are not powers of 2
        warnings.simplefilter("ignore", UserWarning)
        points = qmc.Sobol(d=problem.n, scramble=True, seed=seed).random(count - 1)
    projected = np.stack([np.asarray(problem.project(jnp.asarray(p)), dtype=float) for p in points])
    return np.concatenate([first, projected])


@dataclasses.dataclass
class StartSearch:
    """What [`periodic_start`][optim.way_in.periodic_start] found.

    Attributes:
        problem: the problem with its start replaced by the chosen design (SI).
        evaluator: the steady-state evaluator that classified the candidates; its last
            periodic steady state is the chosen start's, so passing it to
            [`optimize`][optim.optimize.optimize] does not solve the start again.
        classified: per candidate, in order: ``unit_design`` (scaled), ``value_deg`` (the
            objective, degrees; None where the solve failed), ``regime`` and ``seconds``
            (wall time of its classification, s; the first includes compilation).
        chosen: index of the chosen candidate in ``classified``.
        periodic: whether the chosen design is periodic (False: no candidate was; the
            problem's own start is kept).
    """

    problem: AbstractProblem
    evaluator: SteadyEvaluator
    classified: list
    chosen: int
    periodic: bool

    @property
    def seconds(self) -> float:
        """Wall time of the whole search, s."""
        return float(sum(c["seconds"] for c in self.classified))

    def describe(self) -> dict:
        """Plain values for ``result.json``: ``classified``, ``chosen``, ``periodic``, ``seconds``."""
        return {
            "classified": self.classified,
            "chosen": self.chosen,
            "periodic": self.periodic,
            "seconds": self.seconds,
        }


def periodic_start(
    problem: AbstractProblem,
    count: int = CLASSIFY_STARTS,
    seed: int = 0,
    evaluator: SteadyEvaluator | None = None,
    progress: bool = True,
) -> StartSearch:
    """A periodic start among ``count`` candidate starts of a steady-state problem
    ([`start_points`][optim.way_in.start_points]: the problem's start, then scrambled Sobol
    points), each classified by its steady state (value only: over the orbit where it is
    periodic, else the long-run statistical estimate), in order. The search stops at the first
    periodic candidate whose value is the lowest classified so far. A periodic candidate above a
    value already seen (a design that is not periodic but better, or a better periodic one) is
    passed over: a heuristic, since a descent from it is likely to start in a poorer basin.
    Where no candidate stops the search, the lowest periodic one is chosen. A candidate whose
    value is not finite is never chosen and sets no bar.

    Args:
        problem: a problem whose objective is [`optim.steady.Steady`][].
        count: candidates classified at most, >= 1.
        seed: seed of the Sobol points.
        evaluator: the evaluator to classify with (default: a new one for ``problem``).
        progress: show a progress bar over the candidates.

    Returns:
        a [`StartSearch`][optim.way_in.StartSearch] whose evaluator warm-starts from the chosen
        candidate's orbit (kept as it was classified: it is not solved again); where no
        candidate is periodic, the problem's own start is kept and
        ``periodic`` is False (an optimiser run from it stops at once, saying why).

    Raises:
        ParameterError: ``count < 1`` or an objective other than the steady state.
    """
    evaluator = SteadyEvaluator(problem) if evaluator is None else evaluator
    points = start_points(problem, count, seed)
    classified, lowest, best, chosen = [], np.inf, np.inf, None  # lowest value of any candidate, of a periodic one
    bar = tqdm(points, desc="classifying starts", unit="design", disable=not progress)
    for k, u in enumerate(bar):
        tic = time.perf_counter()
        x = np.asarray(problem.from_unit(jnp.asarray(u)))
        value, info = evaluator.value(x)
        regime = info["regime"] if info["ok"] else FAILED
        finite = bool(np.isfinite(value))
        classified.append(
            {
                "unit_design": np.asarray(u).tolist(),
                "value_deg": float(value) if finite else None,
                "regime": regime,
                "seconds": time.perf_counter() - tic,
            }
        )
        bar.set_postfix(regime=regime)
        if not finite:
            continue
        if regime == PERIODIC and value < best:  # kept by the evaluator: later candidates do not evict it
            best, chosen, x_best = value, k, x
            evaluator.warm_from(x)
            if value <= lowest:
                break
        lowest = min(lowest, value)
    bar.close()
    periodic = chosen is not None
    if periodic:  # a later periodic candidate's orbit may be the last: the kept one is the warm start again
        evaluator.warm_from(x_best)
        if chosen:
            problem = dataclasses.replace(problem, start=tuple(float(v) for v in x_best))
    return StartSearch(problem, evaluator, classified, chosen if periodic else 0, periodic)
