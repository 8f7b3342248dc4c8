"""The best of local runs from several starts ([`multistart`][optim.starts.multistart]): the
problem's start and scrambled Sobol points of the box ([`optim.way_in.start_points`][]). The way
in of a single run, a periodic start for the steady-state objective, is [`optim.way_in`][]; its
names are importable from here too."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from jaxcrank.errors import CorruptFileError
from jaxcrank.physics.params import ParameterError

from .optimize import Settings, optimize
from .problem import AbstractProblem
from .way_in import CLASSIFY_STARTS, StartSearch, periodic_start, start_points

__all__ = ["CLASSIFY_STARTS", "StartSearch", "multistart", "periodic_start", "start_points"]


def multistart(
    problem: AbstractProblem,
    settings: Settings | None = None,
    out: Path | None = None,
    resume: bool = False,
    progress: bool = True,
) -> dict:
    """Minimise ``problem`` from ``settings.starts`` designs ([`start_points`][optim.way_in.start_points]), one
    run of [`optimize`][optim.optimize.optimize] after another, all sharing its compiled programs. For
    objectives with several basins (impact-dominated designs often have them), the best
    of several local runs.

    Args:
        out: run directory: start k runs in ``out/start_k`` (k = 000, 001, ...) with its
            own checkpoint, and ``multistart.json`` records the start designs and the
            finished runs (no checkpoints when None).
        resume: continue the runs in ``out``: finished starts are read back from their
            checkpoints, the interrupted one resumes, the rest run.

    Returns [`optimize`][optim.optimize.optimize]'s dict of the best run (lowest ``final_objective``), plus
    ``runs`` (per start: ``start_unit``, ``final``, ``final_objective``, ``converged``,
    ``iterations``) and ``best_start`` (its index).

    Raises:
        ParameterError: ``out`` already holds a multistart run and ``resume`` is False, or
            the run there was made with other start designs.
    """
    settings = Settings() if settings is None else settings
    points = start_points(problem, settings.starts, settings.seed)
    plan = None
    if out is not None:
        out = Path(out)
        plan = out / "multistart.json"
        if plan.exists():
            if not resume:
                raise ParameterError(f"{out} already holds a multistart run: pass --resume or choose another --out")
            try:
                recorded = np.asarray(json.loads(plan.read_text())["start_unit"], dtype=float)
            except (ValueError, KeyError, TypeError) as err:
                raise CorruptFileError(f"{plan}: cannot be read ({err})") from None
            if recorded.shape != points.shape or not np.array_equal(recorded, points):
                raise ParameterError(
                    f"{plan}: the run was made from other start designs (starts, seed or problem differ)"
                )
        out.mkdir(parents=True, exist_ok=True)

    def record(runs):
        if plan is not None:  # written before the first start too: a killed run is never overwritten
            tmp = plan.with_suffix(".tmp")
            tmp.write_text(json.dumps({"start_unit": points.tolist(), "seed": settings.seed, "runs": runs}, indent=1))
            tmp.replace(plan)

    results, runs = [], []
    if plan is not None and not plan.exists():
        record(runs)
    for k, u in enumerate(points):
        x0 = tuple(float(v) for v in np.asarray(problem.from_unit(jnp.asarray(u))))
        run_dir = None if out is None else out / f"start_{k:03d}"
        again = run_dir is not None and resume and (run_dir / "checkpoint.npz").exists()
        res = optimize(dataclasses.replace(problem, start=x0), settings, out=run_dir, resume=again, progress=progress)
        results.append(res)
        runs.append(
            {
                "start_unit": u.tolist(),
                "final": res["final"],
                "final_objective": res["final_objective"],
                "converged": res["converged"],
                "iterations": len(res["history"]),
            }
        )
        record(runs)
    best = int(np.argmin([r["final_objective"] for r in runs]))
    return {**results[best], "runs": runs, "best_start": best}
