"""``jaxcrank optimize --problem FILE.toml``: a design problem described as data ([`optim.spec`][]),
minimised under its constraints ([`optim.constrained`][]).

The run folder gets ``problem.toml`` (a copy of the file), ``round_NN/`` (each round's
checkpoint and history), ``rounds.json`` (the finished rounds: ``--resume`` continues after
them), ``history.csv`` (every iterate with each term's and constraint's value, units in the
quantity's name; the objective ``f`` in the terms' unit; the optimiser's ``merit``, dimensionless:
the round's augmented Lagrangian, the objective over its reference plus the constraints' penalty,
and its gradient ``grad_merit_<variable>_per_SI``), ``history.png`` (the objective and each
constraint per iterate, its bounds shaded) and ``result.json``:

- ``problem``, ``names``, ``method``, ``feasible`` (every constraint holds at the final design);
- ``objective_start`` and ``objective_final`` (the weighted sum of the terms + cost);
- ``objectives``: per term, ``quantity``, ``weight``, ``start`` and ``value`` (final), ``lower``
  and ``upper`` (None), ``satisfied`` (True);
- ``constraints``: per constraint, ``quantity``, ``lower``, ``upper``, ``start``, ``value``
  (final), ``start_satisfied`` and ``satisfied``;
- ``start_design_SI``, ``final_design_SI``, ``final_parameters_SI`` (every mechanism parameter the
  design sets, derived lengths' points and mass properties included), ``final_mechanism`` and
  ``simulate_command`` (as ``jaxcrank optimize`` writes them for a preset problem);
- ``rounds`` (the augmented Lagrangian's), ``iterations``, ``start_search`` (the way in; each
  candidate's ``merit`` as in ``history.csv``) and
  ``seconds`` (``way_in``, ``gradient_compile``, ``first_gradient``, ``total``) and
  ``time_to_first_gradient_s`` (from the evaluator's making to its first exact gradient, the way in
  included; None without one).
"""

from __future__ import annotations

import csv
import json
import math
import shutil
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from jaxcrank import cache  # noqa: E402
from jaxcrank.physics.params import ParameterError  # noqa: E402

from . import constrained, pareto, spec  # noqa: E402
from .cli import _final_mechanism, run_problem, settings_from_config  # noqa: E402
from .constrained import ROUND_KEYS, settings  # noqa: E402
from .steady import Steady  # noqa: E402


def run(args) -> int:
    """Run ``jaxcrank optimize --problem FILE.toml`` (the parsed command line ``args``)."""
    from jaxcrank import config as mech_config

    path = Path(args.problem)
    if not path.exists():
        raise ParameterError(f"--problem {path}: no such problem file")
    problem, tables = spec.load(path)
    table = dict(tables["optimizer"])
    if args.method is not None:
        table["method"] = args.method
    if args.iterations is not None:
        table["max_iterations"] = args.iterations
    if tables.get("pareto") is not None:
        return run_front(args, path, problem, {**tables, "optimizer": table})
    if not isinstance(problem.objective, Steady):  # a windowed objective bounds no quantity: the plain run
        unknown = set(table) & set(ROUND_KEYS)
        if unknown:
            raise ParameterError(f"[optimizer] {sorted(unknown)}: a windowed objective takes no rounds")
        return run_problem(args, problem, settings_from_config(table), path.stem)
    opt, rounds = settings(table)
    out = args.out
    mech_config.check_resume(out, args.resume)
    if not args.resume and (out / "rounds.json").exists():
        raise ParameterError(f"{out} already holds a run (rounds.json): pass --resume or choose another --out")
    _prepare(args, path, out)
    if not args.quiet:
        print(f"optimize: {problem.description}: classifying starts (compiling on a first run)", file=sys.stderr)
    life = tables.get("life")
    if life is not None:  # the quantities after life.cycles of wear
        from .life_design import solve_for_life

        res = solve_for_life(problem, life, opt, rounds, out=out, resume=args.resume, progress=not args.quiet)
    else:
        res = constrained.solve(problem, opt, rounds, out=out, resume=args.resume, progress=not args.quiet)
    write_history(out / "history.csv", [_merit_named(h) for h in res["history"]])
    plot_history(problem, res["history"], out / "history.png")
    start, final = res["start"], res["final"]
    result = {
        "problem": problem.description,
        "names": list(problem.names),
        "method": f"augmented Lagrangian around {opt.optimizer.label}",
        "feasible": res["feasible"],
        "objective_start": start["objective"],
        "objective_final": final["objective"],
        "objectives": [{**f, "start": s["value"]} for f, s in zip(final["objectives"], start["objectives"])],
        "constraints": [
            {**f, "start": s["value"], "start_satisfied": s["satisfied"]}
            for f, s in zip(final["constraints"], start["constraints"])
        ],
        "start_design_SI": start["design_SI"],
        "final_design_SI": final["design_SI"],
        **_final_mechanism(problem, final["design_SI"], out),
        "rounds": res["rounds"],
        "iterations": len(res["history"]),
        "start_search": _search_merit_named(res["start_search"]),
        "seconds": res["seconds"],
        "time_to_first_gradient_s": res["seconds"].get("first_gradient"),
    }
    if life is not None:
        first = res["new_clearance"]
        result["life"] = {
            "cycles": life.cycles,
            "rtol": life.rtol,
            "steps_cycles": res["evaluator"].schedule,
            "new_clearance_design_SI": None if first is None else first["final_design"],
        }
    (out / "result.json").write_text(json.dumps(result, indent=2))
    print(f"{problem.description}: objective {start['objective']:.6g} -> {final['objective']:.6g}")
    for c in result["constraints"]:
        lo, hi = (-math.inf if c["lower"] is None else c["lower"]), (math.inf if c["upper"] is None else c["upper"])
        bounds = f"[{lo:g}, {hi:g}]"
        print(f"  {c['quantity']} = {c['value']:.6g} in {bounds}: {'satisfied' if c['satisfied'] else 'VIOLATED'}")
    print(f"simulate the final design: {result['simulate_command']}")
    return 0


