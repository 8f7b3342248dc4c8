"""The exact steady-state gradient against central differences of runs from rest, at
periodic designs of the nine-variable design problem whose orbit has no idle memory.

The reference is the steady-state objective as a user would compute it without the
steady-state solver: a plain simulation from pins-centred rest, ``--revolutions``
revolutions, then Eq. 19 (``rms_transmission_angle_error_deg``) over the next k
revolutions (k the orbit's period; rtol = atol = 1e-10, 3600 samples per revolution).
Its central differences, step ``--h`` of the unit box per variable, are compared with
the implicit-function-theorem gradient
(:func:`jaxcrank.numerics.steady.steady_value_and_grad`, unit-box variables).

Candidates: the designs of ``bench/steady_gradient.py``, the unit designs stored in
``bench/results/design_frozen_law.json`` (the earlier single-problem head-to-head, measured
under the frozen memory law: every method's checkpoints, the ``ours`` method's classified
designs; their sources are labelled ``design.json:...``, the file's name when they were
recorded, so that a rerun resumes the recorded results) and ``--sobol`` scrambled Sobol
points of the unit box (``--seed``), classified in one batch
(:func:`jaxcrank.runs.regimes.classify`, kernel engine, 20 revolutions from rest);
``steady_state`` (defaults) on the periodic ones gives the period, the Floquet multipliers
and the neutral entries. Designs whose orbit has no idle approach-speed memory
(``neutral`` holds only the two works) are evaluated, period 1 first, then by leading
multiplier, up to ``--designs`` of them.

Per evaluated design and per run from rest at u +- h e_i: Eq. 19, and the distance (max
over the dynamic entries, ``steady.active``, scaled units) between its section state after
``--revolutions`` and the section state of the same design continued ``--continue``
revolutions (rounded up to whole periods) from the centre design's settled state (its run
from rest; pins carried over, :func:`jaxcrank.numerics.steady.carry_state`): the orbit the
gradient follows. For a period-k orbit the distance is the smallest over its k section
points (continued 0 to k - 1 revolutions further; ``phase_revolutions``), since a run from
rest may settle onto the orbit in another phase. A run farther than ``--left-tol`` scaled
units has left that orbit.

With ``--random``, the candidates are the Sobol points alone and the first ``--designs``
periodic ones are evaluated in the order they were drawn, idle memory or not (nothing is
screened for passing); each evaluated design is also re-solved from its own orbit with
every approach-speed memory halved and doubled (``unique_orbit``: the largest section
difference over the dynamic entries, scaled units, and Eq. 19's relative change).

With ``--continued``, each evaluated design also gets ``continued``: the central differences
of runs continued on the orbit the gradient follows (each run at u +- h e_i continued from
the centre design's settled state, then Eq. 19 over one period), against the same exact
gradient. Where runs from rest at u +- h settle onto another orbit than the centre's (a
design near the boundary between the basins of coexisting orbits), the from-rest objective
jumps there and no gradient can match its differences; the continued runs say whether the
gradient is that of the orbit it follows.

Writes ``--out`` (default ``bench/results/steady_from_rest.json``) after every design (a
rerun resumes: the screening and the finished designs are kept), with the memory law of
the joints. Usage:
``python bench/steady_from_rest.py --designs 8 --sobol 128 --seed 0``;
``python bench/steady_from_rest.py --random --designs 10 --sobol 32 --seed 1
--out bench/results/steady_from_rest_random.json``, then the same with ``--continued``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

import jax.numpy as jnp
import numpy as np
from _common import machine
from scipy.stats import qmc
from steady_gradient import _tracked as tracked
from steady_gradient import designs as gradient_designs

import jaxcrank as jc
from jaxcrank.numerics.steady import carry_state, steady_value_and_grad
from jaxcrank.physics import model
from jaxcrank.runs.regimes import classify
from optim.presets import design_problem

KEY = "rms_transmission_angle_error_deg"
ROOT = Path(__file__).resolve().parent
WORKS = {"driver_work", "dissipated_work"}
TOL = {"rtol": 1e-10, "atol": 1e-10, "max_steps": 10_000_000}


def law_entries(mech):
    """Indices (into the state) of the joint laws' entries, and of the approach-speed memories."""
    names = model.law_state_names(mech)
    start = 2 * model.n_dof(mech)
    law = np.arange(start, start + len(names))
    return law, np.array([start + i for i, n in enumerate(names) if n.endswith("approach_memory")])


