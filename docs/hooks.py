"""mkdocs hooks.

- Regenerate the benchmark tables from bench/results/*.json before each build.
- Serve the notebooks (``notebooks/*.ipynb``) as ``docs/notebooks/`` and the benchmark figures
  (``bench/results/*.png``) as ``docs/bench_results/``, without symlinks in the repository, so a fresh
  clone on any platform builds with ``mkdocs build --strict``.
"""

import importlib.util
from pathlib import Path

from mkdocs.plugins import event_priority
from mkdocs.structure.files import File

_ROOT = Path(__file__).resolve().parent.parent

_spec = importlib.util.spec_from_file_location("gen_tables", Path(__file__).with_name("gen_tables.py"))
gen_tables = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(gen_tables)

# docs-relative folder -> (source folder, file pattern)
EXPOSED = {
    "notebooks": (_ROOT / "notebooks", "*.ipynb"),
    "bench_results": (_ROOT / "bench" / "results", "*.png"),
}


def on_pre_build(config, **kwargs):
    """Write docs/generated/*.md from the bench JSON (the README is left to docs/gen_tables.py)."""
    gen_tables.write(readme=False)


# Runs before mkdocs-jupyter's on_files (priority 0), which turns the added .ipynb files into pages.
@event_priority(50)
def on_files(files, config, **kwargs):
    """Add the notebooks and the benchmark figures to the documentation files.

    A file already among the documentation files (e.g. through a local symlink) is left as it is.
    """
    for dest, (src_dir, pattern) in EXPOSED.items():
        for src in sorted(src_dir.glob(pattern)):
            uri = f"{dest}/{src.name}"
            if files.get_file_from_path(uri) is not None:
                continue
            if src_dir == _ROOT / dest:
                # A plain File (not File.generated): mkdocs-jupyter's page wrapper needs `src_dir` to
                # find the notebook, and <root>/<uri> is the notebook itself.
                file = File(uri, str(_ROOT), config.site_dir, config.use_directory_urls)
            else:
                file = File.generated(config, uri, abs_src_path=str(src))
            files.append(file)
    return files


def on_serve(server, config, builder, **kwargs):
    """Rebuild on changes to the exposed folders under `mkdocs serve`."""
    for src_dir, _ in EXPOSED.values():
        server.watch(str(src_dir))
    return server
