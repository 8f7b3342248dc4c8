"""What ``import jaxcrank`` changes for a user's own JAX code in the same process.

    python bench/import_effects.py [--out bench/results/import_effects.json] [--repeats 7]

``import jaxcrank`` turns on float64 (``jax_enable_x64``) and adds two XLA CPU options
to ``XLA_FLAGS`` (docs/xla-runtime.md). This script runs the same user code in three
fresh processes: JAX alone, after ``import jaxcrank``, and after ``import jaxcrank``
with ``JAXCRANK_KEEP_XLA_FLAGS=1`` (float64 on, XLA options left alone). The user code:

- the default dtype of ``jnp.ones(3)`` and of ``jnp.array(0.1)``;
- an explicitly float32 elementwise kernel ``x * y + z`` (4M elements): time and
  whether its bits equal JAX-alone's (FMA contraction rounds differently);
- a float32 matrix product 1024 x 1024: time and bits;
- a ``fori_loop`` of 100 000 small float32 steps: time (the while-loop option);
- the same kernel written without dtypes (``jnp.linspace``): dtype and time.

Times are the median of ``--repeats`` calls after one compiling call, on one process
each (the machine's other load adds noise; compare ratios, not absolute times).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

_CHILD = r"""
import hashlib, json, statistics, sys, time
if sys.argv[1] == "jaxcrank":
    import jaxcrank  # noqa: F401
import jax
import jax.numpy as jnp

def timed(fn, *args, repeats):
    jax.block_until_ready(fn(*args))
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        jax.block_until_ready(fn(*args))
        times.append(time.perf_counter() - t)
    return statistics.median(times)

def digest(a):
    import numpy as np
    return hashlib.sha256(np.asarray(a).tobytes()).hexdigest()[:16]

repeats = int(sys.argv[2])
key = jax.random.key(0)
k1, k2, k3 = jax.random.split(key, 3)
n = 4_000_000
x, y, z = (jax.random.normal(k, (n,), dtype=jnp.float32) for k in (k1, k2, k3))
fma = jax.jit(lambda x, y, z: jnp.sin(x) * y + z * x)
a = jax.random.normal(k1, (1024, 1024), dtype=jnp.float32)
matmul = jax.jit(lambda a: a @ a)
loop = jax.jit(lambda v: jax.lax.fori_loop(0, 100_000, lambda i, v: v * 0.999 + jnp.float32(1e-3) * jnp.sin(v), v))
v0 = jnp.linspace(0.0, 1.0, 16, dtype=jnp.float32)
untyped = jax.jit(lambda u: jnp.sin(u) * u + 0.5)
u = jnp.linspace(0.0, 1.0, n)
out = {
    "x64": bool(jax.config.jax_enable_x64),
    "xla_flags": __import__("os").environ.get("XLA_FLAGS", ""),
    "default_dtype_ones": str(jnp.ones(3).dtype),
    "default_dtype_scalar": str(jnp.array(0.1).dtype),
    "elementwise_f32_s": timed(fma, x, y, z, repeats=repeats),
    "elementwise_f32_digest": digest(fma(x, y, z)),
    "matmul_f32_s": timed(matmul, a, repeats=repeats),
    "matmul_f32_digest": digest(matmul(a)),
    "fori_loop_f32_s": timed(loop, v0, repeats=repeats),
    "fori_loop_f32_digest": digest(loop(v0)),
    "untyped_dtype": str(untyped(u).dtype),
    "untyped_s": timed(untyped, u, repeats=repeats),
}
print(json.dumps(out))
"""

SETUPS = {
    "jax_alone": ("jax", {}),
    "import_jaxcrank": ("jaxcrank", {}),
    "import_jaxcrank_keep_xla_flags": ("jaxcrank", {"JAXCRANK_KEEP_XLA_FLAGS": "1"}),
}


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, default=Path("bench/results/import_effects.json"))
    p.add_argument("--repeats", type=int, default=7)
    a = p.parse_args(argv)
    root = Path(__file__).resolve().parents[1]
    report = {}
    for name, (first, extra) in SETUPS.items():
        env = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", "JAXCRANK_KEEP_XLA_FLAGS")}
        env.update(JAX_PLATFORMS="cpu", PYTHONPATH=str(root), **extra)
        out = subprocess.run(
            [sys.executable, "-c", _CHILD, first, str(a.repeats)], env=env, capture_output=True, text=True, check=True
        )
        report[name] = json.loads(out.stdout.strip().splitlines()[-1])
        print(name, report[name], flush=True)
    alone = report["jax_alone"]
    for r in report.values():
        r["same_bits_as_jax_alone"] = {
            k: r[f"{k}_digest"] == alone[f"{k}_digest"] for k in ("elementwise_f32", "matmul_f32", "fori_loop_f32")
        }
        r["time_ratio_to_jax_alone"] = {
            k: r[f"{k}_s"] / alone[f"{k}_s"] for k in ("elementwise_f32", "matmul_f32", "fori_loop_f32", "untyped")
        }
    sys.path.insert(0, str(root / "bench"))
    from _common import machine

    report["machine"] = machine(repeats=a.repeats)
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps(report, indent=2))
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
