"""The one process-wide setting jaxcrank makes at import, as documented in
docs/xla-runtime.md ("What import jaxcrank changes"): float64 on, and jaxcrank's XLA
options in XLA_FLAGS unless the user opted out; a user's explicit dtypes are kept."""

import json
import os
import subprocess
import sys

import pytest

from jaxcrank.numerics import runtime

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

_CHILD = """
import json, os, sys
import jaxcrank
import jax, jax.numpy as jnp
print(json.dumps({
    "x64": bool(jax.config.jax_enable_x64),
    "xla_flags": os.environ.get("XLA_FLAGS", ""),
    "status": jaxcrank.numerics.runtime.status,
    "default": str(jnp.ones(3).dtype),
    "explicit": str((jnp.ones(3, dtype=jnp.float32) * 0.5).dtype),
}))
"""


def _fresh(**env_extra) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", runtime.OPT_OUT)}
    env.update(JAX_PLATFORMS="cpu", **env_extra)
    out = subprocess.run([sys.executable, "-c", _CHILD], env=env, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_import_turns_on_float64_and_keeps_explicit_float32():
    r = _fresh()
    assert r["x64"] and r["default"] == "float64"
    assert r["explicit"] == "float32"  # a user's float32 arrays stay float32 (weakly typed Python scalars)


def test_import_adds_the_xla_options_unless_the_user_opts_out():
    import platform

    if platform.machine().lower() not in runtime._X86:
        pytest.skip("jaxcrank sets its XLA options on x86 only")
    r = _fresh()
    assert r["status"] == "set" and r["xla_flags"] == runtime.with_options("")
    kept = _fresh(**{runtime.OPT_OUT: "1"})
    assert kept["status"] == "kept" and kept["xla_flags"] == "" and kept["x64"]


def test_import_loads_no_jax_and_jax_imported_first_still_gets_float64():
    """``import jaxcrank`` loads neither JAX nor the model (its names load on first use), so a
    command can print its first line at once; float64 is on whichever comes first."""
    code = (
        "import sys, json\n"
        "{first}\n"
        "import jaxcrank\n"
        "loaded = 'jax' in sys.modules\n"
        "import jax, jax.numpy as jnp\n"
        "print(json.dumps({{'jax_loaded': loaded, 'x64': bool(jax.config.jax_enable_x64), "
        "'dtype': str(jnp.ones(2).dtype), 'paper': type(jaxcrank.paper()).__name__}}))"
    )
    env = {k: v for k, v in os.environ.items() if k != "JAX_ENABLE_X64"}
    for first, jax_loaded in (("", False), ("import jax", True)):
        out = subprocess.run(
            [sys.executable, "-c", code.format(first=first)], env=env, cwd=ROOT, capture_output=True, text=True
        )
        assert out.returncode == 0, out.stderr[-2000:]
        r = json.loads(out.stdout.strip().splitlines()[-1])
        assert r == {"jax_loaded": jax_loaded, "x64": True, "dtype": "float64", "paper": "SliderCrank"}, r


def test_the_lazy_names_are_the_statically_imported_ones_and_all_resolve():
    """The names ``jaxcrank`` loads on first use (``_FROM``) are exactly those its
    ``TYPE_CHECKING`` block imports (what type checkers and the API pages read), from the same
    modules, and every name of ``__all__`` resolves."""
    import ast

    import jaxcrank

    tree = ast.parse(open(os.path.join(ROOT, "jaxcrank", "__init__.py")).read())
    block = next(n for n in tree.body if isinstance(n, ast.If) and getattr(n.test, "id", "") == "TYPE_CHECKING")
    static = {a.name: node.module for node in block.body for a in node.names}
    assert static == jaxcrank._ORIGIN
    for name in jaxcrank.__all__:
        assert getattr(jaxcrank, name) is not None, name