def _prepare(args, path: Path, out: Path) -> None:
    """Create the run folder ``out``, turn on the compilation cache (unless ``--no-cache``; the
    steady-state programs traced with equinox's checks as NaN, so the cache keeps them) and copy
    the problem file into it as ``problem.toml``."""
    out.mkdir(parents=True, exist_ok=True)
    if not args.no_cache:
        try:
            cache.enable(args.cache_dir)
            cache.checks_as_nan_from_now()
        except OSError as err:
            print(f"jaxcrank optimize: no compilation cache ({err})", file=sys.stderr)
    if path.resolve() != (out / "problem.toml").resolve():
        shutil.copyfile(path, out / "problem.toml")


def run_front(args, path: Path, problem, tables: dict) -> int:
    """Trace the Pareto front of a problem file with a ``[pareto]`` table into ``args.out``
    ([`optim.pareto.run_front`][]: ``pareto.json``, ``pareto.csv``, ``pareto.png``, ``point_NN/``)."""
    pareto.front_settings(problem, tables["pareto"])  # a bad table stops the run before any file is written
    out = args.out
    _prepare(args, path, out)
    state = pareto.run_front(problem, tables, out, progress=not args.quiet, resume=args.resume)
    front = [p for p in state["points"] if p["nondominated"]]
    print(
        f"{problem.description}: {len(front)} of {len(state['points'])} points on the front, "
        f"hypervolume {state['hypervolume']:.6g}; {out / 'pareto.csv'}, {out / 'pareto.png'}"
        + (f" ({state['note']})" if state.get("note") else "")
    )
    return 0


#: the optimiser's columns, named for a preset problem's objective in degrees, as the augmented
#: Lagrangian's: ``merit`` is dimensionless (the round's objective over its reference plus the
#: constraints' penalty; 1 at the round's start), its gradient per SI unit of each variable
_MERIT = {"objective_deg": "merit", "objective_without_cost_deg": "merit_without_cost", "cost_deg": "cost"}


def _merit_named(row: dict) -> dict:
    """A history row of a problem file's run with the optimiser's columns named as `_MERIT` says."""
    out = {}
    for k, v in row.items():
        if k.startswith("grad_") and k.endswith("_deg_per_SI"):
            k = "grad_merit_" + k[len("grad_") : -len("_deg_per_SI")] + "_per_SI"
        out[_MERIT.get(k, k)] = v
    return out


def _search_merit_named(search: dict | None) -> dict | None:
    """The way in's record with each candidate's ``value_deg`` named ``merit`` (dimensionless)."""
    if not search:
        return search
    named = [{("merit" if k == "value_deg" else k): v for k, v in c.items()} for c in search.get("classified", [])]
    return {**search, "classified": named}


def write_history(path: Path, history: list[dict]) -> None:
    """Every iterate of every round, one row each (the union of the rows' columns)."""
    cols = list(dict.fromkeys(k for h in history for k in h))
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=cols)
        w.writeheader()
        w.writerows(history)


def plot_history(problem, history: list[dict], png: Path) -> None:
    """The objective and every constrained quantity per iterate, the rounds' starts marked and
    each constraint's feasible band shaded; saved to ``png``."""
    panels = 1 + len(problem.limits)
    fig, axes = plt.subplots(panels, 1, figsize=(6.5, 2.2 + 1.8 * panels), sharex=True, squeeze=False)
    axes = axes[:, 0]
    it = list(range(len(history)))
    axes[0].plot(it, [h.get("f", float("nan")) for h in history], "o-", ms=3)
    axes[0].set_ylabel("objective")
    axes[0].set_title(problem.description, fontsize=9)
    for ax, (q, lo, hi, _) in zip(axes[1:], problem.limits):
        ax.plot(it, [h.get(f"constraint:{q}", float("nan")) for h in history], "o-", ms=3, color="C1")
        ymin, ymax = ax.get_ylim()
        ax.axhspan(ymin if lo is None else lo, ymax if hi is None else hi, color="C2", alpha=0.15, label="allowed")
        ax.set_ylim(ymin, ymax)
        ax.set_ylabel(q.replace("kinematics.", ""), fontsize=8)
        ax.legend(fontsize=7, loc="best")
    starts = [i for i, h in enumerate(history) if h.get("iteration") == 0]
    for ax in axes:
        for i in starts:
            ax.axvline(i, color="0.7", lw=0.8)
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("iterate (grey lines: a round of new multipliers starts)")
    fig.tight_layout()
    fig.savefig(png, dpi=120)
    plt.close(fig)
