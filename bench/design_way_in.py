"""The way in on the design family's problems: does every classified candidate have a value, which
start is chosen, and how long until the first exact gradient?

``python bench/design_way_in.py [--problems NAME ...] [--seeds 0 1]`` writes
``bench/results/design_way_in.json``. For each problem of ``bench_design.PROBLEMS`` and seed, in a
fresh evaluator with no compiled gradient program (the steady-state solve compiled before, untimed,
as in the head-to-head): :func:`optim.way_in.periodic_start` with the head-to-head's settings
(``CLASSIFY`` candidates, the bench's ``STEADY`` objective), then the first exact gradient at the
chosen start when it is periodic. Recorded: each candidate's value, regime, phase, note and CPU
seconds; the candidates without a value (``failed``), each checked by a run from rest of
``settle_revolutions`` revolutions at the bench's tolerances (``from_rest_ok``); the chosen start;
the CPU time of the way in and to the first gradient (way in plus compilation). Times are CPU
seconds of this process (run it pinned to one core: ``taskset -c 1``).
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
sys.path.insert(0, str(Path(__file__).resolve().parent))


def run(name: str, seed: int) -> dict:
    import jax.numpy as jnp
    from bench_design import CLASSIFY, build

    import jaxcrank as jc
    from jaxcrank.numerics import shooting
    from jaxcrank.physics.state import initial_state
    from optim.programs import forget_programs
    from optim.steady import SteadyEvaluator
    from optim.way_in import periodic_start, start_points

    problem = build(name)
    x0 = np.asarray(problem.from_unit(jnp.asarray(start_points(problem, 1)[0])))
    SteadyEvaluator(problem).value(x0)  # compiles the steady-state solve (untimed)
    forget_programs()
    ev = SteadyEvaluator(problem)
    t0 = time.process_time()
    found = periodic_start(problem, count=CLASSIFY, seed=seed, evaluator=ev, progress=False)
    way_in = time.process_time() - t0
    first = None
    if found.periodic:
        ev.value_and_grad(np.asarray(found.problem.start))
        first = time.process_time() - t0
    options = problem.objective.options
    failed = []
    for c in found.classified:
        if c["value_deg"] is None:
            mech = problem.mechanism(jnp.asarray(problem.from_unit(jnp.asarray(c["unit_design"]))))
            sim = jc.simulate(
                mech,
                ts=shooting.section_times(mech, options.settle_revolutions),
                y0=initial_state(mech),
                options=options.solve,
                throw=False,
            )
            failed.append({"unit_design": c["unit_design"], "from_rest_ok": bool(sim.ok)})
    return {
        "problem": name,
        "seed": seed,
        "classified": found.classified,
        "chosen": found.chosen,
        "chosen_periodic": found.periodic,
        "chosen_value_deg": found.classified[found.chosen]["value_deg"] if found.classified else None,
        "candidates_without_value": failed,
        "way_in_cpu_s": way_in,
        "first_gradient_cpu_s": first,
        "gradient_compile_s": ev.compile_seconds,
    }


def main(argv=None) -> int:
    import jax

    jax.config.update("jax_enable_x64", True)
    from _common import machine
    from bench_design import PROBLEMS

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--problems", nargs="+", default=list(PROBLEMS), choices=list(PROBLEMS))
    p.add_argument("--seeds", nargs="+", type=int, default=[0, 1])
    p.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "design_way_in.json")
    args = p.parse_args(argv)
    runs = []
    for name in args.problems:
        for seed in args.seeds:
            r = run(name, seed)
            runs.append(r)
            values = [c["value_deg"] for c in r["classified"]]
            first = r["first_gradient_cpu_s"]
            print(
                f"{name} seed {seed}: {len(values)} classified, {sum(v is None for v in values)} without a value; "
                f"start {r['chosen']} ({'periodic' if r['chosen_periodic'] else 'not periodic'}, "
                f"{r['chosen_value_deg']}); way in {r['way_in_cpu_s']:.0f} CPU-s, first gradient "
                f"{first if first is None else round(first)} CPU-s",
                flush=True,
            )
    without = [c for r in runs for c in r["candidates_without_value"]]
    out = {
        "command": "python bench/design_way_in.py " + " ".join(sys.argv[1:]),
        "runs": runs,
        "summary": {
            "classified": sum(len(r["classified"]) for r in runs),
            "without_value": len(without),
            "without_value_where_a_run_from_rest_finishes": sum(c["from_rest_ok"] for c in without),
            "first_gradient_cpu_s": {f"{r['problem']}_seed{r['seed']}": r["first_gradient_cpu_s"] for r in runs},
            "max_first_gradient_cpu_s": max(
                (r["first_gradient_cpu_s"] for r in runs if r["first_gradient_cpu_s"] is not None), default=math.nan
            ),
        },
        "machine": machine(),
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(out, indent=2, default=str))
    print(json.dumps(out["summary"], indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
