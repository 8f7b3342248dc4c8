"""The generator's jaxpr interpreter: one emitter per JAX primitive, in one table.

[`EMITTERS`][jaxcrank.numerics.kernel.primitives.EMITTERS] maps a primitive's name to a small function
``emit(w, eqn, ins) -> outs`` that writes the equation's C statements with the writer ``w``
(`jaxcrank.numerics.kernel.text`) and returns the names of its outputs' elements (object arrays of C
expressions, one per output of the equation). [`interpret`][jaxcrank.numerics.kernel.primitives.interpret]
walks a jaxpr and dispatches each equation once, through the table; a primitive without an entry raises
`jaxcrank.numerics.kernel.text.UnsupportedPrimitive` naming it.

Rounding follows XLA's CPU lowering where it matters: ``integer_pow`` is the same chain of
multiplications, ``max``/``min`` propagate NaN, ``asin`` is XLA's decomposition, ``rsqrt`` is
``1 / sqrt``, float operations of literals are computed here as XLA's constant folding computes them,
and a division by a literal is the product with its reciprocal (XLA's algebraic simplifier).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable

import numpy as np
from jax.extend import core as jex_core

from . import indexing, provenance
from .text import _FOLD, UnsupportedPrimitive, _array, _ctype, _value, _Writer, literal

#: an emitter: (writer, jaxpr equation, input element names) -> output element names, one array per output
Emitter = Callable[[_Writer, object, list], list]


def _kmax(a, b):
    return a + b if math.isnan(a) or math.isnan(b) else max(a, b)


def _kmin(a, b):
    return a + b if math.isnan(a) or math.isnan(b) else min(a, b)


def _host_divide(a, b):
    if b != 0.0:
        return a / b
    return math.copysign(math.inf, a) * math.copysign(1.0, b) if a else math.nan


#: float64 operations computed here when every operand is a literal, as XLA's constant
#: folding computes them (IEEE arithmetic, the host's libm): the generated code then
#: holds the value XLA's program holds
_HOST = {
    "add": lambda a, b: a + b,
    "add_any": lambda a, b: a + b,
    "sub": lambda a, b: a - b,
    "mul": lambda a, b: a * b,
    "div": _host_divide,
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


def _dtype(eqn):
    """The dtype of the equation's first output (float64 for an equation without outputs)."""
    return eqn.outvars[0].aval.dtype if eqn.outvars else np.float64


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


# --- elementwise arithmetic, comparison, logic and libm calls ---------------------------------------------------


def _infix(op: str, w, eqn, ins):
    """``a op b``: integer operations and comparisons folded when both operands are known (a
    comparison of literals is a boolean literal, ``KTRUE``/``KFALSE``: a C comparison of two
    scalars is the int 1, which is no lane mask in the vector build), float64 literals computed
    here, a float division by a literal as a product."""
    name, dtype = eqn.primitive.name, _dtype(eqn)
    integer = np.issubdtype(eqn.invars[0].aval.dtype, np.integer)
    if (integer or name in _COMPARISONS) and op in _FOLD:
        return [_folded(w, op, dtype, *ins)]
    host = _HOST.get(name) if dtype == np.float64 else None
    if name == "div" and dtype == np.float64:
        return [_elementwise(w, _divide, dtype, *ins, host=host)]
    return [_elementwise(w, lambda a, b: f"{a} {op} {b}", dtype, *ins, host=host)]


def _call1(fn: str, w, eqn, ins):
    """A one-argument libm function, ``KF1(fn, a)``."""
    return [_elementwise(w, lambda a: f"KF1({fn}, {a})", _dtype(eqn), *ins, host=_HOST.get(eqn.primitive.name))]


def _call2(fn: str, w, eqn, ins):
    """A two-argument libm function, ``KF2(fn, a, b)``."""
    fmt = lambda a, b: f"KF2({fn}, {a}, {b})"  # noqa: E731
    return [_elementwise(w, fmt, _dtype(eqn), *ins, host=_HOST.get(eqn.primitive.name))]


