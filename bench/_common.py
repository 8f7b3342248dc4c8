"""Helpers shared by the benchmark scripts (``python bench/NAME.py`` puts this folder
on ``sys.path``): timing and a description of the machine for the JSON files."""

from __future__ import annotations

import os
import platform
import time


def timed(fn, warmup: int = 0):
    """``(fn(), seconds)``: the wall time of one call, its results ready, after ``warmup``
    untimed calls (e.g. 1 to leave compilation out)."""
    import jax

    for _ in range(warmup):
        jax.block_until_ready(fn())
    start = time.perf_counter()
    out = fn()
    jax.block_until_ready(out)
    return out, time.perf_counter() - start


def machine(**extra) -> dict:
    """Platform, Python, JAX and diffrax versions, CPU counts, jaxcrank's XLA options and
    the device, for a benchmark's JSON (``extra`` entries added)."""
    import diffrax
    import jax

    from jaxcrank import runtime

    return {
        "platform": platform.platform(),
        "python": platform.python_version(),
        "jax": jax.__version__,
        "diffrax": diffrax.__version__,
        "cpu_count": os.cpu_count(),
        "cpus_usable": len(os.sched_getaffinity(0)),
        **runtime.describe(),
        "device": f"{jax.default_backend()}: {jax.devices()[0].device_kind}",
        **extra,
    }