def unique_orbit(mech, steady):
    """Re-solve ``mech``'s steady state from its own orbit with every approach-speed memory
    scaled by 0.5 and by 2: the largest section difference over the dynamic entries (scaled)
    and Eq. 19's relative change, per factor."""
    _, memories = law_entries(mech)
    active = np.asarray(steady.active)
    y = np.asarray(steady.section_state)
    k = int(steady.period_revolutions)
    samples = steady.samples_per_revolution
    # the orbit's k section points: a warm start may land on any of them (the same orbit)
    phases = [np.asarray(steady.orbit.ys[j * samples]) for j in range(k)]
    out = {}
    for factor in (0.5, 2.0):
        y0 = y.copy()
        y0[memories] *= factor
        again = jc.steady_state(mech, warm_start=jnp.asarray(y0), throw=False)
        same_regime = again.regime == steady.regime and int(again.period_revolutions) == int(steady.period_revolutions)
        end = np.asarray(again.section_state)
        distance = min(float(np.max(np.abs(end - p)[: active.size][active])) for p in phases)
        v0, v1 = float(steady.metrics[KEY]), float(again.metrics[KEY])
        out[str(factor)] = {
            "regime": again.regime,
            "period_revolutions": int(again.period_revolutions),
            "section_difference_scaled": distance if same_regime else None,
            "eq19_relative_change": abs(v1 - v0) / abs(v0) if same_regime else None,
        }
    out["same_orbit"] = all(
        e["section_difference_scaled"] is not None
        and e["section_difference_scaled"] <= 1e-6
        and e["eq19_relative_change"] <= 1e-8
        for e in (out["0.5"], out["2.0"])
    )
    return out


def candidates(prob, n_sobol, seed, sobol_only=False):
    """(source, unit design) pairs, duplicates removed; ``sobol_only``: the Sobol points alone."""
    lo, hi = np.array(prob.lower), np.array(prob.upper)
    out = [(f"steady_gradient:{name}", (np.asarray(x) - lo) / (hi - lo)) for name, x in gradient_designs().items()]
    study = json.loads((ROOT / "results" / "design_frozen_law.json").read_text())
    if sobol_only:
        out, study = [], {"problems": []}
    for problem in study["problems"]:
        if problem["n_variables"] != 9:
            continue
        for method, res in problem["methods"].items():
            for j, c in enumerate(res.get("checkpoints", [])):
                out.append((f"design.json:{method}:checkpoint{j}", np.asarray(c["unit_design"])))
            for j, c in enumerate(res.get("classified", [])):
                if c.get("regime") == "periodic":
                    out.append((f"design.json:{method}:classified{j}", np.asarray(c["unit_design"])))
    if n_sobol:
        units = qmc.Sobol(d=9, scramble=True, seed=seed).random(n_sobol)
        out += [(f"sobol(seed={seed}):{j}", u) for j, u in enumerate(units)]
    seen, unique = set(), []
    for source, u in out:
        key = tuple(np.round(u, 9))
        if key not in seen:
            seen.add(key)
            unique.append((source, u))
    return unique


def screen(prob, build, cands, rows, limit=None):
    """Regime by ``classify`` (kernel), then ``steady_state`` on the periodic designs (in
    order, until ``limit`` of them are periodic by ``steady_state``; the rest keep the
    classification alone). ``rows``: screened rows already done (kept)."""
    done = {r["source"] for r in rows}
    todo = [(s, u) for s, u in cands if s not in done]
    if not todo:
        return rows
    lo, hi = np.array(prob.lower), np.array(prob.upper)
    names = prob.physical(jnp.asarray(lo + todo[0][1] * (hi - lo)))[0]
    physical = np.array([np.asarray(prob.physical(jnp.asarray(lo + u * (hi - lo)))[1]) for _, u in todo])
    table = classify(prob.base, names, physical, engine="kernel")
    order = np.argsort(np.asarray(table["index"]).astype(int))
    regimes, statuses = np.asarray(table["regime"])[order], np.asarray(table["status"])[order]
    for (source, u), regime, status in zip(todo, regimes, statuses):
        row = {
            "source": source,
            "unit_design": u.tolist(),
            "classify_status": str(status),
            "classify_regime": str(regime),
        }
        enough = limit is not None and sum(r.get("regime") == "periodic" for r in rows) >= limit
        if regime == "periodic" and not enough:
            steady = jc.steady_state(build(jnp.asarray(u)), throw=False)
            row.update(
                regime=steady.regime,
                period_revolutions=int(steady.period_revolutions),
                neutral=list(steady.neutral),
                multipliers_abs=[float(v) for v in steady.multiplier_moduli[:4]],
            )
            head = (steady.regime, steady.period_revolutions, row["neutral"], row["multipliers_abs"][:2])
            print("screen", source, *head, flush=True)
        rows.append(row)
    return rows


