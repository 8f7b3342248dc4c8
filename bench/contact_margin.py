"""Does the ideal mechanism's contact margin lead into the periodic regime?

``python bench/contact_margin.py [--design-json bench/results/design_frozen_law.json] [--starts 6]``

The nine-variable design problem at its preset stroke and crank speed, with the
steady-state objective settings of ``bench/bench_design.py`` (``STEADY``).
:func:`jaxcrank.physics.ideal.contact_margin` is a closed-form property of the *ideal*
mechanism: how far the loads through B and C stay from zero over a revolution, relative to
their RMS. No simulation with clearance enters it. Two questions:

1. **Does it predict the regime?** Labelled designs: the start and the Sobol points that
   an earlier head-to-head's ``sobol`` method classified, in its order (the scrambled Sobol
   sequence of ``--seed`` is regenerated; the regimes are those in the trace of
   ``--design-json``, by default ``bench/results/design_frozen_law.json``: the single-problem
   head-to-head measured under the frozen memory law with wall-time budgets, the last one
   with a ``sobol`` method). Reports the margin's ROC AUC for "periodic" (the probability that a
   periodic design has the larger margin than a not-periodic one; 0.5 is no information)
   and the periodic fraction below and above the median margin.
2. **Is it a way in?** From the start design and from the first not-periodic Sobol designs
   (``--starts`` in all), projected Adam ascent on the margin (step ``--lr`` in the unit
   box), each iterate classified by the steady-state solve (value only) until one is
   periodic or ``--max-steps`` iterates are spent (each start with its own evaluator, warm-started
   only along its own path). Reported: classifications, wall time
   and the margin at entry, against regime-classified multistart, whose expected number
   of classifications until the first periodic design is 1 / (periodic fraction) among the
   labelled designs.

Writes ``bench/results/contact_margin.json``.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))


def auc(pos, neg) -> float:
    """ROC AUC: P(a positive scores above a negative), ties counted half."""
    pos, neg = np.asarray(pos)[:, None], np.asarray(neg)[None, :]
    return float(np.mean((pos > neg) + 0.5 * (pos == neg)))


def labelled_designs(design_json: Path, seed: int, n: int):
    """(unit designs (k, n), regimes) of the sobol method of an earlier head-to-head (the
    single-problem schema of ``design_frozen_law.json``), failed ones dropped."""
    from scipy.stats import qmc

    data = json.loads(design_json.read_text())
    (problem,) = data["problems"]
    trace = problem["methods"]["sobol"]["trace"]
    sampler = qmc.Sobol(d=n, scramble=True, seed=seed)
    points = [np.asarray(data["start_unit_design"])]
    while len(points) < len(trace):
        points.extend(sampler.random(2))
    keep = [(p, r) for p, (_, _, r) in zip(points, trace) if r in ("periodic", "not periodic")]
    return np.array([p for p, _ in keep]), [r for _, r in keep]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--design-json", type=Path, default=ROOT / "bench" / "results" / "design_frozen_law.json")
    ap.add_argument("--seed", type=int, default=0, help="the head-to-head's seed (its Sobol sequence)")
    ap.add_argument("--starts", type=int, default=6)
    ap.add_argument("--lr", type=float, default=0.05)
    ap.add_argument("--max-steps", type=int, default=12)
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "contact_margin.json")
    args = ap.parse_args(argv)

    import bench_design
    import jax
    import jax.numpy as jnp
    import optax

    from jaxcrank.numerics.steady import SteadyStateError
    from jaxcrank.physics import ideal
    from optim.objective_config import objective_from_config
    from optim.presets import design_problem
    from optim.steady import SteadyEvaluator

    problem = design_problem(
        objective_from_config({"method": "steady_state", **bench_design.STEADY})
    )  # the preset, as in the recorded run

    def margin(u):
        return ideal.contact_margin(problem.mechanism(problem.from_unit(u)))

    margins = jax.jit(jax.vmap(margin))
    value_and_grad = jax.jit(jax.value_and_grad(margin))

    units, regimes = labelled_designs(args.design_json, args.seed, problem.n)
    m = np.asarray(margins(jnp.asarray(units)))
    periodic = np.array([r == "periodic" for r in regimes])
    median = float(np.median(m))
    fraction = float(periodic.mean())
    prediction = {
        "designs": len(units),
        "periodic": int(periodic.sum()),
        "periodic_fraction": fraction,
        "auc_margin_for_periodic": auc(m[periodic], m[~periodic]),
        "median_margin": median,
        "periodic_fraction_below_median": float(periodic[m <= median].mean()),
        "periodic_fraction_above_median": float(periodic[m > median].mean()),
        "margins": m.tolist(),
        "regimes": regimes,
    }
    print(json.dumps({k: v for k, v in prediction.items() if not isinstance(v, list)}, indent=1), flush=True)

    evaluator = SteadyEvaluator(problem)
    evaluator.value(np.asarray(problem.from_unit(units[0])))  # compile (untimed)
    starts = [units[0]] + [u for u, p in zip(units[1:], periodic[1:]) if not p]
    ways = []
    for u0 in starts[: args.starts]:
        evaluator = SteadyEvaluator(problem)  # no warm start from another start's orbit
        u = jnp.asarray(u0)
        opt = optax.adam(args.lr)
        state = opt.init(u)
        steps, t0, entry = [], time.perf_counter(), None
        for k in range(args.max_steps):
            try:
                value, info = evaluator.value(np.asarray(problem.from_unit(np.asarray(u))))
                regime = info["regime"] if info["ok"] else "failed"
            except SteadyStateError as err:  # a failed solve: a failed classification, as in the head-to-head
                value, regime = math.nan, f"failed: {str(err).split(':')[0]}"
            mk, g = value_and_grad(u)
            steps.append({"margin": float(mk), "regime": regime, "value": value})
            if steps[-1]["regime"] == "periodic":
                entry = k + 1
                break
            upd, state = opt.update(-g, state, u)
            u = jnp.clip(optax.apply_updates(u, upd), 0.0, 1.0)
        ways.append(
            {
                "start_unit_design": np.asarray(u0).tolist(),
                "classifications_to_periodic": entry,
                "wall_s": time.perf_counter() - t0,
                "steps": steps,
            }
        )
        print(
            f"start {len(ways)}: periodic after {entry} classifications, "
            f"margins {[round(s['margin'], 3) for s in steps]}"
        )
    reached = [w["classifications_to_periodic"] for w in ways if w["classifications_to_periodic"]]
    result = {
        "command": "python bench/contact_margin.py " + " ".join(argv if argv is not None else sys.argv[1:]),
        "design_json": str(args.design_json.relative_to(ROOT))
        if args.design_json.is_relative_to(ROOT)
        else str(args.design_json),
        "steady_objective": bench_design.STEADY,
        "prediction": prediction,
        "margin_ascent": {
            "lr": args.lr,
            "max_steps": args.max_steps,
            "starts": len(ways),
            "reached_periodic": len(reached),
            "mean_classifications_when_reached": float(np.mean(reached)) if reached else None,
            "runs": ways,
        },
        "multistart_expected_classifications": 1.0 / fraction if fraction > 0 else math.inf,
    }
    args.out.write_text(json.dumps(result, indent=1, default=float))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