def _macro2(macro: str, w, eqn, ins):
    """``max``/``min`` as the NaN-propagating ``KMAX``/``KMIN``."""
    fmt = lambda a, b: f"{macro}({a}, {b})"  # noqa: E731
    return [_elementwise(w, fmt, _dtype(eqn), *ins, host=_HOST[eqn.primitive.name])]


def _unary(fmt: Callable[[str], str], w, eqn, ins):
    """A one-operand expression; float64 literals computed here where the host knows the function."""
    dtype = _dtype(eqn)
    host = _HOST.get(eqn.primitive.name) if dtype == np.float64 else None
    return [_elementwise(w, fmt, dtype, *ins, host=host)]


def _logic(macro: str, bitwise: str, w, eqn, ins):
    """``and``/``or``: the logic macro on booleans, the bitwise operator on integers."""
    dtype = _dtype(eqn)
    if dtype == np.bool_:
        return [_elementwise(w, lambda a, b: f"{macro}({a}, {b})", dtype, *ins)]
    return [_elementwise(w, lambda a, b: f"{a} {bitwise} {b}", dtype, *ins)]


def _integer_pow_of(w: _Writer, x: str, y: int, dtype) -> str:
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


def _integer_pow(w, eqn, ins):
    x, y, dtype = ins[0], int(eqn.params["y"]), _dtype(eqn)
    out = np.empty(x.shape, dtype=object)
    for idx in np.ndindex(x.shape):
        out[idx] = _integer_pow_of(w, x[idx], y, dtype)
    return [out]


def _select_n(w, eqn, ins):
    """``select_n(pred, a, b)`` as ``KSEL(pred, b, a)``, or the known case when ``pred`` is a literal."""
    pred, *cases = ins
    if len(cases) != 2:
        raise UnsupportedPrimitive("select_n with more than two cases")
    dtype = _dtype(eqn)
    select = "KSEL" if np.dtype(dtype) == np.float64 else "KSELL"
    arrays = np.broadcast_arrays(_array(pred), *[_array(c) for c in cases])
    out = np.empty(arrays[0].shape, dtype=object)
    for idx in np.ndindex(out.shape):
        c, a, b = (x[idx] for x in arrays)
        known = _value(c)
        out[idx] = (b if known else a) if known is not None else w.new(f"{select}({c}, {b}, {a})", dtype)
    return [out]


def _clamp(w, eqn, ins):
    return [_elementwise(w, lambda lo, x, hi: f"KMIN(KMAX({x}, {lo}), {hi})", _dtype(eqn), *ins)]


def _convert_element_type(w, eqn, ins):
    new_dtype = eqn.params["new_dtype"]
    ctype, src = _ctype(new_dtype), _ctype(eqn.invars[0].aval.dtype)
    if ctype == src:
        return ins
    macro = {"KB": "B", "KL": "L", "KD": "D"}
    return [_elementwise(w, lambda a: f"K{macro[src]}2{macro[ctype]}({a})", new_dtype, *ins)]


# --- rearrangements: they only move names and emit nothing ----------------------------------------------------


def _slice(w, eqn, ins):
    p = eqn.params
    strides = p["strides"] or (1,) * ins[0].ndim
    return [ins[0][tuple(slice(a, b, s) for a, b, s in zip(p["start_indices"], p["limit_indices"], strides))]]


def _broadcast_in_dim(w, eqn, ins):
    x, shape, dims = ins[0], tuple(eqn.params["shape"]), tuple(eqn.params["broadcast_dimensions"])
    expanded = x.reshape([x.shape[dims.index(d)] if d in dims else 1 for d in range(len(shape))])
    return [np.broadcast_to(expanded, shape).copy()]


def _split(w, eqn, ins):
    cuts = np.cumsum(eqn.params["sizes"])[:-1]
    return list(np.split(ins[0], cuts, axis=eqn.params["axis"]))


def _iota(w, eqn, ins):
    p = eqn.params
    idx = np.indices(tuple(p["shape"]))[p["dimension"]]
    return [np.vectorize(lambda v: literal(np.asarray(v, dtype=p["dtype"]).item()), otypes=[object])(idx)]


