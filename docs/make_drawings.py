"""Make the docs' drawings and animations with the command line, as a user would:

    python docs/make_drawings.py

- ``docs/img/linkages/<name>.svg``: ``jaxcrank draw`` of every preset and of every
  linkage file in ``docs/linkages/``;
- ``docs/img/paper.gif`` and ``docs/img/crank-rocker.gif``: ``jaxcrank simulate`` then
  ``jaxcrank animate`` of the last revolution;
- from the paper's run (0.4 s, the README's first command): ``docs/img/slider_x.png`` and
  ``docs/img/figures/paper_bearing_loads.png``.
"""

from __future__ import annotations

import shutil
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
IMG = ROOT / "docs" / "img"


def main() -> int:
    from jaxcrank.physics.presets import PRESETS
    from jaxcrank.runs.cli import main as jaxcrank

    drawings = {name: ["--mechanism", name] for name in PRESETS}
    for path in sorted((ROOT / "docs" / "linkages").glob("*.toml")):
        drawings[path.stem] = ["--config", str(path)]
    for name, how in drawings.items():
        if jaxcrank(["draw", *how, "--out", str(IMG / "linkages" / f"{name}.svg")]) != 0:
            return 1
    runs = {"paper": ["--mechanism", "paper", "--t1", "0.4"]}
    runs["crank-rocker"] = ["--config", str(ROOT / "docs/linkages/crank-rocker.toml"), "--t1", "0.2"]
    with tempfile.TemporaryDirectory() as tmp:
        for name, how in runs.items():
            run = Path(tmp) / name
            figures = [] if name == "paper" else ["--no-figures"]
            if jaxcrank(["simulate", *how, "--out", str(run), "--quiet", *figures]) != 0:
                return 1
            if name == "paper":
                (IMG / "figures").mkdir(exist_ok=True)
                shutil.copyfile(run / "figures" / "slider_x.png", IMG / "slider_x.png")
                shutil.copyfile(run / "figures" / "bearing_loads.png", IMG / "figures" / "paper_bearing_loads.png")
            out = IMG / f"{name}.gif"
            if jaxcrank(["animate", str(run), "--out", str(out), "--frames-per-revolution", "60", "--dpi", "80"]):
                return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
