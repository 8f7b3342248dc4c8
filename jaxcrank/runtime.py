"""The XLA CPU setting jaxcrank runs with, applied when jaxcrank is imported.

Since JAX 0.4.32, XLA's CPU backend runs every kernel of a while loop through its
thunk runtime: one dispatch per kernel per iteration, with dependency tracking and
work stealing between threads. A solver step of this model is a few hundred tiny
kernels, so the dispatches, not the arithmetic, set the cost: 17 us a step on the
paper run (1.7 s for 0.4 s simulated; ``bench/results/step_cost_thunk_runtime.json``). XLA has a pass
that compiles a whole while loop into one kernel (the loop's instructions are then
plain code in one function) when the loop accesses fewer bytes than
``xla_cpu_small_while_loop_byte_threshold`` (its default is 1 kB). At 1 GB diffrax's
loop is one kernel and the paper run takes 1.6 us a step (0.16 s,
``bench/results/step_cost.json``). Loops that
contain custom calls (LAPACK), scatters or sorts are never compiled this way.

XLA reads ``XLA_FLAGS`` once, when JAX starts its backend (the first array or
computation), so :func:`configure` runs at ``import jaxcrank``: it adds the options below to
``XLA_FLAGS`` unless

- the user's ``XLA_FLAGS`` already set them (their values win),
- ``JAXCRANK_KEEP_XLA_FLAGS=1`` asks jaxcrank to leave ``XLA_FLAGS`` alone, or
- JAX's backend has already started (then it warns: import jaxcrank before running
  any JAX computation, or put the option in ``XLA_FLAGS`` before starting Python).

The second option, ``--xla_cpu_max_isa=AVX``, keeps XLA from using fused multiply-add
(FMA) instructions. Inside a loop compiled as one kernel, LLVM contracts ``a*b + c``
into an FMA where its vectoriser happens to, so the same arithmetic rounds differently
in different kernels, in different lanes of a ``vmap`` batch, and for different batch
sizes. Two things depend on bitwise repeatable arithmetic, and impact chaos amplifies
the last bit (measured, ``tests/test_sensitivity.py``, ``tests/test_sweep.py``):

- reverse-mode gradients: diffrax's checkpointed adjoint recomputes forward steps in
  the backward pass, a separate kernel; with FMA the recomputed trajectory drifted from
  the forward one and the Jacobian of 1 ms windows was 1-10 % off central differences
  (1e-5 without FMA);
- sweep tables: a design's numbers depended on its position in the batch and on the
  batch size (2e-8 relative after 3 ms), so a table changed with ``chunk`` and with the
  number of devices or processes.

Leaving out FMA costs no measurable speed: ``XLA_FLAGS=--xla_cpu_max_isa=AVX2 python
bench/step_cost.py`` (AVX2 has FMA; the user's value wins) timed the paper run at 0.22 s
against 0.16 s without FMA, one run each on one core, where an earlier run had it the
other way round (0.168 s against 0.176 s): within this machine's run-to-run noise. The option names
an x86 instruction set; on other machines (e.g. ARM) :func:`configure` sets neither
option and XLA's defaults apply (the thunk runtime: slower, exact gradients).

Neither option changes what is computed, only how: results differ from XLA's defaults
by floating-point rounding.
"""

from __future__ import annotations

import os
import platform
import re
import warnings

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
    try:
        from jax._src import xla_bridge
    except ImportError:  # pragma: no cover - layout of a future JAX
        return False
    started = getattr(xla_bridge, "backends_are_initialized", None)
    return bool(started()) if started is not None else False


def configure(environ=os.environ, machine: str | None = None) -> str:
    """Add the options to ``environ["XLA_FLAGS"]`` if they can still take effect;
    returns (and stores in :data:`status`) what was done."""
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
                "options (jaxcrank.runtime): simulations on the CPU then run about 10x slower, or, where "
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
