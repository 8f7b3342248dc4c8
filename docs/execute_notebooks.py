"""Execute the notebooks in place at their full settings, so that they are committed with outputs.

Usage (from the repository root)::

    python docs/execute_notebooks.py                      # every notebook in notebooks/
    python docs/execute_notebooks.py notebooks/01_paper_reproduction.ipynb

Each notebook runs in a fresh ``python3`` kernel with ``notebooks/`` as its working directory
and the ``JAXCRANK_NOTEBOOK_*`` variables removed (the tests set them for short settings). The
notebook file is overwritten with its outputs; the wall time of each run is printed.
"""

import argparse
import os
import sys
import time
from pathlib import Path

import nbformat
from nbclient import NotebookClient

ROOT = Path(__file__).resolve().parent.parent


def execute(path: Path, timeout: int) -> float:
    """Execute one notebook in place; return the wall time in seconds."""
    for key in [k for k in os.environ if k.startswith("JAXCRANK_NOTEBOOK_")]:
        del os.environ[key]
    nb = nbformat.read(path, as_version=4)
    tic = time.perf_counter()
    NotebookClient(
        nb, timeout=timeout, kernel_name="python3", resources={"metadata": {"path": str(path.parent)}}
    ).execute()
    wall = time.perf_counter() - tic
    nbformat.write(nb, path)
    return wall


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("notebooks", nargs="*", type=Path, help="notebooks to run (default: notebooks/*.ipynb)")
    parser.add_argument("--timeout", type=int, default=3600, help="per-cell timeout in s (default 3600)")
    args = parser.parse_args(argv)
    paths = args.notebooks or sorted((ROOT / "notebooks").glob("*.ipynb"))
    for path in paths:
        wall = execute(path.resolve(), args.timeout)
        print(f"{path}: executed in {wall:.0f} s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
