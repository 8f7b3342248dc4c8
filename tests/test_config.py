"""TOML configs and --set overrides take the library's parameter names (jaxcrank.runs.config)."""

import pytest

import jaxcrank as jc
from jaxcrank.physics.params import ParameterError, get_parameter, set_parameter
from jaxcrank.runs import config


@pytest.mark.parametrize("name", ["clearance_B", "clearance_C"])
def test_clearance_override_matches_the_library(name):
    """--set clearance_X=c gives the mechanism of set_parameter (hole kept, pin shrunk)."""
    c = 2.0e-4
    mech = config.apply_overrides(jc.paper(), [f"{name}={c!r}"])
    expected = set_parameter(jc.paper(), name, c)
    assert config.to_dict(mech) == config.to_dict(expected)
    assert get_parameter(mech, name) == pytest.approx(c, rel=0.0, abs=1e-18)


def test_clearance_uses_the_hole_radius_set_beside_it():
    mech = config.apply_overrides(jc.paper(), ["joint_C.hole_radius=0.01", "clearance_C=3e-4"])
    assert float(mech.joint_C.hole_radius) == 0.01
    assert get_parameter(mech, "clearance_C") == pytest.approx(3e-4, rel=0.0, abs=1e-15)


def test_clearance_in_a_toml_file(tmp_path):
    path = tmp_path / "c.toml"
    path.write_text("clearance_B = 1e-4\n[contact]\nrestitution = 0.7\n")
    mech = config.load(path)
    assert get_parameter(mech, "clearance_B") == pytest.approx(1e-4, rel=0.0, abs=1e-15)
    assert float(mech.contact.restitution) == 0.7


@pytest.mark.parametrize(
    "overrides, needle",
    [
        (["clearance_B=0"], "clearance_B = 0 m is out of range"),
        (["clearance_C=0.008"], "joint_C.hole_radius"),
        (["clearance_B=-1e-4"], "out of range"),
        (["clearance_B=1e-4", "joint_B.pin_radius=0.0075"], "both set the pin radius"),
        (["clearance_B=tight"], "clearance_B must be a number"),
        (["clearance_D=1e-4"], "unknown parameter 'clearance_D'"),
    ],
)
def test_bad_clearances_are_named(overrides, needle):
    with pytest.raises(ParameterError, match=needle):
        config.apply_overrides(jc.paper(), overrides)


def test_simulate_and_steady_read_the_same_mechanism_options(tmp_path):
    """``--design`` (an optimiser's result.json), then ``--set`` and ``--rpm`` on top, the
    same for ``jaxcrank simulate`` and ``jaxcrank steady``; --config and --design exclude
    each other."""
    import argparse
    import json
    import math

    from jaxcrank.runs import steady_cli

    design = set_parameter(jc.paper(), "rod_mass", 1.7)
    result = tmp_path / "result.json"
    result.write_text(json.dumps({"final_mechanism": config.to_dict(design)}))
    argv = ["--design", str(result), "--set", "slider_mass=0.9", "--rpm", "300"]
    parsers = [argparse.ArgumentParser(), argparse.ArgumentParser()]
    config.add_mechanism_arguments(parsers[0], "simulate")
    steady_cli.add_arguments(parsers[1])
    for p in parsers:
        mech = config.mechanism_from_arguments(p.parse_args(argv))
        assert float(get_parameter(mech, "rod_mass")) == 1.7
        assert float(get_parameter(mech, "slider_mass")) == 0.9
        assert math.isclose(float(mech.crank_speed), 10.0 * math.pi, rel_tol=1e-15)
        with pytest.raises(SystemExit):
            p.parse_args(["--design", str(result), "--config", str(result)])
