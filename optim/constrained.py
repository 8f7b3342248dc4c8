"""Constraints on any quantity, with their exact gradients: the augmented Lagrangian around the
optimiser of [`optim.optimize`][], inside its regime guard.

A [`DesignProblem`][optim.design.DesignProblem] minimises ``f(x) = sum_i w_i q_i(x) + cost(x)`` subject
to ``lower_j <= c_j(x) <= upper_j`` on quantities (metrics of the steady-state orbit, kinematics
of the ideal mechanism) and to bounds and linear constraints (held exactly by the projection).
Each bound on a quantity is a scaled inequality ``g(x) = (c(x) - upper) / s + margin <= 0`` (or
``(lower - c(x)) / s + margin``; ``s`` the constraint's scale; the small ``margin`` makes the
limit strictly feasible). The augmented Lagrangian (Powell-Hestenes-Rockafellar) of round k,

``L_k(x) = f(x) / |f(x_0)| + sum_j (max(0, lambda_j + mu g_j(x))^2 - lambda_j^2) / (2 mu)``,

is minimised by [`optim.optimize.optimize`][] from the last round's design (its regime guard,
checkpoints and history as for any problem); then ``lambda_j <- max(0, lambda_j + mu g_j)``,
and ``mu`` grows tenfold when the largest violation did not fall to a quarter of the last round's
(the first round: of the start's). Every value and
gradient comes from one compiled program per orbit structure
([`QuantityEvaluator`][optim.constrained.QuantityEvaluator]): the problem's outputs and their
Jacobian, by the implicit function theorem at the orbit, so a round's new multipliers cost no
compilation. The rounds stop when every constraint holds and the design moved less than the
optimiser's ``xtol``, or after ``rounds``.
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from jaxcrank.physics.params import ParameterError
from jaxcrank.runs.sweep_table import atomic_write

from .cli import STEADY_OPTIMIZER, settings_from_config
from .design import DesignProblem
from .problem import values_key, with_values
from .steady import RegimeGuard, SteadyEvaluator, _key, _light, report

#: the inequality's margin in units of the constraint's scale: limits are approached from inside
MARGIN = 1e-3
#: the ``[optimizer]`` keys of the augmented Lagrangian (the others are the optimiser's)
ROUND_KEYS = ("rounds", "penalty", "growth")


@dataclasses.dataclass(frozen=True)
class Rounds:
    """The augmented Lagrangian's settings.

    Attributes:
        rounds: outer rounds (multiplier updates), >= 1.
        penalty: the first round's penalty weight mu, > 0.
        growth: mu's growth when the violation did not fall to a quarter, > 1.
    """

    rounds: int = 6
    penalty: float = 10.0
    growth: float = 10.0

    def __post_init__(self):
        if not (isinstance(self.rounds, int) and self.rounds >= 1):
            raise ParameterError(f"[optimizer] rounds = {self.rounds!r} must be an integer >= 1")
        if not self.penalty > 0 or not self.growth > 1:
            raise ParameterError(f"[optimizer] penalty = {self.penalty:g} must be > 0 and growth {self.growth:g} > 1")


def structure(problem: DesignProblem) -> DesignProblem:
    """``problem`` without what its outputs do not depend on (start, title, bounds on quantities,
    weights, the cost's weight): problems with the same structure share the compiled outputs program."""
    return dataclasses.replace(
        problem,
        start=None,
        title="",
        cost_weight=0.0,
        terms=tuple((q, 1.0) for q, _ in problem.terms),
        limits=tuple((q, -math.inf, math.inf, None) for q, *_ in problem.limits),
    )


def scales(problem: DesignProblem) -> np.ndarray:
    """Each constraint's scale: given, or its largest |bound| (1 where both are 0)."""
    out = []
    for _, lo, hi, s in problem.limits:
        size = max(abs(v) for v in (lo, hi) if v is not None)
        out.append(s if s is not None else (size if size > 0 else 1.0))
    return np.asarray(out, dtype=float)


def settings(table: dict):
    """The optimiser settings and the [`Rounds`][optim.constrained.Rounds] of a problem file's
    ``[optimizer]`` table: the steady-state default (Adam with the regime guard) changed by its
    keys, the `ROUND_KEYS` going to the rounds.

    Raises:
        ParameterError: an unknown key or a bad value, naming it."""
    values = dict(table)
    rounds = Rounds(**{k: values.pop(k) for k in ROUND_KEYS if k in values})
    values = values if "method" in values else {**STEADY_OPTIMIZER, **values}
    return dataclasses.replace(settings_from_config(values), guard=RegimeGuard()), rounds


def inequalities(problem: DesignProblem, values) -> tuple[np.ndarray, np.ndarray]:
    """The scaled inequalities ``g <= 0`` of the constraints' ``values`` (margin not included) and,
    per inequality, the index of its constraint and its sign (d g / d c = sign / scale)."""
    s = scales(problem)
    g, rows = [], []
    for j, (_, lo, hi, _) in enumerate(problem.limits):
        if hi is not None:
            g.append((values[j] - hi) / s[j]), rows.append((j, 1.0 / s[j]))
        if lo is not None:
            g.append((lo - values[j]) / s[j]), rows.append((j, -1.0 / s[j]))
    return np.asarray(g, dtype=float), np.asarray(rows, dtype=float).reshape(-1, 2)


def satisfied(problem: DesignProblem, values, tol: float = 0.0) -> list[bool]:
    """Whether each constraint holds at its ``values`` (within ``tol`` of its unit)."""
    out = []
    for v, (_, lo, hi, _) in zip(values, problem.limits):
        out.append(bool(np.isfinite(v) and (lo is None or v >= lo - tol) and (hi is None or v <= hi + tol)))
    return out


class QuantityEvaluator(SteadyEvaluator):
    """The steady-state evaluator of a [`DesignProblem`][optim.design.DesignProblem]: the problem's outputs
    (terms, cost, constraints' quantities) and their Jacobian at concrete designs, and the
    augmented Lagrangian's value and gradient from them (`set_round`). Outputs are kept per
    design, so every iterate is reported with its constraint values
    ([`row`][optim.constrained.QuantityEvaluator.row])."""

    def __init__(self, problem: DesignProblem):
        super().__init__(problem)
        self.outputs = {}  # design key -> outputs vector (numpy)
        self.retarget(problem)

    def retarget(self, problem: DesignProblem) -> None:
        """Measure ``problem`` from now on, keeping the steady states found so far (a problem that
        differs in its bounds, weights or start: a Pareto front's next point). The outputs kept per
        design stay when the quantities are the same; the multipliers start at zero."""
        if structure(problem) != structure(self.problem):
            self.outputs = {}
        self.problem = problem.with_objective(self.objective)
        self.lam = np.zeros(len(inequalities(problem, np.zeros(len(problem.limits)))[0]))
        self.mu, self.f_ref, self.offset = 10.0, None, 0.0
        shape = structure(problem)
        self._plain = jax.jit(lambda x, metrics: shape.outputs(metrics, x))
        self._plain_jac = jax.jit(jax.jacfwd(lambda x, metrics: shape.outputs(metrics, x)))

    # -------------------------------------------------------------- the outputs
    def _metrics(self, steady) -> dict:
        if steady.periodic:
            return {k: jnp.asarray(v) for k, v in steady.metrics.items()}
        return {k: jnp.asarray(float(s["value"])) for k, s in steady.statistics.items()}

    def outputs_at(self, x) -> np.ndarray:
        """The outputs at SI design ``x`` (NaN where the solve failed), cached."""
        key = _key(x)
        if key not in self.outputs:
            steady = self.steady_at(x)
            k = len(self.problem.quantities) + 1
            self.outputs[key] = (
                np.asarray(self._plain(jnp.asarray(key), self._metrics(steady))) if steady.ok else np.full(k, np.nan)
            )
        return self.outputs[key]

    def _program_key(self, steady, folded: bool = False):
        shape = structure(self.problem)
        return ("outputs", shape if folded else values_key(shape), steady.period_revolutions, steady.active)

    def _program_fun(self, steady, folded: bool = False):
        problem, objective, template = self.problem, self.objective, _light(steady)

        def f(x, section_state, monodromy, values):
            p = problem if folded else with_values(problem, values)
            light = dataclasses.replace(template, section_state=section_state, monodromy=monodromy)
            return p.outputs(objective.rms_at(p.mechanism(x), light, every=True), x)

        return lambda *a: (f(*a), jax.jacfwd(f)(*a))

    def outputs_and_jacobian(self, x) -> tuple[np.ndarray, np.ndarray, dict]:
        """The outputs at SI design ``x``, their Jacobian (k, n) per SI unit, and the regime
        report. Periodic: exact through the orbit; not periodic: the metrics' long-run values
        with no gradient (the kinematics' and the cost's exact); failed: NaN."""
        x = np.asarray(x, dtype=float)
        steady = self.steady_at(x)
        info = self.last_report = report(steady)
        k = len(self.problem.quantities) + 1
        if not steady.ok:
            return np.full(k, np.nan), np.full((k, x.size), np.nan), info
        if steady.periodic:
            args = self._args(x, steady)
            out, jac = self._program(steady, args)(*args)
            self._gradient_done()
        else:
            metrics = self._metrics(steady)
            out, jac = self._plain(jnp.asarray(x), metrics), self._plain_jac(jnp.asarray(x), metrics)
        self.outputs[_key(x)] = np.asarray(out)
        return np.asarray(out), np.asarray(jac), info

    # -------------------------------------------------------------- the augmented Lagrangian
    def objective_of(self, outputs) -> float:
        """``f``: the weighted terms + cost of an outputs vector."""
        terms, cost, _ = self.problem.split(outputs)
        return float(np.dot([w for _, w in self.problem.terms], terms) + cost)

    def lagrangian(self, outputs, jac=None):
        """The round's augmented Lagrangian (dimensionless) of an outputs vector, and its gradient
        (n,) from their Jacobian when given."""
        p = self.problem
        n_terms = len(p.terms)
        f = self.objective_of(outputs)
        if self.f_ref is None and math.isfinite(f):
            self.f_ref = abs(f) if f != 0.0 else 1.0
        ref = self.f_ref or 1.0
        g, rows = inequalities(p, np.asarray(outputs)[n_terms + 1 :])
        shifted = np.maximum(0.0, self.lam + self.mu * (g + MARGIN))
        value = f / ref + float(np.sum(shifted**2 - self.lam**2)) / (2.0 * self.mu) - self.offset
        if jac is None:
            return value
        jac = np.asarray(jac)
        w = np.asarray([w for _, w in p.terms])
        grad = (w @ jac[:n_terms] + p.cost_weight * jac[n_terms]) / ref
        for (j, slope), s in zip(rows, shifted):
            grad = grad + s * slope * jac[n_terms + 1 + int(j)]
        return value, grad

    def set_round(self, lam, mu, x) -> None:
        """Start a round with multipliers ``lam`` and penalty ``mu``, offset so that the round's
        start ``x`` has value 1 (the optimiser scales by the start's value)."""
        self.lam, self.mu, self.offset = np.asarray(lam, dtype=float), float(mu), 0.0
        self.offset = self.lagrangian(self.outputs_at(x)) - 1.0

    def report_at(self, x) -> dict:
        """[`report`][optim.steady.report] of the steady state the outputs at SI design ``x`` come from."""
        return report(self.steady_at(x))

    def value(self, x) -> tuple[float, dict]:
        out = self.outputs_at(x)
        self.last_report = self.report_at(x)
        return (math.nan if not np.all(np.isfinite(out)) else self.lagrangian(out)), self.last_report

    def value_and_grad(self, x) -> tuple[float, np.ndarray, dict]:
        out, jac, info = self.outputs_and_jacobian(x)
        if not (np.all(np.isfinite(out)) and np.all(np.isfinite(jac))):
            return math.nan, np.full(np.shape(x), np.nan), info
        value, grad = self.lagrangian(out, jac)
        return float(value), np.asarray(grad), info

    def row(self, x) -> dict:
        """The history columns of SI design ``x``: each term's and constraint's value (units
        in the quantity's name) and the objective ``f``; empty when ``x`` was not evaluated."""
        out = self.outputs.get(_key(x))
        if out is None:
            return {}
        terms, cost, cons = self.problem.split(out)
        return {
            "f": self.objective_of(out),
            **{f"term:{q}": float(v) for (q, _), v in zip(self.problem.terms, terms)},
            **{f"constraint:{c[0]}": float(v) for c, v in zip(self.problem.limits, cons)},
        }


def next_penalty(mu: float, worst: float, before: float, growth: float) -> float:
    """The next round's penalty: ``mu * growth`` when the round's largest scaled violation
    ``worst`` is positive and did not fall to a quarter of ``before`` (the last round's, or the
    start's after the first round), else ``mu``."""
    return mu * growth if worst > 0.0 and worst > 0.25 * before else mu


def _worst(problem: DesignProblem, ev: QuantityEvaluator, x) -> float:
    """The largest scaled violation at SI design ``x`` (0 when every constraint holds; inf where an
    output is not finite)."""
    g, _ = inequalities(problem, problem.split(ev.outputs_at(np.asarray(x, dtype=float)))[2])
    return float(np.max(g, initial=0.0)) if np.all(np.isfinite(g)) else math.inf


def report_terms(problem: DesignProblem, outputs) -> dict:
    """``objectives`` and ``constraints`` of an outputs vector: each with ``quantity``, ``value``,
    ``lower``, ``upper`` and ``satisfied`` (objectives: ``weight``, no bounds); and ``f``."""
    terms, cost, cons = problem.split(outputs)
    ok = satisfied(problem, cons)
    return {
        "objective": float(np.dot([w for _, w in problem.terms], terms) + cost),
        "cost": cost,
        "objectives": [
            {"quantity": q, "weight": w, "value": float(v), "lower": None, "upper": None, "satisfied": True}
            for (q, w), v in zip(problem.terms, terms)
        ],
        "constraints": [
            {"quantity": q, "value": float(v), "lower": lo, "upper": hi, "satisfied": s}
            for (q, lo, hi, _), v, s in zip(problem.limits, cons, ok)
        ],
    }


def solve(
    problem: DesignProblem,
    settings,
    rounds: Rounds = Rounds(),
    out: Path | None = None,
    resume: bool = False,
    progress: bool = True,
    evaluator: QuantityEvaluator | None = None,
) -> dict:
    """Minimise a [`DesignProblem`][optim.design.DesignProblem] under its constraints (module docstring).

    Args:
        settings: the optimiser of each round ([`optim.optimize.Settings`][]; its
            ``max_iterations`` and ``max_seconds`` are per round).
        rounds: the augmented Lagrangian's settings.
        out: run folder: ``round_NN/`` per round (the optimiser's checkpoint and history) and
            ``rounds.json`` (the finished rounds); None: no checkpoints.
        resume: continue from ``out``: finished rounds are kept, the unfinished one resumed.
        evaluator: an evaluator to reuse ([`QuantityEvaluator.retarget`][optim.constrained.QuantityEvaluator.retarget]
            to ``problem``): its steady states warm-start this solve (the points of a Pareto front).

    Returns a dict: ``rounds`` (per round: the design, multipliers, penalty, objective and
    largest violation), ``history`` (every iterate of every round, with its terms' and
    constraints' values), ``start`` and ``final`` ([`report_terms`][optim.constrained.report_terms] with
    ``design_SI``), ``final_design`` (SI; the best design that satisfies every constraint, else the
    least violating), ``feasible``, ``start_search`` (the way in, when it ran) and ``seconds``.
    """
    from .optimize import optimize
    from .way_in import periodic_start

    tic = time.perf_counter()
    if evaluator is None:
        ev = QuantityEvaluator(problem)
    else:
        ev = evaluator
        ev.retarget(problem)
    ev.mu = rounds.penalty
    state = _load(out) if resume and out is not None and (Path(out) / "rounds.json").exists() else None
    found = None
    if state is None:
        found = periodic_start(problem, seed=settings.seed, progress=progress, evaluator=ev)
        x = np.asarray(found.problem.from_unit(found.problem.start_unit()), dtype=float)
        state = {
            "start": x.tolist(),
            "f_ref": ev.f_ref,
            "rounds": [],
            "search": found.describe(),
            "search_seconds": found.seconds,
        }
        lam, mu = np.zeros_like(ev.lam), rounds.penalty
    else:
        ev.f_ref = state["f_ref"]
        last = state["rounds"][-1] if state["rounds"] else None
        x = np.asarray(last["design_SI"] if last else state["start"])
        lam = np.asarray(last["next_multipliers"]) if last else np.zeros_like(ev.lam)
        mu = last["next_penalty"] if last else rounds.penalty
    history = []
    for k in range(len(state["rounds"]), rounds.rounds):
        ev.set_round(lam, mu, x)
        folder = None if out is None else Path(out) / f"round_{k:02d}"
        again = resume and folder is not None and (folder / "checkpoint.npz").exists()
        res = optimize(
            dataclasses.replace(problem, start=tuple(x)),
            settings,
            out=folder,
            resume=again,
            progress=progress,
            evaluator=ev,
        )
        for h in res["history"]:
            design = [h[f"{n}_SI"] for n in problem.names]
            history.append({"round": k, **h, **ev.row(design)})
        x_new = np.asarray(res["final"], dtype=float)
        g, _ = inequalities(problem, problem.split(ev.outputs_at(x_new))[2])
        worst = float(np.max(g)) if g.size else 0.0
        before = state["rounds"][-1]["max_violation"] if state["rounds"] else _worst(problem, ev, state["start"])
        lam = np.maximum(0.0, lam + mu * (g + MARGIN)) if g.size else lam
        mu_next = next_penalty(mu, worst, before, rounds.growth)
        moved = float(np.max(np.abs(np.asarray(problem.to_unit(x_new)) - np.asarray(problem.to_unit(x)))))
        state["rounds"].append(
            {
                "round": k,
                "design_SI": x_new.tolist(),
                "multipliers": ev.lam.tolist(),
                "penalty": mu,
                "objective": ev.objective_of(ev.outputs_at(x_new)),
                "max_violation": worst,
                "moved": moved,
                "stop_reason": res["stop_reason"],
                "next_multipliers": lam.tolist(),
                "next_penalty": mu_next,
            }
        )
        state["f_ref"] = ev.f_ref
        if out is not None:
            _save(out, state)
        x, mu = x_new, mu_next
        if worst <= 0.0 and (moved < settings.xtol or not problem.limits):
            break
    candidates = [np.asarray(state["start"])] + [np.asarray(r["design_SI"]) for r in state["rounds"]]
    candidates += [np.asarray([h[f"{n}_SI"] for n in problem.names]) for h in history]
    final = _best(problem, ev, candidates)
    start_out, final_out = ev.outputs_at(np.asarray(state["start"])), ev.outputs_at(final)
    return {
        "rounds": state["rounds"],
        "history": history,
        "start": {"design_SI": list(state["start"]), **report_terms(problem, start_out)},
        "final": {"design_SI": final.tolist(), **report_terms(problem, final_out)},
        "final_design": final.tolist(),
        "feasible": all(satisfied(problem, problem.split(final_out)[2])),
        "start_search": state.get("search"),
        "seconds": {
            "way_in": state.get("search_seconds", 0.0),
            "total": time.perf_counter() - tic,
            "gradient_compile": ev.compile_seconds,
            "first_gradient": ev.first_gradient,
        },
    }


def _best(problem: DesignProblem, ev: QuantityEvaluator, designs) -> np.ndarray:
    """The design with the lowest objective among those that satisfy every constraint, else the
    one with the smallest largest violation."""
    scored = []
    for x in designs:
        out = ev.outputs_at(x)
        if not np.all(np.isfinite(out)) or not problem.feasible(x):
            continue
        g, _ = inequalities(problem, problem.split(out)[2])
        worst = float(np.max(g)) if g.size else 0.0
        scored.append((max(worst, 0.0), ev.objective_of(out), x))
    if not scored:
        raise ParameterError("no design of the run could be evaluated (every steady-state solve failed)")
    return min(scored, key=lambda s: (s[0], s[1]))[2]


def _save(out, state) -> None:
    path = Path(out) / "rounds.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write(path, lambda f: f.write(json.dumps(state, indent=1).encode()))


def _load(out) -> dict:
    return json.loads((Path(out) / "rounds.json").read_text())
