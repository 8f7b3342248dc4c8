"""The kernel's code generator (jaxcrank.numerics.kernel.codegen, .primitives, .namemap,
.provenance): one emitter per primitive in one table, and it covers the paper model; an
unsupported primitive is named; the name map gives every parameter its pytree path and
only relabels indices; comments name the model source each block came from."""

import re
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.extend import core as jex_core

import jaxcrank as jc
from jaxcrank.numerics.kernel import build, codegen, engine, namemap, primitives, provenance, source
from jaxcrank.physics import model

ROOT = Path(__file__).resolve().parents[1]


def _primitive_names(jaxpr) -> set[str]:
    """Every primitive of ``jaxpr`` and of the jaxprs nested in its equations (calls, scan bodies)."""
    names = set()
    for eqn in jaxpr.eqns:
        names.add(eqn.primitive.name)
        for value in eqn.params.values():
            for sub in value if isinstance(value, tuple) else (value,):
                if isinstance(sub, jex_core.ClosedJaxpr):
                    names |= _primitive_names(sub.jaxpr)
                elif isinstance(sub, jex_core.Jaxpr):
                    names |= _primitive_names(sub)
    return names


def test_every_primitive_of_the_paper_model_has_an_emitter():
    """The jaxprs the kernel is generated from (vector field, per-step metric signals,
    diffrax's dense output) use only primitives with an entry in the table."""
    st = source.structure(jc.paper())
    lay = source.layout(st)
    p, y = jnp.zeros(lay.n_params), jnp.zeros(lay.n_state)
    field = jax.make_jaxpr(lambda p, t, y: model.vector_field(t, y, source._mechanism(st, p)))(p, 0.0, y)
    frame = jax.make_jaxpr(lambda p, t, y: model.evaluate(source._mechanism(st, p), t, y))(p, 0.0, y)
    used = _primitive_names(field.jaxpr) | _primitive_names(frame.jaxpr)
    assert {"mul", "sin", "select_n", "jit"} <= used  # the walk sees the model's primitives
    assert used <= set(codegen.EMITTERS), sorted(used - set(codegen.EMITTERS))
    assert all(callable(emit) for emit in codegen.EMITTERS.values())


@pytest.mark.parametrize(
    ("fn", "name"),
    [(lambda x: (jax.lax.erf(x),), "erf"), (lambda x: (jnp.cumsum(x),), "cumsum"), (lambda x: (jnp.sort(x),), "sort")],
)
def test_an_unsupported_primitive_is_named(fn, name):
    with pytest.raises(codegen.UnsupportedPrimitive, match=rf"'{name}'"):
        codegen.emit_function("f", fn, [("x", (3,))], ["out"])
    assert name not in codegen.EMITTERS


def test_small_function_through_the_table():
    """A function of a few primitives is written as the expected statements: sine and cosine
    of one argument fused, a division by a literal as a product, a product of literals
    computed at generation, stacking and reversing emitting nothing; each block after a
    comment naming its line of this file."""

    def fn(x):
        s = x[0] * 2.0
        a = jnp.sin(s) * jnp.cos(s)
        b = x[1] / 4.0 + 2.0 * 3.0
        return (jnp.stack([a, b])[::-1],)

    text, shapes = codegen.emit_function("f", fn, [("x", (2,))], ["out"])
    assert shapes == [(2,)]
    lines = text.splitlines()
    assert lines[0] == "KFN void KNAME(f)(const KD *KRESTRICT x, KD *KRESTRICT out) {"
    assert [ln for ln in lines[1:] if not ln.startswith("  /*")] == [
        "  const KD v0 = KV(x[0] * 2.0);",
        "  KD v1, v2;",
        "  KSINCOS(v0, v1, v2);",
        "  const KD v3 = KV(v1 * v2);",
        "  const KD v4 = KV(x[1] * 0.25);",
        "  const KD v5 = KV(v4 + 6.0);",
        "  out[0] = KV(v5);",
        "  out[1] = KV(v3);",
        "}",
    ]
    comments = [ln for ln in lines if ln.startswith("  /*")]
    assert len(comments) == 4 and comments[-1] == "  /* outputs */"
    assert all(
        re.fullmatch(r"  /\* test_codegen\.py:\d+ test_small_function_through_the_table\.fn \*/", c)
        for c in comments[:3]
    )


