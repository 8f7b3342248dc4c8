"""Determinism: the same design, settings and chunk give bit-identical outputs across
runs in one process and across processes (docs/reliability.md, "Determinism")."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

pytestmark = pytest.mark.slow  # several processes

_SCRIPT = """
import hashlib, json
import numpy as np
import jaxcrank as jc
from jaxcrank import outputs, sweep

def digest(a):
    return hashlib.sha256(np.ascontiguousarray(np.asarray(a, dtype=float)).tobytes()).hexdigest()

settings = sweep.Settings(revolutions=0.03, samples_per_revolution=1200, metrics_from_revolution=0.01,
                          options=jc.DEFAULTS.replace(max_steps=20000))
res = {}
for run in range(2):
    # 10 ms of the paper run: through the start-up impacts, where any last-bit difference grows
    sim = jc.simulate(jc.paper(), 0.01, n_samples=1001)
    cols = outputs.trajectory(sim)
    res[f"simulate run {run}"] = [digest(sim.ys), digest(np.stack([cols[k] for k in outputs.columns(sim.mechanism)])),
                                  int(sim.num_steps)]
    tab = sweep.run(jc.paper(), ["clearance_C", "contact.restitution"],
                    [[2.5e-4, 0.9], [3e-4, 0.7], [4e-4, 1.0]], settings, chunk=2, progress=False, engine="xla")
    res[f"sweep run {run}"] = [digest(np.stack([tab[k] for k in sweep.metric_names(jc.paper())])), list(tab["status"]),
                               digest(tab["steps"])]
print(json.dumps(res))
"""


def test_bit_identical_across_runs_and_processes():
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", _SCRIPT],
            env=env,
            cwd=ROOT,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for _ in range(2)
    ]
    try:
        outs = [p.communicate(timeout=600) for p in procs]
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
    for p, (_, err) in zip(procs, outs):
        assert p.returncode == 0, err[-3000:]
    first, second = (json.loads(out.strip().splitlines()[-1]) for out, _ in outs)
    assert first["sweep run 0"][1] == ["ok", "ok", "ok"]
    for kind in ("simulate", "sweep"):
        assert first[f"{kind} run 0"] == first[f"{kind} run 1"], kind  # across runs
        assert first[f"{kind} run 0"] == second[f"{kind} run 0"], kind  # across processes
