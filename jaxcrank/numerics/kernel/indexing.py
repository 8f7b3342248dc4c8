"""Array-structured primitives for [`jaxcrank.numerics.kernel.codegen`][]: dot
products and reductions written out as sums, scans unrolled, and indexing by run-time
values (``argmax``, dynamic slices) written as selects over every position. Emits the
same macro vocabulary as the generator (``KSEL``, ``KAND``, ...)."""

from __future__ import annotations

import itertools
from collections.abc import Callable

import numpy as np

from .text import UnsupportedPrimitive, _array, _sum, _value, _Writer, literal


def _select(dtype) -> str:
    """The select macro of a dtype: ``KSEL`` for floats, ``KSELL`` for integers and booleans."""
    return "KSEL" if np.dtype(dtype) == np.float64 else "KSELL"


def _all(conds) -> str:
    out = conds[0]
    for c in conds[1:]:
        out = f"KAND({out}, {c})"
    return out


def dot_general(w: _Writer, lhs: np.ndarray, rhs: np.ndarray, params, dtype) -> np.ndarray:
    (lc, rc), (lb, rb) = params["dimension_numbers"]
    lf = [d for d in range(lhs.ndim) if d not in lc and d not in lb]
    rf = [d for d in range(rhs.ndim) if d not in rc and d not in rb]
    lt = np.transpose(lhs, list(lb) + lf + list(lc))
    rt = np.transpose(rhs, list(rb) + rf + list(rc))
    nb, k = len(lb), int(np.prod([lhs.shape[d] for d in lc], dtype=int))
    batch = lt.shape[:nb]
    lt = lt.reshape(batch + tuple(lhs.shape[d] for d in lf) + (k,))
    rt = rt.reshape(batch + tuple(rhs.shape[d] for d in rf) + (k,))
    lfree, rfree = lt.shape[nb:-1], rt.shape[nb:-1]
    out = np.empty(batch + lfree + rfree, dtype=object)
    for b in np.ndindex(batch):
        for i in np.ndindex(lfree):
            for j in np.ndindex(rfree):
                prods = [w.new(f"{lt[b + i + (m,)]} * {rt[b + j + (m,)]}", dtype) for m in range(k)]
                out[b + i + j] = _sum(w, prods, dtype)
    return out


def reduce(w: _Writer, x: np.ndarray, axes, combine: Callable[[str, str], str], dtype) -> np.ndarray:
    keep = [d for d in range(x.ndim) if d not in axes]
    moved = np.transpose(x, keep + list(axes))
    shape = moved.shape[: len(keep)]
    flat = moved.reshape(shape + (-1,))
    out = np.empty(shape, dtype=object)
    for idx in np.ndindex(shape):
        acc = flat[idx + (0,)]
        for m in range(1, flat.shape[-1]):
            acc = w.new(combine(acc, flat[idx + (m,)]), dtype)
        out[idx] = acc
    return out


def scan(w: _Writer, eqn, ins, run: Callable) -> list[np.ndarray]:
    """A scan of static length, unrolled (``run``: the generator's jaxpr interpreter)."""
    p = eqn.params
    if p["reverse"]:
        raise UnsupportedPrimitive("scan with reverse=True")
    body, consts = p["jaxpr"].jaxpr, p["jaxpr"].consts
    nc, nk = p["num_consts"], p["num_carry"]
    fixed, carry, xs = ins[:nc], list(ins[nc : nc + nk]), ins[nc + nk :]
    ys = []
    for i in range(p["length"]):
        out = run(w, body, consts, list(fixed) + carry + [x[i] for x in xs])
        carry, y = out[:nk], out[nk:]
        ys.append(y)
    stacked = [np.stack([y[j] for y in ys]) for j in range(len(eqn.outvars) - nk)]
    return carry + stacked


def argmax(w: _Writer, x: np.ndarray, axes, index_dtype) -> np.ndarray:
    (axis,) = axes
    moved = np.moveaxis(x, axis, -1)
    out = np.empty(moved.shape[:-1], dtype=object)
    for idx in np.ndindex(out.shape):
        best, where = moved[idx + (0,)], literal(np.asarray(0, dtype=index_dtype).item())
        for m in range(1, moved.shape[-1]):
            v = moved[idx + (m,)]
            better = w.new(f"KOR({v} > {best}, KAND({v} != {v}, {best} == {best}))", np.bool_)
            best = w.new(f"KSEL({better}, {v}, {best})", np.float64)
            where = w.new(f"KSELL({better}, {m}L, {where})", index_dtype)
        out[idx] = where
    return out


def _starts(w: _Writer, operand: np.ndarray, indices, sizes) -> list:
    """Start indices clamped into range as XLA does: Python ints when known, else C expressions."""
    out = []
    for d, idx in enumerate(indices):
        hi = operand.shape[d] - sizes[d]
        i = _array(idx).item()
        v = _value(i)
        if v is not None:
            out.append(min(max(int(v), 0), hi))
        else:
            out.append(w.new(f"KSELL({i} < 0L, 0L, KSELL({i} > {hi}L, {hi}L, {i}))", np.int64))
    return out


def dynamic_slice(w: _Writer, operand: np.ndarray, indices, sizes, dtype) -> np.ndarray:
    starts = _starts(w, operand, indices, sizes)
    out = np.empty(sizes, dtype=object)
    for idx in np.ndindex(*sizes):
        options = [[]]
        for d, s in enumerate(starts):
            if isinstance(s, int):
                options = [o + [(s + idx[d], None)] for o in options]
            else:
                options = [o + [(k + idx[d], (s, k))] for o in options for k in range(operand.shape[d] - sizes[d] + 1)]
        expr = None
        for opt in reversed(options):
            value = operand[tuple(i for i, _ in opt)]
            conds = [f"{s} == {k}L" for _, c in opt if c is not None for s, k in [c]]
            expr = value if expr is None else w.new(f"{_select(dtype)}({_all(conds)}, {value}, {expr})", dtype)
        out[idx] = expr
    return out


def dynamic_update_slice(w: _Writer, operand: np.ndarray, update: np.ndarray, indices, dtype) -> np.ndarray:
    starts = _starts(w, operand, indices, update.shape)
    out = operand.copy()
    for idx in np.ndindex(operand.shape):
        conds, inside, src = [], True, []
        for d, s in enumerate(starts):
            if isinstance(s, int):
                k = idx[d] - s
                inside &= 0 <= k < update.shape[d]
                src.append([(k, None)])
            else:
                src.append(
                    [
                        (idx[d] - k, k)
                        for k in range(operand.shape[d] - update.shape[d] + 1)
                        if 0 <= idx[d] - k < update.shape[d]
                    ]
                )
                conds.append(s)
        if not inside or any(not opts for opts in src):
            continue
        expr = operand[idx]
        for combo in itertools.product(*src):
            value = update[tuple(k for k, _ in combo)]
            terms = [f"{starts[d]} == {c}L" for d, (_, c) in enumerate(combo) if c is not None]
            expr = value if not terms else w.new(f"{_select(dtype)}({_all(terms)}, {value}, {expr})", dtype)
        out[idx] = expr
    return out