def test_names_only_relabel_indices():
    """With names, ``emit_function`` writes ``p[P_a]`` where it wrote ``p[0]``: the same text
    once each macro is replaced by its index; a wrong count of names is refused."""

    def fn(p, y):
        return (y * p[0] + jnp.sin(p[1]),)

    args = ([("p", (2,)), ("y", (3,))], ["rate"])
    plain, _ = codegen.emit_function("f", fn, *args)
    idents = {"p": ("P_a", "P_b"), "y": ("Y_u", "Y_v", "Y_w"), "rate": ("Y_u", "Y_v", "Y_w")}
    named, _ = codegen.emit_function("f", fn, *args, names=idents)
    assert "p[P_b]" in named and "rate[Y_w]" in named and "p[1]" not in named
    index = {ident: str(i) for group in idents.values() for i, ident in enumerate(group)}
    assert re.sub(r"\b[PY]_[a-z]\b", lambda m: index[m.group(0)], named) == plain
    with pytest.raises(ValueError, match="2 names for the 3 elements of 'y'"):
        codegen.emit_function("f", fn, *args, names={"y": ("a", "b")})


def test_leaf_paths_and_macros_are_generic():
    tree = {"joint": {"radius": 1.0}, "links": [2.0, 3.0], "a-b": 4.0}
    assert namemap.leaf_paths(tree) == ("a-b", "joint.radius", "links.0", "links.1")
    assert namemap.macros("P_", ["joint.radius", "joint_radius", "links.0", "--"]) == (
        "P_joint_radius",
        "P_joint_radius_1",
        "P_links_0",
        "P_3",
    )


def _resolve(tree, path: str):
    for key in path.split("."):
        if isinstance(tree, dict):
            tree = tree[key]
        else:
            tree = tree[int(key)] if key.isdigit() else getattr(tree, key)
    return tree


def test_name_map_gives_each_parameter_its_pytree_path():
    """Every run-time parameter has a ``#define`` with its index and its leaf's path, the
    path leads to the leaf whose value the kernel reads at that index, and the code reads
    parameters only by name."""
    mech = jc.paper()
    st = source.structure(mech)
    text = source.field_source(st)
    defines = re.findall(r"^#define (P_\w+) +(\d+)  /\* (\S+) \*/$", text, flags=re.M)
    paths = namemap.leaf_paths(mech)
    assert [(int(i), path) for _, i, path in defines] == list(enumerate(paths))
    values = source.parameter_vector(mech)
    for (ident, _, path), value in zip(defines, values):
        assert float(_resolve(mech, path)) == value, path
        assert ident == "P_" + re.sub(r"[^A-Za-z0-9_]+", "_", path)
    assert not re.search(r"\bp\[\d+\]", text)
    # no state names passed: the state entries are named from the description (model.state_names)
    state = re.findall(r"^#define (Y_\w+) +(\d+)  /\* (.+?) \*/$", text, flags=re.M)
    assert [(int(i), name) for _, i, name in state] == list(enumerate(model.state_names(mech)))
    sweep_text = source.kernel_source(source.structure(mech, ["clearance_B", "contact.restitution"]))
    assert re.search(r"^#define P_contact_restitution +1  /\* contact\.restitution \*/$", sweep_text, flags=re.M)
    assert re.search(r"^ \*   crank_length = 0\.15$", sweep_text, flags=re.M)  # the baked-in values, listed
    with pytest.raises(ValueError, match="state names"):
        source.field_source(st, ("a", "b"))


