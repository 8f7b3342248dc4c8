"""The one place jaxcrank reads or sets private parts of other packages.

Each function here stands for something the package offers no public API for; the
rest of jaxcrank calls these functions and never imports a private module itself
(``tests/test_structure.py`` checks that). Checked against jax 0.10.2,
equinox 0.13.8 and diffrax 0.7.2; each access falls back to a safe answer where the
private name has moved.
"""

from __future__ import annotations

import contextlib


def backends_started() -> bool:
    """Whether JAX has started a backend (after which ``XLA_FLAGS`` no longer act).

    JAX has no public query for this: ``jax.extend.backend.backends()`` starts them.
    Private: ``jax._src.xla_bridge.backends_are_initialized``. Falls back to False.
    """
    import sys

    if "jax" not in sys.modules:  # nothing has imported JAX, so nothing has started a backend
        return False
    try:
        from jax._src import xla_bridge
    except ImportError:  # pragma: no cover - layout of a future JAX
        return False
    started = getattr(xla_bridge, "backends_are_initialized", None)
    return bool(started()) if started is not None else False


@contextlib.contextmanager
def equinox_checks_as_nan():
    """While tracing inside this block, ``equinox.error_if`` checks (diffrax uses them on
    traced times) return NaN instead of compiling a host callback that raises.

    Equinox offers this only process-wide, through the ``EQX_ON_ERROR=nan`` environment
    variable read once at its import; its ``on_error`` argument is not reachable for
    the checks inside diffrax. Private: the module setting
    ``equinox._errors.EQX_ON_ERROR``, set for the block and restored after it.
    """
    from equinox import _errors

    before = _errors.EQX_ON_ERROR
    _errors.EQX_ON_ERROR = "nan"
    try:
        yield
    finally:
        _errors.EQX_ON_ERROR = before


def equinox_checks_as_nan_from_now() -> None:
    """``equinox.error_if`` checks traced from now on in this process return NaN (the module
    setting of [`equinox_checks_as_nan`][jaxcrank._private.equinox_checks_as_nan], not restored)."""
    from equinox import _errors

    _errors.EQX_ON_ERROR = "nan"


def equinox_checking_as_nan() -> bool:
    """Whether ``equinox.error_if`` checks traced now return NaN."""
    from equinox import _errors

    return _errors.EQX_ON_ERROR == "nan"


def is_stepsize_controller_tolerance(value) -> bool:
    """Whether ``value`` (a root finder's ``rtol``, ``atol`` or ``norm``) is diffrax's
    placeholder "take it from the step-size controller"
    (``diffrax.with_stepsize_controller_tols``), which ``diffeqsolve`` fills in only for
    an implicit solver it sees directly.

    diffrax exports the wrapper but not the placeholder. Private: its class
    ``diffrax._root_finder._with_tols._UseStepSizeTol`` (a class test, not the singleton's
    identity: a solver sent to a worker process is a copy); where it has moved, any
    value of a class of that name.
    """
    try:
        from diffrax._root_finder._with_tols import _UseStepSizeTol
    except ImportError:  # pragma: no cover - layout of a future diffrax
        return type(value).__name__ == "_UseStepSizeTol"
    return isinstance(value, _UseStepSizeTol)


def source_frames(source_info) -> list[tuple[str, int, str]]:
    """The user frames (not JAX's own) of the Python stack that traced a jaxpr equation,
    innermost first, each as (file path, line, function's qualified name); the
    equation's ``source_info``.

    JAX records the stack for its error messages and offers no public reader of it.
    Private: ``jax._src.source_info_util.user_frames``. Falls back to no frames.
    """
    try:
        from jax._src import source_info_util
    except ImportError:  # pragma: no cover - layout of a future JAX
        return []
    try:
        frames = source_info_util.user_frames(getattr(source_info, "traceback", None))
        return [(f.file_name, int(f.start_line), f.function_name) for f in frames]
    except (AttributeError, TypeError):  # pragma: no cover - layout of a future JAX
        return []


def named_scopes(source_info) -> tuple[str, ...]:
    """The ``jax.named_scope`` names around a jaxpr equation, outermost first (within the
    jaxpr that holds it; transformations such as ``jvp`` left out).

    Private: ``jax._src.source_info_util.Scope``, the class of a name-stack entry made
    by ``named_scope``. Falls back to no names.
    """
    try:
        from jax._src.source_info_util import Scope
    except ImportError:  # pragma: no cover - layout of a future JAX
        return ()
    stack = getattr(getattr(source_info, "name_stack", None), "stack", ())
    return tuple(s.name for s in stack if isinstance(s, Scope))


def equation_context(source_info):
    """A context in which equations traced anew carry ``source_info`` (the stack and named
    scopes of the equation they re-trace), as ``jax.core.eval_jaxpr`` re-traces a jaxpr, so
    a jaxpr evaluated equation by equation keeps the provenance of its equations.

    Private: ``jax._src.source_info_util.user_context`` and ``current_name_stack``. Falls
    back to no context (the equations then carry the evaluator's stack).
    """
    try:
        from jax._src import source_info_util
    except ImportError:  # pragma: no cover - layout of a future JAX
        return contextlib.nullcontext()
    try:
        stack = source_info_util.current_name_stack() + source_info.name_stack
        return source_info_util.user_context(source_info.traceback, name_stack=stack)
    except (AttributeError, TypeError):  # pragma: no cover - layout of a future JAX
        return contextlib.nullcontext()


def mark_animation_started(anim) -> None:
    """Tell a matplotlib ``Animation`` its frames are drawn (by the caller, not by
    matplotlib's event loop), so it does not warn, when deleted, that it rendered nothing.

    Matplotlib has no public switch for that warning. Private: the attribute
    ``Animation._draw_was_started`` (matplotlib 3.x). Where it has moved, the warning may
    show; nothing else changes.
    """
    anim._draw_was_started = True
