"""C code from a JAX function's jaxpr: the kernel's single source of truth.

[`emit_function`][jaxcrank.numerics.kernel.codegen.emit_function] traces a function of fixed-shape float64 arrays with
`jax.make_jaxpr` and writes it as one straight-line C function: every array
element becomes a local (``const KD vN = ...;``); slicing, reshaping, broadcasting,
stacking and concatenation only rearrange names and emit nothing; dot products and
reductions are written out as sums, scans unrolled, run-time indexing written as
selects (`jaxcrank.numerics.kernel.indexing`). Nested ``jit`` and custom-derivative calls are inlined
(their primal jaxpr); identical expressions are computed once. Only primitives with an
exact translation are accepted; anything else raises
`jaxcrank.numerics.kernel.text.UnsupportedPrimitive`
naming it, so a model change that needs a new primitive fails at generation time,
never silently in the kernel.

The text is written in a small macro vocabulary (types ``KD``/``KB``/``KL``, selects
``KSEL``, logic ``KAND``, libm calls ``KF1(sin, x)``, ...) that
`.source` instantiates twice: for scalars (C and CUDA C++) and for GCC vectors of
four designs, one per lane. Rounding follows XLA's CPU lowering where it matters:
``integer_pow`` is the same chain of multiplications, ``max``/``min`` propagate NaN,
``asin`` is XLA's decomposition, ``rsqrt`` is ``1 / sqrt``; sums of dot products may
associate differently from XLA (a few ulp).
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Sequence

import jax
import jax.numpy as jnp
import numpy as np
from jax.extend import core as jex_core

from . import indexing
from .text import _FOLD, UnsupportedPrimitive, _array, _ctype, _value, _Writer, literal

_BINARY = {"add": "+", "add_any": "+", "sub": "-", "mul": "*", "div": "/"}
_COMPARE = {"gt": ">", "lt": "<", "ge": ">=", "le": "<=", "eq": "==", "ne": "!="}
_UNARY = {
    "sin": "sin",
    "cos": "cos",
    "tan": "tan",
    "acos": "acos",
    "atan": "atan",
    "sinh": "sinh",
    "cosh": "cosh",
    "tanh": "tanh",
    "exp": "exp",
    "log": "log",
    "log1p": "log1p",
    "expm1": "expm1",
    "sqrt": "sqrt",
    "cbrt": "cbrt",
    "abs": "fabs",
    "floor": "floor",
    "ceil": "ceil",
}
_IDENTITY = {"stop_gradient", "copy", "copy_p", "optimization_barrier", "reduce_precision"}
_CALLS = {"jit", "pjit", "closed_call", "core_call", "remat", "checkpoint", "custom_jvp_call", "custom_vjp_call"}


def _kmax(a, b):
    return a + b if math.isnan(a) or math.isnan(b) else max(a, b)


def _kmin(a, b):
    return a + b if math.isnan(a) or math.isnan(b) else min(a, b)


#: float64 operations computed here when every operand is a literal, as XLA's constant
#: folding computes them (IEEE arithmetic, the host's libm): the generated code then
#: holds the value XLA's program holds
_HOST = {
    "add": lambda a, b: a + b,
    "add_any": lambda a, b: a + b,
    "sub": lambda a, b: a - b,
    "mul": lambda a, b: a * b,
    "div": lambda a, b: a / b if b != 0.0 else math.copysign(math.inf, a) * math.copysign(1.0, b) if a else math.nan,
    "max": _kmax,
    "min": _kmin,
    "neg": lambda a: -a,
    "square": lambda a: a * a,
    "sqrt": math.sqrt,
    "rsqrt": lambda a: 1.0 / math.sqrt(a),
    "sin": math.sin,
    "cos": math.cos,
    "exp": math.exp,
    "abs": abs,
    "pow": math.pow,
    "atan2": math.atan2,
    "asin": lambda a: 2.0 * math.atan2(a, 1.0 + math.sqrt((1.0 - a) * (1.0 + a))),
}


def _elementwise(w: _Writer, fmt: Callable[..., str], dtype, *args, host=None) -> np.ndarray:
    """One statement per element; computed here instead when ``host`` (a Python function
    of floats) is given and every operand is a literal."""
    arrays = np.broadcast_arrays(*[_array(a) for a in args])
    out = np.empty(arrays[0].shape, dtype=object)
    for idx in np.ndindex(out.shape):
        operands = [a[idx] for a in arrays]
        values = [_value(o) for o in operands]
        if host is not None and all(isinstance(v, float) for v in values):
            try:
                out[idx] = literal(float(host(*values)))
                continue
            except (ValueError, OverflowError, ZeroDivisionError):
                pass  # a domain error: leave it to the C code
        out[idx] = w.new(fmt(*operands), dtype)
    return out


def _divide(a: str, b: str) -> str:
    """``a / b``; by a literal, the product with its reciprocal, as XLA's algebraic
    simplifier rewrites a division by a constant of the traced program."""
    v = _value(b)
    if isinstance(v, float) and v != 0.0 and math.isfinite(v):
        return f"{a} * {literal(1.0 / v)}"
    return f"{a} / {b}"


def _integer_pow(w: _Writer, x: str, y: int, dtype) -> str:
    """``x ** y`` as XLA computes it: binary exponentiation, a reciprocal for y < 0."""
    if y == 0:
        return literal(1.0)
    if y in (1, 2, 3):
        return x if y == 1 else w.new(f"{x} * {x}" if y == 2 else f"({x} * {x}) * {x}", dtype)
    if y == -1:
        return w.new(f"1.0 / {x}", dtype)
    recip, n, acc, base = y < 0, abs(y), None, x
    while n > 0:
        if n & 1:
            acc = base if acc is None else w.new(f"{acc} * {base}", dtype)
        n >>= 1
        if n > 0:
            base = w.new(f"{base} * {base}", dtype)
    return w.new(f"1.0 / {acc}", dtype) if recip else acc


def _folded(w: _Writer, op: str, dtype, a, b) -> np.ndarray:
    """An integer or comparison op, computed here when both operands are literals
    (loop counters of unrolled scans), else emitted."""
    arrays = np.broadcast_arrays(_array(a), _array(b))
    out = np.empty(arrays[0].shape, dtype=object)
    for idx in np.ndindex(out.shape):
        x, y = arrays[0][idx], arrays[1][idx]
        vx, vy = _value(x), _value(y)
        if vx is not None and vy is not None:
            v = _FOLD[op](vx, vy)
            out[idx] = literal(bool(v)) if isinstance(v, bool) else literal(v)
        else:
            out[idx] = w.new(f"{x} {op} {y}", dtype)
    return out


def _read(env: dict, atom) -> np.ndarray:
    if isinstance(atom, jex_core.Literal):
        val = np.asarray(atom.val)
        return np.vectorize(literal, otypes=[object])(val) if val.ndim else _array(literal(val.item()))
    return env[atom]


def _inner(params):
    for key in ("jaxpr", "call_jaxpr", "fun_jaxpr"):
        if key in params:
            inner = params[key]
            if isinstance(inner, jex_core.ClosedJaxpr):
                return inner.jaxpr, inner.consts
            return inner, ()
    raise UnsupportedPrimitive("a call primitive without a jaxpr")


def _constant(value) -> np.ndarray:
    val = np.asarray(value)
    if val.ndim == 0:
        return _array(literal(val.item()))
    return np.vectorize(literal, otypes=[object])(val)


def _run(w: _Writer, jaxpr, consts, args) -> list[np.ndarray]:
    env: dict = {}
    for var, c in zip(jaxpr.constvars, consts):
        env[var] = _constant(c)
    for var, a in zip(jaxpr.invars, args):
        env[var] = a
    for eqn in jaxpr.eqns:
        ins = [_read(env, v) for v in eqn.invars]
        outs = _primitive(w, eqn, ins)
        for var, val in zip(eqn.outvars, outs):
            env[var] = val
    return [_read(env, v) for v in jaxpr.outvars]


def _primitive(w: _Writer, eqn, ins) -> list[np.ndarray]:
    name, p = eqn.primitive.name, eqn.params
    out_aval = eqn.outvars[0].aval if eqn.outvars else None
    dtype = out_aval.dtype if out_aval is not None else np.float64
    if name in _CALLS:
        inner, consts = _inner(p)
        n = len(inner.invars)
        return _run(w, inner, consts, ins[len(ins) - n :] if name == "custom_vjp_call" else ins[:n])
    if name in _IDENTITY:
        return ins
    if name in _BINARY or name in _COMPARE:
        op = _BINARY.get(name) or _COMPARE[name]
        if np.issubdtype(eqn.invars[0].aval.dtype, np.integer) and op in _FOLD:
            return [_folded(w, op, dtype, *ins)]
        host = _HOST.get(name) if dtype == np.float64 else None
        if name == "div" and dtype == np.float64:
            return [_elementwise(w, _divide, dtype, *ins, host=host)]
        return [_elementwise(w, lambda a, b: f"{a} {op} {b}", dtype, *ins, host=host)]
    if name in ("max", "min"):
        return [_elementwise(w, lambda a, b: f"K{name.upper()}({a}, {b})", dtype, *ins, host=_HOST[name])]
    if name in _UNARY:
        fn = _UNARY[name]
        return [_elementwise(w, lambda a: f"KF1({fn}, {a})", dtype, *ins, host=_HOST.get(name))]
    simple = {
        "neg": lambda a: f"-{a}",
        # XLA's decomposition of asin (chlo.asin), not libm's: the same rounding
        "asin": lambda a: f"2.0 * KF2(atan2, {a}, 1.0 + KF1(sqrt, (1.0 - {a}) * (1.0 + {a})))",
        "square": lambda a: f"{a} * {a}",
        "rsqrt": lambda a: f"1.0 / KF1(sqrt, {a})",
        "sign": lambda a: f"KSIGN({a})",
        "not": lambda a: f"KNOT({a})",
        "is_finite": lambda a: f"KISFINITE({a})",
        "logistic": lambda a: f"1.0 / (1.0 + KF1(exp, -{a}))",
    }
    if name in simple:
        host = _HOST.get(name) if dtype == np.float64 else None
        return [_elementwise(w, simple[name], dtype, *ins, host=host)]
    if name in ("and", "or"):
        if dtype == np.bool_:
            macro = "KAND" if name == "and" else "KOR"
            return [_elementwise(w, lambda a, b: f"{macro}({a}, {b})", dtype, *ins)]
        op = "&" if name == "and" else "|"
        return [_elementwise(w, lambda a, b: f"{a} {op} {b}", dtype, *ins)]
    if name in ("pow", "atan2", "nextafter", "rem"):
        fn = {"pow": "pow", "atan2": "atan2", "nextafter": "nextafter", "rem": "fmod"}[name]
        return [_elementwise(w, lambda a, b: f"KF2({fn}, {a}, {b})", dtype, *ins, host=_HOST.get(name))]
    if name == "integer_pow":
        x = ins[0]
        out = np.empty(x.shape, dtype=object)
        for idx in np.ndindex(x.shape):
            out[idx] = _integer_pow(w, x[idx], int(p["y"]), dtype)
        return [out]
    if name == "select_n":
        pred, *cases = ins
        if len(cases) != 2:
            raise UnsupportedPrimitive("select_n with more than two cases")
        arrays = np.broadcast_arrays(_array(pred), *[_array(c) for c in cases])
        out = np.empty(arrays[0].shape, dtype=object)
        for idx in np.ndindex(out.shape):
            c, a, b = (x[idx] for x in arrays)
            known = _value(c)
            select = "KSEL" if np.dtype(dtype) == np.float64 else "KSELL"
            out[idx] = (b if known else a) if known is not None else w.new(f"{select}({c}, {b}, {a})", dtype)
        return [out]
    if name == "scan":
        return indexing.scan(w, eqn, ins, _run)
    if name == "argmax":
        return [indexing.argmax(w, ins[0], tuple(p["axes"]), p["index_dtype"])]
    if name == "dynamic_slice":
        return [indexing.dynamic_slice(w, ins[0], ins[1:], tuple(p["slice_sizes"]), dtype)]
    if name == "dynamic_update_slice":
        return [indexing.dynamic_update_slice(w, ins[0], ins[1], ins[2:], dtype)]
    if name == "clamp":
        return [_elementwise(w, lambda lo, x, hi: f"KMIN(KMAX({x}, {lo}), {hi})", dtype, *ins)]
    if name == "convert_element_type":
        ctype = _ctype(p["new_dtype"])
        src = _ctype(eqn.invars[0].aval.dtype)
        if ctype == src:
            return ins
        macro = {"KB": "B", "KL": "L", "KD": "D"}
        fmt = lambda a: f"K{macro[src]}2{macro[ctype]}({a})"  # noqa: E731
        return [_elementwise(w, fmt, p["new_dtype"], *ins)]
    if name == "slice":
        strides = p["strides"] or (1,) * ins[0].ndim
        sl = tuple(slice(a, b, s) for a, b, s in zip(p["start_indices"], p["limit_indices"], strides))
        return [ins[0][sl]]
    if name == "squeeze":
        return [np.squeeze(ins[0], axis=tuple(p["dimensions"])) if p["dimensions"] else ins[0]]
    if name == "expand_dims":
        return [np.expand_dims(ins[0], tuple(p["dimensions"]))]
    if name == "reshape":
        return [ins[0].reshape(p["new_sizes"])]
    if name == "broadcast_in_dim":
        x, shape, dims = ins[0], tuple(p["shape"]), tuple(p["broadcast_dimensions"])
        expanded = x.reshape([x.shape[dims.index(d)] if d in dims else 1 for d in range(len(shape))])
        return [np.broadcast_to(expanded, shape).copy()]
    if name == "transpose":
        return [np.transpose(ins[0], p["permutation"])]
    if name == "concatenate":
        return [np.concatenate(ins, axis=p["dimension"])]
    if name == "stack":
        return [np.stack(ins, axis=p["axis"])]
    if name == "split":
        cuts = np.cumsum(p["sizes"])[:-1]
        return list(np.split(ins[0], cuts, axis=p["axis"]))
    if name == "rev":
        return [np.flip(ins[0], axis=tuple(p["dimensions"]))]
    if name == "iota":
        shape, dim = tuple(p["shape"]), p["dimension"]
        idx = np.indices(shape)[dim]
        return [np.vectorize(lambda v: literal(np.asarray(v, dtype=p["dtype"]).item()), otypes=[object])(idx)]
    if name == "dot_general":
        return [indexing.dot_general(w, ins[0], ins[1], p, dtype)]
    if name == "reduce_sum":
        return [indexing.reduce(w, ins[0], tuple(p["axes"]), lambda a, b: f"{a} + {b}", dtype)]
    if name in ("reduce_max", "reduce_min"):
        fn = "KMAX" if name == "reduce_max" else "KMIN"
        return [indexing.reduce(w, ins[0], tuple(p["axes"]), lambda a, b: f"{fn}({a}, {b})", dtype)]
    raise UnsupportedPrimitive(f"primitive {name!r} has no scalar C translation in jaxcrank.numerics.kernel.codegen")


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


def emit_function(
    name: str,
    fn: Callable,
    inputs: Sequence[tuple[str, tuple[int, ...]]],
    outputs: Sequence[str],
) -> tuple[str, list[tuple[int, ...]]]:
    """Generate ``KFN void KNAME(name)(const KD *in0, ..., KD *out0, ...)``.

    Args:
        name: the C function's name.
        fn: a JAX function of float64 arrays with the shapes of ``inputs``,
            returning a tuple of arrays (one per entry of ``outputs``).
        inputs: (C parameter name, shape) per argument of ``fn``; a shape ``()``
            is passed as a ``KD`` by value, others as a flat row-major pointer.
        outputs: C parameter names of the outputs (flat row-major pointers).

    Returns:
        (C source of the function, output shapes).

    Raises:
        UnsupportedPrimitive: naming a primitive without a scalar translation.
    """
    examples = [jnp.zeros(shape, dtype=jnp.float64) for _, shape in inputs]
    closed = jax.make_jaxpr(fn)(*examples)
    w = _Writer()
    args = []
    for arg_name, shape in inputs:
        if shape == ():
            args.append(_array(arg_name))
        else:
            flat = [f"{arg_name}[{i}]" for i in range(int(np.prod(shape, dtype=int)))]
            args.append(_array(flat).reshape(shape))
    results = _run(w, closed.jaxpr, closed.consts, args)
    if len(results) != len(outputs):
        raise ValueError(f"{name}: the function returns {len(results)} arrays for {len(outputs)} output names")
    body = _fuse_sincos(w.lines)
    shapes = []
    for out_name, res in zip(outputs, results):
        res = _array(res)
        shapes.append(res.shape)
        for i, expr in enumerate(res.reshape(-1)):
            body.append(f"  {out_name}[{i}] = KV({expr});")
    params = [f"KD {n}" if s == () else f"const KD *KRESTRICT {n}" for n, s in inputs]
    params += [f"KD *KRESTRICT {n}" for n in outputs]
    head = f"KFN void KNAME({name})({', '.join(params)})"
    return head + " {\n" + "\n".join(body) + "\n}\n", shapes
