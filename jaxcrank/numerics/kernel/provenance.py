"""Where each block of generated C came from: comments naming the Python source of the
jaxpr equations that a block of statements computes.

Every equation of a traced jaxpr remembers the Python stack that created it. The
comment names the innermost frame in jaxcrank's own code (outside this kernel package,
whose functions only feed the model its inputs) and the first caller in another file,
e.g. ``/* jaxcrank/physics/ideal.py:43 positions, in jaxcrank/physics/kinematics.py:23
full_positions */``; an equation without such a frame (diffrax's dense output) names its
innermost frame outside JAX. ``jax.named_scope`` names, where the model sets any, lead
the comment in brackets. Paths are relative to the package's parent (or to
``site-packages``), so the text, and the build cache's key, do not depend on where the
package is installed.
"""

from __future__ import annotations

import contextlib
import functools
from pathlib import Path

from ... import _private
from .text import _Writer

_PACKAGE = Path(__file__).resolve().parents[2]  # .../jaxcrank
_KERNEL = Path(__file__).resolve().parent  # .../jaxcrank/numerics/kernel


@functools.lru_cache(maxsize=512)
def _place(file_name: str) -> tuple[str, str]:
    """(the path shown in comments, its kind: ``"model"`` for jaxcrank's code outside this
    package, ``"kernel"`` for this package's, ``"other"``)."""
    path = Path(file_name)
    path = path.resolve() if path.is_absolute() else path
    if path.is_relative_to(_PACKAGE):
        return path.relative_to(_PACKAGE.parent).as_posix(), "kernel" if path.is_relative_to(_KERNEL) else "model"
    parts = path.parts
    if "site-packages" in parts:
        i = len(parts) - 1 - parts[::-1].index("site-packages")
        return Path(*parts[i + 1 :]).as_posix(), "other"
    return path.name, "other"


def _frame(frame: tuple[str, int, str]) -> str:
    file_name, line, function = frame
    return f"{_place(file_name)[0]}:{line} {function.replace('.<locals>', '')}"


def describe(frames: list[tuple[str, int, str]], scopes: tuple[str, ...] = ()) -> str | None:
    """The comment text for an equation traced at ``frames`` (innermost first, as
    `jaxcrank._private.source_frames` gives them) inside the named scopes ``scopes``:
    the innermost frame of the model's code (else outside this package, else any) and
    its first caller in another file; None when nothing is known."""
    model = [f for f in frames if _place(f[0])[1] == "model"]
    pool = model or [f for f in frames if _place(f[0])[1] == "other"] or frames
    text = None
    if pool:
        text = _frame(pool[0])
        caller = next((f for f in pool[1:] if f[0] != pool[0][0]), None)
        if caller is not None:
            text += f", in {_frame(caller)}"
    if scopes:
        text = f"[{'/'.join(scopes)}]" + ("" if text is None else f" {text}")
    return None if text is None else text.replace("*/", "* /")


@contextlib.contextmanager
def entering(w: _Writer, eqn):
    """While the statements of ``eqn`` are written: ``w`` comments them with their source
    (the named scopes of the calls around ``eqn`` kept for the equations inside it)."""
    outer_scopes, outer_where = w.scopes, w.where
    w.scopes = outer_scopes + _private.named_scopes(eqn.source_info)
    w.where = describe(_private.source_frames(eqn.source_info), w.scopes)
    try:
        yield
    finally:
        w.scopes, w.where = outer_scopes, outer_where
