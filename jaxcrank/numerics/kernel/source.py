"""The kernel's C source for one mechanism structure: generated model functions plus
the adaptive Tsitouras 5(4) loop of ``solver.c``.

A *structure* ([`Structure`][jaxcrank.numerics.kernel.source.Structure]) is what changes the traced code: the contact
and
friction laws, which joints are ideal, and the layout of the parameter pytree. Every
float parameter is a run-time input (a row of the ``params`` matrix, in
[`parameter_vector`][jaxcrank.numerics.kernel.source.parameter_vector] order), so one compiled library serves every
design of a
structure, whatever the swept parameters.

Three functions are generated from JAX ([`.codegen`][jaxcrank.numerics.kernel.codegen]):

- ``jk_field(p, t, y, rate)``: [`jaxcrank.physics.model.vector_field`][jaxcrank.physics.dynamics.vector_field];
- ``jk_frame(p, t, y, rate, peak, rms)``: the same rate plus the per-step signals of
  the peak metrics and the RMS metrics ([`jaxcrank.numerics.tracking`][]'s
  definitions, from [`jaxcrank.physics.model.evaluate`][jaxcrank.physics.frame.evaluate]);
- ``jk_interp(t0, t1, y0, k, t, y)``: diffrax's Tsit5 dense output.

The tableau and the controller's constants are read from diffrax's objects here, so
the loop steps with the numbers the JAX path uses. A name map at the top of the source
([`.namemap`][jaxcrank.numerics.kernel.namemap]) names every parameter by its path in the
mechanism's pytree, and the generated functions index the parameters by those names.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from importlib import resources
from typing import Any, NamedTuple

import diffrax
import jax
import numpy as np

from ...physics import model, signals
from ...physics.linkage import AbstractMechanism as Mechanism
from ...physics.parameters import set_parameters
from . import codegen, namemap


class Structure(NamedTuple):
    """What the generated code depends on (hashable).

    Attributes:
        treedef: the mechanism's pytree structure (laws, names,
            ideal flags and the pytree layout remain).
        constants: the values of every float parameter, baked into the code as
            literals (the compiler folds them), with ``names`` the run-time inputs;
            or ``None``: every float parameter is a run-time input
            ([`parameter_vector`][jaxcrank.numerics.kernel.source.parameter_vector] order).
        names: the parameters ([`jaxcrank.physics.parameters.set_parameter`][] names)
            that are run-time inputs when ``constants`` is given.
    """

    treedef: Any
    constants: tuple[float, ...] | None = None
    names: tuple[str, ...] = ()


def skeleton(st: Structure) -> Mechanism:
    """The mechanism of ``st`` with every float parameter zero (for its names and layout only)."""
    return jax.tree_util.tree_unflatten(st.treedef, [0.0] * st.treedef.num_leaves)


def structure(mech: Mechanism, names: Sequence[str] | None = None) -> Structure:
    """The [`Structure`][jaxcrank.numerics.kernel.source.Structure] of ``mech``: every float parameter a run-time input
    (``names`` None), or ``mech``'s values baked in and only ``names`` as inputs
    (a sweep over ``names``: per-design code for the parameters that do not vary)."""
    leaves, treedef = jax.tree_util.tree_flatten(mech)
    if names is None:
        return Structure(treedef)
    return Structure(treedef, tuple(float(v) for v in parameter_vector(mech)), tuple(names))


def parameter_vector(mech: Mechanism) -> np.ndarray:
    """The float parameters of ``mech`` in the order the kernel reads them (SI), shape (P,).

    Raises:
        TypeError: for a leaf that is not a real scalar (the kernel has scalar parameters only).
    """
    leaves = jax.tree_util.tree_leaves(mech)
    out = np.empty(len(leaves))
    for i, leaf in enumerate(leaves):
        arr = np.asarray(leaf)
        if arr.shape != () or not np.issubdtype(arr.dtype, np.number):
            raise TypeError(f"mechanism leaf {i} is not a real scalar ({leaf!r}); the kernel needs scalar parameters")
        out[i] = float(arr)
    return out


class Layout(NamedTuple):
    """Sizes of one structure's generated code (all static)."""

    n_params: int
    n_state: int
    n_peak: int
    n_rms: int


def _mechanism(st: Structure, p):
    """The mechanism whose run-time inputs are ``p`` (traced)."""
    treedef = st.treedef
    if st.constants is None:
        return jax.tree_util.tree_unflatten(treedef, [p[i] for i in range(treedef.num_leaves)])
    base = jax.tree_util.tree_unflatten(treedef, list(st.constants))
    return set_parameters(base, list(st.names), [p[i] for i in range(len(st.names))])


