"""Compiled programs outlive the process (jaxcrank.cache): a second process loads the
optimiser's value-and-gradient program instead of tracing and compiling it again."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np

from jaxcrank import cache

ROOT = Path(__file__).resolve().parents[1]

# one process: enable the cache in FOLDER, build the optimiser's programs for a tiny
# paper problem, evaluate the gradient once; report the compile-cache events and
# whether the objective was traced (its Python code ran)
CHILD = r"""
import json, sys
import jax
from jaxcrank import cache
folder = cache.enable(sys.argv[1])
jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
events = []
jax.monitoring.register_event_listener(lambda name, **kw: events.append(name))
import numpy as np
from optim.objective import Objective
from optim.optimize import programs
from optim.problem import Problem, paper_problem
traced = []
original = Problem.objective_value
def counting(self, *a, **k):
    traced.append(1)
    return original(self, *a, **k)
Problem.objective_value = counting
prob = paper_problem(Objective(t_start=0.0, t_end=2e-3, window=1e-3, windows=2, window_solver="tsit5"), start=None)
vg, _ = programs(prob)
value, grad = vg(np.asarray(prob.start_unit()), 1.0)
print(json.dumps({"traced": len(traced), "value": float(value), "grad": np.asarray(grad).tolist(),
                  "hits": events.count("/jax/compilation_cache/cache_hits"),
                  "misses": events.count("/jax/compilation_cache/cache_misses")}))
"""


def _run(folder: Path) -> dict:
    out = subprocess.run(
        [sys.executable, "-c", CHILD, str(folder)], cwd=ROOT, capture_output=True, text=True, timeout=600
    )
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_a_second_process_loads_the_gradient_program_instead_of_compiling_it(tmp_path):
    first = _run(tmp_path)
    assert first["traced"] >= 1 and first["misses"] >= 1
    exported = list((tmp_path / "exported").glob("*.bin"))
    assert len(exported) == 1, "the traced program is stored"
    executables = [p for p in tmp_path.iterdir() if p.is_file()]
    assert executables, "XLA's executable is stored (no host callback kept it out)"

    second = _run(tmp_path)
    assert second["traced"] == 0, "the second process must not trace the objective"
    assert second["misses"] == 0 and second["hits"] >= 1, second
    assert sorted(p.name for p in tmp_path.iterdir() if p.is_file()) == sorted(p.name for p in executables)
    # the loaded program computes the same numbers, bit for bit
    assert second["value"] == first["value"]
    np.testing.assert_array_equal(second["grad"], first["grad"])


def test_caching_is_off_with_the_environment_switch(monkeypatch):
    monkeypatch.setenv(cache.ENV, "off")
    assert cache.enable() is None


def test_enable_makes_and_names_the_folder_it_uses(tmp_path):
    import jax

    before = jax.config.jax_compilation_cache_dir
    try:
        assert cache.enable(tmp_path / "xla") == tmp_path / "xla"
        assert (tmp_path / "xla").is_dir() and cache.folder() == tmp_path / "xla"
    finally:
        jax.config.update("jax_compilation_cache_dir", before)
        cache._folder = None
