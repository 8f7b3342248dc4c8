"""A worn mechanism through the commands a user runs on it: simulate, steady and sweep.

The fact checked: a hole worn uniformly by w (profile ``a_0 = w``) is a round hole larger by w
(model: the worn contact's penetration is ``|d| - c - w_h - w_p`` and the hole's local radius of
curvature ``R_h + w_h + w_h''``), so each command gives, on the worn four-bar written to a file, what
it gives on the four-bar whose hole at B is larger by w.

The two runs do not take the same steps: the state is scaled by the largest clearance of the
mechanism (the worn joint's is its new one), so each run's integration error is its own. The
integrals (RMS values) converge together as the tolerance tightens and are compared at rel 1e-6
at ``TOL`` (rtol = atol on the scaled state). The maxima (peak forces, largest deviations) are
taken at the solver's steps or the samples, after impacts that amplify every difference: they
converge with the tolerance too, but far more slowly, so they are not compared.
"""

from __future__ import annotations

import json
import math

import equinox as eqx
import numpy as np
import pytest

import jaxcrank as jc
from jaxcrank.numerics.wear_run import with_profiles, with_wear
from jaxcrank.physics.wear import new_profile
from jaxcrank.runs import cli, config, sweep

#: the uniform wear depth of the hole at B, m (the four-bar's clearance there is 0.5 mm)
W = 4e-5
RPM = "300"
#: the solves' tolerances (module docstring)
TOL = "1e-10"

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """The worn four-bar and its round twin as TOML files, ``(worn, round)``."""
    folder = tmp_path_factory.mktemp("worn")
    base = jc.preset("four-bar")
    worn = with_wear(base, ["B"])
    modes = worn.joints["B"].modes
    worn = with_profiles(worn, {"B": (new_profile(modes).at[0].set(W), new_profile(modes))})
    bigger = eqx.tree_at(lambda m: m.joints["B"].hole_radius, base, base.joints["B"].hole_radius + W)
    paths = folder / "worn.toml", folder / "round.toml"
    for mech, path in zip((worn, bigger), paths):
        config.save(mech, path)
    assert "hole_wear" in paths[0].read_text() and config.load(paths[0]).joints["B"].name == "worn"
    return paths


def _numbers(summary: dict) -> dict:
    return {k: v for k, v in summary.items() if isinstance(v, float) and math.isfinite(v)}


def _same_metrics(a: dict, b: dict):
    """The RMS metrics of two runs' ``metrics`` agree (module docstring)."""
    rms = [k for k in _numbers(a) if k.startswith("rms_")]
    assert len(rms) >= 3 and a.keys() == b.keys()
    for k in rms:
        assert a[k] == pytest.approx(b[k], rel=1e-6), k


def _summary(command: str, path, out, *extra) -> dict:
    args = [command, "--config", str(path), "--rpm", RPM, "--out", str(out), "--no-figures", "--quiet"]
    assert cli.main([*args, "--rtol", TOL, "--atol", TOL, *extra]) == 0
    return json.loads((out / "summary.json").read_text())


def test_simulate_on_a_worn_file_is_the_larger_round_hole(files, tmp_path):
    worn, round_ = (_summary("simulate", p, tmp_path / n, "--t1", "0.1") for p, n in zip(files, ("w", "r")))
    _same_metrics(worn["metrics"], round_["metrics"])


def test_steady_on_a_worn_file_is_the_larger_round_hole(files, tmp_path):
    worn, round_ = (_summary("steady", p, tmp_path / n) for p, n in zip(files, ("w", "r")))
    assert worn["regime"] == round_["regime"] == "periodic"
    _same_metrics(worn["metrics"], round_["metrics"])


def test_sweep_on_a_worn_file_is_the_larger_round_hole(files, tmp_path):
    spec = tmp_path / "spec.toml"
    spec.write_text(
        'sampling = "grid"\n[parameters."contact.restitution"]\nvalues = [0.7, 0.9]\n'
        "[simulation]\nrevolutions = 0.5\nsamples_per_revolution = 720\nmetrics_from_revolution = 0.0\n"
        f"rtol = {TOL}\natol = {TOL}\nmax_steps = 2000000\n"
    )
    tables = []
    for path, name in zip(files, ("w", "r")):
        out = tmp_path / name
        args = ["sweep", "--spec", str(spec), "--config", str(path), "--rpm", RPM, "--out", str(out), "--quiet"]
        assert cli.main([*args, "--engine", "xla"]) == 0
        tables.append(sweep.read_table(out / "table.csv"))
    worn, round_ = tables
    rms = [k for k in worn if k.startswith("rms_")]
    assert rms and list(worn["status"]) == list(round_["status"]) == ["ok", "ok"]
    for k in rms:
        np.testing.assert_allclose(worn[k], round_[k], rtol=1e-6, err_msg=k)
