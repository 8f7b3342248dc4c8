"""The package's layout: files of a readable size, imports that run one way (no import
cycle between modules; jaxcrank's layers physics, numerics, analysis, views, runs each import
only the ones before them), and private APIs of other packages read in one shim only
(jaxcrank/_private.py). Static checks of the sources: nothing is imported or run."""

import ast
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MAX_LINES = 450
# files allowed over the limit (none: the list may only shrink)
OPTIM_OVER_LIMIT: set[str] = set()
SHIM = "jaxcrank/_private.py"
PRIVATE = re.compile(
    r"\bjax\._src\b|from jax import _src\b|\bequinox\._[a-z]|\bdiffrax\._[a-z]|from (equinox|diffrax) import _[a-z]"
)


def _sources(*packages):
    return sorted(f for p in packages for f in (ROOT / p).rglob("*.py"))


def _name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _module_imports(path: Path, modules: set[str]) -> set[str]:
    """The modules of ``modules`` that ``path`` imports at module level (statements
    inside functions, which run on first use, are not import-time edges)."""
    name = _name(path)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out = set()
    for node in ast.parse(path.read_text()).body:
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names if a.name in modules}
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            for alias in node.names:
                sub = f"{target}.{alias.name}"
                if sub in modules:
                    out.add(sub)
                elif target in modules:
                    out.add(target)
    out.discard(name)
    return out


def _resolve(path: Path, node: ast.ImportFrom) -> str:
    """The absolute module name an ``import from`` statement in ``path`` reads from."""
    if not node.level:
        return node.module or ""
    name = _name(path)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    base = package.split(".")
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _all_imports(path: Path) -> set[str]:
    """Every name ``path`` imports, anywhere in the file (functions included: an import
    on first use is still a dependency), as absolute dotted names (``from a import b``
    gives ``a.b``)."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            target = _resolve(path, node)
            out |= {f"{target}.{a.name}" for a in node.names}
    return out


#: jaxcrank's layers, each importing only from the ones before it (jaxcrank/__init__.py)
LAYERS = ("physics", "numerics", "analysis", "views", "runs")
#: modules of the top package every layer may import
SHARED = ("jaxcrank.errors", "jaxcrank._private")


def _layer_violations(package="jaxcrank"):
    """``file: imported name`` for every import of a later layer (or of the top package,
    which imports them all) by a module of an earlier one."""
    found = []
    for f in _sources(package):
        parts = _name(f).split(".")
        if len(parts) < 2 or parts[1] not in LAYERS:
            continue
        own = LAYERS.index(parts[1])
        for name in sorted(_all_imports(f)):
            pieces = name.split(".")
            if pieces[0] != package or any(name == s or name.startswith(s + ".") for s in SHARED):
                continue
            layer = pieces[1] if len(pieces) > 1 and pieces[1] in LAYERS else None
            if layer is None and LAYERS[own] != LAYERS[-1]:
                found.append(f"{f.relative_to(ROOT)}: {name} (the top package imports every layer)")
            elif layer is not None and LAYERS.index(layer) > own:
                found.append(f"{f.relative_to(ROOT)}: {name} ({parts[1]} may not import {layer})")
    return found


def _cycles(packages):
    files = _sources(*packages)
    modules = {_name(f) for f in files}
    graph = {_name(f): _module_imports(f, modules) for f in files}
    # a package's __init__ re-exporting its modules is not a cycle with them: drop the
    # edges from a package to its own modules
    graph = {m: {d for d in deps if not d.startswith(m + ".")} for m, deps in graph.items()}
    cycles, state = [], {}

    def visit(m, stack):
        state[m] = "open"
        for d in sorted(graph.get(m, ())):
            if state.get(d) == "open":
                cycles.append(stack[stack.index(d) :] + [d])
            elif d not in state:
                visit(d, stack + [d])
        state[m] = "done"

    for m in sorted(graph):
        if m not in state:
            visit(m, [m])
    return cycles


def test_no_file_of_jaxcrank_is_over_the_line_limit():
    over = {
        str(f.relative_to(ROOT)): n for f in _sources("jaxcrank") if (n := len(f.read_text().splitlines())) > MAX_LINES
    }
    assert not over, f"files over {MAX_LINES} lines: {over}"


def test_no_file_of_optim_is_over_the_line_limit_but_those_being_split():
    over = {str(f.relative_to(ROOT)) for f in _sources("optim") if len(f.read_text().splitlines()) > MAX_LINES}
    assert over <= OPTIM_OVER_LIMIT, f"files over {MAX_LINES} lines: {sorted(over - OPTIM_OVER_LIMIT)}"


def test_no_import_cycle_between_the_modules_of_jaxcrank_and_optim():
    assert _cycles(["jaxcrank", "optim"]) == []


def test_the_cycle_finder_finds_a_cycle(tmp_path, monkeypatch):
    pkg = tmp_path / "cyc"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from . import b\n")
    (pkg / "b.py").write_text("from .a import x\n")
    (pkg / "c.py").write_text("def f():\n    from . import a\n")  # on first use: no edge
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    assert _cycles(["cyc"]) == [["cyc.a", "cyc.b", "cyc.a"]]


def test_the_layers_import_one_way():
    """physics imports nothing of numerics, analysis or runs; numerics nothing of
    analysis or runs; analysis nothing of runs; none of them the top package."""
    assert _layer_violations() == []


def test_the_layer_check_finds_an_import_against_the_order(tmp_path, monkeypatch):
    pkg = tmp_path / "jaxcrank"
    for layer in LAYERS:
        (pkg / layer).mkdir(parents=True)
        (pkg / layer / "__init__.py").write_text("")
    (pkg / "__init__.py").write_text("")
    (pkg / "errors.py").write_text("")
    (pkg / "physics" / "a.py").write_text("from ..errors import E\ndef f():\n    from ..runs import cli\n")
    (pkg / "numerics" / "b.py").write_text("from ..physics import a\nimport jaxcrank.analysis.metrics\n")
    (pkg / "analysis" / "c.py").write_text("from .. import __version__\nfrom ..numerics.b import x\n")
    (pkg / "runs" / "d.py").write_text("from .. import __version__\nfrom ..analysis import c\n")
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    assert _layer_violations() == [
        "jaxcrank/analysis/c.py: jaxcrank.__version__ (the top package imports every layer)",
        "jaxcrank/numerics/b.py: jaxcrank.analysis.metrics (numerics may not import analysis)",
        "jaxcrank/physics/a.py: jaxcrank.runs.cli (physics may not import runs)",
    ]


def test_private_apis_of_other_packages_only_in_the_shim():
    found = [
        f"{f.relative_to(ROOT)}:{i}: {line.strip()}"
        for f in _sources("jaxcrank", "optim")
        if f.relative_to(ROOT).as_posix() != SHIM
        for i, line in enumerate(f.read_text().splitlines(), start=1)
        if PRIVATE.search(line)
    ]
    assert not found, "private APIs outside jaxcrank/_private.py:\n" + "\n".join(found)
    assert PRIVATE.search((ROOT / SHIM).read_text())  # the pattern does see the shim's accesses
