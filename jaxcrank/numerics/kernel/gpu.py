"""The kernel on an NVIDIA GPU: the same generated source compiled as CUDA by NVRTC
(through CuPy), one trajectory per GPU thread.

The source is the CPU kernel's ([`jaxcrank.numerics.kernel.source.kernel_source`][]);
under ``__CUDACC__`` its functions are ``__device__`` functions and its entry point
is the ``__global__`` ``jk_solve_gpu``. It is compiled with ``--fmad=false`` (no fused
multiply-add, the rounding of the CPU kernel and of XLA's CPU programs). Needs CuPy
(``pip install cupy-cuda12x``, the ``gpu`` extra) and a CUDA device.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Sequence

import numpy as np

from ...physics.linkage import AbstractMechanism as Mechanism
from ...physics.parameters import set_parameters
from ...physics.params import ParameterError
from . import engine, source

OPTIONS = ("--std=c++14", "--fmad=false")


def available() -> bool:
    """Whether CuPy and a CUDA device are present."""
    try:
        import cupy

        return cupy.cuda.runtime.getDeviceCount() > 0
    except Exception:  # no CuPy, no driver or no device
        return False


@functools.lru_cache(maxsize=16)
def _function(st: source.Structure):
    import cupy

    start = time.perf_counter()
    module = cupy.RawModule(code=source.kernel_source(st), options=OPTIONS)
    fn = module.get_function("jk_solve_gpu")
    fn.compile_s = time.perf_counter() - start
    return fn


def compile_seconds(st: source.Structure) -> float:
    """Seconds NVRTC took to compile the kernel of ``st`` in this process (compiling it now if needed)."""
    return _function(st).compile_s


def solve(base: Mechanism, names: Sequence[str], xs: np.ndarray, settings, block: int = 128) -> engine.Batch:
    """[`jaxcrank.numerics.kernel.engine.solve`][] on the GPU: the same arguments and
    results (host arrays), ``block`` threads per CUDA block.

    Raises:
        ParameterError: for a solver other than tsit5.
    """
    import cupy

    if settings.options.solver_name != "tsit5":
        raise ParameterError(f"the kernel engine solves with tsit5 only, not {settings.options.solver_name!r}")
    xs = np.atleast_2d(np.asarray(xs, dtype=np.float64))
    n = len(xs)
    periods = np.array([float(set_parameters(base, list(names), [float(v) for v in x]).period) for x in xs])
    st = source.structure(base, names)
    lay = source.layout(st)
    fn = _function(st)
    o = settings.options
    dev = {
        "params": cupy.asarray(np.ascontiguousarray(xs)),
        "t_end": cupy.asarray(settings.revolutions * periods),
        "t_start": cupy.asarray(settings.metrics_from_revolution * periods),
        "y": cupy.asarray(engine.initial_states(base, names, xs)),
        "peaks": cupy.zeros((n, lay.n_peak)),
        "whole": cupy.zeros((n, lay.n_peak)),
        "sums": cupy.zeros((n, lay.n_rms)),
        "count": cupy.zeros(n, dtype=cupy.int64),
        "accepted": cupy.zeros(n, dtype=cupy.int64),
        "rejected": cupy.zeros(n, dtype=cupy.int64),
        "result": cupy.zeros(n, dtype=cupy.int32),
    }
    args = (
        np.int64(n), dev["params"], dev["t_end"], dev["t_start"], np.int64(settings.n_samples),
        np.int64(o.max_steps), np.float64(o.rtol), np.float64(o.atol), np.float64(o.dt0), dev["y"],
        dev["peaks"], dev["whole"], dev["sums"], dev["count"], dev["accepted"], dev["rejected"], dev["result"],
    )  # fmt: skip
    fn(((n + block - 1) // block,), (block,), args)
    cupy.cuda.runtime.deviceSynchronize()
    host = {k: cupy.asnumpy(v) for k, v in dev.items()}
    values = engine.finish(st, host["peaks"], host["sums"], host["count"])
    finite = np.all(np.isfinite(host["y"]), axis=1) & np.all(np.isfinite(values), axis=1)
    status = np.where(host["result"] == 0, np.where(finite, engine.OK, engine.NON_FINITE), engine.MAX_STEPS)
    return engine.Batch(values, status.astype(np.int64), host["accepted"], host["rejected"], host["y"], host["whole"])
