"""The docs: generated tables match the bench JSON, every module has an API page, the README is short."""

import importlib.util
import os
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def _gen_tables():
    spec = importlib.util.spec_from_file_location("gen_tables", ROOT / "docs" / "gen_tables.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_readme_headline_table_is_generated_from_bench_json():
    gen = _gen_tables()
    assert gen.check() == [], "README headline table is stale: run python docs/gen_tables.py"


def test_every_table_renders_from_the_json_it_names():
    gen = _gen_tables()
    for name, text in ((p.stem, t) for p, t in gen.render().items()):
        assert text.count("\n|") >= 2, name
        for cited in re.findall(r"bench/results/([\w.]+)\.json", text):
            assert (ROOT / "bench" / "results" / f"{cited}.json").exists(), (name, cited)


#: jaxcrank's layers (jaxcrank/__init__.py); a module's page is named without its layer
LAYERS = ("physics", "numerics", "analysis", "views", "runs")
#: packages documented on one page (their modules are the package's internals)
ONE_PAGE = ("jaxcrank.numerics.kernel",)


def _modules(package: str) -> list[str]:
    """Dotted names of the modules of ``package`` (a directory under the root): the
    top package's ``__init__`` as the package, the modules of a ONE_PAGE package as that
    package; other subpackages' ``__init__`` are left out (their modules have the pages)."""
    out = set()
    for path in (ROOT / package).rglob("*.py"):
        parts = list(path.relative_to(ROOT).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
            if len(parts) > 1 and ".".join(parts) not in ONE_PAGE:
                continue  # a subpackage: its modules have the pages
        name = ".".join(parts)
        out.add(next((p for p in ONE_PAGE if name == p or name.startswith(p + ".")), name))
    return sorted(out)


def _api_page(module: str) -> str | None:
    """The API page of a module: ``api/<name without jaxcrank and its layer>.md``
    (``jaxcrank.physics.linkage`` -> ``api/linkage.md``, ``jaxcrank.analysis.validation.events``
    -> ``api/validation.events.md``), ``api/optim.<name>.md`` for optim; None for optim's
    package."""
    parts = module.split(".")
    if parts[0] == "optim":
        return f"api/{module}.md" if len(parts) > 1 else None
    if len(parts) == 1:
        return "api/jaxcrank.md"
    rest = parts[2:] if parts[1] in LAYERS else parts[1:]
    return f"api/{'.'.join(rest)}.md"


def test_every_module_has_an_api_page_in_the_nav():
    nav = (ROOT / "mkdocs.yml").read_text()
    pages = dict(re.findall(r"^\s*- ([\w.]+):\s*(api/\S+\.md)\s*$", nav, flags=re.M))
    for page in set(re.findall(r":\s*(\S+\.md)\s*$", nav, flags=re.M)):
        assert (ROOT / "docs" / page).exists(), page
    modules = _modules("jaxcrank") + _modules("optim")
    for module in modules:
        page = _api_page(module)
        if page is None:
            continue
        assert pages.get(module) == page, f"{module} has no API page {page} in mkdocs.yml's nav"
        assert f"::: {module}" in (ROOT / "docs" / page).read_text(), page
    # and no page for a module that is gone
    documented = {m for m in modules if _api_page(m)}
    assert set(pages) <= documented, f"API pages of modules that do not exist: {sorted(set(pages) - documented)}"
    on_disk = {f"api/{p.name}" for p in (ROOT / "docs" / "api").glob("*.md")}
    assert on_disk == set(pages.values()), f"pages outside the nav: {sorted(on_disk - set(pages.values()))}"


def test_readme_is_short_and_gives_the_ci_test_command():
    readme = (ROOT / "README.md").read_text()
    assert len(readme.splitlines()) <= 150
    ci = (ROOT / ".ci" / "run").read_text()
    assert "\npython -m pytest\n" in ci and "\npython -m pytest\n" in readme
    assert "jaxcrank simulate --out runs/paper" in readme
    slow = 'python -m pytest -m "slow and not long"'
    assert slow in readme and slow in ci  # CI runs the slow tests that are not long
    assert "python -m pytest -m long" in readme
    for link in re.findall(r"\]\(((?:docs|notebooks)/[^)#]+)", readme):
        assert (ROOT / link).exists(), link


#: a Sphinx cross-reference role (``:func:`x```), which mkdocstrings renders as literal text
SPHINX_ROLE = re.compile(r":(?:func|class|mod|meth|attr|data|obj|exc|ref|py:\w+):`")


def _docstrings():
    """(where, text) of every docstring of jaxcrank and optim (the API pages' text)."""
    import ast

    for path in sorted([*(ROOT / "jaxcrank").rglob("*.py"), *(ROOT / "optim").rglob("*.py")]):
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
                text = ast.get_docstring(node, clean=False)
                if text:
                    yield f"{path.relative_to(ROOT)}:{getattr(node, 'name', 'module')}", text


def test_no_sphinx_role_or_rest_literal_block_in_the_docs():
    """The docs are Markdown (mkdocstrings, Google style): a Sphinx role or a reST literal
    block (a line ending in ``::``) would show up as raw text on the site. Checked in the
    pages, the README and every docstring the API pages render."""
    texts = [(str(p.relative_to(ROOT)), p.read_text()) for p in [ROOT / "README.md", *(ROOT / "docs").glob("*.md")]]
    found = []
    for where, text in [*texts, *_docstrings()]:
        fenced = False
        for line in text.splitlines():
            if line.strip().startswith("```"):
                fenced = not fenced
                continue
            if fenced:
                continue
            if SPHINX_ROLE.search(line) or line.rstrip().endswith("::"):
                found.append(f"{where}: {line.strip()}")
    assert not found, "\n".join(found)


@pytest.mark.slow  # the whole site with its API pages (about a minute)
def test_the_site_builds_strict_so_every_cross_reference_resolves(tmp_path):
    """``mkdocs build --strict`` (what CI runs): an unresolved cross-reference, a broken link
    or anchor, or a page outside the nav fails the build."""
    import shutil
    import subprocess
    import sys

    if shutil.which("mkdocs") is None and importlib.util.find_spec("mkdocs") is None:
        pytest.skip("mkdocs is not installed (pip install -e '.[docs]')")
    run = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
        cwd=ROOT,
        capture_output=True,
        text=True,
        env={**os.environ, "NO_MKDOCS_2_WARNING": "1"},
    )
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]


