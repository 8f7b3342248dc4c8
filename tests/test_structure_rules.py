"""Two rules of the package's structure, by reading its sources (nothing is imported):

- only the mechanism descriptions name the slider-crank's bodies and joints; everything
  else takes names from the description (the tree's joints, the outputs, the metric
  names), so that it works for any linkage;
- jaxcrank's layers import one way: physics <- numerics <- analysis <- views <- runs.
"""

import ast
import io
import re
import tokenize
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# --------------------------------------------------------------------------- slider-crank names

#: the mechanism descriptions, where the slider-crank's names belong: the presets and the
#: catalogue of named mechanisms; optim's named design problems on the paper's mechanism
#: (optim/presets.py), their description (optim/design.py) and the slider-crank's derived
#: geometry (optim/geometry.py). TOML and other data files are not Python and are not read.
DESCRIPTIONS = {
    "jaxcrank/physics/presets.py",
    "jaxcrank/physics/catalogue.py",
    "optim/presets.py",
    "optim/design.py",
    "optim/geometry.py",
}
#: rules that do not apply to a file, and why:
#: - a prismatic joint's two sides are its guide and its slider (Prismatic.slider, the TOML
#:   key "slider", GuideClearance's slider block and slider_material): the word is the
#:   joint's vocabulary in the modules that describe and run prismatic joints;
#: - the compiled kernel names Butcher tableaux A, B, C and speaks the C language.
EXEMPT = {
    "jaxcrank/physics/guide.py": {"slider"},
    "jaxcrank/runs/codec.py": {"slider"},
    "jaxcrank/numerics/kernel/build.py": {"joint"},
    "jaxcrank/numerics/kernel/engine.py": {"joint"},
    "jaxcrank/numerics/kernel/primitives.py": {"joint"},
    "jaxcrank/numerics/kernel/source.py": {"joint"},
}


def _words(text: str) -> list[str]:
    """The parts of an identifier or a string between non-alphanumerics, underscores
    included (``peak_contact_force_C_N`` -> peak, contact, force, C, N)."""
    return [w for w in re.split(r"[^A-Za-z0-9]+", text) if w]


def _leaks(kind: str, text: str) -> set[str]:
    """The rules an identifier (``kind`` "name") or a one-line string literal ("string")
    breaks:

    - ``rod``: the word rod anywhere (rod_length, "rod", "rod_x", "rod_material...");
    - ``slider``: the word slider joined to others (slider_mass, "slider_x",
      "max_abs_slider_x_deviation_m") or the string "slider"; the identifier ``slider``
      alone (a prismatic joint's field) and prose ("the slider in its guide") are not;
    - ``crank pin``: crank_pin, crankpin;
    - ``joint``: the joints B and C: the string "B" or "C", an identifier with B or C
      as an underscore-separated part (joint_B, c_C), a string with B or C as a part
      joined by _ or . (clearance_B, joints.C.pin_radius, peak_contact_force_C_N); a
      bare B or C (a matrix) and prose ("a C compiler") are not.
    """
    out = set()
    body = text
    if kind == "string":
        body = re.sub(r"^[rbfuRBFU]*(['\"])|(['\"])$", "", text)
        body = body.replace("slider-crank", "")  # a preset kind's name, not a body
    if "rod" in _words(body):
        out.add("rod")
    if re.search(r"crank_?pin", body, flags=re.I):
        out.add("crank pin")
    if kind == "name":
        if "slider" in body.split("_") and body != "slider":
            out.add("slider")
        if {"B", "C"} & set(body.split("_")) and body not in ("B", "C"):
            out.add("joint")
    else:
        if body == "slider" or re.search(r"slider[_.]\w|\w[_.]slider\b", body):
            out.add("slider")
        if body in ("B", "C") or re.search(r"(?:^|[\w.][_.])[BC](?:[_.][\w.]|$)", body):
            out.add("joint")
    return out


def _documentation_lines(tree: ast.AST) -> set[int]:
    """Lines of docstrings: documentation speaks of the paper's mechanism freely."""
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)) and node.body:
            first = node.body[0]
            if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant):
                if isinstance(first.value.value, str):
                    out.update(range(first.lineno, first.end_lineno + 1))
    return out


def _offenders(path: Path) -> list[str]:
    rel = path.relative_to(ROOT).as_posix()
    source = path.read_text()
    documentation = _documentation_lines(ast.parse(source))
    found = []
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type == tokenize.NAME:
            kind = "name"
        elif tok.type == tokenize.STRING and tok.start[0] not in documentation:
            if tok.string.lstrip("rbfuRBFU").startswith(('"""', "'''")):
                continue  # a block of text (help, a C source template): documentation
            kind = "string"
        else:
            continue  # comments, docstrings, numbers, operators
        for rule in sorted(_leaks(kind, tok.string) - EXEMPT.get(rel, set())):
            found.append(f"{rel}:{tok.start[0]}: {rule}: {tok.string[:70]}")
    return found