def test_comments_name_the_model_source():
    """The field's statements are commented with the physics function and line they were
    traced from: each named file exists, the line is in it and the function is defined there."""
    text = source.field_source(source.structure(jc.paper()))
    places = re.findall(r"/\* (jaxcrank/physics/\w+\.py):(\d+) ([\w.<>]+)", text)
    assert len(places) > 100
    assert {"jaxcrank/physics/laws.py", "jaxcrank/physics/dynamics.py"} <= {f for f, _, _ in places}  # contact laws
    for file_name, line, function in set(places):
        lines = (ROOT / file_name).read_text().splitlines()
        assert 1 <= int(line) <= len(lines), (file_name, line)
        named = [part for part in function.split(".") if not part.startswith("<")]  # <lambda>, <listcomp>, ...
        leaf = named[-1] if named else None
        assert leaf is None or re.search(rf"def {re.escape(leaf)}\b", "\n".join(lines)), (file_name, function)


def test_named_scopes_lead_the_comment():
    """``jax.named_scope`` names, through nested ``jit``s, open the comment in brackets."""

    @jax.jit
    def inner(x):
        with jax.named_scope("inner"):
            return jnp.sin(x) * 3.0

    def fn(x):
        with jax.named_scope("outer"):
            return (inner(x[0]) + x[1],)

    text, _ = codegen.emit_function("f", fn, [("x", (2,))], ["out"])
    assert "/* [outer/inner] " in text and "test_codegen.py" in text
    assert provenance.describe([], ()) is None
    assert provenance.describe([], ("a", "b")) == "[a/b]"


@pytest.mark.skipif(not engine.available(), reason="no C compiler")
def test_named_field_compiles_and_equals_the_numbered_one():
    """The field source with state names (``y[Y_name]``) compiles and computes, bit for bit,
    what the source without them computes, in scalar and vector builds."""
    mech = jc.paper()
    st = source.structure(mech)
    n_state = source.layout(st).n_state
    named = source.field_source(st, tuple(f"state.{i}" for i in range(n_state)))
    assert "y[Y_state_3]" in named and "rate[Y_state_3] = " in named
    rng = np.random.default_rng(0)
    n = 64
    ts, ys = rng.uniform(0.0, 0.4, n), rng.normal(size=(n, n_state))
    params = np.ascontiguousarray(np.tile(source.parameter_vector(mech), (n, 1)))
    outs = []
    for text in (named, source.field_source(st)):
        lib = build.compile_source(text).lib
        for batch in (lib.jk_field_batch, lib.jk_field_batch_v):
            out = np.zeros_like(ys)
            batch(n, params, ts, ys, out)
            outs.append(out)
    assert np.all(np.isfinite(outs[0]))
    for out in outs[1:]:
        np.testing.assert_array_equal(out, outs[0])


def test_dispatch_goes_through_the_table(monkeypatch):
    """An emitter added to the table is used: the table is the only dispatch."""
    calls = []

    def emit_sin(w, eqn, ins):
        calls.append(eqn.primitive.name)
        return [np.vectorize(lambda a: w.new(f"KF1(mysin, {a})", np.float64), otypes=[object])(ins[0])]

    monkeypatch.setitem(primitives.EMITTERS, "sin", emit_sin)
    text, _ = codegen.emit_function("f", lambda x: (jnp.sin(x),), [("x", (2,))], ["out"])
    assert calls == ["sin"] and "KF1(mysin, x[1])" in text


def test_comments_do_not_change_the_cached_library():
    """Sources that differ only in comments (source lines moved by an edit) share one
    compiled library; a change of code does not."""
    text = source.field_source(source.structure(jc.paper()))
    moved = re.sub(r"(/\* jaxcrank/physics/\w+\.py:)(\d+)", lambda m: m.group(1) + str(int(m.group(2)) + 1), text)
    assert moved != text
    assert build.library_path(moved) == build.library_path(text)
    assert build.library_path(text + "\nint jk_other;\n") != build.library_path(text)