class Names(NamedTuple):
    """The names of a structure's outputs (static): its peak metrics, its RMS metrics,
    all its metrics in order, the initial values of the running peaks and its state entries."""

    peak: tuple[str, ...]
    rms: tuple[str, ...]
    metrics: tuple[str, ...]
    peak_init: tuple[float, ...]
    state: tuple[str, ...]


@functools.lru_cache(maxsize=64)
def names(st: Structure) -> Names:
    """The [`Names`][jaxcrank.numerics.kernel.source.Names] of a structure, read off its mechanism under a
    trace (the skeleton's zero parameters are never checked)."""
    n_params = st.treedef.num_leaves if st.constants is None else len(st.names)
    found = []

    def probe(p):
        mech = _mechanism(st, p)
        defs = signals.metric_definitions(mech)
        init = tuple(-np.inf if defs[k].reduction == "max" else 0.0 for k in signals.peak_metrics(mech))
        found.append(
            Names(signals.peak_metrics(mech), signals.rms_metrics(mech), tuple(defs), init, model.state_names(mech))
        )
        return p

    jax.eval_shape(probe, jax.ShapeDtypeStruct((n_params,), np.float64))
    return found[0]


def layout(st: Structure) -> Layout:
    n_params = st.treedef.num_leaves if st.constants is None else len(st.names)
    nm = names(st)
    return Layout(n_params, len(nm.state), len(nm.peak), len(nm.rms))


def parameter_names(st: Structure) -> tuple[str, ...]:
    """The name of each run-time input ``p[i]`` of ``st``'s code: the pytree path of the
    mechanism leaf (``joints.B.pin_radius``) when every parameter is an input, else ``st.names``."""
    return namemap.leaf_paths(skeleton(st)) if st.constants is None else tuple(st.names)


def _groups(st: Structure, state_names: Sequence[str] | None) -> list[namemap.Group]:
    nm = names(st)
    state_names = nm.state if state_names is None else tuple(state_names)
    if len(state_names) != layout(st).n_state:
        raise ValueError(f"{len(state_names)} state names for a state of {layout(st).n_state} entries")
    return [
        namemap.Group(("p",), "P_", parameter_names(st), "the run-time parameters (SI)"),
        namemap.Group(
            ("y", "rate", "y0", "out"), "Y_", state_names, "the scaled state (dimensionless) and its rate (1/s)"
        ),
        namemap.Group(("peak",), "PEAK_", nm.peak, "per-step signals of the peak metrics"),
        namemap.Group(("rms",), "RMS_", nm.rms, "per-step signals of the RMS metrics"),
    ]


def _name_map(st: Structure, state_names: Sequence[str] | None) -> str:
    """The name map of ``st``'s code ([`.namemap`][jaxcrank.numerics.kernel.namemap]), with the
    values baked into it when only some parameters are run-time inputs."""
    baked = () if st.constants is None else tuple(zip(namemap.leaf_paths(skeleton(st)), st.constants))
    return namemap.name_map(_groups(st, state_names), baked)


def _functions(st: Structure, state_names: Sequence[str] | None = None) -> str:
    lay = layout(st)
    names = namemap.index_names(_groups(st, state_names))

    def field(p, t, y):
        return (model.vector_field(t, y, _mechanism(st, p)),)

    def frame(p, t, y):
        mech = _mechanism(st, p)
        f = model.evaluate(mech, t, y)
        return f.state_rate, signals.peak_values(mech, f), signals.rms_signals(mech, f)

    def interp(t0, t1, y0, k, t):
        return (diffrax.Tsit5.interpolation_cls(t0=t0, t1=t1, y0=y0, y1=y0, k=k).evaluate(t),)

    pin = [("p", (lay.n_params,)), ("t", ()), ("y", (lay.n_state,))]
    src_field, _ = codegen.emit_function("jk_field", field, pin, ["rate"], names)
    src_frame, shapes = codegen.emit_function("jk_frame", frame, pin, ["rate", "peak", "rms"], names)
    n = lay.n_state
    src_interp, _ = codegen.emit_function(
        "jk_interp", interp, [("t0", ()), ("t1", ()), ("y0", (n,)), ("k", (7, n)), ("t", ())], ["out"], names
    )
    assert shapes == [(n,), (lay.n_peak,), (lay.n_rms,)], shapes
    vector = "\n".join(["#ifndef __CUDACC__", VECTOR, src_field, src_frame, "#endif"])
    return "\n".join([SCALAR, src_field, src_frame, src_interp, vector])


def _array(name: str, values) -> str:
    vals = ", ".join(codegen.literal(float(v)) for v in np.ravel(values))
    return f"static KCONST double {name}[{np.size(values)}] = {{{vals}}};"