def no_idle_memory(row):
    return row.get("regime") == "periodic" and set(row["neutral"]) <= WORKS


def from_rest(mech, revolutions, k):
    """Scaled section state after ``revolutions`` from rest and Eq. 19 over the next ``k``."""
    T = float(mech.period)
    sim = jc.simulate(
        mech,
        t1=(revolutions + k) * T,
        n_samples=(revolutions + k) * 3600 + 1,
        metrics_start=revolutions * T,
        save_samples=False,
        save_ts=jnp.array([revolutions * T]),
        options=jc.SolveOptions(**TOL),
    )
    return np.asarray(sim.ys[0]), float(sim.metrics[KEY])


def continued_sections(centre_mech, y, mech, revolutions, count=1):
    """Section states of ``mech`` after ``revolutions``, ``revolutions + 1``, ...
    (``count`` of them, one solve) continued from the centre's state ``y``, shape (count, state)."""
    y0 = carry_state(centre_mech, jnp.asarray(y), mech).at[-2:].set(0.0)
    ts = jnp.concatenate([jnp.zeros(1), revolutions + jnp.arange(count, dtype=float)]) * float(mech.period)
    sim = jc.simulate(mech, ts=ts, y0=y0, options=jc.SolveOptions(**TOL))
    return np.asarray(sim.ys[1:])


def continued_value(centre_mech, y, mech, revolutions, k):
    """Eq. 19 of ``mech`` over the k revolutions after ``revolutions`` continued from the
    centre's section state ``y`` (pins carried over), sampled as `from_rest`."""
    return tracked(mech, revolutions, y0=carry_state(centre_mech, jnp.asarray(y), mech).at[-2:].set(0.0), k=k)


def compare(grad, fd) -> dict:
    """The exact gradient ``grad`` against central differences ``fd``: the relative error in
    norm, whether every component above 5 % of the norm has the right sign, and whether both
    hold the requirement (error within 2 %)."""
    norm = np.linalg.norm(fd)
    big = np.abs(fd) > 0.05 * norm
    rel = float(np.linalg.norm(grad - fd) / norm)
    signs = bool(np.all(np.sign(grad[big]) == np.sign(fd[big])))
    return {"rel_error_norm": rel, "signs_agree_above_5pct_of_norm": signs, "meets_requirement": rel <= 0.02 and signs}


