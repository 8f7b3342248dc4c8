"""Faults: a sweep and an optimisation killed with SIGKILL at random points resume to
the table and history of an uninterrupted run; truncated or corrupted tables and
checkpoints raise CorruptFileError naming the file (never a silent restart).

Each run is a subprocess (it compiles its own solve: equinox's run-time checks are host
callbacks, which JAX's persistent compilation cache does not store)."""

from __future__ import annotations

import csv
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import optax
import pytest

import jaxcrank as jc
from jaxcrank import cli, sweep
from jaxcrank.errors import CorruptFileError

ROOT = Path(__file__).resolve().parents[1]

_SWEEP = """
import sys
from pathlib import Path
import jaxcrank as jc
from jaxcrank import sampling, sweep
out = Path(sys.argv[1])
settings = sweep.Settings(revolutions=0.02, samples_per_revolution=1200, metrics_from_revolution=0.0,
                          options=jc.DEFAULTS.replace(max_steps=20000))
names, designs = sampling.latin_hypercube({"clearance_C": (1e-4, 5e-4), "contact.restitution": (0.5, 1.0)}, 14, seed=1)
sweep.run(jc.paper(), names, designs, settings, out=out, resume=(out / "table.csv").exists(), chunk=1,
          progress=False, engine="xla")
"""

_OPTIMIZE = """
import sys
from pathlib import Path
from optim.objective import Pathwise
from optim.optimize import Settings, optimize
from optim.presets import paper_problem
out = Path(sys.argv[1])
prob = paper_problem(Pathwise(t_start=0.0, t_end=2e-3))
optimize(prob, Settings(max_iterations=6, gtol=0.0, xtol=0.0), out=out,
         resume=(out / "checkpoint.npz").exists(), progress=False)
"""


