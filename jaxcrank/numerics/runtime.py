"""The XLA CPU options jaxcrank runs with, applied when jaxcrank is imported.

Two options are added to ``XLA_FLAGS`` by [`configure`][jaxcrank.numerics.runtime.configure] (on x86 machines):

- ``--xla_backend_extra_options=xla_cpu_small_while_loop_byte_threshold=1e9``: XLA
  compiles a diffrax solver loop into one kernel instead of dispatching each of its
  small kernels per step through the thunk runtime (the per-step cost is then the
  arithmetic, not the dispatches);
- ``--xla_cpu_max_isa=AVX``: no fused multiply-add contraction, so the same arithmetic
  rounds the same way in every kernel, ``vmap`` lane and batch size (reverse-mode
  gradients recompute forward steps in another kernel; sweep rows must not depend on
  their batch).

They are not added when the user's ``XLA_FLAGS`` already sets them (the user's values
win), when ``JAXCRANK_KEEP_XLA_FLAGS=1``, or when JAX's backend has already started
(XLA reads ``XLA_FLAGS`` once; [`configure`][jaxcrank.numerics.runtime.configure] then warns). Neither option changes
what is computed, only how it is rounded. The measurements behind them are in the
docs ("XLA runtime").
"""

from __future__ import annotations

import os
import platform
import re
import warnings

from .. import _private

OPTION = "xla_cpu_small_while_loop_byte_threshold"
THRESHOLD_BYTES = 1_000_000_000
ISA_FLAG = "--xla_cpu_max_isa"
ISA = "AVX"  # 256-bit vectors, no FMA
OPT_OUT = "JAXCRANK_KEEP_XLA_FLAGS"

_EXTRA = "--xla_backend_extra_options"
_X86 = ("x86_64", "amd64", "i686", "x86")

#: What :func:`configure` did at import: "set" (added options), "user" (XLA_FLAGS
#: already had both), "kept" (opted out), "not x86" or "too late" (JAX had started).
status = "not configured"


def with_options(flags: str) -> str:
    """``flags`` (an ``XLA_FLAGS`` string) with both options added where missing.

    Another ``--xla_backend_extra_options`` entry is extended, not replaced; values
    already there (the threshold, or any ``--xla_cpu_max_isa``) are kept.
    """
    if ISA_FLAG not in flags:
        flags = f"{flags} {ISA_FLAG}={ISA}".strip()
    if OPTION in flags:
        return flags
    entry = f"{OPTION}={THRESHOLD_BYTES}"
    match = re.search(rf"{_EXTRA}=(\S*)", flags)
    if match is None:
        return f"{flags} {_EXTRA}={entry}"
    existing = match.group(1)
    merged = f"{existing},{entry}" if existing else entry
    return flags[: match.start(1)] + merged + flags[match.end(1) :]


def _backend_started() -> bool:
    return _private.backends_started()


def configure(environ=os.environ, machine: str | None = None) -> str:
    """Add the options to ``environ["XLA_FLAGS"]`` if they can still take effect;
    returns (and stores in `status`) what was done."""
    global status
    flags = environ.get("XLA_FLAGS", "")
    machine = platform.machine() if machine is None else machine
    if environ.get(OPT_OUT, "") not in ("", "0"):
        status = "kept"
    elif machine.lower() not in _X86:
        status = "not x86"
    elif with_options(flags) == flags:
        status = "user"
    elif _backend_started():
        status = "too late"
        import jax

        if jax.default_backend() == "cpu":
            warnings.warn(
                "jaxcrank was imported after JAX started its backend, so it could not set its XLA "
                "options (jaxcrank.numerics.runtime): simulations on the CPU then run about 10x slower, or, where "
                "XLA_FLAGS already compile while loops into one kernel, with inexact reverse-mode "
                "gradients. Import "
                "jaxcrank before running any JAX computation, or start Python with "
                f"XLA_FLAGS='{with_options(flags)}'.",
                RuntimeWarning,
                stacklevel=3,
            )
    else:
        environ["XLA_FLAGS"] = with_options(flags)
        status = "set"
    return status


def describe() -> dict:
    """What a run's ``summary.json`` records about the XLA setting."""
    return {"xla_flags": os.environ.get("XLA_FLAGS", ""), "jaxcrank_xla_setting": status}
