"""TOML configs and --set overrides take the library's parameter names (jaxcrank.runs.config),
and every mechanism goes to TOML and back (jaxcrank.runs.codec)."""

import math
from pathlib import Path

import equinox as eqx
import pytest

import jaxcrank as jc
from jaxcrank.physics.guide import GuideClearance
from jaxcrank.physics.lubrication import Lubricated
from jaxcrank.physics.memory import ForgettingMemory, FrozenMemory
from jaxcrank.physics.params import ParameterError
from jaxcrank.physics.presets import paper_guide
from jaxcrank.runs import config

get_parameter, set_parameter = jc.get_parameter, jc.set_parameter
DOCS = Path(__file__).resolve().parents[1] / "docs"


@pytest.mark.parametrize("name", ["clearance_B", "clearance_C"])
def test_clearance_override_matches_the_library(name):
    """--set clearance_X=c gives the mechanism of set_parameter (hole kept, pin shrunk)."""
    c = 2.0e-4
    mech = config.apply_overrides(jc.paper(), [f"{name}={c!r}"])
    expected = set_parameter(jc.paper(), name, c)
    assert config.to_dict(mech) == config.to_dict(expected)
    assert get_parameter(mech, name) == pytest.approx(c, rel=0.0, abs=1e-18)


def test_clearance_uses_the_hole_radius_set_beside_it():
    mech = config.apply_overrides(jc.paper(), ["joints.C.hole_radius=0.01", "clearance_C=3e-4"])
    assert float(mech.joints["C"].hole_radius) == 0.01
    assert get_parameter(mech, "clearance_C") == pytest.approx(3e-4, rel=0.0, abs=1e-15)


def test_clearance_in_a_toml_file(tmp_path):
    path = tmp_path / "c.toml"
    path.write_text('mechanism = "slider-crank"\nclearance_B = 1e-4\n[contact]\nrestitution = 0.7\n')
    mech = config.load(path)
    assert get_parameter(mech, "clearance_B") == pytest.approx(1e-4, rel=0.0, abs=1e-15)
    assert float(mech.joints["B"].contact.restitution) == float(mech.joints["C"].contact.restitution) == 0.7


@pytest.mark.parametrize(
    "name, value",
    [
        ("contact.restitution", 0.6),
        ("friction.coefficient", 0.2),
        ("memory.memory_time", 2e-5),
        ("pin_material.youngs_modulus", 1e11),
        ("hole_material.poisson_ratio", 0.25),
    ],
)
def test_tied_overrides_match_the_library(name, value):
    """``--set contact.restitution=...`` is set_parameter's tied name: every joint that has it."""
    mech = config.apply_overrides(jc.paper(), [f"{name}={value!r}"])
    assert eqx.tree_equal(mech, set_parameter(jc.paper(), name, value)) is True
    assert get_parameter(mech, f"joints.B.{name}") == get_parameter(mech, f"joints.C.{name}") == value


@pytest.mark.parametrize("name", ["bodies.coupler.points.B.x", "bodies.coupler.centre_of_mass.y", "ground.O4.x"])
def test_a_coordinate_override_matches_the_library(name):
    """``--set bodies.coupler.points.B.x=...`` sets that coordinate of a written-out linkage, as
    set_parameter's name does, and leaves the other coordinate."""
    base = config.load(DOCS / "linkages" / "crank-rocker.toml")
    value = get_parameter(base, name) + 0.01
    mech = config.apply_overrides(base, [f"{name}={value!r}"])
    assert config.to_dict(mech) == config.to_dict(set_parameter(base, name, value))
    other = name[:-1] + ("y" if name.endswith("x") else "x")
    assert get_parameter(mech, other) == get_parameter(base, other)
    with pytest.raises(ParameterError, match="ground.O4"):
        config.apply_overrides(base, ["ground.O4.z=0.4"])


def test_a_guides_clearance_is_its_gap():
    mech = config.apply_overrides(paper_guide(), ["clearance_guide=1e-4"])
    assert float(mech.joints["guide"].clearance) == 1e-4
    assert eqx.tree_equal(mech, jc.with_clearance(paper_guide(), guide=1e-4))


