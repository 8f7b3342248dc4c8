"""Bad input raises a clear error naming the parameter; config round trip; CLI."""

import json

import equinox as eqx
import pytest

import jaxcrank as jc
from jaxcrank import cli, config

BAD = [
    ({"rod_length": 0.15}, "rod_length"),
    ({"offset": 0.3}, "rod_length"),
    ({"joints": {"B": {"pin_radius": 8e-3}}}, "pin_radius"),
    ({"joints": {"C": {"pin_radius": 9e-3}}}, "pin_radius"),
    ({"rod_mass": 0.0}, "rod_mass"),
    ({"slider_mass": -1.0}, "slider_mass"),
    ({"crank_mass": -0.1}, "crank_mass"),
    ({"rod_inertia": 0.0}, "rod_inertia"),
    ({"driver": {"speed": 0.0}}, "driver.speed"),
    ({"driver": {"speed": -5.0}}, "driver.speed"),
    ({"joints": {"B": {"hole_material": {"youngs_modulus": 0.0}}}}, "youngs_modulus"),
    ({"joints": {"B": {"pin_material": {"poisson_ratio": 0.5}}}}, "poisson_ratio"),
    ({"joints": {"C": {"pin_material": {"poisson_ratio": 0.0}}}}, "poisson_ratio"),
    ({"contact": {"restitution": 0.0}}, "restitution"),
    ({"contact": {"restitution": 1.2}}, "restitution"),
    ({"friction": {"coefficient": -0.1}}, "friction coefficient"),
    ({"friction": {"slip_speed": 1e-5}}, "slip_speed"),
    ({"friction": {"slip_speed": float("nan")}}, "slip_speed"),
    ({"friction": {"slip_speed": float("inf")}}, "slip_speed"),
    ({"contact": {"law": "hertzian"}}, "contact.law"),
    ({"friction": {"law": "stribeck"}}, "friction.law"),
    ({"rod_lenght": 0.4}, "rod_lenght"),
    ({"contact": {"stiffness": 1.0}}, "contact.stiffness"),
    ({"rod_length": "long"}, "rod_length"),
    ({"joints": {"B": 3.0}}, "joints.B"),
    ({"joint_B": {"pin_radius": 7e-3}}, "joint_B"),
    ({"joints": {"D": {"law": "ideal"}}}, "unknown joint 'D'"),
    ({"joints": {"B": {"law": "bushing"}}}, "joints.B.law"),
    ({"joints": {"A": {"pin_radius": 7e-3}}}, "joints.A.pin_radius"),
    ({"memory": {"law": "eternal"}}, "memory.law"),
    ({"memory": {"memory_time": 0.0}}, "memory_time"),
    ({"driver": {"type": "motor"}}, "driver.type"),
    ({"driver": {"law": "constant_speed"}}, "driver.law"),
    ({"joints": {"B": {"type": "revolute"}}}, "joints.B.type"),
    ({"joints": {"guide": {"direction": 0.1}}}, "joints.guide.direction"),
    ({"mechanism": "crank-rocker"}, "mechanism"),
    ({"mechanism": "four-bar", "rocker_length": 0.05}, "crank-rocker"),
]


@pytest.mark.parametrize("data,name", BAD, ids=[n for _, n in BAD])
def test_bad_input_names_parameter(data, name):
    with pytest.raises(jc.ParameterError, match=name):
        config.from_dict(data)


def test_errors_state_valid_range():
    with pytest.raises(jc.ParameterError, match=r"valid range.*\(0, 1\]"):
        config.from_dict({"contact": {"restitution": 1.5}})
    with pytest.raises(jc.ParameterError, match='law = "ideal"'):
        jc.Clearance(hole_radius=8e-3, pin_radius=8e-3)


def test_ideal_joint_has_no_clearance_to_set():
    mech = config.from_dict({"joints": {"C": {"law": "ideal"}}})
    assert mech.joints["C"].ideal and not mech.joints["B"].ideal
    with pytest.raises(jc.ParameterError, match="joint 'C' is ideal"):
        jc.set_parameter(mech, "clearance_C", 1e-4)


def test_malformed_toml(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text("rod_length = = 3\n")
    with pytest.raises(jc.ParameterError, match="malformed TOML"):
        config.load(path)


def test_toml_round_trip(tmp_path):
    mech = config.apply_overrides(jc.paper(), ["rod_length=0.41", "contact.law=flores", "joints.C.law=ideal"])
    path = tmp_path / "m.toml"
    config.save(mech, path)
    again = config.load(path)
    assert eqx.tree_equal(mech, again)
    assert isinstance(again.joints["B"].contact.law, jc.laws.Flores) and again.joints["C"].ideal


def test_paper_preset_values(paper):
    assert paper.crank_length == 0.150 and paper.rod_length == 0.403 and paper.offset == 0.050
    assert (paper.crank_mass, paper.rod_mass, paper.slider_mass) == (0.6967, 1.5473, 1.7964)
    assert (paper.crank_inertia, paper.rod_inertia, paper.slider_inertia) == (1.931e-3, 2.233e-4, 3.431e-4)
    assert paper.joints["B"].clearance == pytest.approx(5e-4) and paper.joints["C"].clearance == pytest.approx(5e-4)
    assert paper.joints["A"].ideal and paper.joints["guide"].ideal
    assert paper.driver.speed == pytest.approx(62.83185307) and paper.driver.initial_angle == 0.0
    for j in "BC":
        assert isinstance(paper.joints[j].contact.law, jc.laws.Hybrid)


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
    figures = {p.name for p in (out / "figures").glob("*.png")}
    assert {"rod_x.png", "slider_x.png", "contact_force.png", "bearing_loads.png", "driving_moment.png"} <= figures
    # config.toml reproduces the run's parameters
    assert all(config.load(out / "config.toml").joints[j].friction.coefficient == 0.05 for j in "BC")


def test_cli_bad_input_exits_with_message(tmp_path, capsys):
    rc = cli.main(["simulate", "--out", str(tmp_path), "--set", "contact.restitution=2", "--quiet"])
    assert rc == 2
    assert "restitution" in capsys.readouterr().err
