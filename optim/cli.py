"""``jaxcrank optimize [--config FILE] [--out DIR] [--resume] [--grid N] [options]``.

The run directory gets ``optimize.toml`` (the resolved settings; ``--resume``
reads it back), ``checkpoint.npz`` and ``history.csv`` (after every iteration),
``history.png`` (the paper's Fig. 11, the reported best iterate marked) and
``result.json``. With ``--grid N`` (N > 0; default 0, no grid) two-variable problems
also get ``grid.csv`` and ``landscape.png``: the objective on an N x N vmap grid over
the box with the optimiser's path; it costs N^2 solves (docs/optimisation.md times
it). With ``--starts N`` (N > 1) each start runs in ``start_NNN/`` (its own checkpoint
and history) and ``multistart.json`` lists the starts; the top-level files describe
the best run ([`optim.starts.multistart`][]). With one start and the steady-state
objective, the run first finds a periodic start ([`optim.way_in.periodic_start`][]).

``result.json`` holds: the problem and method; ``converged`` (true when a stopping
test was met) and ``stop_reason`` (the test, or why the run stopped without meeting one: the
iteration or time limit, a failed line search, a design outside the periodic regime with a zero
gradient); ``iterations``; ``evaluations`` (value-and-gradient evaluations);
the start and final design (``*_design_SI``, the variables' values) and objective
(deg); ``reduction_percent``; ``final_parameters_SI`` (the mechanism parameters the
final design sets, by their library names); ``final_mechanism`` (every parameter of
the final design's mechanism, SI, as in ``config.toml``); ``simulate_command`` (the
command that simulates the final design: ``jaxcrank simulate --design
DIR/result.json``); ``starts`` (how many starts ran) and, for ``--starts N > 1``,
``start_runs`` (each start's result) and ``best_start`` (the index of the best);
``start_search`` (the classified candidate starts, steady-state objective with one start),
``seconds_this_call`` (wall time by phase, s); ``grid`` (with ``--grid N``) and, for slider-crank
problems, ``paper`` (the paper's numbers).

The optimiser's compiled programs are kept in a cache folder ([`jaxcrank.runs.cache`][];
``--cache-dir``, ``--no-cache``), so a second run with the same problem and settings
loads them instead of tracing and compiling again.

The config file (TOML, every key optional: ``problem``, ``[optimizer]``, ``[objective]``,
``[design]``, ``[mechanism]``) is described, with an example, on the docs page "Optimiser
config files" (docs/optimiser-config.md); a test builds that example.

``final_mechanism`` in result.json is the final design's mechanism in the format of
[`jaxcrank.runs.config.to_dict`][] (its ``mechanism`` key names the kind), which
``jaxcrank simulate --design`` reads back.
"""

from __future__ import annotations

import dataclasses
import json
import sys
import time
import tomllib
from pathlib import Path

import tomli_w

from jaxcrank import cache
from jaxcrank import config as mech_config
from jaxcrank.physics.params import ParameterError

from .design import TERMS
from .objective import EQ19
from .objective_config import objective_config, objective_from_config
from .optimize import STEADY_LEARNING_RATE, Settings, default_settings, optimize, steady_evaluator
from .optimizers import OPTIMIZERS, from_settings
from .presets import PROBLEMS, design_problem, paper_reference
from .presets import problem as preset_problem
from .problem import AbstractProblem as Problem
from .spec import derived_from_table, derived_table
from .starts import multistart, periodic_start
from .steady import Steady

#: the default ``[optimizer]`` settings with the steady-state objective (those of
#: [`optim.optimize.default_settings`][], with the regime guard)
STEADY_OPTIMIZER = {"method": "adam", "learning_rate": STEADY_LEARNING_RATE}
#: the ``[design]`` keys that change a problem's derived group
GROUP_KEYS = ("stroke", "stroke_tolerance", "min_transmission_deg", "scale_links")
GRID_CHUNK = 21  # designs per vmap batch of the landscape (and of the final design's re-evaluation)


def add_parser(sub):
    """Add the ``optimize`` command to the subparsers ``sub`` of an argparse parser."""
    return add_arguments(sub.add_parser("optimize", help="minimise the RMS transmission-angle error with optax"))


