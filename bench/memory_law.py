"""The approach-speed memory law in persistent contact: the forgetting memory (the default)
against the frozen one, and the regime over the reference approach speed ``v_ref``.

1. ``paper_run``: the paper run (0.4 s, the solve defaults, metrics over 0.1-0.4 s) under each law, over
   ``--starts`` starts (every entry of the start + k x 1e-15 scaled units, k = 0, 1, ...: the
   run amplifies rounding after its first impacts, so one run per law says little). Per
   metric: mean and standard deviation per law, and the difference of the means in units of
   its standard error.
2. ``v_ref_map``: the regime after ``--settle`` revolutions from rest
   ([`jaxcrank.runs.regimes.classify`][], kernel engine, ``steady_state``'s tolerances) at a
   few designs of the nine-variable design problem and the paper preset, for each ``v_ref``
   of ``--v-ref`` and under the frozen memory; a figure of the map.

    python bench/memory_law.py       # -> bench/results/memory_law.json, docs/img/memory_vref.png
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import jax.numpy as jnp
import numpy as np
from _common import machine

import jaxcrank as jc
from jaxcrank.numerics.shooting import STEADY_DEFAULTS
from jaxcrank.physics import memory
from jaxcrank.runs import config
from jaxcrank.runs.regimes import classify
from optim.presets import ADAM_RUNS_SI, NOT_PERIODIC_SI, design_problem

ROOT = Path(__file__).resolve().parent
PERTURBATION = 1e-15


def with_memory(mech, law):
    """``mech`` with ``law`` as the memory law of every clearance joint."""
    return config.apply_overrides(mech, [f"memory.law={law}"])


def paper_run(starts):
    out = {}
    for law in ("frozen", "forgetting"):
        mech = with_memory(jc.paper(), law)
        y0 = jc.model.initial_state(mech)
        rows = []
        for k in range(starts):
            sim = jc.simulate(mech, ts=jnp.linspace(0.0, 0.4, 14401), y0=y0 + k * PERTURBATION, metrics_start=0.1)
            rows.append({name: float(v) for name, v in sim.metrics.items()})
        out[law] = rows
    table = {}
    for name in out["forgetting"][0]:
        a = np.array([r[name] for r in out["forgetting"]])
        b = np.array([r[name] for r in out["frozen"]])
        se = np.sqrt(a.var(ddof=1) / a.size + b.var(ddof=1) / b.size)
        table[name] = {
            "forgetting_mean": a.mean(),
            "forgetting_std": a.std(ddof=1),
            "frozen_mean": b.mean(),
            "frozen_std": b.std(ddof=1),
            "relative_change": (a.mean() - b.mean()) / abs(b.mean()) if b.mean() != 0 else None,
            "difference_over_standard_error": (a.mean() - b.mean()) / se if se > 0 else None,
        }
    return {"starts": starts, "perturbation_scaled": PERTURBATION, "metrics": table}


def designs():
    """name -> mechanism: designs of the nine-variable problem and the paper preset."""
    prob = design_problem()
    steady = json.loads((ROOT / "results" / "steady_gradient.json").read_text())["designs"]
    cma = next(e for e in steady if e["design"] == "cma_best")["design_SI"]
    named = {"ADAM_RUNS_SI[0]": ADAM_RUNS_SI[0], "ADAM_RUNS_SI[1]": ADAM_RUNS_SI[1], "ADAM_RUNS_SI[2]": ADAM_RUNS_SI[2]}
    named.update({"NOT_PERIODIC_SI": NOT_PERIODIC_SI, "cma_best": cma})
    out = {name: prob.mechanism(jnp.asarray(x)) for name, x in named.items()}
    out["paper preset"] = jc.paper()
    return out


def v_ref_map(v_refs, settle):
    # steady_state's tolerances; the budget of the paper preset's 40 revolutions (it needs
    # more than the default 2 000 000 steps: 600 rpm and long slow contacts)
    options = STEADY_DEFAULTS.replace(max_steps=8_000_000)
    rows = []
    for name, mech in designs().items():
        mech = with_memory(mech, "forgetting")
        table = classify(mech, ["memory.v_ref"], [[v] for v in v_refs], settle_revolutions=settle, options=options,
                         progress=False)  # fmt: skip
        frozen = with_memory(mech, "frozen")
        ref = classify(frozen, ["memory.memory_time"], [[memory.FrozenMemory().memory_time]], settle_revolutions=settle,
                       options=options, progress=False)  # fmt: skip
        order = np.argsort(np.asarray(table["index"]).astype(int))
        cells = [
            {"v_ref_m_s": v, "status": str(s), "regime": str(r), "period_revolutions": float(p)}
            for v, s, r, p in zip(
                v_refs,
                np.asarray(table["status"])[order],
                np.asarray(table["regime"])[order],
                np.asarray(table["period_revolutions"])[order],
            )
        ]
        frozen_cell = {"regime": str(ref["regime"][0]), "period_revolutions": float(ref["period_revolutions"][0])}
        rows.append({"design": name, "forgetting": cells, "frozen": frozen_cell})
        print(name, [(c["v_ref_m_s"], c["regime"], c["period_revolutions"]) for c in cells], "frozen", frozen_cell,
              flush=True)  # fmt: skip
    return {"settle_revolutions": settle, "v_ref_m_s": list(v_refs), "designs": rows}


def label(cell):
    if cell.get("status", "ok") != "ok":
        return cell["status"]
    return f"P{int(cell['period_revolutions'])}" if cell["regime"] == "periodic" else "not P"


def plot(result, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    m = result["v_ref_map"]
    cols = [f"{v:g}" for v in m["v_ref_m_s"]] + ["frozen"]
    names = [r["design"] for r in m["designs"]]
    grid = [[*r["forgetting"], r["frozen"]] for r in m["designs"]]
    fig, ax = plt.subplots(figsize=(1.1 * len(cols) + 2.5, 0.55 * len(names) + 1.6))
    colours = np.array([[0.55, 0.8, 0.55] if c["regime"] == "periodic" else [0.95, 0.6, 0.55] for r in grid for c in r])
    ax.imshow(colours.reshape(len(names), len(cols), 3), aspect="auto")
    for i, r in enumerate(grid):
        for j, c in enumerate(r):
            ax.text(j, i, label(c), ha="center", va="center", fontsize=9)
    ax.set_xticks(range(len(cols)), cols)
    ax.set_yticks(range(len(names)), names)
    ax.axvline(len(cols) - 1.5, color="k", lw=1)
    ax.set_xlabel("v_ref, m/s (forgetting memory)  |  frozen memory")
    ax.set_title(f"Regime after {m['settle_revolutions']} revolutions from rest (P k: period k revolutions)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--starts", type=int, default=8, help="starts per law of the paper run")
    parser.add_argument("--settle", type=int, default=40, help="revolutions from rest before the regime test")
    parser.add_argument("--v-ref", type=float, nargs="+", default=[0.003, 0.01, 0.03, 0.1, 0.3, 1.0])
    parser.add_argument("--out", type=Path, default=ROOT / "results" / "memory_law.json")
    parser.add_argument("--figure", type=Path, default=ROOT.parent / "docs" / "img" / "memory_vref.png")
    args = parser.parse_args()
    defaults = memory.ForgettingMemory()
    result = {
        "forgetting_defaults": {k: float(getattr(defaults, k)) for k in ("v_ref", "tau", "t_dwell", "gate_width")},
        "paper_run": paper_run(args.starts),
        "v_ref_map": v_ref_map(args.v_ref, args.settle),
        "machine": machine(),
    }
    args.out.write_text(json.dumps(result, indent=1))
    plot(result, args.figure)
    print("wrote", args.out, args.figure)


if __name__ == "__main__":
    main()