@pytest.mark.parametrize(
    "overrides, needle",
    [
        (["clearance_B=0"], "clearance_B = 0 m is out of range"),
        (["clearance_C=0.008"], "joints.C.hole_radius"),
        (["clearance_B=-1e-4"], "out of range"),
        (["clearance_B=1e-4", "joints.B.pin_radius=0.0075"], "both set the pin radius"),
        (["clearance_B=tight"], "clearance_B must be a number"),
        (["clearance_D=1e-4"], "unknown parameter 'clearance_D'"),
        (["clearance_A=1e-4"], "joint 'A' is ideal"),
        (["joints.B=3", "clearance_B=1e-4"], r"\[joints.B\] must be a table"),
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
        assert math.isclose(float(mech.driver.speed), 10.0 * math.pi, rel_tol=1e-15)
        with pytest.raises(SystemExit):
            p.parse_args(["--design", str(result), "--config", str(result)])


def test_mechanism_option_picks_a_preset():
    import argparse

    p = argparse.ArgumentParser()
    config.add_mechanism_arguments(p, "simulate")
    mech = config.mechanism_from_arguments(p.parse_args(["--mechanism", "four-bar", "--set", "clearance_C=1e-4"]))
    assert isinstance(mech, jc.FourBar) and get_parameter(mech, "clearance_C") == pytest.approx(1e-4, abs=1e-15)
    with pytest.raises(SystemExit):
        p.parse_args(["--mechanism", "crank-rocker"])


# ------------------------------------------------------------------ round trips


def _round_trips():
    paper = jc.paper()
    return {
        "paper": paper,
        "four-bar": jc.four_bar(),
        "paper-guide": paper_guide(),
        "paper written out": paper.linkage(),
        "four-bar written out": jc.four_bar().linkage(),
        "forgetting memory": eqx.tree_at(lambda m: m.joints["B"].memory, paper, ForgettingMemory(tau=0.01)),
        "lubricated": eqx.tree_at(
            lambda m: m.joints["C"], paper, Lubricated(hole_radius=8e-3, pin_radius=7.5e-3, viscosity=0.05, length=0.02)
        ),
        "speed profile": jc.SliderCrank(
            driver=jc.SpeedProfile(body="crank", speed=60.0, initial_angle=0.3, cosine=(0.1,), sine=(0.05, 0.02))
        ),
        "torque": jc.SliderCrank(driver=jc.Torque(body="crank", torque=1.5, initial_speed=60.0)),
        "laws by name": config.apply_overrides(paper, ["contact.law=flores", "friction.law=ambrosio", "gravity=0"]),
        "one ideal pin": config.apply_overrides(jc.four_bar(), ["joints.B.law=ideal"]),
        "a slanted guide": _slanted(),
    }


def _slanted():
    """A slider-crank written out with a guide at 30 deg through (0.05, 0.02), a body
    guess, and a guide clearance."""
    lk = jc.paper().linkage()
    guide = jc.Prismatic(
        guide=jc.Site("ground", "guide"), slider=jc.Site("slider", "C"), direction=math.pi / 6, angle=math.pi / 6
    )
    lk = eqx.tree_at(lambda m: m.connections["guide"], lk, guide)
    lk = eqx.tree_at(lambda m: m.ground["guide"], lk, jc.Point(0.05, 0.02))
    lk = eqx.tree_at(lambda m: m.bodies["rod"].guess, lk, jc.Pose(0.3, 0.1, 0.2), is_leaf=lambda x: x is None)
    return eqx.tree_at(lambda m: m.joints["guide"], lk, GuideClearance(length=0.04, height=0.026))


@pytest.mark.parametrize("name", list(_round_trips()))
def test_every_mechanism_goes_to_toml_and_back(name, tmp_path):
    mech = _round_trips()[name]
    path = tmp_path / "m.toml"
    config.save(mech, path)
    again = config.load(path)
    assert type(again) is type(mech)
    assert eqx.tree_equal(mech, again) is True
    assert config.to_dict(again) == config.to_dict(mech)


def test_a_joint_table_completes_the_presets_law():
    """A file's ``[joints.B]`` with a few settings keeps the preset's law and its other
    settings; a table that names another law replaces it."""
    mech = config.from_dict({"joints": {"B": {"pin_radius": 7.9e-3, "contact": {"restitution": 0.5}}}})
    law = mech.joints["B"]
    assert isinstance(law, jc.Clearance) and float(law.hole_radius) == 8e-3 and float(law.pin_radius) == 7.9e-3
    assert float(law.contact.restitution) == 0.5 and isinstance(law.contact.law, jc.laws.Hybrid)
    assert eqx.tree_equal(mech.joints["C"], jc.paper().joints["C"]) is True
    assert config.from_dict({"joints": {"B": {"law": "ideal"}}}).joints["B"].ideal
    with pytest.raises(ParameterError, match="joints.A.pin_radius; the Ideal law takes no parameters"):
        config.from_dict({"joints": {"A": {"pin_radius": 7e-3}}})


def test_overrides_that_switch_a_law_drop_its_old_settings():
    """``joints.C.law=ideal`` beside the tied ``contact.law=flores``: C is ideal, B gets the
    law; ``memory.law=forgetting`` replaces the frozen memory with the forgetting one's defaults."""
    mech = config.apply_overrides(jc.paper(), ["joints.C.law=ideal", "contact.law=flores"])
    assert mech.joints["C"].ideal and isinstance(mech.joints["B"].contact.law, jc.laws.Flores)
    mech = config.apply_overrides(jc.paper(), ["memory.law=forgetting", "memory.tau=0.05"])
    for j in "BC":
        assert eqx.tree_equal(mech.joints[j].memory, ForgettingMemory(tau=0.05)) is True
    back = config.apply_overrides(mech, ["joints.B.memory.law=frozen"])
    assert eqx.tree_equal(back.joints["B"].memory, FrozenMemory()) is True


def test_a_linkage_written_in_toml(tmp_path):
    """A four-bar written out body by body in a file, with the tied ``[contact]`` table and
    a clearance shorthand, is the preset's linkage."""
    path = tmp_path / "fourbar.toml"
    path.write_text(
        """mechanism = "linkage"
name = "four-bar"
clearance_C = 5e-4
[contact]
restitution = 0.7
[ground]
A = [0.0, 0.0]
D = [0.4, 0.0]
[bodies.crank]
mass = 0.5
inertia = 0.00041666666666666675
points = {A = [0.0, 0.0], B = [0.1, 0.0]}
centre_of_mass = [0.05, 0.0]
[bodies.coupler]
mass = 1.2
inertia = 0.012249999999999997
points = {B = [0.0, 0.0], C = [0.35, 0.0]}
centre_of_mass = [0.175, 0.0]
[bodies.rocker]
mass = 1.0
inertia = 0.0075
points = {D = [0.0, 0.0], C = [0.3, 0.0]}
centre_of_mass = [0.15, 0.0]
[joints.A]
type = "revolute"
hole = "ground.A"
pin = "crank.A"
[joints.B]
type = "revolute"
hole = "coupler.B"
pin = "crank.B"
law = "clearance"
hole_radius = 0.008
pin_radius = 0.0075
[joints.C]
type = "revolute"
hole = "coupler.C"
pin = "rocker.C"
law = "clearance"
hole_radius = 0.008
[joints.D]
type = "revolute"
hole = "ground.D"
pin = "rocker.D"
[driver]
type = "constant_speed"
body = "crank"
speed = 62.83185307179586
[outputs]
deviations = [["rocker", "angle"]]
acceleration = ["rocker", "angle"]
transmission = [["coupler", "C", "B"], ["rocker", "C", "D"]]
"""
    )
    mech = config.load(path)
    expected = jc.set_parameter(jc.four_bar(), "contact.restitution", 0.7).linkage()
    assert isinstance(mech, jc.Linkage)
    assert eqx.tree_equal(mech, expected) is True
