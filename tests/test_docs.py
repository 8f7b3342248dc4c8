"""The docs: generated tables match the bench JSON, every module has an API page, the README is short."""

import importlib.util
import re
from pathlib import Path

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


def test_every_module_has_an_api_page_in_the_nav():
    nav = (ROOT / "mkdocs.yml").read_text()
    pages = set(re.findall(r":\s*(\S+\.md)\s*$", nav, flags=re.M))
    for page in pages:
        assert (ROOT / "docs" / page).exists(), page
    for package in ("jaxcrank", "optim"):
        for path in (ROOT / package).glob("*.py"):
            if path.stem == "__init__":
                continue
            name = path.stem if package == "jaxcrank" else f"optim.{path.stem}"
            page = f"api/{name}.md"
            assert page in pages, f"{package}/{path.name} has no API page {page} in mkdocs.yml's nav"
            assert f"::: {package}.{path.stem}" in (ROOT / "docs" / page).read_text()


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
