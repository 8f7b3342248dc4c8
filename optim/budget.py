"""Time budgets that hold in every phase of a run.

A [`Budget`][optim.budget.Budget] is checked by the steady-state evaluator
([`optim.steady.SteadyEvaluator`][]) before each new steady-state solve and each compilation,
so every phase of a run that evaluates designs (the way in, the gradient steps, the regime
guard's and the line search's trial points) stops within one solve of it, with
[`BudgetSpent`][optim.budget.BudgetSpent] naming the phase.
"""

from __future__ import annotations

import dataclasses
import time

from jaxcrank.physics.params import ParameterError

__all__ = ["Budget", "BudgetSpent"]


class BudgetSpent(RuntimeError):
    """A run's time budget ([`Budget`][optim.budget.Budget]) was spent before a new steady-state solve
    or compilation; the message names the phase."""


@dataclasses.dataclass
class Budget:
    """A time budget that every phase of a run checks before its next steady-state solve or
    compilation (the way in, the gradient steps, the regime guard's and the line search's trial
    points): the run overshoots it by at most one solve.

    Attributes:
        seconds: the budget, s (> 0).
        clock: the clock it is measured on (default wall time, ``time.perf_counter``; CPU time:
            ``time.process_time``).

    Raises:
        ParameterError: ``seconds`` not > 0.
    """

    seconds: float
    clock: object = time.perf_counter

    def __post_init__(self):
        if not (isinstance(self.seconds, (int, float)) and self.seconds > 0):
            raise ParameterError(f"max_seconds = {self.seconds!r} must be a number > 0 (None: no time budget)")
        self.started = self.clock()

    def elapsed(self) -> float:
        """Time since the budget was made, s (on its clock)."""
        return self.clock() - self.started

    def spent(self) -> bool:
        """Whether the budget is spent."""
        return self.elapsed() > self.seconds

    def check(self, phase: str) -> None:
        """Raise [`BudgetSpent`][optim.budget.BudgetSpent] naming ``phase`` when the budget is spent."""
        if self.spent():
            raise BudgetSpent(f"time budget max_seconds = {self.seconds:g} s spent (at {phase})")
