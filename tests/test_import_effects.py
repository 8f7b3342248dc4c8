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
