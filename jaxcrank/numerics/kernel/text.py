"""The generated code's vocabulary shared by `.codegen` and `.indexing`:
literals, the type macros, and the writer that names every emitted expression."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np


class UnsupportedPrimitive(NotImplementedError):
    """The traced function uses a primitive the generator cannot write as scalar C."""


def literal(value) -> str:
    """A C literal of a float, int or bool (infinities, NaN and booleans as the prelude's macros)."""
    if isinstance(value, (bool, np.bool_)):
        return "KTRUE" if value else "KFALSE"
    if isinstance(value, (int, np.integer)):
        return f"{int(value)}L"
    v = float(value)
    if math.isnan(v):
        return "KNAN"
    if math.isinf(v):
        return "KINF" if v > 0 else "(-KINF)"
    text = repr(v)
    return text if ("e" in text or "." in text) else text + ".0"


def _value(expr):
    """The Python value of a literal written by [`literal`][jaxcrank.numerics.kernel.text.literal] , or None for a C
    expression."""
    if not isinstance(expr, str):
        return None
    if expr.endswith("L") and expr[:-1].lstrip("-").isdigit():
        return int(expr[:-1])
    if expr in ("KTRUE", "KFALSE"):
        return expr == "KTRUE"
    try:
        return float(expr)
    except ValueError:
        return None


_FOLD = {
    "+": lambda a, b: a + b,
    "-": lambda a, b: a - b,
    "*": lambda a, b: a * b,
    ">": lambda a, b: a > b,
    "<": lambda a, b: a < b,
    ">=": lambda a, b: a >= b,
    "<=": lambda a, b: a <= b,
    "==": lambda a, b: a == b,
    "!=": lambda a, b: a != b,
}


def _ctype(dtype) -> str:
    """The generated code's type macro: ``KD`` (float64), ``KB`` (bool), ``KL`` (integers)."""
    dtype = np.dtype(dtype)
    if dtype == np.bool_:
        return "KB"
    if np.issubdtype(dtype, np.integer):
        return "KL"
    if dtype != np.float64:
        raise UnsupportedPrimitive(f"dtype {dtype}: the kernel computes in float64 only")
    return "KD"


class _Writer:
    """Emits C statements and names their results.

    Attributes:
        lines: the statements (and comments) written so far.
        where: the source of the statements written next (a comment's text, or None);
            the comment precedes the next statement when it differs from the last one written.
        scopes: the ``jax.named_scope`` names around the equation being written.
    """

    def __init__(self):
        self.lines: list[str] = []
        self.count = 0
        self.seen: dict[tuple[str, str], str] = {}
        self.where: str | None = None
        self.scopes: tuple[str, ...] = ()
        self._said: str | None = None

    def new(self, expr: str, dtype) -> str:
        """The name of ``expr``'s value: a new local, or the one an identical expression
        already has (every expression is pure, so this common-subexpression elimination
        is exact)."""
        key = (expr, _ctype(dtype))
        if key in self.seen:
            return self.seen[key]
        name = f"v{self.count}"
        self.seen[key] = name
        self.count += 1
        ctype = _ctype(dtype)
        if self.where is not None and self.where != self._said:
            self.lines.append(f"  /* {self.where} */")
            self._said = self.where
        wrap = "KV" if ctype == "KD" else "KVL"  # a statement of literals alone is a scalar: broadcast it
        self.lines.append(f"  const {ctype} {name} = {wrap}({expr});")
        return name


def _array(x) -> np.ndarray:
    return np.asarray(x, dtype=object)


def _sum(w: _Writer, terms: Sequence[str], dtype) -> str:
    if not terms:
        return literal(0.0)
    acc = terms[0]
    for t in terms[1:]:
        acc = w.new(f"{acc} + {t}", dtype)
    return acc