def test_the_optimiser_config_page_example_builds_its_problem():
    """The complete example of docs/optimiser-config.md is a valid config: ``jaxcrank
    optimize`` builds the problem and settings it describes."""
    import tomllib

    from optim import cli

    text = (ROOT / "docs" / "optimiser-config.md").read_text()
    cfg = tomllib.loads(re.search(r"```toml\n(.*?)```", text, re.S).group(1))
    problem, settings = cli.build(cfg)
    assert type(problem).__name__ == "DesignProblem" and len(problem.names) == 9
    assert type(settings.optimizer).__name__ == "ProjectedLBFGS" and settings.starts == 4
    assert settings.max_iterations == 40 and settings.max_seconds == 1800
    assert type(problem.objective).__name__ == "Steady"


def test_the_design_study_tutorial_files_are_what_its_commands_read():
    """The tutorial's two files are valid: the optimiser config builds its four-variable design
    problem (Adam at 0.05 with the regime guard, the steady-state objective), and the sweep spec
    parses with the design's base mechanism and keeps its two metrics."""
    import tomllib

    import jaxcrank as jc
    from jaxcrank.runs.spec import spec_from_dict
    from optim import cli
    from optim.steady import RegimeGuard

    text = (ROOT / "docs" / "tutorial-design-study.md").read_text()
    config, spec = (tomllib.loads(b) for b in re.findall(r"```toml\n(.*?)```", text, re.S))
    problem, settings = cli.build(config)
    assert problem.names == ("rod_length", "min_transmission_angle", "clearance_B", "clearance_C")
    assert problem.description.startswith("design: 4 variables, stroke 240 mm")
    assert settings.optimizer.settings() == {"method": "adam", "learning_rate": 0.05} and settings.max_iterations == 30
    assert isinstance(settings.guard, RegimeGuard) and type(problem.objective).__name__ == "Steady"
    parsed = spec_from_dict(spec, base=jc.paper())
    assert list(parsed.metrics) == ["rms_transmission_angle_error_deg", "peak_contact_force_C_N"]


def test_code_blocks_wrap_instead_of_running_past_the_text_column():
    """Long lines in code blocks (the install command, config comments) wrap: the site's
    stylesheet sets it and mkdocs.yml loads it. docs/check_pages.py measures it in a
    browser (every code block no wider than its box, at 1280 and 390 px)."""
    cfg = (ROOT / "mkdocs.yml").read_text()
    assert re.search(r"extra_css:\n\s+- stylesheets/extra\.css", cfg)
    css = (ROOT / "docs" / "stylesheets" / "extra.css").read_text()
    rule = re.search(r"\.md-typeset pre > code,?[^{]*\{([^}]*)\}", css)
    assert rule and "white-space: pre-wrap" in rule.group(1)