def _squeeze(w, eqn, ins):
    dims = eqn.params["dimensions"]
    return [np.squeeze(ins[0], axis=tuple(dims)) if dims else ins[0]]


# --- calls, scans and the array-structured primitives of `indexing` --------------------------------------------


def _inner(params):
    for key in ("jaxpr", "call_jaxpr", "fun_jaxpr"):
        if key in params:
            inner = params[key]
            if isinstance(inner, jex_core.ClosedJaxpr):
                return inner.jaxpr, inner.consts
            return inner, ()
    raise UnsupportedPrimitive("a call primitive without a jaxpr")


def _call(w, eqn, ins):
    """A nested ``jit`` or custom-derivative call, inlined (its primal jaxpr)."""
    inner, consts = _inner(eqn.params)
    n = len(inner.invars)
    return interpret(w, inner, consts, ins[len(ins) - n :] if eqn.primitive.name == "custom_vjp_call" else ins[:n])


def _reduce(combine: Callable[[str, str], str], w, eqn, ins):
    return [indexing.reduce(w, ins[0], tuple(eqn.params["axes"]), combine, _dtype(eqn))]


def _params(fn: Callable[[list, dict], np.ndarray]) -> Emitter:
    """The emitter of a primitive that emits nothing: one output, ``fn(ins, eqn.params)``."""
    return lambda w, eqn, ins: [fn(ins, eqn.params)]


#: infix operators of C by primitive name (arithmetic and comparisons)
_INFIX = {"add": "+", "add_any": "+", "sub": "-", "mul": "*", "div": "/"}
_COMPARISONS = {"gt": ">", "lt": "<", "ge": ">=", "le": "<=", "eq": "==", "ne": "!="}
_INFIX |= _COMPARISONS
#: libm functions of one and of two arguments by primitive name
_LIBM1 = {n: n for n in ("sin", "cos", "tan", "acos", "atan", "sinh", "cosh", "tanh", "exp", "log", "log1p")}
_LIBM1 |= {n: n for n in ("expm1", "sqrt", "cbrt", "floor", "ceil")} | {"abs": "fabs"}
_LIBM2 = {"pow": "pow", "atan2": "atan2", "nextafter": "nextafter", "rem": "fmod"}

