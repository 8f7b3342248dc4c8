"""Regime map of a small grid: the batch classification (``jaxcrank.runs.regimes``) on
the kernel and on the JAX path against ``steady_state`` run design by design.

Two grids of ``--points`` x ``--points`` over rod_mass x clearance_B (rod mass 0.8 to
1.2 x, clearance at B 0.5 to 2 x): ``cma_best``, around CMA-ES's best design of the
nine-variable problem (bench/results/steady_gradient.json; every design periodic), and
``mixed``, around a design of that problem whose motion is not periodic (``CHAOTIC_SI``:
periodic and not periodic designs, some near the recurrence tolerance). Every engine with its defaults (the
steady-state ones: 20 settle revolutions, max_period 4, recurrence_tol 1e-3, tsit5 at
rtol = atol = 1e-10). ``steady_state`` is asked for the regime only (its statistics run,
for designs that are not periodic, with 4 revolutions at 360 samples: it does not change
the regime). Wall times: the kernel's second call (its compiled library cached; the
first call's time, which may include compiling it, is reported too), the JAX path's
first call (XLA compilation included), and ``steady_state``'s total over the grid (its
compilation included: the first design's share). Writes ``bench/results/regimes.json``.
Usage: ``taskset -c 0 python bench/bench_regimes.py`` (one core: the kernel uses every
CPU the process may run on).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from _common import machine

from jaxcrank.numerics.kernel import engine as kernel_engine
from jaxcrank.numerics.steady import SteadyOptions, steady_state
from jaxcrank.physics.parameters import get_parameter, set_parameters
from jaxcrank.runs import regimes
from optim.presets import NOT_PERIODIC_SI, design_problem

jax.config.update("jax_enable_x64", True)
ROOT = Path(__file__).resolve().parent
NAMES = ["rod_mass", "clearance_B"]


CHAOTIC_SI = list(NOT_PERIODIC_SI)


def _table(t):
    return {
        "regime": t["regime"].tolist(),
        "period_revolutions": t["period_revolutions"].tolist(),
        "recurrence_distance_scaled": t["recurrence_distance_scaled"].tolist(),
        "steps": t["steps"].tolist(),
    }


def bench_grid(base, points, xla):
    """One grid's classification by each engine and by steady_state, with wall times."""
    m0, c0 = (float(get_parameter(base, n)) for n in NAMES)
    grid = np.array([[m, c] for m in np.linspace(0.8, 1.2, points) * m0 for c in np.linspace(0.5, 2.0, points) * c0])
    out = {"names": NAMES, "units": ["kg", "m"], "designs_SI": grid.tolist()}
    start = time.perf_counter()
    regimes.classify(base, NAMES, grid, progress=False, engine="kernel")
    first = time.perf_counter() - start
    start = time.perf_counter()
    kernel = regimes.classify(base, NAMES, grid, progress=False, engine="kernel")
    out["kernel"] = {
        "wall_s": time.perf_counter() - start,
        "wall_s_first_call": first,
        "threads": kernel_engine.default_threads(),
        **_table(kernel),
    }
    print(f"kernel: {out['kernel']['wall_s']:.1f} s (first call {first:.1f} s)", flush=True)
    if xla:
        start = time.perf_counter()
        table = regimes.classify(base, NAMES, grid, progress=False, engine="xla")
        out["xla"] = {"wall_s_with_compilation": time.perf_counter() - start, "chunk": 1, **_table(table)}
        print(f"xla: {out['xla']['wall_s_with_compilation']:.1f} s", flush=True)
    steady, per_design = [], []
    start = time.perf_counter()
    for x in grid:
        t = time.perf_counter()
        s = steady_state(
            set_parameters(base, NAMES, [float(v) for v in x]),
            SteadyOptions(statistics_revolutions=4, samples_per_revolution=360),
            throw=False,
        )
        per_design.append(time.perf_counter() - t)
        steady.append(
            {
                "ok": s.ok,
                "result": str(s.result),
                "regime": s.regime if s.ok else "",
                "period_revolutions": s.period_revolutions,
                "residual_scaled": float(s.residual),
                "max_multiplier_modulus": float(np.max(s.multiplier_moduli, initial=0.0)),
            }
        )
        print(f"steady_state {x}: {steady[-1]['regime']} {s.period_revolutions} ({per_design[-1]:.1f} s)", flush=True)
    out["steady_state"] = {
        "wall_s_with_compilation": time.perf_counter() - start,
        "wall_s_per_design": per_design,
        "designs": steady,
    }
    ref = [(s["regime"], s["period_revolutions"]) for s in steady]
    for name in ("kernel", "xla"):
        if name in out:
            got = list(zip(out[name]["regime"], [int(k) if k == k else 0 for k in out[name]["period_revolutions"]]))
            out[name]["agree_with_steady_state"] = int(sum(a == b for a, b in zip(got, ref)))
            out[name]["disagree_indices"] = [i for i, (a, b) in enumerate(zip(got, ref)) if a != b]
    if "xla" in out:
        same = [a == b for a, b in zip(out["kernel"]["regime"], out["xla"]["regime"])]
        out["kernel_agrees_with_xla"] = int(sum(same))
    out["designs"] = len(grid)
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=4, help="grid points per parameter (4)")
    ap.add_argument("--no-xla", action="store_true", help="skip the JAX path's batch classification")
    args = ap.parse_args()
    designs = json.loads((ROOT / "results" / "steady_gradient.json").read_text())["designs"]
    cma = next(d for d in designs if d["design"] == "cma_best")["design_SI"]
    prob = design_problem()
    bases = {"cma_best": prob.mechanism(jnp.asarray(cma)), "mixed": prob.mechanism(jnp.asarray(CHAOTIC_SI))}
    out = {"grids": {}}
    for name, base in bases.items():
        print(name, flush=True)
        out["grids"][name] = bench_grid(base, args.points, not args.no_xla)
    out["machine"] = machine()
    path = ROOT / "results" / "regimes.json"
    path.write_text(json.dumps(out, indent=1))
    for name, g in out["grids"].items():
        print(name, {k: g[k].get("agree_with_steady_state") for k in ("kernel", "xla") if k in g}, g["designs"])
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
