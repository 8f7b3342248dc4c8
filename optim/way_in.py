"""The way in: where a single optimisation run starts.

[`start_points`][optim.way_in.start_points] gives the problem's start and scrambled Sobol points
of the box. The steady-state gradient is exact on the periodic orbit and exactly zero outside the
periodic regime (without a trend estimate), so a gradient run from a design that is not periodic
has nowhere to go. [`periodic_start`][optim.way_in.periodic_start] classifies candidate starts by
their steady state, value only, until one is periodic and has the lowest value classified so far;
every design has a value (the long-run statistics where it is not periodic), and the start is
never a periodic design worse than one already seen. It hands the start's steady state to the
optimiser (its evaluator warm-starts from it): the start is solved once.
"""

from __future__ import annotations

import dataclasses
import time

import jax.numpy as jnp
import numpy as np
from tqdm.auto import tqdm

from jaxcrank.physics.params import ParameterError

from .budget import BudgetSpent
from .problem import AbstractProblem
from .steady import FAILED, PERIODIC, SteadyEvaluator

__all__ = ["CLASSIFY_STARTS", "StartSearch", "periodic_start", "start_points"]

#: candidate starts classified at most by `periodic_start` (the problem's start and 7 Sobol points)
CLASSIFY_STARTS = 8
#: candidates `periodic_start` classifies around a best design that is not periodic
LOCAL_STARTS = 4
#: the standard deviation of those candidates' steps, scaled design units
LOCAL_STEP = 0.05


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
            objective, degrees; None where the solve failed), ``regime``, ``phase`` (``start``,
            ``sobol`` or ``local``), ``seconds`` (wall time of its classification, s; the first
            includes compilation) and, where shooting failed and the long-run statistics stand in,
            ``note``.
        chosen: index of the chosen candidate in ``classified``.
        periodic: whether the chosen design is periodic (False: the lowest value seen is a design
            that is not periodic, or no candidate has a value and the problem's own start is kept).
        stopped: why the search ended early (the time budget), or None.
    """

    problem: AbstractProblem
    evaluator: SteadyEvaluator
    classified: list
    chosen: int
    periodic: bool
    stopped: str | None = None

    @property
    def seconds(self) -> float:
        """Wall time of the whole search, s."""
        return float(sum(c["seconds"] for c in self.classified))

    def describe(self) -> dict:
        """Plain values for ``result.json``: ``classified``, ``chosen``, ``periodic``, ``seconds``
        and ``stopped``."""
        return {
            "classified": self.classified,
            "chosen": self.chosen,
            "periodic": self.periodic,
            "seconds": self.seconds,
            "stopped": self.stopped,
        }


def periodic_start(
    problem: AbstractProblem,
    count: int = CLASSIFY_STARTS,
    seed: int = 0,
    evaluator: SteadyEvaluator | None = None,
    progress: bool = True,
    local: int = LOCAL_STARTS,
) -> StartSearch:
    """The start of a steady-state problem's gradient run, chosen by value among classified
    candidates, whatever their regime.

    The candidates are [`start_points`][optim.way_in.start_points] (the problem's start, then
    scrambled Sobol points), each classified by its steady state (value only: over the orbit where
    it is periodic, else the long-run statistical value), in order. The search stops at the first
    periodic candidate whose value is the lowest seen so far. Where the lowest value seen is a
    design that is not periodic (the steady-state gradient there is zero), up to ``local``
    candidates are classified around it (steps of `LOCAL_STEP` in the scaled box, recentred on
    any better design): the first periodic one with the lowest value seen is the start. Else the
    start is the lowest-valued design seen: periodic or not, never a periodic design worse than
    one already seen. A candidate whose solve failed (no value) is never chosen. While the
    search goes on past a periodic candidate, its gradient program is compiled in the background
    ([`SteadyEvaluator.prepare`][optim.steady.SteadyEvaluator.prepare]). The evaluator's
    ``budget`` ([`optim.budget.Budget`][]) ends the search early: the best design classified
    so far is the start.

    Args:
        problem: a problem whose objective is [`optim.steady.Steady`][].
        count: candidates of the first phase at most, >= 1.
        seed: seed of the Sobol points and of the local steps.
        evaluator: the evaluator to classify with (default: a new one for ``problem``).
        progress: show a progress bar over the candidates.
        local: candidates classified around a best design that is not periodic, >= 0.

    Returns:
        a [`StartSearch`][optim.way_in.StartSearch] whose problem starts at the chosen design
        and whose evaluator holds its steady state (kept as it was classified: it is not solved
        again; the warm start of the next solve where it is periodic). ``periodic`` is False
        where the chosen design is not periodic (an optimiser run from it stops at once without
        a trend estimate, saying why) or no candidate has a value (the problem's own start is kept).

    Raises:
        ParameterError: ``count < 1``, ``local < 0`` or an objective other than the steady state.
    """
    if not (isinstance(local, int) and local >= 0):
        raise ParameterError(f"local = {local!r} must be an integer >= 0")
    evaluator = SteadyEvaluator(problem) if evaluator is None else evaluator
    points = list(start_points(problem, count, seed))
    rng = np.random.default_rng(seed)
    classified, lowest, best = [], None, None  # lowest: index of the lowest value; best: of the lowest periodic
    bar = tqdm(total=count, desc="classifying starts", unit="design", disable=not progress)
    phase, stop = "start", None
    while points and stop is None:
        u = points.pop(0)
        tic = time.perf_counter()
        x = np.asarray(problem.from_unit(jnp.asarray(u)))
        try:
            value, info = evaluator.value(x)
        except BudgetSpent as err:
            stop = str(err)
            break
        regime = info["regime"] if info["ok"] else FAILED
        finite = bool(np.isfinite(value))
        classified.append(
            {
                "unit_design": np.asarray(u).tolist(),
                "value_deg": float(value) if finite else None,
                "regime": regime,
                "phase": phase,
                "seconds": time.perf_counter() - tic,
                **({"note": info["note"]} if info.get("note") else {}),
            }
        )
        bar.update(1)
        bar.set_postfix(regime=regime)
        phase = "sobol" if phase == "start" else phase
        k = len(classified) - 1
        if finite:
            low = None if lowest is None else classified[lowest]["value_deg"]
            if low is None or value < low or (value == low and regime == PERIODIC):
                lowest = k
            if regime == PERIODIC and (best is None or value < classified[best]["value_deg"]):
                best = k
                evaluator.warm_from(x)  # kept: later candidates do not evict it
                if best == lowest:
                    break
                evaluator.prepare(x)  # the search goes on: compile its gradient program meanwhile
        if not points and lowest is not None and lowest != best and phase != "local" and local:
            phase = "local"  # the lowest value seen is not periodic: look around it
            points = _around(problem, classified[lowest]["unit_design"], local, rng)
            bar.total += local
        elif phase == "local" and lowest == k and points:  # a better design that is not periodic: recentre
            points = _around(problem, classified[k]["unit_design"], len(points), rng)
    bar.close()
    chosen = lowest  # the lowest value seen: the best periodic design where none is lower
    if chosen is None:  # no candidate has a value: the problem's own start is kept
        return StartSearch(problem, evaluator, classified, 0, False, stop)
    x_chosen = np.asarray(problem.from_unit(jnp.asarray(classified[chosen]["unit_design"])))
    evaluator.warm_from(x_chosen)  # cached or kept: no new solve
    if chosen:
        problem = dataclasses.replace(problem, start=tuple(float(v) for v in x_chosen))
    return StartSearch(problem, evaluator, classified, chosen, classified[chosen]["regime"] == PERIODIC, stop)


def _around(problem: AbstractProblem, u, n: int, rng) -> list:
    """``n`` scaled designs around ``u``: normal steps of `LOCAL_STEP` per coordinate, projected
    onto the feasible set."""
    u = np.asarray(u, dtype=float)
    steps = rng.normal(0.0, LOCAL_STEP, size=(n, u.size))
    return [np.asarray(problem.project(jnp.asarray(np.clip(u + d, 0.0, 1.0))), dtype=float) for d in steps]
