"""C code from a JAX function's jaxpr: the kernel's single source of truth.

[`emit_function`][jaxcrank.numerics.kernel.codegen.emit_function] traces a function of fixed-shape float64 arrays with
`jax.make_jaxpr` and writes it as one straight-line C function: every array
element becomes a local (``const KD vN = ...;``); slicing, reshaping, broadcasting,
stacking and concatenation only rearrange names and emit nothing; dot products and
reductions are written out as sums, scans unrolled, run-time indexing written as
selects (`jaxcrank.numerics.kernel.indexing`). Nested ``jit`` and custom-derivative calls are inlined
(their primal jaxpr); identical expressions are computed once. Each primitive is written by its
entry in one table ([`jaxcrank.numerics.kernel.primitives.EMITTERS`][]); only primitives with an
exact translation have one, and anything else raises
`jaxcrank.numerics.kernel.text.UnsupportedPrimitive`
naming it, so a model change that needs a new primitive fails at generation time,
never silently in the kernel. Comments name the Python source each block of statements was
traced from ([`.provenance`][jaxcrank.numerics.kernel.provenance]), and array elements may be
indexed by names (``p[P_joint_B_pin_radius]``) instead of numbers.

The text is written in a small macro vocabulary (types ``KD``/``KB``/``KL``, selects
``KSEL``, logic ``KAND``, libm calls ``KF1(sin, x)``, ...) that
`.source` instantiates twice: for scalars (C and CUDA C++) and for GCC vectors of
four designs, one per lane. Rounding follows XLA's CPU lowering where it matters
([`.primitives`][jaxcrank.numerics.kernel.primitives]); sums of dot products may
associate differently from XLA (a few ulp).
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from .primitives import EMITTERS, interpret
from .text import UnsupportedPrimitive, _array, _Writer, literal

__all__ = ["EMITTERS", "UnsupportedPrimitive", "emit_function", "literal"]


_TRIG = re.compile(r"^  const KD (v\d+) = KV\(KF1\((sin|cos), (v\d+)\)\);$")


def _fuse_sincos(lines: list[str]) -> list[str]:
    """Sine and cosine of one argument as one ``KSINCOS`` (libm's sincos gives both, with
    the values of sin and cos), where both are taken."""
    trig = {}
    for i, line in enumerate(lines):
        m = _TRIG.match(line)
        if m:
            trig.setdefault(m.group(3), {})[m.group(2)] = (i, m.group(1))
    out = list(lines)
    for arg, both in trig.items():
        if len(both) == 2:
            (i, s_name), (j, c_name) = both["sin"], both["cos"]
            first, second = min(i, j), max(i, j)
            out[first] = f"  KD {s_name}, {c_name};\n  KSINCOS({arg}, {s_name}, {c_name});"
            out[second] = None
    return [line for line in out if line is not None]


def _drop_empty_comments(lines: list[str]) -> list[str]:
    """The lines without comments that no statement follows (after the fusion moved one)."""
    out = []
    for line in lines:
        if out and out[-1].startswith("  /*") and line.startswith("  /*"):
            out.pop()
        out.append(line)
    return out


def _elements(arg: str, size: int, names: Mapping[str, Sequence[str]]) -> list[str]:
    """``arg[i]`` for each element, ``i`` written as ``names[arg][i]`` where names are given."""
    index = names.get(arg)
    if index is None:
        return [f"{arg}[{i}]" for i in range(size)]
    if len(index) != size:
        raise ValueError(f"{len(index)} names for the {size} elements of {arg!r}")
    return [f"{arg}[{i}]" for i in index]


def emit_function(
    name: str,
    fn: Callable,
    inputs: Sequence[tuple[str, tuple[int, ...]]],
    outputs: Sequence[str],
    names: Mapping[str, Sequence[str]] | None = None,
) -> tuple[str, list[tuple[int, ...]]]:
    """Generate ``KFN void KNAME(name)(const KD *in0, ..., KD *out0, ...)``.

    Args:
        name: the C function's name.
        fn: a JAX function of float64 arrays with the shapes of ``inputs``,
            returning a tuple of arrays (one per entry of ``outputs``).
        inputs: (C parameter name, shape) per argument of ``fn``; a shape ``()``
            is passed as a ``KD`` by value, others as a flat row-major pointer.
        outputs: C parameter names of the outputs (flat row-major pointers).
        names: per input or output name, the index of each of its flat elements as the
            code writes it (a macro the caller defines, such as ``P_crank_length``);
            arrays not named here are indexed by numbers.

    Returns:
        (C source of the function, output shapes).

    Raises:
        UnsupportedPrimitive: naming a primitive without a scalar translation.
        ValueError: ``names`` has the wrong number of names for an array, or ``fn``
            returns a different number of arrays than ``outputs`` names.
    """
    names = dict(names or {})
    examples = [jnp.zeros(shape, dtype=jnp.float64) for _, shape in inputs]
    closed = jax.make_jaxpr(fn)(*examples)
    w = _Writer()
    args = []
    for arg_name, shape in inputs:
        if shape == ():
            args.append(_array(arg_name))
        else:
            flat = _elements(arg_name, int(np.prod(shape, dtype=int)), names)
            args.append(_array(flat).reshape(shape))
    results = interpret(w, closed.jaxpr, closed.consts, args)
    if len(results) != len(outputs):
        raise ValueError(f"{name}: the function returns {len(results)} arrays for {len(outputs)} output names")
    body = _drop_empty_comments(_fuse_sincos(w.lines) + ["  /* outputs */"])
    shapes = []
    for out_name, res in zip(outputs, results):
        res = _array(res)
        shapes.append(res.shape)
        for target, expr in zip(_elements(out_name, res.size, names), res.reshape(-1)):
            body.append(f"  {target} = KV({expr});")
    params = [f"KD {n}" if s == () else f"const KD *KRESTRICT {n}" for n, s in inputs]
    params += [f"KD *KRESTRICT {n}" for n in outputs]
    head = f"KFN void KNAME({name})({', '.join(params)})"
    return head + " {\n" + "\n".join(body) + "\n}\n", shapes
