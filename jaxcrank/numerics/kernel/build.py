"""Compiling the kernel's C source with the machine's C compiler and loading it.

The shared library is cached under ``$JAXCRANK_KERNEL_CACHE`` (default
``~/.cache/jaxcrank/kernel``), named by a hash of the source without its comments
(they name lines of the model's files, which move when those files are edited without
changing the code), the compiler's version, its flags and the CPU model, so a changed
model, compiler or machine compiles anew and an unchanged one loads in milliseconds.
Compilation writes to a temporary file and renames it, so concurrent processes never
load a half-written library.

Flags: ``-O3 -march=native`` (the machine's vector instructions),
``-ffp-contract=off`` (no fused multiply-add: the rounding of XLA's CPU programs
under [`jaxcrank.numerics.runtime`][]), ``-fno-math-errno`` (inline square roots;
no change of values) and ``-fopenmp`` (one trajectory per thread).
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import os
import platform
import re
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

FLAGS = ("-O3", "-march=native", "-ffp-contract=off", "-fno-math-errno", "-fopenmp", "-shared", "-fPIC", "-std=gnu11")


class KernelBuildError(RuntimeError):
    """The kernel could not be compiled or loaded; the message says why and what to do."""


def compiler() -> str | None:
    """The C compiler the kernel uses (``$CC``, else ``gcc`` or ``cc`` on the PATH), or None."""
    for name in (os.environ.get("CC"), "gcc", "cc"):
        if name and shutil.which(name):
            return shutil.which(name)
    return None


def cache_dir() -> Path:
    """Where compiled kernels are kept (``$JAXCRANK_KERNEL_CACHE`` or ``~/.cache/jaxcrank/kernel``)."""
    env = os.environ.get("JAXCRANK_KERNEL_CACHE")
    return Path(env) if env else Path.home() / ".cache" / "jaxcrank" / "kernel"


@functools.lru_cache(maxsize=1)
def _machine_key() -> str:
    cc = compiler()
    version = subprocess.run([cc, "--version"], capture_output=True, text=True).stdout if cc else ""
    cpu = ""
    try:
        cpu = next((ln for ln in Path("/proc/cpuinfo").read_text().splitlines() if ln.startswith("model name")), "")
    except OSError:
        pass
    return "\n".join([version, cpu, platform.machine(), " ".join(FLAGS)])


_COMMENT = re.compile(r"/\*.*?\*/", flags=re.S)


def library_path(source: str) -> Path:
    """The cache path of the library compiled from ``source`` (the same for sources that differ
    only in their ``/* */`` comments)."""
    digest = hashlib.sha256((_COMMENT.sub("", source) + _machine_key()).encode()).hexdigest()[:24]
    return cache_dir() / f"jaxcrank_kernel_{digest}.so"


class Compiled:
    """A loaded kernel library.

    Attributes:
        lib: the ``ctypes.CDLL``.
        path: its file.
        compile_s: seconds spent compiling it in this process (0 when it came from the cache).
        layout: (parameters, state size, peak signals, RMS signals).
    """

    def __init__(self, path: Path, compile_s: float):
        self.path, self.compile_s = path, compile_s
        self.lib = ctypes.CDLL(str(path))
        dp = np.ctypeslib.ndpointer(dtype=np.float64, flags="C_CONTIGUOUS")
        lp = np.ctypeslib.ndpointer(dtype=np.int64, flags="C_CONTIGUOUS")
        ip = np.ctypeslib.ndpointer(dtype=np.int32, flags="C_CONTIGUOUS")
        cl, ci, cd = ctypes.c_long, ctypes.c_int, ctypes.c_double
        self.lib.jk_field_batch.argtypes = [cl, dp, dp, dp, dp]
        self.lib.jk_field_batch_v.argtypes = [cl, dp, dp, dp, dp]
        self.layout = None
        if hasattr(self.lib, "jk_solve"):  # a whole kernel (field_source builds the field alone)
            self.lib.jk_solve.argtypes = [cl, ci, dp, dp, dp, cl, cl, cd, cd, cd, dp, dp, dp, dp, lp, lp, lp, ip]
            self.lib.jk_solve_v.argtypes = self.lib.jk_solve.argtypes
            self.lib.jk_frame_batch.argtypes = [cl, dp, dp, dp, dp, dp, dp]
            self.lib.jk_layout.argtypes = [lp]
            out = np.zeros(4, dtype=np.int64)
            self.lib.jk_layout(out)
            self.layout = tuple(int(v) for v in out)


def compile_source(source: str) -> Compiled:
    """Compile ``source`` (or load it from the cache) and return the loaded library.

    Raises:
        KernelBuildError: no C compiler, or the compiler failed (its output is in the message).
    """
    path = library_path(source)
    if path.exists():
        return Compiled(path, 0.0)
    cc = compiler()
    if cc is None:
        raise KernelBuildError("no C compiler found (gcc or cc, or $CC): install one or use engine='xla'")
    path.parent.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    with tempfile.TemporaryDirectory(dir=path.parent) as tmp:
        src = Path(tmp) / "kernel.c"
        src.write_text(source)
        out = Path(tmp) / path.name
        proc = subprocess.run([cc, *FLAGS, str(src), "-o", str(out), "-lm"], capture_output=True, text=True)
        if proc.returncode != 0:
            raise KernelBuildError(f"{cc} could not compile the kernel:\n{proc.stderr[-4000:]}")
        os.replace(out, path)
    return Compiled(path, time.perf_counter() - start)
