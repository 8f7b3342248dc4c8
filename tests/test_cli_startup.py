"""``jaxcrank --help`` adds no command's options: the CLI modules import JAX, diffrax and
optax only once a command is named (the package's own import aside)."""

import ast
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def test_cli_module_imports_only_the_standard_library_at_the_top():
    tree = ast.parse((ROOT / "jaxcrank" / "runs" / "cli.py").read_text())
    for node in tree.body:
        if isinstance(node, ast.Import):
            assert all(a.name.split(".")[0] in sys.stdlib_module_names for a in node.names), ast.unparse(node)
        elif isinstance(node, ast.ImportFrom):
            ok = node.module == "__future__" or (
                node.level == 0 and node.module.split(".")[0] in sys.stdlib_module_names
            )
            ok = ok or (node.level == 2 and node.module is None and [a.name for a in node.names] == ["__version__"])
            assert ok, ast.unparse(node)


def test_top_level_help_loads_no_command():
    probe = (
        "import sys\nfrom jaxcrank.runs.cli import main\ntry:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
        "print(sorted(m for m in ('optax', 'optim', 'jaxcrank.runs.sweep', 'matplotlib') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", probe], cwd=ROOT, capture_output=True, text=True, check=True)
    assert "simulate" in out.stdout and "optimize" in out.stdout
    assert out.stdout.strip().splitlines()[-1] == "[]", out.stdout
