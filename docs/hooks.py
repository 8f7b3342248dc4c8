"""mkdocs hook: regenerate the benchmark tables from bench/results/*.json before each build."""

import importlib.util
from pathlib import Path

_spec = importlib.util.spec_from_file_location("gen_tables", Path(__file__).with_name("gen_tables.py"))
gen_tables = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(gen_tables)


def on_pre_build(config, **kwargs):
    """Write docs/generated/*.md from the bench JSON (the README is left to docs/gen_tables.py)."""
    gen_tables.write(readme=False)
