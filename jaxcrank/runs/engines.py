"""The engines a sweep can solve its designs with.

- ``"xla"``: [`jaxcrank.simulate`][jaxcrank.numerics.solve.simulate] compiled by XLA (alone or in ``vmap`` batches,
  one process or several workers): the differentiable reference;
- ``"kernel"``: [`jaxcrank.numerics.kernel`][], each design's adaptive tsit5 solve in
  one compiled C function, one design per CPU thread: the same model (generated from
  it), solver, controller and metrics, for throughput. Needs a C compiler.

[`default_engine`][jaxcrank.runs.engines.default_engine] is the kernel where it can run the sweep, else XLA. A sweep
with an output directory records its engine there (``engine.txt``) and a resumed sweep keeps it:
the two engines round differently, which impact chaos amplifies, so a table is never a mix
([`resolve`][jaxcrank.runs.engines.resolve]).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..physics.params import ParameterError

ENGINES = ("kernel", "xla")


def kernel_available() -> bool:
    """Whether the kernel engine can be used here (a C compiler is on the PATH)."""
    from ..numerics.kernel import engine

    return engine.available()


def kernel_takes(mechanism) -> bool:
    """Whether every parameter of ``mechanism`` is a scalar, as the kernel's are (a worn
    joint's profiles are arrays)."""
    import jax
    import numpy as np

    return all(np.ndim(leaf) == 0 for leaf in jax.tree_util.tree_leaves(mechanism))


def default_engine(settings=None, workers: int = 1, distributed: bool = False, mechanism=None) -> str:
    """``"kernel"`` where it can run the sweep (a C compiler, the tsit5 solver, one
    process: no ``workers`` and no ``jax.distributed`` job, and a ``mechanism`` whose
    parameters are all scalars), else ``"xla"``."""
    fits = (settings is None or settings.options.solver_name == "tsit5") and int(workers) == 1 and not distributed
    fits = fits and (mechanism is None or kernel_takes(mechanism))
    return "kernel" if fits and kernel_available() else "xla"


#: the file in a sweep's output directory that names the engine its table was made with
ENGINE_FILE = "engine.txt"


def recorded(out) -> str | None:
    """The engine recorded in the sweep directory ``out`` (None when there is none)."""
    path = Path(out) / ENGINE_FILE
    return path.read_text().strip() if path.exists() else None


def resolve(
    engine: str | None,
    settings=None,
    workers: int = 1,
    distributed: bool = False,
    out=None,
    resume: bool = False,
    mechanism=None,
) -> str:
    """The engine a sweep runs with: ``engine`` when given, else, resuming the sweep in
    ``out``, the engine it was started with, else [`default_engine`][jaxcrank.runs.engines.default_engine].

    Raises:
        ParameterError: resuming a sweep that was started with another engine than ``engine``.
    """
    before = recorded(out) if (out is not None and resume) else None
    if engine is None:
        return before or default_engine(settings, workers, distributed, mechanism)
    if before is not None and engine != before:
        raise ParameterError(
            f"engine = {engine!r}: the sweep in {out} was started with engine {before!r} (its {ENGINE_FILE}); "
            f"resume it with engine = {before!r} (--engine {before}), or start a new sweep in another directory"
        )
    return engine


def default_chunk() -> int:
    """Designs per kernel call (and per checkpoint) when a sweep gives none: 16 per thread."""
    from ..numerics.kernel import engine

    return 16 * engine.default_threads()


def check(engine: str, settings, workers: int, mechanism=None) -> None:
    """Raise [`ParameterError`][jaxcrank.physics.params.ParameterError] for an unknown engine, or a kernel sweep with a
    solver other than tsit5, several worker processes, a ``jax.distributed`` job, no
    C compiler, or a ``mechanism`` with a parameter that is not a scalar."""
    if engine not in ENGINES:
        raise ParameterError(f"engine = {engine!r} is unknown; valid: {', '.join(ENGINES)}")
    if engine != "kernel":
        return
    if mechanism is not None and not kernel_takes(mechanism):
        raise ParameterError(
            "the kernel engine takes scalar parameters only (a worn joint's profiles are arrays): use xla"
        )
    if settings.options.solver_name != "tsit5":
        raise ParameterError(
            f"the kernel engine solves with tsit5 only, not solver = {settings.options.solver_name!r}: use xla"
        )
    if int(workers) != 1:
        raise ParameterError(f"workers = {workers}: the kernel engine uses one thread per core itself; use workers = 1")
    import jax

    if jax.process_count() > 1:
        raise ParameterError("the kernel engine runs in one process: use engine = 'xla' in a jax.distributed job")
    if not kernel_available():
        raise ParameterError("the kernel engine needs a C compiler (gcc or cc, or $CC): install one or use xla")


def kernel_evaluate(base, names, settings, xs):
    """Metrics (n, len(METRICS)), status codes and accepted steps of designs ``xs`` (n, k)
    by the kernel: [`jaxcrank.runs.sweep._evaluate`][jaxcrank.runs.sweep_dispatch.evaluate]'s contract."""
    from ..numerics.kernel import engine

    out = engine.solve(base, names, np.asarray(xs), settings)
    return out.metrics, out.status, out.steps
