"""Compiled programs outlive the process (jaxcrank.runs.cache): a second process loads the
optimiser's value-and-gradient program instead of tracing and compiling it again."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from jaxcrank import cache

ROOT = Path(__file__).resolve().parents[1]

# one process: enable the cache in FOLDER, build the optimiser's programs for a tiny
# paper problem, evaluate the gradient once; report the compile-cache events and
# whether the objective was traced (its Python code ran)
CHILD = r"""
import json, sys
import jax
from jaxcrank import SolveOptions, cache
folder = cache.enable(sys.argv[1])
jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
events = []
jax.monitoring.register_event_listener(lambda name, **kw: events.append(name))
import numpy as np
import pytest
from optim.ensemble import Ensemble
from optim.optimize import programs
from optim.design import DesignProblem
from optim.presets import paper_problem
traced = []
original = DesignProblem.objective_value
def counting(self, *a, **k):
    traced.append(1)
    return original(self, *a, **k)
DesignProblem.objective_value = counting
tsit5 = SolveOptions.from_text("tsit5", max_steps=5_000)
prob = paper_problem(Ensemble(t_start=0.0, t_end=2e-3, window=1e-3, windows=2, window_options=tsit5), start=None)
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


def test_a_stored_program_is_read_back_and_a_damaged_one_replaced(tmp_path, monkeypatch):
    import jax
    import jax.numpy as jnp

    monkeypatch.setattr(cache, "_folder", tmp_path)
    spec = jax.ShapeDtypeStruct((3,), jnp.float64)
    x = np.arange(3.0)
    first = cache.exported(lambda v: jnp.sin(v) * 2.0, "test.sin", spec)
    (stored,) = (tmp_path / "exported").glob("*.bin")
    again = cache.exported(lambda v: v, "test.sin", spec)  # same key: the stored program, not this function
    np.testing.assert_array_equal(again(x), first(x))
    np.testing.assert_array_equal(again(x), np.sin(x) * 2.0)
    stored.write_bytes(b"damaged")
    replaced = cache.exported(lambda v: jnp.sin(v) * 2.0, "test.sin", spec)
    np.testing.assert_array_equal(replaced(x), np.sin(x) * 2.0)
    assert stored.read_bytes() != b"damaged"


def test_an_unwritable_cache_folder_warns_and_the_program_still_runs(tmp_path, monkeypatch):
    import jax
    import jax.numpy as jnp

    blocker = tmp_path / "not_a_folder"
    blocker.write_text("a file where the cache folder would be")
    monkeypatch.setattr(cache, "_folder", blocker)
    with pytest.warns(UserWarning, match="could not store"):
        f = cache.exported(lambda v: v + 1.0, "test.plus", jax.ShapeDtypeStruct((2,), jnp.float64))
    np.testing.assert_array_equal(f(np.zeros(2)), np.ones(2))
    with pytest.raises(OSError):
        cache.enable(blocker / "xla")


def test_checks_as_nan_from_now_holds_for_the_rest_of_the_process():
    """In a fresh process: checks raise by default; after ``checks_as_nan_from_now`` every trace
    (a block of ``checks_as_nan`` included, which restores the process's setting) has them as NaN."""
    code = (
        "from jaxcrank.runs import cache\n"
        "assert not cache.checking_as_nan()\n"
        "with cache.checks_as_nan():\n"
        "    assert cache.checking_as_nan()\n"
        "assert not cache.checking_as_nan()\n"
        "cache.checks_as_nan_from_now()\n"
        "with cache.checks_as_nan():\n"
        "    pass\n"
        "assert cache.checking_as_nan()\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, cwd=Path(__file__).resolve().parents[1])
