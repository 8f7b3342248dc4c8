"""Evaluating a function with every shared value computed once.

XLA's CPU compiler fuses a chain of cheap elementwise operations (additions, products,
selects, even sines and cosines) into every fusion that uses its result, and recomputes
the chain in each of them: only a few operations (divisions, square roots, reductions)
are computed once and stored. The equations of motion are long chains of scalar
operations (the kinematics, the joint laws) whose results many outputs share (every
generalized acceleration needs every contact force), so a vector-field call computed
much of its work several times over.

[`compute_once`][jaxcrank.physics.fusion.compute_once] evaluates a function through its
jaxpr with every floating-point value that two or more operations use passed through
[`materialize`][jaxcrank.physics.fusion.materialize], which XLA keeps as a reduction: each
shared value is computed once and read by its users. The values are the same (a sum with
negative zeros); gradients and batching go through unchanged.
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax
from jax.extend.core import Literal

from .._private import equation_context

#: operations that only move or reshape values (cheap to repeat; their inputs are what
#: is worth sharing)
_MOVES = frozenset(
    {
        "broadcast_in_dim",
        "concatenate",
        "convert_element_type",
        "copy",
        "expand_dims",
        "reshape",
        "slice",
        "squeeze",
        "stop_gradient",
    }
)
#: call primitives whose body is evaluated inline (custom-derivative calls keep their rules)
_INLINE = frozenset({"pjit", "jit", "closed_call", "core_call"})
#: how many entries the sum of a materialized value has: XLA rewrites sums of up to
#: eight entries as additions, which it would fuse (and repeat) again
_SUM_ENTRIES = 9


def materialize(x: jax.Array) -> jax.Array:
    """``x`` unchanged (a sum of x and negative zeros), as an operation XLA computes once
    and stores instead of repeating it in every fusion that reads it."""
    x = jnp.asarray(x)
    zeros = lax.broadcast(jnp.asarray(-0.0, dtype=x.dtype), (_SUM_ENTRIES - 1, *x.shape))
    return lax.reduce(lax.concatenate([lax.expand_dims(x, (0,)), zeros], 0), np.zeros((), x.dtype), lax.add, (0,))


def _shared(v) -> bool:
    return jnp.issubdtype(v.aval.dtype, jnp.inexact)


#: what repeating one operation costs, in additions (trigonometric functions are cheap to
#: XLA's fusion, not to the processor); operations not listed cost one
_COST = {"sin": 12, "cos": 12, "tan": 16}
#: a shared value is stored once its repeated chain would cost more than this
_THRESHOLD = 2


def _op_cost(eqn) -> int:
    """What repeating ``eqn`` costs (a call: its body's operations)."""
    name = eqn.primitive.name
    if name in _MOVES:
        return 0
    for key in ("call_jaxpr", "jaxpr", "fun_jaxpr"):
        inner = eqn.params.get(key)
        if inner is not None and hasattr(inner, "eqns"):
            return sum(_op_cost(e) for e in inner.eqns)
        if inner is not None and hasattr(inner, "jaxpr"):
            return sum(_op_cost(e) for e in inner.jaxpr.eqns)
    return _COST.get(name, 1)


def _evaluate(jaxpr, consts, args) -> list:
    """Evaluate ``jaxpr`` on ``args``, materializing the floating-point values two or more
    of its equations (or its outputs) use, where recomputing them would cost more than
    storing them."""
    users: dict = {}
    for i, eqn in enumerate(jaxpr.eqns):
        for v in eqn.invars:
            if not isinstance(v, Literal):
                users.setdefault(v, set()).add(i)
    for v in jaxpr.outvars:
        if not isinstance(v, Literal):
            users.setdefault(v, set()).add(-1)
    env = dict(zip(jaxpr.constvars, consts))
    env.update(zip(jaxpr.invars, args))
    cost: dict = {}  # per variable: the operations a fusion that reads it repeats

    def read(v):
        return v.val if isinstance(v, Literal) else env[v]

    for eqn in jaxpr.eqns:
        ins = [read(v) for v in eqn.invars]
        name = eqn.primitive.name
        with equation_context(eqn.source_info):  # the new equations keep the model's source lines
            if name in _INLINE and "jaxpr" in eqn.params:
                inner = eqn.params["jaxpr"]
                outs = _evaluate(inner.jaxpr, inner.consts, ins)
            else:
                outs = eqn.primitive.bind(*ins, **eqn.primitive.get_bind_params(eqn.params))
                outs = outs if eqn.primitive.multiple_results else [outs]
            chain = _op_cost(eqn) + sum(cost.get(v, 0) for v in eqn.invars if not isinstance(v, Literal))
            for v, out in zip(eqn.outvars, outs):
                cost[v] = chain
                if chain > _THRESHOLD and name not in _MOVES and len(users.get(v, ())) > 1 and _shared(v):
                    out = materialize(out)
                    cost[v] = 0
                env[v] = out
    return [read(v) for v in jaxpr.outvars]


def compute_once(fn: Callable, *args):
    """``fn(*args)``, with every floating-point value that two or more of its operations
    use computed once in XLA's program (see the module docstring). ``args`` are pytrees
    of arrays; what ``fn`` closes over (a mechanism's parameters, traced or not) stays as
    it is, so numbers known at trace time stay known."""
    flat, treedef = jax.tree_util.tree_flatten(args)
    closed, shape = jax.make_jaxpr(lambda *xs: fn(*jax.tree_util.tree_unflatten(treedef, xs)), return_shape=True)(*flat)
    out = _evaluate(closed.jaxpr, closed.consts, flat)
    return jax.tree_util.tree_unflatten(jax.tree_util.tree_structure(shape), out)
