"""Expected errors on the command line end in one line naming what to change,
exit code 2 and no traceback (none of these cases reaches a solve)."""

import json

import numpy as np
import pytest

from jaxcrank.runs.cli import main


def _one_line_error(capsys, code, *needles):
    err = capsys.readouterr().err
    assert code == 2
    assert "Traceback" not in err and err.count("\n") == 1 and err.startswith("jaxcrank: error:")
    for needle in needles:
        assert needle in err, err


def test_malformed_optimisation_toml(tmp_path, capsys):
    cfg = tmp_path / "opt.toml"
    cfg.write_text("problem = paper\n[optimizer\n")
    code = main(["optimize", "--config", str(cfg), "--out", str(tmp_path / "run"), "--quiet"])
    _one_line_error(capsys, code, "opt.toml", "malformed TOML")


def test_bad_grid_from_file(tmp_path, capsys):
    bad = tmp_path / "grid.csv"
    bad.write_text("crank_length_SI,rod_length_SI,rms_error_deg\n0.11,0.39,0.02\n")
    code = main(["optimize", "--out", str(tmp_path / "run"), "--grid", "3", "--grid-from", str(bad), "--quiet"])
    _one_line_error(capsys, code, "--grid-from", "3 x 3")


def test_resume_of_a_run_with_other_variables(tmp_path, capsys):
    out = tmp_path / "run"
    out.mkdir()
    meta = {
        "names": ["crank_length", "rod_length"],
        "method": "lbfgs",
        "f0": 1.0,
        "quiet": 0,
        "converged": None,
        "history": [{"iteration": 0}],
    }
    np.savez(out / "checkpoint.npz", u=np.zeros(2), meta=np.asarray(json.dumps(meta)))
    code = main(["optimize", "--out", str(out), "--resume", "--method", "adam", "--grid", "0", "--quiet"])
    _one_line_error(capsys, code, "--resume", "lbfgs", "adam")


def test_missing_config_file(tmp_path, capsys):
    code = main(["simulate", "--config", str(tmp_path / "nope.toml"), "--out", str(tmp_path / "run")])
    _one_line_error(capsys, code, "nope.toml")


@pytest.mark.parametrize("command", ["optimize", "sweep", "regimes"])
def test_resume_of_a_missing_run_directory_creates_nothing(tmp_path, capsys, command):
    """``--resume`` into a directory that does not exist is a one-line error that creates
    nothing, for every command that resumes (a sweep or regime map would otherwise start
    a fresh run and exit 0)."""
    out = tmp_path / "never_ran"
    spec = tmp_path / "spec.toml"
    spec.write_text('sampling = "grid"\n[parameters.clearance_C]\nvalues = [2.5e-4, 3e-4]\n')
    args = [] if command == "optimize" else ["--spec", str(spec)]
    code = main([command, *args, "--out", str(out), "--resume", "--quiet"])
    _one_line_error(capsys, code, "--resume", str(out), "does not exist")
    assert not out.exists()


def test_clearance_out_of_range_names_the_parameter_and_range(tmp_path, capsys):
    code = main(["simulate", "--set", "clearance_B=0.009", "--out", str(tmp_path / "run"), "--quiet"])
    _one_line_error(capsys, code, "clearance_B", "joints.B.hole_radius")


def test_design_file_without_a_final_mechanism(tmp_path, capsys):
    bad = tmp_path / "result.json"
    bad.write_text(json.dumps({"final_design_SI": [0.1]}))
    code = main(["simulate", "--design", str(bad), "--out", str(tmp_path / "run"), "--quiet"])
    _one_line_error(capsys, code, "result.json", "final_mechanism")