EMITTERS: dict[str, Emitter] = {
    **{name: functools.partial(_infix, op) for name, op in _INFIX.items()},
    **{name: functools.partial(_call1, fn) for name, fn in _LIBM1.items()},
    **{name: functools.partial(_call2, fn) for name, fn in _LIBM2.items()},
    "max": functools.partial(_macro2, "KMAX"),
    "min": functools.partial(_macro2, "KMIN"),
    "neg": functools.partial(_unary, lambda a: f"-{a}"),
    # XLA's decomposition of asin (chlo.asin), not libm's: the same rounding
    "asin": functools.partial(_unary, lambda a: f"2.0 * KF2(atan2, {a}, 1.0 + KF1(sqrt, (1.0 - {a}) * (1.0 + {a})))"),
    "square": functools.partial(_unary, lambda a: f"{a} * {a}"),
    "rsqrt": functools.partial(_unary, lambda a: f"1.0 / KF1(sqrt, {a})"),
    "sign": functools.partial(_unary, lambda a: f"KSIGN({a})"),
    "not": functools.partial(_unary, lambda a: f"KNOT({a})"),
    "is_finite": functools.partial(_unary, lambda a: f"KISFINITE({a})"),
    "logistic": functools.partial(_unary, lambda a: f"1.0 / (1.0 + KF1(exp, -{a}))"),
    "and": functools.partial(_logic, "KAND", "&"),
    "or": functools.partial(_logic, "KOR", "|"),
    "integer_pow": _integer_pow,
    "select_n": _select_n,
    "clamp": _clamp,
    "convert_element_type": _convert_element_type,
    **dict.fromkeys(("stop_gradient", "copy", "copy_p", "optimization_barrier", "reduce_precision"), lambda w, e, i: i),
    "slice": _slice,
    "squeeze": _squeeze,
    "expand_dims": _params(lambda ins, p: np.expand_dims(ins[0], tuple(p["dimensions"]))),
    "reshape": _params(lambda ins, p: ins[0].reshape(p["new_sizes"])),
    "broadcast_in_dim": _broadcast_in_dim,
    "transpose": _params(lambda ins, p: np.transpose(ins[0], p["permutation"])),
    "concatenate": _params(lambda ins, p: np.concatenate(ins, axis=p["dimension"])),
    "stack": _params(lambda ins, p: np.stack(ins, axis=p["axis"])),
    "split": _split,
    "rev": _params(lambda ins, p: np.flip(ins[0], axis=tuple(p["dimensions"]))),
    "iota": _iota,
    **dict.fromkeys(
        ("jit", "pjit", "closed_call", "core_call", "remat", "checkpoint", "custom_jvp_call", "custom_vjp_call"), _call
    ),
    "scan": lambda w, eqn, ins: indexing.scan(w, eqn, ins, interpret),
    "argmax": lambda w, eqn, ins: [indexing.argmax(w, ins[0], tuple(eqn.params["axes"]), eqn.params["index_dtype"])],
    "dynamic_slice": lambda w, eqn, ins: [
        indexing.dynamic_slice(w, ins[0], ins[1:], tuple(eqn.params["slice_sizes"]), _dtype(eqn))
    ],
    "dynamic_update_slice": lambda w, eqn, ins: [
        indexing.dynamic_update_slice(w, ins[0], ins[1], ins[2:], _dtype(eqn))
    ],
    "dot_general": lambda w, eqn, ins: [indexing.dot_general(w, ins[0], ins[1], eqn.params, _dtype(eqn))],
    "reduce_sum": functools.partial(_reduce, lambda a, b: f"{a} + {b}"),
    "reduce_max": functools.partial(_reduce, lambda a, b: f"KMAX({a}, {b})"),
    "reduce_min": functools.partial(_reduce, lambda a, b: f"KMIN({a}, {b})"),
}
"""The emitter of every primitive the generator translates, by primitive name."""


def emit_equation(w: _Writer, eqn, ins: list) -> list:
    """The C of one jaxpr equation through its entry in [`EMITTERS`][jaxcrank.numerics.kernel.primitives.EMITTERS].

    Raises:
        UnsupportedPrimitive: the primitive has no entry (its name in the message).
    """
    emit = EMITTERS.get(eqn.primitive.name)
    if emit is None:
        raise UnsupportedPrimitive(
            f"primitive {eqn.primitive.name!r} has no scalar C translation in jaxcrank.numerics.kernel.primitives"
        )
    return emit(w, eqn, ins)


def _read(env: dict, atom) -> np.ndarray:
    if isinstance(atom, jex_core.Literal):
        return _constant(atom.val)
    return env[atom]


def _constant(value) -> np.ndarray:
    val = np.asarray(value)
    if val.ndim == 0:
        return _array(literal(val.item()))
    return np.vectorize(literal, otypes=[object])(val)


def interpret(w: _Writer, jaxpr, consts, args) -> list[np.ndarray]:
    """Write ``jaxpr`` applied to ``args`` (arrays of C expressions) with ``w``; the names of its
    outputs' elements. Each equation's statements are preceded by a comment naming the Python
    source it was traced from, when that changes ([`.provenance`][jaxcrank.numerics.kernel.provenance])."""
    env: dict = {}
    for var, c in zip(jaxpr.constvars, consts):
        env[var] = _constant(c)
    for var, a in zip(jaxpr.invars, args):
        env[var] = a
    for eqn in jaxpr.eqns:
        ins = [_read(env, v) for v in eqn.invars]
        with provenance.entering(w, eqn):
            outs = emit_equation(w, eqn, ins)
        for var, val in zip(eqn.outvars, outs):
            env[var] = val
    return [_read(env, v) for v in jaxpr.outvars]
