"""Pareto fronts of two objectives with exact gradients: the epsilon-constraint method around
[`optim.constrained.solve`][].

The first objective is the problem's own, ``f1(x) = sum_i w_i q_i(x) + cost(x)`` (its
``[objective]`` terms); the second is one quantity ``q2`` ([`optim.quantities`][]) named in the
problem file's ``[pareto]`` table, minimised as ``f2 = weight * q2`` (a negative weight maximises
it). Every point is a constrained minimisation with exact steady-state gradients, the problem's
own constraints held:

1. the first anchor minimises ``f1`` (the problem as it is);
2. the second anchor minimises ``f2`` alone (the terms replaced by ``q2``, no cost);
3. for ``points - 2`` levels ``eps_k`` evenly spaced strictly between the anchors' values of
   ``f2``, in increasing order, a point minimises ``f1`` subject to ``f2 <= eps_k`` (a bound on
   ``q2``), each started from the previous point's design (the first from the second anchor's).

The first anchor and the epsilon points carry the bound on ``q2`` in every solve (infinite for
the anchor), so they share one compiled outputs-and-Jacobian program per orbit structure
([`optim.constrained.structure`][]): a new level costs no compilation. The second anchor has
its own objective and so its own program. One evaluator serves every point: its steady states
warm-start the next solve.

The front is the feasible points (every constraint of the problem holds) that no other such
point dominates ([`nondominated`][optim.pareto.nondominated]). Its quality is the 2-D
hypervolume ([`hypervolume`][optim.pareto.hypervolume]): the area the front dominates up to a
reference point, by default the front's nadir plus `REFERENCE_MARGIN` (10 %) of its range in
each objective ([`reference_point`][optim.pareto.reference_point]).

Files of [`run_front`][optim.pareto.run_front]: ``pareto.json`` (the settings and every finished
point, replaced atomically after each: a killed run resumes without losing them), ``point_NN/``
(each point's rounds and checkpoints: the unfinished point resumes mid-solve), ``pareto.csv``
(one row per point) and ``pareto.png`` (the front).
"""

from __future__ import annotations

import csv
import dataclasses
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from jaxcrank.physics.parameters import parameter_unit
from jaxcrank.physics.params import ParameterError
from jaxcrank.runs.sweep_table import atomic_write

from . import constrained
from . import quantities as Q
from .design import DesignProblem
from .programs import PROGRAMS
from .steady import Steady

#: the keys of a ``[pareto]`` table
KEYS = ("quantity", "points", "weight", "scale")
#: the most points a front may ask for
MAX_POINTS = 100
#: the reference point's distance beyond the nadir, a fraction of each objective's range
REFERENCE_MARGIN = 0.1
#: the units quantity names end in, longest first
_UNITS = ("rad_s2", "m_s2", "rad_s", "m_s", "N_m", "deg", "rad", "m", "N", "s")


@dataclasses.dataclass(frozen=True)
class Front:
    """The settings of a front (a ``[pareto]`` table, [`front_settings`][optim.pareto.front_settings]).

    Attributes:
        quantity: the second objective's quantity ``q2``, by its ``summary.json`` name.
        points: points on the front, both anchors included, in [3, `MAX_POINTS`].
        weight: ``f2 = weight * q2`` (finite, nonzero; negative: ``q2`` is maximised).
        scale: the size the bound on ``q2`` measures violations by, in ``q2``'s unit (None: the
            anchors' spread in ``q2``).
    """

    quantity: str
    points: int = 7
    weight: float = 1.0
    scale: float | None = None