def continued_differences(build, res, args):
    """Central differences of Eq. 19 on the orbit the gradient follows: each run at u +- h e_i
    continued ``--continue`` revolutions (a whole number of periods) from the centre design's
    state after ``--revolutions`` from rest, then Eq. 19 over one period; compared with the
    stored exact gradient like the runs from rest. A plain simulation, no steady-state solver."""
    u0, h, k = np.asarray(res["unit_design"]), res["h_box"], int(res["period_revolutions"])
    t0 = time.perf_counter()
    centre = build(jnp.asarray(u0))
    y_centre, _ = from_rest(centre, args.revolutions, k)
    cont = k * -(-args.cont // k)
    fd = []
    for i in range(u0.size):
        values = []
        for sign in (1.0, -1.0):
            u = u0.copy()
            u[i] += sign * h
            values.append(continued_value(centre, y_centre, build(jnp.asarray(u)), cont, k))
        fd.append((values[0] - values[1]) / (2 * h))
    fd = np.array(fd)
    return {
        "revolutions_continued": cont,
        "gradient_fd": fd.tolist(),
        **compare(np.asarray(res["gradient_ift"]), fd),
        "wall_s": time.perf_counter() - t0,
    }


def evaluate(build, row, h, args):
    u0 = np.asarray(row["unit_design"])
    t0 = time.perf_counter()
    steady = jc.steady_state(build(jnp.asarray(u0)), throw=False)
    k = int(steady.period_revolutions)
    value, grad = steady_value_and_grad(lambda sim: sim.metrics[KEY], build, jnp.asarray(u0), steady)
    grad = np.asarray(grad)
    active = np.asarray(steady.active)
    centre = build(jnp.asarray(u0))
    y_centre, value_rest = from_rest(centre, args.revolutions, k)
    m = active.size
    centre_to_orbit = float(np.max(np.abs(y_centre - np.asarray(steady.section_state))[:m][active]))
    fd, runs = [], []
    for i in range(u0.size):
        pair = []
        for sign in (1.0, -1.0):
            u = u0.copy()
            u[i] += sign * h
            mech = build(jnp.asarray(u))
            y_rest, v = from_rest(mech, args.revolutions, k)
            # a whole number of periods, and then each of the k - 1 revolutions after it: a run
            # from rest may settle onto any of a period-k orbit's k section points (its phase)
            sections = continued_sections(centre, y_centre, mech, k * -(-args.cont // k), k)
            phases = [np.abs(y_rest - section)[:m] for section in sections]
            phase = int(np.argmin([np.max(diff[active]) for diff in phases]))
            diff = phases[phase]
            d = float(np.max(diff[active]))
            law = law_entries(mech)[0]
            memories = float(np.max(diff[law][active[law]], initial=0.0))
            pair.append(
                {
                    "value_deg": v,
                    "distance_scaled": d,
                    "phase_revolutions": phase,
                    "distance_coordinates_rates_scaled": float(np.max(diff[: law[0]])),
                    "distance_memories_scaled": memories,
                    "left_orbit": d > args.left_tol,
                }
            )
        fd.append((pair[0]["value_deg"] - pair[1]["value_deg"]) / (2 * h))
        runs.append(pair)
        print(f"  var {i}: fd {fd[-1]:+.6g} ift {grad[i]:+.6g} distances {[p['distance_scaled'] for p in pair]}",
              flush=True)  # fmt: skip
    fd = np.array(fd)
    agreement = compare(grad, fd)
    left = sum(p["left_orbit"] for pair in runs for p in pair)
    per_var = [
        float(abs(fd[i] - grad[i]) / abs(grad[i])) if grad[i] != 0 else None for i in range(u0.size)
    ]  # relative error per component
    return {
        "h_box": h,
        "value_ift_deg": float(value),
        "value_from_rest_deg": value_rest,
        "centre_from_rest_to_orbit_scaled": centre_to_orbit,
        "gradient_ift": grad.tolist(),
        "gradient_fd": fd.tolist(),
        "rel_error_norm": agreement["rel_error_norm"],
        "rel_error_per_variable": per_var,
        "signs_agree_above_5pct_of_norm": agreement["signs_agree_above_5pct_of_norm"],
        "runs": runs,
        "runs_left_orbit": int(left),
        "runs_off_orbit_above_1e-6": int(sum(p["distance_scaled"] > 1e-6 for pair in runs for p in pair)),
        "variables_with_both_runs_on_orbit": [
            i for i, pair in enumerate(runs) if not any(p["left_orbit"] for p in pair)
        ],
        "meets_requirement": agreement["meets_requirement"],
        "unique_orbit": unique_orbit(centre, steady) if args.random else None,
        "wall_s": time.perf_counter() - t0,
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--designs", type=int, default=8, help="designs to evaluate (no idle memory)")
    parser.add_argument("--sobol", type=int, default=128, help="Sobol points screened")
    parser.add_argument("--seed", type=int, default=0, help="Sobol scramble seed")
    parser.add_argument("--h", type=float, nargs="+", default=[1e-3], help="steps of the differences, box")
    parser.add_argument("--revolutions", type=int, default=30, help="revolutions from rest before the objective")
    parser.add_argument("--continue", dest="cont", type=int, default=25, help="revolutions of a continued run")
    parser.add_argument("--left-tol", type=float, default=1e-3, help="distance (scaled) of a run that left the orbit")
    parser.add_argument("--max-candidates", type=int, help="screen only the first N candidates (default all)")
    parser.add_argument("--out", type=Path, default=ROOT / "results" / "steady_from_rest.json")
    parser.add_argument(
        "--random", action="store_true", help="Sobol points only, periodic ones evaluated in draw order, idle or not"
    )
    parser.add_argument(
        "--continued",
        action="store_true",
        help="add to each evaluated design the differences of runs continued on its orbit (continued_differences)",
    )
    args = parser.parse_args()
    prob = design_problem()
    lo, hi = jnp.asarray(prob.lower), jnp.asarray(prob.upper)
    args.memory_law = memory_law(prob.base)

    def build(u):
        return prob.mechanism(lo + u * (hi - lo))

    state = {"screened": [], "evaluated": []}
    if args.out.exists():
        state = {k: json.loads(args.out.read_text())[k] for k in state}
    cands = candidates(prob, args.sobol, args.seed, sobol_only=args.random)[: args.max_candidates]
    state["screened"] = screen(prob, build, cands, state["screened"], limit=args.designs if args.random else None)
    _write(args, state)
    if args.random:  # in draw order, nothing screened out but the regime
        pool = [r for r in state["screened"] if r.get("regime") == "periodic"]
    else:
        pool = [r for r in state["screened"] if no_idle_memory(r)]
        pool.sort(key=lambda r: (r["period_revolutions"] != 1, r["multipliers_abs"][0]))
    print(f"{len(pool)} periodic designs without idle memory", flush=True)
    if args.continued:
        for res in state["evaluated"]:
            if "continued" not in res:
                res["continued"] = continued_differences(build, res, args)
                c = res["continued"]
                print(f"{res['source']}: continued rel error {c['rel_error_norm']:.3g} signs "
                      f"{c['signs_agree_above_5pct_of_norm']} ({c['wall_s']:.0f} s)", flush=True)  # fmt: skip
                _write(args, state)
        return
    for row in pool[: args.designs]:
        for h in args.h:
            if any(e["source"] == row["source"] and e["h_box"] == h for e in state["evaluated"]):
                continue
            print("evaluate", row["source"], "h", h, row["period_revolutions"], row["multipliers_abs"][:2], flush=True)
            res = {k: row[k] for k in ("source", "unit_design", "regime", "period_revolutions", "neutral")}
            res["multipliers_abs"] = row["multipliers_abs"]
            res.update(evaluate(build, row, h, args))
            print(f"  rel error {res['rel_error_norm']:.3g} signs {res['signs_agree_above_5pct_of_norm']} "
                  f"left {res['runs_left_orbit']}/18 ({res['wall_s']:.0f} s)", flush=True)  # fmt: skip
            state["evaluated"].append(res)
            _write(args, state)
    _write(args, state)


def memory_law(base):
    """The memory law of ``base``'s joints: its class by joint and its settings (SI)."""
    laws = {j: type(base.joints[j].memory).__name__ for j in base.joints if hasattr(base.joints[j], "memory")}
    law = base.joints[next(iter(laws))].memory
    return {"by_joint": laws, "settings": {f.name: float(getattr(law, f.name)) for f in dataclasses.fields(law)}}


def _write(args, state):
    ev = state["evaluated"]
    hs = sorted({e["h_box"] for e in ev})
    summary = {
        "periodic_screened": sum(r.get("regime") == "periodic" for r in state["screened"]),
        "without_idle_memory": sum(no_idle_memory(r) for r in state["screened"]),
        "evaluated": {str(h): sum(e["h_box"] == h for e in ev) for h in hs},
        "meets_requirement": {str(h): sum(e["meets_requirement"] for e in ev if e["h_box"] == h) for h in hs},
        "no_run_left_orbit": {str(h): sum(e["runs_left_orbit"] == 0 for e in ev if e["h_box"] == h) for h in hs},
        "every_run_within_1e-6": {
            str(h): sum(e["runs_off_orbit_above_1e-6"] == 0 for e in ev if e["h_box"] == h) for h in hs
        },
    }
    meta = {"revolutions": args.revolutions, "continued": args.cont, "left_tol_scaled": args.left_tol, **TOL}
    meta.update(random_draw=args.random, sobol=args.sobol, seed=args.seed, memory_law=args.memory_law)
    if any("continued" in e for e in ev):
        summary["continued_meets_requirement"] = {
            str(h): sum(e["continued"]["meets_requirement"] for e in ev if e["h_box"] == h and "continued" in e)
            for h in hs
        }
    if args.random:
        summary["drawn"] = len(state["screened"])
        summary["unique_orbit"] = sum(bool(e.get("unique_orbit", {}).get("same_orbit")) for e in ev)
    tmp = args.out.with_suffix(".tmp")
    tmp.write_text(json.dumps({**meta, "summary": summary, **state, "machine": machine()}, indent=1))
    tmp.replace(args.out)


if __name__ == "__main__":
    main()