def _constants(st: Structure) -> str:
    lay = layout(st)
    tab = diffrax.Tsit5.tableau
    a = np.zeros((7, 7))
    for i, row in enumerate(tab.a_lower):
        a[i + 1, : len(row)] = row
    c = np.concatenate([[0.0], tab.c])
    ctrl = diffrax.PIDController(rtol=1.0, atol=1.0, pcoeff=0.0, icoeff=1.0)
    error_order = diffrax.Tsit5().error_order(diffrax.ODETerm(lambda t, y, a: y))
    peak_init = np.array(names(st).peak_init)
    return "\n".join(
        [
            f"#define NP {lay.n_params}",
            f"#define NY {lay.n_state}",
            f"#define NPEAK {lay.n_peak}",
            f"#define NRMS {lay.n_rms}",
            _array("TAB_A", a),
            _array("TAB_C", c),
            _array("TAB_B_ERR", tab.b_error),
            _array("PEAK_INIT", peak_init),
            f"#define SAFETY {codegen.literal(float(ctrl.safety))}",
            f"#define FACTOR_MIN {codegen.literal(float(ctrl.factormin))}",
            f"#define FACTOR_MAX {codegen.literal(float(ctrl.factormax))}",
            f"#define ERROR_EXPONENT {codegen.literal(1.0 / error_order)}",
            f"#define NORM_SQRT_N {codegen.literal(float(np.sqrt(lay.n_state)))}",
        ]
    )


PRELUDE = """\
/* jaxcrank kernel: generated; do not edit */
#ifdef __CUDACC__
#define KFN static __device__
#define KCONST __constant__ const
#define KRESTRICT __restrict__
#else
#define _GNU_SOURCE
#include <math.h>
#define KFN static inline
#define KCONST const
#define KRESTRICT restrict
#endif
#define KINF (__builtin_inf())
#define KNAN (__builtin_nan(""))
KFN double kmax(double a, double b) { return (a != a || b != b) ? a + b : (a > b ? a : b); }
KFN double kmin(double a, double b) { return (a != a || b != b) ? a + b : (a < b ? a : b); }
KFN double ksign(double a) { return a > 0.0 ? 1.0 : (a < 0.0 ? -1.0 : a); }
KFN int kisfinite(double a) { return a - a == 0.0; }
"""

#: the generated code's vocabulary, for scalar code (C and CUDA)
SCALAR = """\
#define KD double
#define KB int
#define KL long
#define KNAME(n) n
#define KV(x) (x)
#define KVL(x) (x)
#define KSEL(c, b, a) ((c) ? (b) : (a))
#define KSELL(c, b, a) ((c) ? (b) : (a))
#define KAND(a, b) ((a) && (b))
#define KOR(a, b) ((a) || (b))
#define KNOT(a) (!(a))
#define KTRUE 1
#define KFALSE 0
#define KB2D(a) ((double)(a))
#define KL2D(a) ((double)(a))
#define KD2B(a) ((a) != 0.0)
#define KL2B(a) ((a) != 0)
#define KD2L(a) ((long)(a))
#define KB2L(a) ((long)(a))
#define KF1(f, x) f(x)
#define KF2(f, a, b) f(a, b)
#define KSINCOS(x, s, c) s = sin(x), c = cos(x)
#define KMAX(a, b) kmax(a, b)
#define KMIN(a, b) kmin(a, b)
#define KSIGN(a) ksign(a)
#define KISFINITE(a) kisfinite(a)
"""