def front_settings(problem: DesignProblem, table: dict) -> Front:
    """The [`Front`][optim.pareto.Front] of a problem file's ``[pareto]`` table.

    Raises:
        ParameterError: naming the key and its valid range: an unknown key, a missing or unknown
            quantity (listing the valid ones), the objective's only term as the quantity, points
            not an integer in [3, `MAX_POINTS`], a weight not finite and nonzero, a scale not
            finite and > 0, or a problem whose objective is not the steady state.
    """
    if not isinstance(table, dict):
        raise ParameterError(f"[pareto] must be a table with keys {', '.join(KEYS)}, not {table!r}")
    bad = set(table) - set(KEYS)
    if bad:
        raise ParameterError(f"[pareto]: unknown keys {sorted(bad)}; valid: {list(KEYS)}")
    if "quantity" not in table:
        raise ParameterError('[pareto] quantity is missing: the second objective, e.g. quantity = "<a metric name>"')
    q = table["quantity"]
    if not isinstance(q, str):
        raise ParameterError(f"[pareto] quantity = {q!r} must be a quantity name (a string)")
    Q.check_quantity(problem.base, q, "[pareto] quantity")
    if [t for t, _ in problem.terms] == [q]:
        raise ParameterError(f"[pareto] quantity = {q!r} is the objective's only term: a front needs another quantity")
    points = table.get("points", 7)
    if isinstance(points, bool) or not isinstance(points, int) or not 3 <= points <= MAX_POINTS:
        raise ParameterError(f"[pareto] points = {points!r} must be an integer in [3, {MAX_POINTS}] (anchors included)")
    weight = table.get("weight", 1.0)
    if isinstance(weight, bool) or not isinstance(weight, (int, float)) or not math.isfinite(weight) or weight == 0:
        raise ParameterError(f"[pareto] weight = {weight!r} must be a finite nonzero number (negative: maximise)")
    scale = table.get("scale")
    if scale is not None and (
        isinstance(scale, bool) or not isinstance(scale, (int, float)) or not (math.isfinite(scale) and scale > 0)
    ):
        raise ParameterError(f"[pareto] scale = {scale!r} must be a finite number > 0, in the unit of {q}")
    if not isinstance(problem.objective, Steady):
        raise ParameterError("[pareto] needs the steady-state objective ([solver] method = 'steady_state')")
    return Front(q, int(points), float(weight), None if scale is None else float(scale))


# ---------------------------------------------------------------------------------------- scoring


def nondominated(values) -> np.ndarray:
    """Which rows of ``values`` (points, objectives), all minimised, no other row dominates (no
    worse in every objective, better in one); rows with a non-finite value are left out, and of
    equal rows only the first is kept. Returns a boolean mask (points,)."""
    v = np.asarray(values, dtype=float).reshape(len(values), -1)
    finite = np.all(np.isfinite(v), axis=1)
    keep = finite.copy()
    for i in np.flatnonzero(finite):
        others = v[finite & (np.arange(len(v)) != i)]
        worse = np.all(others <= v[i], axis=1) & np.any(others < v[i], axis=1)
        equal_before = np.any(np.all(v[:i][finite[:i]] == v[i], axis=1))
        keep[i] = not (np.any(worse) or equal_before)
    return keep


def hypervolume(values, reference) -> float:
    """The 2-D hypervolume of the points ``values`` (points, 2), both objectives minimised: the
    area of the region they dominate that is dominated by ``reference`` (2,), in the product of
    the objectives' units. Points not below the reference in both objectives add nothing;
    dominated and non-finite points are ignored. 0.0 without a point.

    Raises:
        ParameterError: for values that are not (points, 2) or a reference that is not finite."""
    v = np.asarray(values, dtype=float).reshape(-1, 2) if len(values) else np.zeros((0, 2))
    r = np.asarray(reference, dtype=float)
    if v.ndim != 2 or v.shape[1] != 2 or r.shape != (2,) or not np.all(np.isfinite(r)):
        raise ParameterError("hypervolume: values (points, 2) and a finite reference (2,) are needed")
    v = v[nondominated(v)] if len(v) else v
    v = v[np.all(v < r, axis=1)]
    total, level = 0.0, r[1]
    for f1, f2 in v[np.argsort(v[:, 0], kind="stable")]:
        if f2 < level:
            total += (r[0] - f1) * (level - f2)
            level = f2
    return float(total)


def reference_point(values, margin: float = REFERENCE_MARGIN) -> np.ndarray:
    """The hypervolume's reference: the nadir (the worst value of each objective over the
    non-dominated rows of ``values``) plus ``margin`` times the range (nadir - ideal); where the
    range is zero, ``margin`` times |nadir| (1 where that is zero too).

    Raises:
        ParameterError: without a finite point."""
    v = np.asarray(values, dtype=float)
    v = v[nondominated(v)] if len(v) else v
    if not len(v):
        raise ParameterError("reference point: no point with finite objectives")
    nadir, ideal = v.max(axis=0), v.min(axis=0)
    span = nadir - ideal
    span = np.where(span > 0, span, np.where(np.abs(nadir) > 0, np.abs(nadir), 1.0))
    return nadir + margin * span


def levels(low: float, high: float, points: int) -> list[float]:
    """The ``points - 2`` epsilon levels evenly spaced strictly between ``low`` and ``high`` (increasing)."""
    return [low + (high - low) * k / (points - 1) for k in range(1, points - 1)]


# ---------------------------------------------------------------------------------------- the problems


def unit_of(name: str) -> str:
    """The unit a quantity's name ends in (``peak_..._N`` -> ``N``; ``""`` without one)."""
    return next((u for u in _UNITS if name.endswith(f"_{u}")), "")