def _sources():
    files = sorted([*(ROOT / "jaxcrank").rglob("*.py"), *(ROOT / "optim").glob("*.py")])
    return [f for f in files if f.relative_to(ROOT).as_posix() not in DESCRIPTIONS]


def test_no_module_outside_the_descriptions_names_the_slider_cranks_bodies_or_joints():
    found = [line for f in _sources() for line in _offenders(f)]
    assert not found, "slider-crank names outside the mechanism descriptions:\n" + "\n".join(found)


def test_the_rules_see_real_leaks_and_pass_generic_words():
    leaks = {
        ("name", "rod_length"): {"rod"},
        ("string", '"rod"'): {"rod"},
        ("string", '"slider"'): {"slider"},
        ("string", '"max_abs_slider_x_deviation_m"'): {"slider"},
        ("name", "slider_mass"): {"slider"},
        ("name", "joint_B"): {"joint"},
        ("name", "crank_pin"): {"crank pin"},
        ("string", '"C"'): {"joint"},
        ("string", '"clearance_B"'): {"joint"},
        ("string", '"peak_contact_force_C_N"'): {"joint"},
        ("string", 'f"e.g. joints.B.contact.restitution={x}"'): {"joint"},
        ("string", '"rod_material.youngs_modulus"'): {"rod"},
    }
    for (kind, text), rules in leaks.items():
        assert _leaks(kind, text) == rules, text
    generic = [
        ("name", "slider"),  # Prismatic.slider
        ("name", "C"),  # a matrix
        ("string", '"the slider in its guide"'),
        ("string", '"no C compiler found"'),
        ("string", '"C3"'),  # a matplotlib colour
        ("string", '"slider-crank"'),  # a preset kind
        ("string", '"crank"'),
        ("name", "crank_length"),
        ("string", '"joints.{j}.pin_radius"'),
    ]
    for kind, text in generic:
        assert _leaks(kind, text) == set(), text


# --------------------------------------------------------------------------- one-way imports between the layers

LAYERS = ("physics", "numerics", "analysis", "views", "runs")
#: modules of jaxcrank below every layer (any layer may import them)
BASE = {"jaxcrank._private", "jaxcrank.errors", "jaxcrank.__version__"}


def _imports(path: Path, root: Path = ROOT) -> list[tuple[int, str]]:
    """Every module ``path`` imports, at module level or inside functions (a lazy import
    is a dependency all the same), absolute dotted names with ``from X import Y`` giving
    both X and X.Y (X.Y alone when X is the package jaxcrank)."""
    parts = list(path.relative_to(root).with_suffix("").parts)
    package = parts[:-1]
    out = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if target != "jaxcrank":  # ``from .. import _private``: the names alone
                out.append((node.lineno, target))
            out += [(node.lineno, f"{target}.{a.name}") for a in node.names]
    return out


def _layer(module: str) -> int | None:
    """The layer index of a jaxcrank module; the package itself (its __init__ imports every
    layer) counts as above them all; None for the base modules and non-jaxcrank ones."""
    parts = module.split(".")
    if parts[0] != "jaxcrank" or module in BASE or module.startswith(tuple(f"{b}." for b in BASE)):
        return None
    if len(parts) == 1:
        return len(LAYERS)
    return LAYERS.index(parts[1]) if parts[1] in LAYERS else len(LAYERS)


def test_layers_import_one_way():
    """physics imports none of numerics, analysis, views, runs (nor the package's
    __init__); numerics not analysis, views or runs; analysis not views or runs; views
    not runs."""
    found = []
    for layer, name in enumerate(LAYERS):
        for path in sorted((ROOT / "jaxcrank" / name).rglob("*.py")):
            for line, module in _imports(path):
                above = _layer(module)
                if above is not None and above > layer:
                    found.append(f"{path.relative_to(ROOT)}:{line}: imports {module}")
    layering = " <- ".join(LAYERS)
    assert not found, f"imports against the layering {layering}:\n" + "\n".join(found)


def test_the_layering_check_sees_an_upward_import_inside_a_function(tmp_path):
    pkg = tmp_path / "jaxcrank" / "physics"
    pkg.mkdir(parents=True)
    (pkg / "bad.py").write_text("def f():\n    from ..runs import cli\n")
    modules = [m for _, m in _imports(pkg / "bad.py", root=tmp_path)]
    assert "jaxcrank.runs.cli" in modules
    assert _layer("jaxcrank.runs.cli") > _layer("jaxcrank.physics.model")
    assert _layer("jaxcrank._private") is None and _layer("jaxcrank") == len(LAYERS)