#: the same vocabulary on GCC vectors of W lanes, one design per lane (CPU only): the
#: same IEEE operations lane by lane, libm called per lane, so a lane's numbers equal
#: the scalar code's bit for bit
VECTOR = """\
#undef KD
#undef KB
#undef KL
#undef KNAME
#undef KV
#undef KVL
#undef KSEL
#undef KSELL
#undef KAND
#undef KOR
#undef KNOT
#undef KTRUE
#undef KFALSE
#undef KB2D
#undef KL2D
#undef KD2B
#undef KL2B
#undef KD2L
#undef KB2L
#undef KF1
#undef KF2
#undef KSINCOS
#undef KMAX
#undef KMIN
#undef KSIGN
#undef KISFINITE
#define W 4
typedef double vd __attribute__((vector_size(8 * W)));
typedef long vl __attribute__((vector_size(8 * W)));
static const vd KVZ = {-0.0, -0.0, -0.0, -0.0};
#define KD vd
#define KB vl
#define KL vl
#define KNAME(n) n##_v
#define KV(x) (KVZ + (x))
#define KVL(x) (KVLZ + (x))
static const vl KVLZ = {0, 0, 0, 0};
static inline vd kv_sel(vl c, vd b, vd a) { return (vd)(((vl)b & c) | ((vl)a & ~c)); }
static inline vd kv_max(vd a, vd b) { return kv_sel((a != a) | (b != b), a + b, kv_sel(a > b, a, b)); }
static inline vd kv_min(vd a, vd b) { return kv_sel((a != a) | (b != b), a + b, kv_sel(a < b, a, b)); }
#define KSEL(c, b, a) kv_sel((c), KV(b), KV(a))
#define KSELL(c, b, a) (((c) & (b)) | (~(c) & (a)))
#define KAND(a, b) ((a) & (b))
#define KOR(a, b) ((a) | (b))
#define KNOT(a) (~(a))
#define KTRUE (-1L)
#define KFALSE 0L
#define KB2D(a) (-__builtin_convertvector(KVL(a), vd))
#define KL2D(a) __builtin_convertvector(KVL(a), vd)
#define KD2B(a) ((a) != 0.0)
#define KL2B(a) ((a) != 0)
#define KD2L(a) __builtin_convertvector(KV(a), vl)
#define KB2L(a) (-(a))
#define KF1(f, x) ({ vd _x = KV(x), _r; for (int _l = 0; _l < W; _l++) _r[_l] = f(_x[_l]); _r; })
#define KF2(f, a, b) ({ vd _a = KV(a), _b = KV(b), _r; for (int _l = 0; _l < W; _l++) _r[_l] = f(_a[_l], _b[_l]); _r; })
#define KSINCOS(x, s, c) for (int _l = 0; _l < W; _l++) sincos((x)[_l], &(s)[_l], &(c)[_l])
#define KMAX(a, b) kv_max(KV(a), KV(b))
#define KMIN(a, b) kv_min(KV(a), KV(b))
#define KSIGN(a) kv_sel((a) > 0.0, KV(1.0), kv_sel((a) < 0.0, KV(-1.0), KV(a)))
#define KISFINITE(a) (((a) - (a)) == 0.0)
"""


FIELD_BATCH = """
#ifndef __CUDACC__
int jk_field_batch(long n, const double *params, const double *t, const double *y, double *rate) {
  for (long d = 0; d < n; d++) jk_field(params + NP * d, t[d], y + NY * d, rate + NY * d);
  return 0;
}
#endif
"""


def field_source(st: Structure, state_names: Sequence[str] | None = None) -> str:
    """A C source with the generated vector field alone and its batch entry point
    ``jk_field_batch`` (what the field's tests compile: shorter than the whole kernel);
    ``state_names`` as for [`kernel_source`][jaxcrank.numerics.kernel.source.kernel_source]."""
    lay = layout(st)
    pin = [("p", (lay.n_params,)), ("t", ()), ("y", (lay.n_state,))]
    field, _ = codegen.emit_function(
        "jk_field",
        lambda p, t, y: (model.vector_field(t, y, _mechanism(st, p)),),
        pin,
        ["rate"],
        namemap.index_names(_groups(st, state_names)),
    )
    sizes = f"#define NP {lay.n_params}\n#define NY {lay.n_state}"
    return "\n".join(
        [
            PRELUDE,
            sizes,
            _name_map(st, state_names),
            SCALAR,
            field,
            FIELD_BATCH,
            "#ifndef __CUDACC__",
            VECTOR,
            field,
            VECTOR_BATCH,
            "#endif",
        ]
    )


VECTOR_BATCH = """
int jk_field_batch_v(long n, const double *params, const double *t, const double *y, double *rate) {
  for (long d0 = 0; d0 < n; d0 += W) {
    vd p[NP > 0 ? NP : 1], tt, yy[NY], rr[NY];
    for (int l = 0; l < W; l++) {
      long d = d0 + l < n ? d0 + l : n - 1;
      for (int i = 0; i < NP; i++) p[i][l] = params[NP * d + i];
      for (int i = 0; i < NY; i++) yy[i][l] = y[NY * d + i];
      tt[l] = t[d];
    }
    jk_field_v(p, tt, yy, rr);
    for (int l = 0; l < W && d0 + l < n; l++)
      for (int i = 0; i < NY; i++) rate[NY * (d0 + l) + i] = rr[i][l];
  }
  return 0;
}
"""


@functools.lru_cache(maxsize=16)
def kernel_source(st: Structure, state_names: tuple[str, ...] | None = None) -> str:
    """The complete C source (prelude, constants, name map, generated functions, ``solver.c``).

    Args:
        st: the mechanism structure.
        state_names: a name per state entry, for the name map (``y[Y_name]`` in the code);
            None: state entries indexed by number.

    Raises:
        ValueError: ``state_names`` does not have one name per state entry.
    """
    loop = resources.files(__package__).joinpath("solver.c").read_text()
    return "\n".join(
        [
            PRELUDE,
            _constants(st),
            _name_map(st, state_names),
            _functions(st, state_names),
            loop,
            FIELD_BATCH,
            "#ifndef __CUDACC__",
            VECTOR_BATCH,
            "#endif",
        ]
    )
