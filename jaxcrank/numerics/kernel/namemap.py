"""Names for the generated code's array elements: the name map at the top of a kernel source.

The generated functions take flat arrays (``p`` the run-time parameters, ``y`` the
state, ...). The name map defines one macro per element, ``#define P_joints_B_pin_radius 13``,
with the element's full name in a comment, and the functions index by the macro
(``p[P_joints_B_pin_radius]``): the preprocessed code is the same as with numbers, and a
reader sees which parameter each statement reads. Parameter names are the pytree paths
of the mechanism's leaves ([`leaf_paths`][jaxcrank.numerics.kernel.namemap.leaf_paths]),
derived from the pytree itself, so they follow any mechanism description.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from typing import NamedTuple

import jax

from .text import literal


class Group(NamedTuple):
    """The names of one array's elements.

    Attributes:
        arrays: the C names of the arrays indexed by these names (``("y", "rate")``).
        prefix: the macros' prefix (``"Y_"``).
        names: one name per element, or None: the elements are indexed by number.
        meaning: what the elements are, with their units, for the map's heading.
    """

    arrays: tuple[str, ...]
    prefix: str
    names: tuple[str, ...] | None
    meaning: str


def leaf_paths(tree) -> tuple[str, ...]:
    """The pytree path of each leaf of ``tree`` (``joints.B.pin_radius``, ``driver.speed``), in
    `jax.tree_util.tree_leaves` order."""
    flat, _ = jax.tree_util.tree_flatten_with_path(tree)
    return tuple(jax.tree_util.keystr(path, simple=True, separator=".") or "(root)" for path, _ in flat)


def macros(prefix: str, names: Sequence[str]) -> tuple[str, ...]:
    """A distinct C identifier per name: ``prefix`` and the name with every run of characters
    outside ``[A-Za-z0-9_]`` as one ``_`` (the element's index appended where two would clash)."""
    out: list[str] = []
    for i, name in enumerate(names):
        ident = prefix + (re.sub(r"[^A-Za-z0-9_]+", "_", name).strip("_") or str(i))
        out.append(ident if ident not in out else f"{ident}_{i}")
    return tuple(out)


def _comment(text: str) -> str:
    return text.replace("*/", "* /")


def index_names(groups: Sequence[Group]) -> dict[str, tuple[str, ...]]:
    """Per array name, the macros that index its elements (for
    [`emit_function`][jaxcrank.numerics.kernel.codegen.emit_function]'s ``names``); arrays of
    groups without names are left out."""
    out = {}
    for g in groups:
        if g.names is not None:
            for array in g.arrays:
                out[array] = macros(g.prefix, g.names)
    return out


def name_map(groups: Sequence[Group], constants: Sequence[tuple[str, float]] = ()) -> str:
    """The C text of the name map: per group a heading and one ``#define`` per element, and
    the values of the parameters baked into the code as literals (``constants``: (name, value),
    SI), a comment."""
    lines = ["/* Name map: the generated functions index their arrays by these macros."]
    for g in groups:
        arrays = ", ".join(g.arrays)
        how = f"{len(g.names)} names" if g.names is not None else "indexed by number (no names given)"
        lines.append(_comment(f" * {arrays}: {g.meaning}; {how}"))
    lines[-1] += " */"
    rows = [
        (ident, i, name)
        for g in groups
        if g.names is not None
        for i, (ident, name) in enumerate(zip(macros(g.prefix, g.names), g.names))
    ]
    width = max((len(ident) for ident, _, _ in rows), default=0)
    lines += [f"#define {ident:<{width}} {i:>3}  /* {_comment(name)} */" for ident, i, name in rows]
    if constants:
        lines.append(
            "/* Parameter values baked into the code as literals (SI); the run-time inputs p replace those they set:"
        )
        lines += [_comment(f" *   {name} = {literal(float(value))}") for name, value in constants]
        lines.append(" */")
    return "\n".join(lines)