def variable_unit(problem: DesignProblem, name: str) -> str:
    """A design variable's SI unit as written in column names (``m``, ``rad``, ``kg``, ``1``)."""
    if name in {v.name for v in problem.lengths}:
        return "m"
    if problem.derived is not None and name in problem.derived.OWNED:
        return problem.derived.OWNED[name]
    return parameter_unit(problem.base, name)


def bounded(problem: DesignProblem, front: Front, bound: float, scale: float) -> DesignProblem:
    """``problem`` with ``f2 <= weight * bound``, i.e. ``q2 <= bound`` (``q2 >= bound`` for a negative
    weight), appended to its constraints; ``bound`` infinite: the same structure, no bound."""
    if math.isinf(bound):
        bound = math.inf if front.weight > 0 else -math.inf
    limit = (front.quantity, None, bound, scale) if front.weight > 0 else (front.quantity, bound, None, scale)
    return dataclasses.replace(problem, limits=problem.limits + (limit,))


def second_problem(problem: DesignProblem, front: Front) -> DesignProblem:
    """The second anchor's problem: ``f2`` alone (no cost), the problem's constraints kept."""
    return dataclasses.replace(problem, terms=((front.quantity, front.weight),), cost_weight=0.0, title="")


def measure(ev: constrained.QuantityEvaluator, problem: DesignProblem, front: Front, x) -> dict:
    """The values of a point at SI design ``x``, by the evaluator (retargeted to ``problem``'s
    structure with the unbounded ``q2`` when it measures another): ``objective`` (``f1``),
    ``terms``, ``quantity`` (``q2``), ``second`` (``f2``), ``constraints`` (the problem's, in
    order), ``satisfied`` and ``feasible`` (every constraint, bound and linear constraint holds)."""
    loose = bounded(problem, front, math.inf, 1.0)
    if constrained.structure(ev.problem) != constrained.structure(loose):
        ev.retarget(loose)
    out = ev.outputs_at(np.asarray(x, dtype=float))
    terms, cost, cons = loose.split(out)
    f1 = float(np.dot([w for _, w in problem.terms], terms) + cost)
    ok = constrained.satisfied(problem, cons[:-1])
    finite = bool(np.all(np.isfinite(out)))
    return {
        "objective": f1,
        "terms": [float(v) for v in terms],
        "quantity": float(cons[-1]),
        "second": float(front.weight * cons[-1]),
        "constraints": [float(v) for v in cons[:-1]],
        "satisfied": ok,
        "feasible": finite and all(ok) and bool(problem.feasible(np.asarray(x, dtype=float))),
    }


# ---------------------------------------------------------------------------------------- the run


