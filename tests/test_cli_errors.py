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


@pytest.mark.parametrize("command", ["assemble", "draw"])
@pytest.mark.parametrize("angle", ["nan", "inf", "ten"])
def test_an_angle_that_is_not_finite_is_refused(tmp_path, capsys, command, angle):
    """``--angle`` takes a finite number of degrees (argparse says which option, exit code 2)."""
    with pytest.raises(SystemExit) as exit_:
        main([command, "--angle", angle, *(["--out", str(tmp_path / "x.png")] if command == "draw" else [])])
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and "--angle" in err and "Traceback" not in err


def test_an_angle_is_taken_modulo_a_turn():
    from jaxcrank.runs.config import angle_deg

    assert angle_deg("370") == pytest.approx(10.0) and angle_deg("-90") == 270.0 and 0.0 <= angle_deg("1e300") < 360.0


def test_the_headline_of_a_linkage_without_outputs_is_its_loads():
    """Without ``[outputs]`` a linkage has no deviations to report: the printed headline gives the
    largest peak contact force and the peak driving moment instead of nothing; with deviations, as before."""
    from jaxcrank.runs.simulate_cli import headline_text

    loads = {"peak_contact_force_B_N": 10.0, "peak_contact_force_C_N": 30.0, "peak_contact_force_C_whole_run_N": 50.0}
    assert headline_text({**loads, "peak_driving_moment_N_m": 2.0}) == (
        "peak contact force at C = 30 N, peak driving moment = 2 N m"
    )
    assert headline_text({"max_abs_slider_x_deviation_m": 1e-4, **loads}) == "max |slider x dev| = 0.100 mm"
