"""The compiled value-and-gradient programs of the steady-state objective
([`optim.steady.SteadyEvaluator`][]), kept for the process: one per problem structure, orbit
period and dynamic subspace, compiled in the foreground or in one background thread, with
their traces stored in the compilation cache ([`jaxcrank.runs.cache`][]) where it is on.
A program takes the problem's numbers as inputs ([`optim.problem.problem_values`][]), so
problems that differ only in them share it; a problem whose numbers are read at trace time
gets a program of its own with them compiled in."""

from __future__ import annotations

import time

import jax

#: compiled value-and-gradient programs: (problem without its start and numbers, period, dynamic subspace) -> program
PROGRAMS: dict = {}
#: compilations started by `SteadyEvaluator.prepare`: key -> future of (program, seconds, key)
PENDING: dict = {}
COMPILER = []
#: program keys of problems whose numbers cannot be a program's inputs (one is read at trace time)
FOLDED: set = set()
TRACE_ERRORS = (jax.errors.ConcretizationTypeError, jax.errors.TracerArrayConversionError,
                 jax.errors.TracerBoolConversionError, jax.errors.TracerIntegerConversionError)  # fmt: skip


def compiler():
    """The one background thread that compiles prepared programs."""
    if not COMPILER:
        from concurrent.futures import ThreadPoolExecutor

        COMPILER.append(ThreadPoolExecutor(max_workers=1, thread_name_prefix="jaxcrank-compile"))
    return COMPILER[0]


def compile_program(fun, args, key):
    """``fun`` jitted, lowered and compiled for ``args``, and the wall time that took, s. With the
    compilation cache on and equinox's checks as NaN for the process
    ([`jaxcrank.runs.cache.checks_as_nan_from_now`][]: no host callback in the program), its trace is
    stored under ``key`` ([`jaxcrank.runs.cache.exported`][]) and its executable in JAX's cache, so a
    later process loads both."""
    from jaxcrank.runs import cache

    tic = time.perf_counter()
    stored = cache.folder() is not None and cache.checking_as_nan()
    jitted = cache.exported(fun, ("steady gradient", key), *args) if stored else jax.jit(fun)
    program = jitted.lower(*args).compile()
    return program, time.perf_counter() - tic


def forget_programs() -> None:
    """Drop every compiled value-and-gradient program of the steady-state objective (and wait for
    any being compiled), so the next evaluation compiles its own (benchmarks that count
    compilation in each method's time)."""
    for pending in PENDING.values():
        pending.result()
    PENDING.clear()
    PROGRAMS.clear()