def _env() -> dict:
    env = dict(os.environ, JAX_PLATFORMS="cpu", PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    env.pop("JAX_NUM_CPU_DEVICES", None)
    return env


def _rows(path: Path) -> int:
    """Data rows in a CSV file (0 when it does not exist yet)."""
    try:
        with open(path, newline="") as f:
            return max(0, sum(1 for _ in csv.reader(f)) - 1)
    except FileNotFoundError:
        return 0


def _run(code, out, env, timeout=600):
    res = subprocess.run(
        [sys.executable, "-c", code, str(out)], env=env, cwd=ROOT, capture_output=True, text=True, timeout=timeout
    )
    assert res.returncode == 0, res.stderr[-3000:]


def _kill_at(code, out, env, progress_file, target, rng, timeout=600) -> bool:
    """Start the run, SIGKILL it at a random moment once ``progress_file`` has ``target``
    data rows. Returns whether it was killed before finishing."""
    proc = subprocess.Popen(
        [sys.executable, "-c", code, str(out)],
        env=env,
        cwd=ROOT,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline = time.monotonic() + timeout
    try:
        while proc.poll() is None and _rows(progress_file) < target:
            assert time.monotonic() < deadline, "the run made no progress"
            time.sleep(0.01)
        time.sleep(rng.uniform(0.0, 0.3))  # somewhere inside the next unit of work
        killed = proc.poll() is None
        if killed:
            proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    if not killed:
        assert proc.returncode == 0, proc.stderr.read()[-3000:]
    return killed


@pytest.mark.slow  # worker subprocesses killed and restarted
def test_sweep_killed_at_random_points_resumes_to_the_same_table(tmp_path):
    env = _env()
    _run(_SWEEP, tmp_path / "whole", env)
    whole = sweep.read_table(tmp_path / "whole" / "table.csv")
    assert len(whole["index"]) == 14 and np.sum(whole["status"] == "ok") >= 10
    out, rng = tmp_path / "killed", random.Random(18)
    kills = [
        _kill_at(_SWEEP, out, env, out / "table.csv", target, rng) for target in sorted(rng.sample(range(1, 13), 3))
    ]
    assert sum(kills) >= 2, kills  # killed mid-run, not after the end
    _run(_SWEEP, out, env)
    again = sweep.read_table(out / "table.csv")
    assert list(again["index"]) == list(range(14))
    for k in again:
        np.testing.assert_array_equal(again[k], whole[k], err_msg=k)


@pytest.mark.long
@pytest.mark.slow  # five subprocesses that each compile the objective's gradient (~2 min on 2 cores)
def test_optimisation_killed_at_random_points_resumes_to_the_same_history(tmp_path):
    env = _env()
    _run(_OPTIMIZE, tmp_path / "whole", env)
    out, rng = tmp_path / "killed", random.Random(18)
    kills = [
        _kill_at(_OPTIMIZE, out, env, out / "history.csv", target, rng) for target in sorted(rng.sample(range(1, 6), 3))
    ]
    assert sum(kills) >= 2, kills
    _run(_OPTIMIZE, out, env)

    def history(path):
        with open(path / "history.csv", newline="") as f:
            return [{k: v for k, v in row.items() if k != "seconds"} for row in csv.DictReader(f)]

    whole, again = history(tmp_path / "whole"), history(out)
    assert len(whole) == 6 and again == whole  # every digit of the CSV
    a, b = np.load(tmp_path / "whole" / "checkpoint.npz"), np.load(out / "checkpoint.npz")
    for k in a.files:
        if k != "meta":  # the meta holds the per-iteration wall times
            np.testing.assert_array_equal(a[k], b[k], err_msg=k)


# ------------------------------------------------------------------ corrupted files

NAMES = ["clearance_C"]
INVALID = np.array([[9e-3], [1e-2], [2e-2]])  # larger than the 8 mm hole: rows without a solve


@pytest.fixture
def table_dir(tmp_path):
    out = tmp_path / "sweep"
    sweep.run(jc.paper(), NAMES, INVALID, out=out, progress=False, engine="xla")
    return out


def _resume(out):
    return sweep.run(jc.paper(), NAMES, INVALID, out=out, resume=True, progress=False, engine="xla")


def test_resume_of_an_intact_table_solves_nothing(table_dir):
    assert list(_resume(table_dir)["status"]) == ["invalid"] * 3


@pytest.mark.parametrize(
    "damage, match",
    [
        (lambda t: t[:-7], "line 4 has"),  # cut inside the last row
        (lambda t: t + "3,0.5,ok\n", "line 5 has"),  # a short row
        (lambda t: t.replace("invalid", "inv@lid", 1), "unknown status"),
        (lambda t: t.replace("index", "idx", 1), "header"),
        (lambda t: "", "header"),
        (lambda t: t + t.splitlines()[1] + "\n", "appears twice"),
        (lambda t: t.replace("0.009", "0.0091", 1), "parameters"),
        (lambda t: t.replace("0.009", "zz", 1), "not a number"),
        (lambda t: t.replace("\n1,", "\n1.5,", 1), "not a design number"),
    ],
)
def test_damaged_table_is_refused_by_name(table_dir, damage, match):
    path = table_dir / "table.csv"
    path.write_text(damage(path.read_text()))
    with pytest.raises(CorruptFileError, match=match) as err:
        _resume(table_dir)
    assert str(path) in str(err.value)


def test_truncated_designs_file_is_refused_by_name(table_dir):
    path = table_dir / "designs.npy"
    path.write_bytes(path.read_bytes()[:40])
    with pytest.raises(CorruptFileError, match="designs.npy"):
        _resume(table_dir)


def test_cli_resume_of_a_truncated_table_is_one_line(table_dir, tmp_path, capsys):
    spec = tmp_path / "spec.toml"
    spec.write_text("[parameters.clearance_C]\nvalues = [9e-3, 1e-2, 2e-2]\n")
    path = table_dir / "table.csv"
    path.write_text(path.read_text()[:-7])
    assert cli.main(["sweep", "--spec", str(spec), "--out", str(table_dir), "--resume", "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(path) in err[0] and "truncated" in err[0], err


def _checkpoint(out):
    """A real checkpoint of the paper problem after one (made-up) iteration."""
    from optim.checkpoint import history_columns
    from optim.checkpoint import save as write
    from optim.optimize import Settings
    from optim.presets import paper_problem

    prob = paper_problem()
    u = np.array([0.5, 0.5])
    rec = {c: 0.0 for c in history_columns(prob)}
    write(out, prob, Settings(), u, optax.adam(0.1).init(u), [rec], 1.0, 0, None)
    return prob, out / "checkpoint.npz"


@pytest.mark.parametrize(
    "damage, match",
    [
        (lambda b: b[: len(b) // 2], "cannot be read"),
        (lambda b: b[:100] + bytes(200) + b[300:], "cannot be read"),
        (lambda b: b"", "cannot be read"),
    ],
)
def test_damaged_checkpoint_is_refused_by_name(tmp_path, damage, match):
    from optim.checkpoint import load as load_checkpoint
    from optim.optimize import Settings, optimize

    prob, path = _checkpoint(tmp_path)
    load_checkpoint(tmp_path)  # intact: reads
    path.write_bytes(damage(path.read_bytes()))
    with pytest.raises(CorruptFileError, match=match) as err:
        optimize(prob, Settings(), out=tmp_path, resume=True, progress=False)
    assert str(path) in str(err.value)


def test_checkpoint_without_its_metadata_is_refused(tmp_path):
    from optim.checkpoint import load as load_checkpoint

    _, path = _checkpoint(tmp_path)
    with np.load(path) as arrays:
        kept = {k: arrays[k] for k in arrays.files if k != "meta"}
    np.savez(path, **kept)
    with pytest.raises(CorruptFileError, match="checkpoint.npz"):
        load_checkpoint(tmp_path)


def test_cli_resume_of_a_truncated_checkpoint_is_one_line(tmp_path, capsys):
    _, path = _checkpoint(tmp_path)
    path.write_bytes(path.read_bytes()[:200])
    assert cli.main(["optimize", "--out", str(tmp_path), "--resume", "--grid", "0", "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(path) in err[0], err