def add_arguments(p):
    """Add ``optimize``'s description and options to its parser ``p``."""
    p.description = (
        "Optimise a design problem (default: the paper's L1, L2 problem) with gradients "
        "through the simulation; writes history, figures and result.json into --out."
    )
    p.add_argument(
        "--config",
        type=Path,
        help="TOML settings, described on the docs' page 'Optimiser config files' (docs/optimiser-config.md); "
        "default: the paper problem",
    )
    p.add_argument("--out", type=Path, default=Path("runs/optimize"), help="run directory (default runs/optimize)")
    p.add_argument(
        "--resume", action="store_true", help="continue the run in --out from its last checkpoint (--out must exist)"
    )
    p.add_argument(
        "--problem",
        help=f"a problem preset ({', '.join(sorted(PROBLEMS))}; overrides the config's) or a problem file "
        "(FILE.toml: any mechanism, objective and constraints; docs page 'Design your own mechanism')",
    )
    p.add_argument(
        "--method",
        choices=sorted(OPTIMIZERS),
        help="optimiser (default adam: learning rate 0.1, or 0.05 with the steady-state objective)",
    )
    p.add_argument("--iterations", type=int, help="max iterations (default 30)")
    p.add_argument(
        "--starts",
        type=int,
        help="optimise from this many designs (the problem's start, then Sobol points of the box) "
        "and keep the best; each in --out/start_NNN (default 1)",
    )
    p.add_argument("--t-end", type=float, help="end of the evaluation window, s (default 0.3)")
    p.add_argument("--windows", type=int, help="ensemble windows for the gradient (0 = all)")
    p.add_argument(
        "--grid",
        type=int,
        default=0,
        metavar="N",
        help="also evaluate the objective on an N x N grid over the box and draw landscape.png "
        "(two-variable problems; N^2 solves: the paper problem's 21 x 21 grid takes minutes, "
        "about three times its optimisation; default 0: no grid)",
    )
    p.add_argument(
        "--grid-from",
        type=Path,
        metavar="GRID_CSV",
        help="reuse the landscape (Eq. 19 values) of an earlier run's grid.csv over the same box and "
        "objective instead of solving the grid again (the cost term is recomputed)",
    )
    p.add_argument(
        "--cache-dir",
        type=Path,
        help="JAX's persistent compilation cache: a later run loads the compiled gradient instead of "
        "compiling it again (default: $JAXCRANK_CACHE_DIR or ~/.cache/jaxcrank/xla)",
    )
    p.add_argument("--no-cache", action="store_true", help="do not read or write the compilation cache")
    p.add_argument(
        "--regime",
        action="store_true",
        help="also classify the final design's steady state (periodic or not; a steady-state solve, "
        "about a minute) into result.json's final_regime",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    return p


def _settings(args):
    mech_config.check_resume(args.out, args.resume)
    cfg = {}
    resumed = args.resume and (args.out / "optimize.toml").exists() and args.config is None
    if args.config or resumed:
        path = args.config or args.out / "optimize.toml"
        try:
            cfg = tomllib.loads(Path(path).read_text())
        except tomllib.TOMLDecodeError as err:
            raise ParameterError(f"{path}: malformed TOML: {err}") from None
    unknown = set(cfg) - {"problem", "optimizer", "objective", "design", "mechanism"}
    if unknown:
        raise ParameterError(
            f"unknown optimize config keys {sorted(unknown)}; valid: problem, optimizer, objective, design, mechanism"
        )
    if args.problem:
        cfg["problem"] = args.problem
    for key, val in (("method", args.method), ("max_iterations", args.iterations), ("starts", args.starts)):
        if val is not None:
            cfg.setdefault("optimizer", {})[key] = val
    for key, val in (("t_end", args.t_end), ("windows", args.windows)):
        if val is not None:
            cfg.setdefault("objective", {})[key] = val
    return cfg


def _fields(cls, section, values):
    names = {f.name for f in dataclasses.fields(cls)}
    bad = set(values) - names
    if bad:
        raise ParameterError(f"unknown [{section}] keys {sorted(bad)}; valid: {sorted(names)}")
    return values


def build(cfg) -> tuple[Problem, Settings]:
    """The problem and optimiser settings of an optimiser config (docs/optimiser-config.md): the
    preset ``problem`` ([`optim.presets`][]) changed by ``[objective]``, ``[design]`` (fields of
    [`optim.design.DesignProblem`][]; ``stroke``, ``stroke_tolerance``, ``min_transmission_deg``
    and ``scale_links`` change its derived group, ``weights`` the design preset's terms besides
    Eq. 19, ``variables`` a subset of the design preset's) and ``[mechanism]``.

    Raises:
        ParameterError: an unknown problem, key or value."""
    name = cfg.get("problem", "paper")
    if name not in PROBLEMS:
        raise ParameterError(
            f"problem {name!r} is unknown; valid: {', '.join(PROBLEMS)}, or a problem file (a path ending in .toml)"
        )
    section = cfg.get("objective", {})
    design = dict(cfg.get("design", {}))
    objective = objective_from_config(section) if section else None
    if "variables" in design:  # a subset of the design problem's variables, at their default bounds
        if name != "design":
            raise ParameterError(f"[design] variables: only the design problem takes it, not {name!r}")
        problem = design_problem(objective, variables=tuple(design.pop("variables")))
    else:
        problem = preset_problem(name)
        problem = problem if objective is None else problem.with_objective(objective)
    changes = {"base": mech_config.from_dict(cfg["mechanism"])} if "mechanism" in cfg else {}
    group = {k: design.pop(k) for k in GROUP_KEYS if k in design}
    if "derived" in design:
        table = design.pop("derived")
        changes["derived"] = None if table is None else derived_from_table(table)
    if group:
        if problem.derived is None:
            raise ParameterError(f"[design] {sorted(group)}: problem {name!r} has no derived group")
        changes["derived"] = dataclasses.replace(changes.get("derived", problem.derived), **group)
    if "weights" in design:
        weights = dict(design.pop("weights"))
        bad = [k for k in weights if k not in TERMS or k == EQ19]
        if bad:
            raise ParameterError(f"[design] weights of {bad}: valid terms are {list(TERMS)[1:]}")
        changes["terms"] = ((EQ19, 1.0),) + tuple((k, float(weights[k])) for k in TERMS if weights.get(k, 0.0))
    if design:
        design = _fields(type(problem), "design", design)
        design = {
            k: (
                tuple(tuple(r) for r in v) if k in ("A", "scatter", "terms") else tuple(v) if isinstance(v, list) else v
            )
            for k, v in design.items()
        }
    if changes or design:  # one replacement: the new base checked against the new variables
        problem = dataclasses.replace(problem, **changes, **design)
    section = dict(cfg.get("optimizer", {}))
    if not isinstance(problem.objective, Steady):
        return problem, settings_from_config(section)
    # steps kept inside the periodic regime, where the gradient is exact: the library's guard
    section = section if "method" in section else {**STEADY_OPTIMIZER, **section}
    return problem, dataclasses.replace(settings_from_config(section), guard=default_settings(problem).guard)


def settings_from_config(section: dict) -> Settings:
    """[`optim.optimize.Settings`][] of an ``[optimizer]`` table: ``method`` (a name of
    `optim.optimizers.OPTIMIZERS`, default "adam") with its settings, then the
    Settings fields."""
    values = dict(section)
    method = values.pop("method", "adam")
    accepted = OPTIMIZERS[method][1] if method in OPTIMIZERS else ()
    optimizer = from_settings(method, **{k: values.pop(k) for k in list(values) if k in accepted})
    valid = {f.name for f in dataclasses.fields(Settings)} - {"optimizer", "guard"}
    bad = set(values) - valid
    if bad:
        raise ParameterError(
            f"unknown [optimizer] keys {sorted(bad)} for method {method!r}; valid: method, "
            f"{', '.join(accepted)}, {', '.join(sorted(valid))}"
        )
    return Settings(optimizer=optimizer, **values)


def settings_config(settings: Settings) -> dict:
    """The ``[optimizer]`` table of ``settings`` ([`settings_from_config`][optim.cli.settings_from_config] reads it
    back)."""
    plain = {f.name: getattr(settings, f.name) for f in dataclasses.fields(settings)}
    plain.pop("optimizer"), plain.pop("guard")
    plain = {k: v for k, v in plain.items() if v is not None}
    return {**settings.optimizer.settings(), **plain}


def resolved(problem: Problem, settings: Settings, name: str) -> dict:
    return {
        "problem": name,
        "optimizer": settings_config(settings),
        "objective": objective_config(problem.objective),
        "design": {
            "names": list(problem.names),
            "lower": list(problem.lower),
            "upper": list(problem.upper),
            "start": list(problem.start) if problem.start is not None else None,
            "A": [list(r) for r in problem.A],
            "b": list(problem.b),
            "cost_weight": problem.cost_weight,
            "cost_reference": problem.cost_reference,
            **_subclass_fields(problem),
        },
        "mechanism": mech_config.to_dict(problem.base),
    }


def _subclass_fields(problem: Problem) -> dict:
    """The fields a problem class adds to [`AbstractProblem`][optim.problem.AbstractProblem], as TOML values (the
    derived group as its table, each length variable as one; empty limits and lengths left out)."""
    extra = [f.name for f in dataclasses.fields(problem) if f.name not in {g.name for g in dataclasses.fields(Problem)}]
    out = {}
    for k in extra:
        v = getattr(problem, k)
        if k == "limits" and v:
            raise ParameterError("a problem with limits is a problem file: run it with --problem FILE.toml")
        if k in ("limits", "lengths"):  # a problem file's lengths: recorded (its --resume reads the file again)
            out.update({k: [dataclasses.asdict(length) for length in v]} if v else {})
            continue
        out[k] = derived_table(v) if k == "derived" and v is not None else v
        if k in ("terms", "scatter"):
            out[k] = [list(e) for e in v]
    return out


def _regime(problem: Problem, x) -> dict:
    """The steady-state regime of SI design ``x`` ([`optim.steady.report`][])."""
    from .steady import Steady, report

    objective = problem.objective if isinstance(problem.objective, Steady) else Steady(throw=False)
    return report(objective.solve(problem.mechanism(x)))


def _drop_none(d):
    return {k: (_drop_none(v) if isinstance(v, dict) else v) for k, v in d.items() if v is not None}


def run(args) -> int:
    cfg = _settings(args)
    problem, settings = build(cfg)
    return run_problem(args, problem, settings, cfg.get("problem", "paper"))


def run_problem(args, problem: Problem, settings: Settings, name: str) -> int:
    """Optimise ``problem`` with ``settings`` as ``jaxcrank optimize`` does (the command line
    ``args``: out, resume, grid, cache, quiet, regime), writing the run folder; ``name`` is the
    preset's (or the problem file's) name in optimize.toml and result.json."""
    from . import plots, search

    if not args.no_cache:
        try:
            cache.enable(args.cache_dir)
            if isinstance(problem.objective, Steady):  # its solves check results on the host: cacheable programs
                cache.checks_as_nan_from_now()
        except OSError as err:  # the run goes on, compiling as without a cache
            print(
                f"jaxcrank optimize: no compilation cache ({err}); pass --cache-dir DIR or --no-cache", file=sys.stderr
            )
    # read a reused landscape before the optimisation, so a bad file fails at once
    reused = (
        search.read_grid(args.grid_from, problem, args.grid)
        if args.grid_from and args.grid and problem.n == 2
        else None
    )
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    for held in ("checkpoint.npz", "multistart.json"):
        if not args.resume and (out / held).exists():
            raise ParameterError(
                f"{out} already holds a run ({held}): pass --resume to continue it or choose another --out"
            )
    tic, found = time.perf_counter(), None
    if settings.starts == 1 and isinstance(problem.objective, Steady) and not args.resume:
        # the steady-state gradient is zero outside the periodic regime: start from a periodic design
        if not args.quiet:
            print(f"optimize: {problem.description}: classifying starts (compiling on a first run)", file=sys.stderr)
        # one time budget (max_seconds) for the way in and the run
        found = periodic_start(
            problem, seed=settings.seed, progress=not args.quiet, evaluator=steady_evaluator(problem, settings)
        )
        problem = found.problem  # optimize.toml records the chosen start: --resume continues from it
    (out / "optimize.toml").write_text(tomli_w.dumps(_drop_none(resolved(problem, settings, name))))
    if not args.quiet and found is None:  # the first evaluation compiles (and settles from rest)
        print(f"optimize: {problem.description}: evaluating the start (compiling on a first run)", file=sys.stderr)
    if settings.starts > 1:
        res = multistart(problem, settings, out=out, resume=args.resume, progress=not args.quiet)
    else:
        evaluator = found.evaluator if found is not None else None
        res = optimize(problem, settings, out=out, resume=args.resume, progress=not args.quiet, evaluator=evaluator)
    wall = time.perf_counter() - tic
    hist = res["history"]
    plots.plot_history(hist, out / "history.png", title=problem.description, best=res["final_objective"])

    grid_info = None
    if args.grid and problem.n == 2:
        grid = search.grid_search(problem, n=args.grid, chunk=GRID_CHUNK, progress=not args.quiet, errors=reused)
        search.write_grid(out / "grid.csv", problem, grid)
        path = [[h[f"{n}_SI"] for n in problem.names] for h in hist]
        plots.plot_landscape(
            grid, problem.names, path, out / "landscape.png", title=problem.description, final=res["final"]
        )
        # the grid's evaluator at the final design: the same compiled solve as the grid (a
        # differently compiled solve of the same design differs by ~0.5 %: impact chaos
        # amplifies last-bit rounding), so the comparison with the grid's best is like for like
        final_same, _ = search.evaluate(problem, [res["final"]], chunk=GRID_CHUNK, progress=False)
        grid_info = {
            "points_per_axis": args.grid,
            "best_design_SI": grid.best.tolist(),
            "best_objective_deg": grid.best_value,
            "final_objective_grid_evaluator_deg": float(final_same[0]),
            "final_over_grid_best": float(final_same[0]) / grid.best_value,
            "final_over_grid_best_optimiser_value": res["final_objective"] / grid.best_value,
            "failed_designs": int((grid.feasible & ~grid.ok).sum()),
        }

    f_start = hist[0]["objective_deg"] if hist else res["final_objective"]
    result = {
        "problem": problem.description,
        "names": list(problem.names),
        "method": settings.optimizer.label,
        "converged": res["converged"] is not None,
        "stop_reason": res["stop_reason"],
        "iterations": len(hist),
        "evaluations": res["evaluations"],
        "start_design_SI": [hist[0][f"{n}_SI"] for n in problem.names] if hist else res["final"],
        "start_objective_deg": f_start,
        "final_design_SI": res["final"],
        "final_objective_deg": res["final_objective"],
        "reduction_percent": 100.0 * (f_start - res["final_objective"]) / f_start,
        **_final_mechanism(problem, res["final"], out),
        "wall_seconds_this_call": wall,
        "time_to_first_gradient_s": res.get("seconds", {}).get("first_gradient"),
        "seconds_this_call": {
            **({"classifying_starts": found.seconds} if found is not None else {}),
            **{f"{k}_optimizer": v for k, v in res.get("seconds", {}).items()},
        },
        **({"start_search": found.describe()} if found is not None else {}),
        "starts": settings.starts,
        **({"start_runs": res["runs"], "best_start": res["best_start"]} if "runs" in res else {}),
        **({"grid": grid_info} if grid_info else {}),
        "final_regime": _regime(problem, res["final"]) if args.regime else None,
        **({"paper": paper_reference()} if name in ("paper", "robust") else {}),
    }
    (out / "result.json").write_text(json.dumps(result, indent=2))
    print(
        f"{problem.description}: {f_start:.5f} -> {res['final_objective']:.5f} deg "
        f"({result['reduction_percent']:.2f} % lower) at "
        + ", ".join(plots.value_text(n, v) for n, v in zip(problem.names, res["final"]))
        + (f"; grid best {grid_info['best_objective_deg']:.5f} deg" if grid_info else "")
    )
    print(f"{'converged' if result['converged'] else 'not converged'}: {res['stop_reason']}")
    print(f"simulate the final design: {result['simulate_command']}")
    return 0


def _final_mechanism(problem: Problem, final, out: Path) -> dict:
    """result.json's entries for the final design: its mechanism parameters by their library
    names, the whole mechanism (SI, as config.toml) and the command that simulates it."""
    import numpy as np

    x = np.asarray(final, dtype=float)
    if hasattr(problem, "physical"):  # a reparametrised problem: derived variables set several parameters
        names, values = problem.physical(x)
    else:
        names, values = problem.names, x
    return {
        "final_parameters_SI": {n: float(v) for n, v in zip(names, np.asarray(values))},
        "final_mechanism": mech_config.to_dict(problem.mechanism(x)),
        "simulate_command": f"jaxcrank simulate --design {out / 'result.json'} --out {out / 'simulate'}",
    }
