"""Bad input raises a clear error naming the parameter; config round trip; CLI."""

import json

import equinox as eqx
import pytest

import jaxcrank as jc
from jaxcrank import cli, config

BAD = [
    ({"rod_length": 0.15}, "rod_length"),
    ({"offset": 0.3}, "rod_length"),
    ({"joint_B": {"pin_radius": 8e-3}}, "pin_radius"),
    ({"joint_C": {"pin_radius": 9e-3}}, "pin_radius"),
    ({"rod_mass": 0.0}, "rod_mass"),
    ({"slider_mass": -1.0}, "slider_mass"),
    ({"crank_mass": -0.1}, "crank_mass"),
    ({"rod_inertia": 0.0}, "rod_inertia"),
    ({"crank_speed": 0.0}, "crank_speed"),
    ({"crank_speed": -5.0}, "crank_speed"),
    ({"rod_material": {"youngs_modulus": 0.0}}, "youngs_modulus"),
    ({"crank_material": {"poisson_ratio": 0.5}}, "poisson_ratio"),
    ({"slider_material": {"poisson_ratio": 0.0}}, "poisson_ratio"),
    ({"contact": {"restitution": 0.0}}, "restitution"),
    ({"contact": {"restitution": 1.2}}, "restitution"),
    ({"friction": {"coefficient": -0.1}}, "friction coefficient"),
    ({"friction": {"slip_speed": 1e-5}}, "slip_speed"),
    ({"friction": {"slip_speed": float("nan")}}, "slip_speed"),
    ({"friction": {"slip_speed": float("inf")}}, "slip_speed"),
    ({"contact": {"law": "hertzian"}}, "contact law"),
    ({"friction": {"law": "stribeck"}}, "friction law"),
    ({"rod_lenght": 0.4}, "rod_lenght"),
    ({"contact": {"stiffness": 1.0}}, "contact.stiffness"),
    ({"rod_length": "long"}, "rod_length"),
    ({"joint_B": 3.0}, "joint_B"),
]


@pytest.mark.parametrize("data,name", BAD, ids=[n for _, n in BAD])
def test_bad_input_names_parameter(data, name):
    with pytest.raises(jc.ParameterError, match=name):
        config.from_dict(data)


def test_errors_state_valid_range():
    with pytest.raises(jc.ParameterError, match=r"valid range.*\(0, 1\]"):
        config.from_dict({"contact": {"restitution": 1.5}})
    with pytest.raises(jc.ParameterError, match="ideal = true"):
        jc.Joint(hole_radius=8e-3, pin_radius=8e-3)


def test_ideal_joint_allows_zero_clearance():
    assert jc.Joint(hole_radius=8e-3, pin_radius=8e-3, ideal=True).clearance == 0.0


def test_malformed_toml(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text("rod_length = = 3\n")
    with pytest.raises(jc.ParameterError, match="malformed TOML"):
        config.load(path)


def test_toml_round_trip(tmp_path):
    mech = config.apply_overrides(jc.paper(), ["rod_length=0.41", "contact.law=flores", "joint_C.ideal=true"])
    path = tmp_path / "m.toml"
    config.save(mech, path)
    again = config.load(path)
    assert eqx.tree_equal(mech, again)
    assert isinstance(again.contact.law, jc.laws.Flores) and again.joint_C.ideal


def test_paper_preset_values(paper):
    assert paper.crank_length == 0.150 and paper.rod_length == 0.403 and paper.offset == 0.050
    assert (paper.crank_mass, paper.rod_mass, paper.slider_mass) == (0.6967, 1.5473, 1.7964)
    assert (paper.crank_inertia, paper.rod_inertia, paper.slider_inertia) == (1.931e-3, 2.233e-4, 3.431e-4)
    assert paper.joint_B.clearance == pytest.approx(5e-4) and paper.joint_C.clearance == pytest.approx(5e-4)
    assert paper.crank_speed == pytest.approx(62.83185307)
    assert isinstance(paper.contact.law, jc.laws.Hybrid)


def test_cli_simulate_writes_run_directory(tmp_path):
    out = tmp_path / "run"
    rc = cli.main(
        [
            "simulate",
            "--out",
            str(out),
            "--t1",
            "0.01",
            "--samples-per-degree",
            "1",
            "--quiet",
            "--set",
            "friction.coefficient=0.05",
        ]
    )
    assert rc == 0
    header = (out / "trajectory.csv").read_text().splitlines()[0].split(",")
    required = (
        "t crank_angle rod_x rod_vx rod_ax slider_x slider_vx slider_ax ideal_rod_x ideal_rod_vx "
        "ideal_rod_ax ideal_slider_x ideal_slider_vx ideal_slider_ax ecc_B_x ecc_B_y ecc_C_x ecc_C_y "
        "force_B_normal force_C_normal driving_moment ideal_driving_moment transmission_angle "
        "ideal_transmission_angle"
    ).split()
    assert set(required) <= set(header)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["solver"]["steps"] > 0 and "rms_transmission_angle_error_deg" in summary["metrics"]
    assert len(list((out / "figures").glob("*.png"))) == 7
    # config.toml reproduces the run's parameters
    assert config.load(out / "config.toml").friction.coefficient == 0.05


def test_cli_bad_input_exits_with_message(tmp_path, capsys):
    rc = cli.main(["simulate", "--out", str(tmp_path), "--set", "contact.restitution=2", "--quiet"])
    assert rc == 2
    assert "restitution" in capsys.readouterr().err
