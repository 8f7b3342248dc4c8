"""Honest labels: the metrics window a run really had, and failure messages that give
the requested end time and the time reached; output errors reported by name."""

import errno
import json
import os

import numpy as np
import pytest

import jaxcrank as jc
from jaxcrank import cli, outputs


def test_half_revolution_run_states_its_window(tmp_path, capsys):
    """0.01 s at 3000 rpm is half a revolution (the issue's case is 0.05 s at 600 rpm;
    this one is cheaper): the metrics cover the whole run and say so; nothing claims a
    window after the first revolution (which would start at 0.02 s)."""
    out = tmp_path / "half"
    assert (
        cli.main(
            [
                "simulate",
                "--rpm",
                "3000",
                "--t1",
                "0.01",
                "--out",
                str(out),
                "--samples-per-degree",
                "1",
                "--quiet",
                "--no-figures",
            ]
        )
        == 0
    )
    printed = capsys.readouterr().out
    assert "after the first revolution" not in printed
    assert "over the whole run, 0 to 0.01 s (shorter than one revolution, 0.02 s)" in printed
    summary = json.loads((out / "summary.json").read_text())
    m = summary["metrics"]
    assert m["window_start_s"] == 0.0 and m["window_end_s"] == pytest.approx(0.01, rel=1e-12)
    assert summary["simulated_time_s"] == 0.01
    assert "after the first revolution" not in json.dumps(summary)
    assert summary["energy_balance"]["from_s"] == 0.0 and summary["energy_balance"]["to_s"] == pytest.approx(0.01)
    # the numbers cover the whole trajectory the run wrote (10 significant digits in
    # the CSV: positions of ~0.5 m carry up to 2.5e-11 m rounding each): the RMS over
    # its samples after t = 0, the peak over the solve at least the samples' peak
    data = np.genfromtxt(out / "trajectory.csv", delimiter=",", names=True)
    dev = (data["slider_x"] - data["ideal_slider_x"])[1:]
    assert m["rms_slider_x_deviation_m"] == pytest.approx(np.sqrt(np.mean(dev**2)), abs=1e-10)
    assert m["max_abs_slider_x_deviation_m"] >= np.max(np.abs(dev)) - 1e-10


def test_a_metrics_window_without_samples_is_refused():
    sim = jc.simulate(jc.paper(), 0.002, n_samples=11)
    with pytest.raises(jc.ParameterError, match="t_start = 0.2 s leaves no sample"):
        outputs.sample_metrics(sim, 0.2)


@pytest.mark.parametrize("override", ["driver.speed=1e5", "rod_length=1e9"])
def test_failure_message_gives_requested_and_reached_time(tmp_path, capsys, override):
    rc = cli.main(
        [
            "simulate",
            "--t1",
            "0.01",
            "--out",
            str(tmp_path / "f"),
            "--quiet",
            "--no-figures",
            "--max-steps",
            "3000",
            "--set",
            override,
        ]
    )
    assert rc == 2
    err = capsys.readouterr().err
    assert "inf" not in err, err
    assert "max_steps=3000" in err and "requested end time t1 = 0.01 s" in err, err
    reached = float(err.split("the last sample it reached is t = ")[1].split(" s")[0])
    assert 0.0 <= reached < 0.01


def test_failure_message_of_the_python_api():
    with pytest.raises(
        jc.SimulationError,
        match=r"requested end time t1 = 0.01 s \(the last sample it reached is "
        r"t = [0-9.e-]+ s, sample \d+ of 11\)",
    ):
        jc.simulate(jc.paper(), 0.01, n_samples=11, options=jc.SolveOptions(max_steps=10))


def _one_error_line(capsys):
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    return err


def test_unwritable_output_directory_is_named(tmp_path, capsys):
    blocker = tmp_path / "a_file"
    blocker.write_text("not a directory")
    out = blocker / "run"
    assert cli.main(["simulate", "--t1", "0.001", "--out", str(out), "--quiet", "--no-figures"]) == 2
    assert str(blocker) in _one_error_line(capsys)
    spec = tmp_path / "spec.toml"
    spec.write_text(
        "[parameters.clearance_C]\nvalues = [2.5e-4]\n[simulation]\nrevolutions = 0.01\nmetrics_from_revolution = 0\n"
    )
    assert cli.main(["sweep", "--spec", str(spec), "--out", str(out), "--quiet"]) == 2
    assert str(blocker) in _one_error_line(capsys)
    assert cli.main(["optimize", "--out", str(out), "--grid", "0", "--quiet"]) == 2
    assert str(blocker) in _one_error_line(capsys)


def test_full_disk_is_reported_by_name(tmp_path, capsys, monkeypatch):
    """A write that fails with ENOSPC (simulated: no full disk is at hand) ends the CLI
    with one line naming the file, exit status 2."""
    from jaxcrank import config

    def full(mech, path):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))

    monkeypatch.setattr(config, "save", full)
    assert cli.main(["simulate", "--t1", "0.001", "--out", str(tmp_path / "run"), "--quiet"]) == 2
    err = _one_error_line(capsys)
    assert "No space left on device" in err and str(tmp_path / "run" / "config.toml") in err
