"""Design for life: a problem whose quantities are read after N crank revolutions of wear.

A problem file with a ``[life]`` table ([`optim.spec.LifeSpec`][]) measures every term and
constraint at the end of a life run ([`jaxcrank.analysis.life.life`][]) of the design's
mechanism instead of on the new mechanism's steady state: "the RMS deviation after a million
cycles", with the same quantity names. [`LifeEvaluator`][optim.life_design.LifeEvaluator] is the
[`QuantityEvaluator`][optim.constrained.QuantityEvaluator] of such a problem, so the augmented
Lagrangian, the regime guard, the way in, checkpoints and ``result.json`` are those of any problem.

- **Values**: at a design, the life run to ``cycles`` (its first point warm-started from the new
  mechanism's steady state); the quantities are those of the run's last point (the worn
  mechanism's steady orbit, or its long-run statistics where the motion is not periodic).
- **Steps in cycles**: the first design's run chooses them by error control (``rtol``); every
  later design takes the same steps, so the quantities are smooth functions of the design and
  every design is compared at the same cycles. They are written to ``life_schedule.json`` in the
  run folder, so a resumed run keeps them.
- **The way in**: [`solve_for_life`][optim.life_design.solve_for_life] designs for a new clearance
  first (the new mechanism's steady state, cheap) and for life from that design, unless the
  ``[life]`` table says ``start_from_new = false``. The quantities after wear need not be
  monotone where the new ones are, so a gradient run on the life alone can settle on a worse
  local design than the new-clearance one; from it, the life run's best design is at least as
  good on the life's quantities (the start is among the candidates).
- **Gradients**: exact, through the whole run ([`jaxcrank.analysis.life_gradient.replay`][],
  forward mode): each point's orbit by the implicit function theorem and the slow map over
  cycles. A design counts as periodic (the regime guard's test) when every point and predictor
  of its run is; where one is not, the metrics' gradient is zero (the kinematics' stays exact),
  as for the steady state.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from jaxcrank.analysis.life import Life, LifeError, LifeOptions, life
from jaxcrank.analysis.life_gradient import replay

from .constrained import QuantityEvaluator
from .design import DesignProblem
from .spec import LifeSpec
from .steady import FAILED, NOT_PERIODIC, PERIODIC, SteadyEvaluator, _key, report

#: the file in a run folder that keeps the steps in cycles
SCHEDULE_FILE = "life_schedule.json"


def life_options(spec: LifeSpec, steady_options) -> LifeOptions:
    """The [`LifeOptions`][jaxcrank.analysis.life.LifeOptions] of a ``[life]`` table, with the problem's
    steady-state settings (statistics on failure, 10 million steps per solve for a worn hole's start-up)."""
    steady = steady_options.replace(statistics_on_failure=True, max_steps=10_000_000)
    return LifeOptions(rtol=spec.rtol, average_revolutions=spec.average_revolutions, steady=steady)


def all_periodic(run: Life) -> bool:
    """Whether every point and predictor of a life run is periodic (its gradient is exact)."""
    return all(p.steady.periodic for p in list(run.points) + list(run.predictors))


class LifeEvaluator(QuantityEvaluator):
    """The evaluator of a [`DesignProblem`][optim.design.DesignProblem] measured after ``spec.cycles`` of wear
    (module docstring). Every life run is kept (a few per iterate).

    Args:
        problem: the problem; its mechanism has at least one worn joint.
        spec: the ``[life]`` table.
        folder: the run folder: ``life_schedule.json`` is written there when the first run has
            chosen its steps, and read from there (a resumed run) when it exists.
    """

    def __init__(self, problem: DesignProblem, spec: LifeSpec, folder: Path | None = None):
        self.spec = spec
        self.runs: dict = {}  # design key -> Life, or the LifeError's message
        self.folder = None if folder is None else Path(folder)
        self.schedule = None
        if self.folder is not None and (self.folder / SCHEDULE_FILE).exists():
            self.schedule = json.loads((self.folder / SCHEDULE_FILE).read_text())["steps_cycles"]
        super().__init__(problem)
        self.options = life_options(spec, self.objective.options)

    # -------------------------------------------------------------- the runs
    def life_at(self, x) -> Life | str:
        """The life run at SI design ``x`` (kept), or why it failed."""
        key = _key(x)
        if key not in self.runs:
            if self.budget is not None:
                self.budget.check("a life run")
            new = SteadyEvaluator.steady_at(self, x)  # the new mechanism's: the run's first warm start
            try:
                run = life(
                    self.problem.mechanism(jnp.asarray(key)),
                    self.spec.cycles,
                    self.options,
                    schedule=self.schedule,
                    warm_start=new if new.ok else None,
                )
            except LifeError as err:
                run = str(err)
            if self.schedule is None and isinstance(run, Life):
                self._keep_schedule(run.schedule)
            self.runs[key] = run
        return self.runs[key]

    def _keep_schedule(self, steps) -> None:
        self.schedule = [float(s) for s in steps]
        if self.folder is not None:
            self.folder.mkdir(parents=True, exist_ok=True)
            text = json.dumps({"cycles": self.spec.cycles, "rtol": self.spec.rtol, "steps_cycles": self.schedule})
            (self.folder / SCHEDULE_FILE).write_text(text)

    def report_at(self, x) -> dict:
        """[`report`][optim.steady.report] of the run's last steady state, its ``regime`` the run's
        (periodic only when every point and predictor is; ``failed`` with the reason as ``note``)."""
        run = self.life_at(x)
        if not isinstance(run, Life):
            return {"ok": False, "regime": FAILED, "note": run}
        info = report(run.points[-1].steady)
        info["regime"] = PERIODIC if all_periodic(run) else NOT_PERIODIC
        info["life_points"] = len(run.cycles)
        return info

    # -------------------------------------------------------------- the evaluator's interface
    def steady_at(self, x):
        """The steady state at the run's last point (the worn mechanism); where the run failed, the
        new mechanism's."""
        run = self.life_at(x)
        return run.points[-1].steady if isinstance(run, Life) else SteadyEvaluator.steady_at(self, x)

    def regime_at(self, x):
        return self.report_at(x)["regime"]

    def warm_from(self, x) -> None:
        self.life_at(x)  # every run is kept

    def prepare(self, x) -> bool:
        return False  # a life gradient is traced at its run: nothing to compile ahead

    def outputs_at(self, x) -> np.ndarray:
        key = _key(x)
        if key not in self.outputs:
            run = self.life_at(x)
            k = len(self.problem.quantities) + 1
            if isinstance(run, Life):
                metrics = self._metrics(run.points[-1].steady)
                self.outputs[key] = np.asarray(self._plain(jnp.asarray(key), metrics))
            else:
                self.outputs[key] = np.full(k, np.nan)
        return self.outputs[key]

    def outputs_and_jacobian(self, x) -> tuple[np.ndarray, np.ndarray, dict]:
        """The outputs after the run's cycles at SI design ``x``, their Jacobian (k, n) per SI unit
        through the whole run (every point periodic; else the metrics' rows are zero), and the
        run's report."""
        x = np.asarray(x, dtype=float)
        run = self.life_at(x)
        info = self.last_report = self.report_at(x)
        k = len(self.problem.quantities) + 1
        if not isinstance(run, Life):
            return np.full(k, np.nan), np.full((k, x.size), np.nan), info
        if all_periodic(run):
            problem = self.problem

            def f(xx):
                trace = replay(problem.mechanism, xx, run)
                out = problem.outputs({name: v[-1] for name, v in trace.metrics.items()}, xx)
                return out, out

            jac, out = jax.jacfwd(f, has_aux=True)(jnp.asarray(x))
            self._gradient_done()
        else:
            metrics = self._metrics(run.points[-1].steady)
            out, jac = self._plain(jnp.asarray(x), metrics), self._plain_jac(jnp.asarray(x), metrics)
        self.outputs[_key(x)] = np.asarray(out)
        return np.asarray(out), np.asarray(jac), info


def solve_for_life(
    problem: DesignProblem,
    spec: LifeSpec,
    settings,
    rounds,
    out: Path | None = None,
    resume: bool = False,
    progress: bool = True,
) -> dict:
    """Design ``problem`` for its quantities after ``spec.cycles`` of wear (module docstring).

    With ``spec.start_from_new``, first for a new clearance ([`optim.constrained.solve`][] on the
    new mechanism's steady state, into ``out/new_clearance``), then for life from its final design
    (into ``out``); else for life from the problem's start.

    Args:
        settings, rounds: the optimiser and the augmented Lagrangian's rounds, for both runs.
        out: the run folder (None: no checkpoints); resume: continue a killed run in it (a finished
            first run is kept).

    Returns:
        [`optim.constrained.solve`][]'s dict for the life run, with ``new_clearance`` (the first
        run's dict, None without one) and ``evaluator`` (the [`LifeEvaluator`][optim.life_design.LifeEvaluator]).
    """
    from .constrained import solve

    first = None
    if spec.start_from_new:
        folder = None if out is None else Path(out) / "new_clearance"
        again = resume and folder is not None and (folder / "rounds.json").exists()
        first = solve(problem, settings, rounds, out=folder, resume=again, progress=progress)
        problem = dataclasses.replace(problem, start=tuple(float(v) for v in first["final_design"]))
    ev = LifeEvaluator(problem, spec, folder=out)
    again = resume and out is not None and (Path(out) / "rounds.json").exists()
    res = solve(problem, settings, rounds, out=out, resume=again, progress=progress, evaluator=ev)
    return {**res, "new_clearance": first, "evaluator": ev}


__all__ = ["SCHEDULE_FILE", "LifeEvaluator", "all_periodic", "life_options", "solve_for_life"]