def _plain(value):
    """``value`` with NaN and infinities as None (strict JSON)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def _save(path: Path, state: dict) -> None:
    atomic_write(path, lambda f: f.write(json.dumps(_plain(state), indent=1).encode()))


def run_front(problem: DesignProblem, tables: dict, out, progress: bool = True, resume: bool = False) -> dict:
    """Trace the front of a problem file's problem and ``[pareto]`` table (module docstring).

    Args:
        problem: the problem ([`optim.spec.load`][]'s first value); its objective the steady state.
        tables: the run's tables ([`optim.spec.load`][]'s second value): ``optimizer`` (each point's
            optimiser and rounds, as for ``jaxcrank optimize --problem``) and ``pareto``.
        out: the run folder (created): ``pareto.json``, ``point_NN/``, ``pareto.csv``, ``pareto.png``.
        progress: print a line per point and the optimiser's progress bars (stderr).
        resume: continue the run in ``out``: finished points are kept, the unfinished one resumed.

    Returns:
        the state written to ``pareto.json``: ``problem`` (description), ``names``, ``units``
        (per variable), ``front`` (the settings), ``scale`` (the bound's), ``levels`` (the bounds
        on ``q2``, its unit), ``points`` (per point: ``kind`` "first", "second" or "epsilon",
        ``bound``, ``design_SI``, the values of [`measure`][optim.pareto.measure], ``nondominated``,
        ``iterations``, ``rounds``, ``programs_compiled`` (compiled outputs programs the point
        added), ``cpu_seconds`` and ``wall_seconds``), ``reference`` and ``hypervolume`` (in the
        (``f1``, ``f2``) plane, units the objectives'), ``cpu_seconds`` and ``wall_seconds`` (the
        whole front, resumed runs' parts summed) and ``files``.

    Raises:
        ParameterError: a bad ``[pareto]`` table ([`front_settings`][optim.pareto.front_settings]) or
            none; ``out`` holding a run and no ``resume``, or a run of other settings.
    """
    if tables.get("pareto") is None:
        raise ParameterError("the problem file has no [pareto] table: quantity = ..., points = ...")
    front = front_settings(problem, tables["pareto"])
    opt, rounds = constrained.settings(tables.get("optimizer", {}))
    out = Path(out)
    path = out / "pareto.json"
    header = {
        "problem": problem.description,
        "names": list(problem.names),
        "units": [variable_unit(problem, n) for n in problem.names],
        "front": dataclasses.asdict(front),
    }
    if path.exists() and not resume:
        raise ParameterError(f"{out} already holds a front (pareto.json): pass --resume or choose another --out")
    if resume and path.exists():
        state = json.loads(path.read_text())
        if {k: state.get(k) for k in header} != _plain(header):
            raise ParameterError(f"--resume: the front in {out} has other settings or variables; choose another --out")
    else:
        state = {**header, "scale": front.scale, "levels": None, "points": [], "cpu_seconds": 0.0, "wall_seconds": 0.0}
    out.mkdir(parents=True, exist_ok=True)
    _save(path, state)
    ev = constrained.QuantityEvaluator(bounded(problem, front, math.inf, front.scale or 1.0))
    while True:
        k = len(state["points"])
        if k >= 2 and state["levels"] is None:
            q_first, q_second = (state["points"][i]["quantity"] for i in (0, 1))
            if q_first is None or q_second is None:
                raise ParameterError(f"the anchors' {front.quantity} could not be evaluated (steady state failed)")
            spread = abs(q_first - q_second)
            state["scale"] = front.scale or (spread if spread > 0 else max(abs(q_first), 1.0))
            f_first, f_second = front.weight * q_first, front.weight * q_second
            state["levels"] = [e / front.weight for e in levels(f_second, f_first, front.points)] if spread else []
            if not spread:  # the objectives do not conflict over the box
                state["note"] = f"the anchors have the same {front.quantity} ({q_first:.6g}): the front is one design"
            _save(path, state)
        if k >= 2 + len(state["levels"] or []):
            break
        if k == 0:
            kind, bound, solved = "first", None, bounded(problem, front, math.inf, front.scale or 1.0)
        elif k == 1:
            kind, bound, solved = "second", None, second_problem(problem, front)
        else:
            kind, bound = "epsilon", state["levels"][k - 2]
            solved = bounded(problem, front, bound, state["scale"])
        if k:  # warm start: the previous point (the first anchor's for the second anchor)
            solved = dataclasses.replace(solved, start=tuple(state["points"][k - 1]["design_SI"]))
        if progress:
            what = f"{front.quantity} {'<=' if front.weight > 0 else '>='} {bound:.6g}" if bound is not None else kind
            print(f"pareto: point {k + 1} ({what})", file=sys.stderr)
        cpu, wall, before = time.process_time(), time.perf_counter(), len(PROGRAMS)
        folder = out / f"point_{k:02d}"
        res = constrained.solve(solved, opt, rounds, out=folder, resume=resume, progress=progress, evaluator=ev)
        x = res["final_design"]
        values = measure(ev, problem, front, x)
        regime = next((h["regime"] for h in res["history"] if [h[f"{n}_SI"] for n in problem.names] == list(x)), "")
        point = {
            "kind": kind,
            "bound": bound,
            "design_SI": list(x),
            **values,
            "regime": regime,
            "nondominated": False,
            "iterations": len(res["history"]),
            "rounds": len(res["rounds"]),
            "programs_compiled": len(PROGRAMS) - before,
            "cpu_seconds": time.process_time() - cpu,
            "wall_seconds": time.perf_counter() - wall,
        }
        state["points"].append(_plain(point))  # NaN as None, as pareto.json holds it
        state["cpu_seconds"] += point["cpu_seconds"]
        state["wall_seconds"] += point["wall_seconds"]
        _save(path, state)
        if progress:
            v, ok = (values["objective"], values["quantity"]), "feasible" if values["feasible"] else "INFEASIBLE"
            print(f"pareto: point {k + 1}: objective {v[0]:.6g}, {front.quantity} {v[1]:.6g}, {ok}", file=sys.stderr)
    score(state)
    write_csv(out / "pareto.csv", problem, state)
    plot_front(out / "pareto.png", problem, state)
    folders = [f"point_{k:02d}" for k in range(len(state["points"]))]
    state["files"] = ["pareto.json", "pareto.csv", "pareto.png", *folders]
    _save(path, state)
    return state


def score(state: dict) -> None:
    """Mark the feasible non-dominated points of ``state`` (``nondominated``) and set its
    ``reference`` and ``hypervolume`` (None without a feasible point)."""
    pts = state["points"]
    values = np.asarray(
        [[p["objective"], p["second"]] if p["feasible"] else [math.nan, math.nan] for p in pts], dtype=float
    ).reshape(-1, 2)
    mask = nondominated(values)
    for p, m in zip(pts, mask):
        p["nondominated"] = bool(m)
    if not mask.any():
        state["reference"], state["hypervolume"] = None, None
        return
    ref = reference_point(values[mask])
    state["reference"], state["hypervolume"] = ref.tolist(), hypervolume(values[mask], ref)


# ---------------------------------------------------------------------------------------- the files


def write_csv(path: Path, problem: DesignProblem, state: dict) -> None:
    """``pareto.csv``: per point, its index and kind, the bound on ``q2`` (``bound:<q2>``), the design
    (``<variable>_<SI unit>``), ``objective_<unit>`` (``f1``), each term (``term:<quantity>``), the
    second objective's quantity (``second:<q2>``) and ``f2`` (``second_objective``), each
    constraint (``constraint:<quantity>``), ``feasible``, ``nondominated`` and the CPU and wall time."""
    q2 = state["front"]["quantity"]
    rows = []
    for i, p in enumerate(state["points"]):
        row = {"point": i, "kind": p["kind"], f"bound:{q2}": "" if p["bound"] is None else p["bound"]}
        row |= {f"{n}_{u}": v for n, u, v in zip(problem.names, state["units"], p["design_SI"])}
        row[f"objective_{unit_of(problem.terms[0][0])}".rstrip("_")] = p["objective"]
        row |= {f"term:{q}": v for (q, _), v in zip(problem.terms, p["terms"])}
        row |= {f"second:{q2}": p["quantity"], "second_objective": p["second"]}
        row |= {f"constraint:{c[0]}": v for c, v in zip(problem.limits, p["constraints"])}
        row |= {k: p[k] for k in ("feasible", "nondominated", "regime")}
        row |= {"cpu_s": p["cpu_seconds"], "wall_s": p["wall_seconds"]}
        rows.append(row)
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]) if rows else ["point"])
        w.writeheader()
        w.writerows(rows)


def plot_front(path: Path, problem: DesignProblem, state: dict) -> None:
    """``pareto.png``: ``f1`` against ``q2`` at every point (the front's points joined, the anchors
    marked, dominated and infeasible points grey), the bounds' levels dotted and the region the
    hypervolume measures shaded."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    q2, w = state["front"]["quantity"], state["front"]["weight"]
    pts = state["points"]
    fig, ax = plt.subplots(figsize=(6.4, 4.6))
    front = sorted((p for p in pts if p["nondominated"]), key=lambda p: p["objective"])
    if front and state.get("reference"):  # the region the front dominates, up to the reference
        r1, r2 = state["reference"]
        xs = [p["second"] for p in front][::-1] + [r2]  # f2 increasing, f1 decreasing
        ys = [p["objective"] for p in front][::-1]
        ax.fill_between(np.asarray(xs) / w, ys + ys[-1:], r1, step="post", color="C0", alpha=0.1, lw=0)
        ax.plot([r2 / w], [r1], "k+", ms=10, label="hypervolume reference")
    ax.plot([p["quantity"] for p in front], [p["objective"] for p in front], "o-", color="C0", label="front")
    rest = [p for p in pts if not p["nondominated"] and p["objective"] is not None and p["quantity"] is not None]
    if rest:
        ax.plot([p["quantity"] for p in rest], [p["objective"] for p in rest], "x", color="0.5", label="dominated")
    ends = [p for p in pts if p["kind"] != "epsilon" and p["objective"] is not None and p["quantity"] is not None]
    ax.plot([p["quantity"] for p in ends], [p["objective"] for p in ends], "s", mfc="none", mec="C3", label="anchors")
    for b in state.get("levels") or []:
        ax.axvline(b, color="0.8", ls=":", lw=0.8)
    unit2, unit1 = unit_of(q2), unit_of(problem.terms[0][0])
    ax.set_xlabel(f"{q2} [{unit2}]" if unit2 else q2)
    single = len(problem.terms) == 1 and problem.terms[0][1] == 1.0 and problem.cost_weight == 0.0
    name1 = problem.terms[0][0] if single else "objective (weighted terms + cost)"
    ax.set_ylabel(f"{name1} [{unit1}]" if unit1 else name1)
    hv = state.get("hypervolume")
    hv_text = f"\nhypervolume {hv:.4g} ({unit1 or '1'} x {unit2 or '1'}, f2 = {w:g} x {q2})" if hv is not None else ""
    ax.set_title(problem.description + hv_text, fontsize=8)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
