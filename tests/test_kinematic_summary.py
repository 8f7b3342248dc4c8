"""The kinematic summary of the ideal mechanism against closed forms: the offset
slider-crank's stroke, dead centres, time ratio and transmission angle; the crank-shaper's
swing and 2:1 time ratio; the crank-rocker's swing and extreme transmission angles; the
Grashof type of every four-bar loop (crank-rocker, double-crank, double-rocker,
triple-rocker, change point, and the two loops of a Watt six-bar).

Tolerances: with 3600 samples (h = 0.1 deg) the parabola through three samples puts an
extremum's driver angle within O(h^2) of the true one (about 1e-5 deg here) and its value
within O(h^3) (relative 1e-11 here); each tolerance below is about ten times the error
measured, so a change of method (or a lost refinement, 0.05 deg) fails them."""

import json
import math
from pathlib import Path

import numpy as np
import pytest

import jaxcrank as jc
from jaxcrank.analysis.kinematic_summary import format_summary, grashof_loops, kinematic_summary
from jaxcrank.runs.config import load

LINKAGES = Path(__file__).resolve().parents[1] / "docs" / "linkages"
LENGTHS = ("ground_length", "crank_length", "coupler_length", "rocker_length")


def _four_bar(d, a, b, c):
    """The preset four-bar with ground, crank, coupler and rocker lengths d, a, b, c (m),
    set past the preset's crank-rocker check."""
    return jc.set_parameters(jc.four_bar(), LENGTHS, [d, a, b, c], check=False)


def _turn(a, b):
    """|a - b| for driver angles, deg, modulo a turn."""
    return abs((a - b + 180.0) % 360.0 - 180.0)


@pytest.fixture(scope="module")
def summaries():
    """Summaries by name, each computed once (one compilation per structure)."""
    cache = {}

    def get(name):
        if name not in cache:
            mech = load(LINKAGES / f"{name}.toml") if (LINKAGES / f"{name}.toml").exists() else jc.preset(name)
            cache[name] = kinematic_summary(mech)
        return cache[name]

    return get


# --------------------------------------------------------------------------- closed forms


def test_offset_slider_crank_against_closed_form(summaries):
    """The paper's slider-crank (crank L1, rod L2, slider line y = e > 0, crank turning
    counter-clockwise from the x axis): the slider is farthest out where crank and rod are
    extended along one line, at crank angle asin(e / (L1 + L2)), nearest where they fold,
    at 180 deg + asin(e / (L2 - L1)); stroke sqrt((L1 + L2)^2 - e^2) - sqrt((L2 - L1)^2 -
    e^2). Measured: stroke 6e-12 relative, dead centres 7e-6 deg, time ratio 1e-7 relative."""
    mech = jc.preset("paper")
    l1, l2, e = (jc.get_parameter(mech, n) for n in ("crank_length", "rod_length", "offset"))
    s = summaries("paper")
    out, ratio = s["output"], s["time_ratio"]
    assert (out["body"], out["coordinate"], out["full_rotation"]) == ("slider", "x", False)
    stroke = math.sqrt((l1 + l2) ** 2 - e**2) - math.sqrt((l2 - l1) ** 2 - e**2)
    assert out["stroke_m"] == pytest.approx(stroke, rel=1e-10)
    assert out["max_m"] == pytest.approx(math.sqrt((l1 + l2) ** 2 - e**2), rel=1e-10)
    assert out["min_m"] == pytest.approx(math.sqrt((l2 - l1) ** 2 - e**2), rel=1e-10)
    extended = math.degrees(math.asin(e / (l1 + l2)))
    folded = 180.0 + math.degrees(math.asin(e / (l2 - l1)))
    assert _turn(out["max_at_driver_deg"], extended) < 1e-4
    assert _turn(out["min_at_driver_deg"], folded) < 1e-4
    forward = 360.0 - folded + extended  # slider out: from the folded to the extended dead centre
    assert ratio["forward_stroke_deg"] == pytest.approx(forward, abs=1e-4)
    assert ratio["return_stroke_deg"] == pytest.approx(360.0 - forward, abs=1e-4)
    assert ratio["slower_stroke"] == "return"  # e > 0: the return sweeps the larger angle
    assert ratio["ratio"] == pytest.approx((360.0 - forward) / forward, rel=1e-6)
    # the transmission angle: 90 deg + the rod's angle, sin(rod) = (e - L1 sin(crank)) / L2
    mu = s["transmission_angle"]
    assert mu["min_deg"] == pytest.approx(90.0 + math.degrees(math.asin((e - l1) / l2)), abs=1e-9)
    assert mu["max_deg"] == pytest.approx(90.0 + math.degrees(math.asin((e + l1) / l2)), abs=1e-9)
    assert _turn(mu["min_at_driver_deg"], 90.0) < 1e-6 and _turn(mu["max_at_driver_deg"], 270.0) < 1e-6
    assert mu["max_deviation_from_90_deg"] == pytest.approx(math.degrees(math.asin((e + l1) / l2)), abs=1e-9)
    assert s["grashof"] == []  # its loop has a prismatic joint
    assert (s["samples"], s["driver_angle_start_deg"], s["driver_body"]) == (3600, 0.0, "crank")


def test_extremum_angle_error_shrinks_as_the_sample_spacing_squared():
    """The contract's resolution: ten times the samples, up to a hundred times less error in
    a dead centre's driver angle (O(h^2), its factor set by where the extreme falls between
    samples: measured 3.4e-4 and 6.5e-6 deg, 52 times less); 30 times less is required."""
    mech = jc.preset("paper")
    l1, l2, e = (jc.get_parameter(mech, n) for n in ("crank_length", "rod_length", "offset"))
    folded = 180.0 + math.degrees(math.asin(e / (l2 - l1)))
    errors = [_turn(kinematic_summary(mech, n)["output"]["min_at_driver_deg"], folded) for n in (360, 3600)]
    assert errors[1] < errors[0] / 30.0 and errors[0] < 1e-2


def test_crank_shaper_swing_and_two_to_one_time_ratio(summaries):
    """Crank r = 0.10 m about O2, 0.20 m above the lever's pivot O4: the lever swings
    2 asin(r/d) = 60 deg about the vertical, its extremes where it touches the crank circle
    (crank at 330 and 210 deg), and the cutting stroke takes 180 + 60 deg of the crank, the
    return 180 - 60: time ratio 2. The lever's angle is far from a parabola at its extremes
    (it turns back where the lever touches the crank circle): measured 5e-5 deg off at each
    extreme, 1.3e-6 relative in the ratio; swing 3e-11 deg."""
    s = summaries("crank-shaper")
    out, ratio = s["output"], s["time_ratio"]
    assert (out["body"], out["coordinate"]) == ("lever", "angle")
    assert out["swing_deg"] == pytest.approx(2.0 * math.degrees(math.asin(0.10 / 0.20)), abs=1e-9)
    assert out["min_deg"] == pytest.approx(60.0, abs=1e-9) and out["max_deg"] == pytest.approx(120.0, abs=1e-9)
    assert _turn(out["min_at_driver_deg"], 330.0) < 5e-4 and _turn(out["max_at_driver_deg"], 210.0) < 5e-4
    assert ratio["forward_stroke_deg"] == pytest.approx(240.0, abs=1e-3)
    assert ratio["slower_stroke"] == "forward"
    assert ratio["ratio"] == pytest.approx(2.0, rel=1e-5)
    assert s["grashof"] == []


@pytest.mark.parametrize("name", ["four-bar", "crank-rocker"])
def test_crank_rocker_against_closed_form(summaries, name):
    """Ground d = 0.40, crank a = 0.10, coupler b = 0.35, rocker c = 0.30 m: the rocker's
    extremes where crank and coupler are collinear (|AC| = b + a, b - a: cos(psi) =
    (|AC|^2 - d^2 - c^2) / (2 d c)), the transmission angle's where crank and ground are
    (crank at 0 and 180 deg: cos(mu) = (b^2 + c^2 - (d -/+ a)^2) / (2 b c)); one loop, a
    Grashof crank-rocker with the points' distances as link lengths."""
    d, a, b, c = 0.40, 0.10, 0.35, 0.30
    s = summaries(name)
    psi = {r: math.acos((r**2 - d**2 - c**2) / (2 * d * c)) for r in (b + a, b - a)}
    out = s["output"]
    assert out["min_deg"] == pytest.approx(math.degrees(psi[b + a]), abs=1e-8)
    assert out["max_deg"] == pytest.approx(math.degrees(psi[b - a]), abs=1e-8)
    rocker_pin = {r: (d + c * math.cos(p), c * math.sin(p)) for r, p in psi.items()}
    extended = math.degrees(math.atan2(rocker_pin[b + a][1], rocker_pin[b + a][0]))
    folded = math.degrees(math.atan2(-rocker_pin[b - a][1], -rocker_pin[b - a][0]))
    assert _turn(out["min_at_driver_deg"], extended) < 1e-4 and _turn(out["max_at_driver_deg"], folded) < 1e-4
    forward = (folded - extended) % 360.0
    assert s["time_ratio"]["ratio"] == pytest.approx(
        max(forward, 360 - forward) / min(forward, 360 - forward), rel=1e-6
    )
    mu = s["transmission_angle"]
    for key, r in (("min_deg", d - a), ("max_deg", d + a)):
        assert mu[key] == pytest.approx(math.degrees(math.acos((b**2 + c**2 - r**2) / (2 * b * c))), abs=1e-9)
    [loop] = s["grashof"]
    assert loop["type"] == "crank-rocker" and loop["grashof"] and loop["shortest_link"] == "crank"
    assert [x["body"] for x in loop["links"]] == ["crank", "coupler", "rocker", "ground"]
    assert [x["length_m"] for x in loop["links"]] == pytest.approx([a, b, c, d], abs=1e-15)
    assert loop["s_plus_l_m"] == pytest.approx(a + d) and loop["p_plus_q_m"] == pytest.approx(b + c)
    assert loop["joints"] == (["A", "B", "C", "D"] if name == "four-bar" else ["O2", "A", "B", "O4"])


# --------------------------------------------------------------------------- Grashof types


def test_double_crank_turns_its_output_fully():
    """Ground shortest (d = 0.10 m; a, b, c = 0.30, 0.35, 0.40 m): a double-crank, whose
    rocker turns fully, so it has no swing extremes and no time ratio."""
    s = kinematic_summary(_four_bar(0.10, 0.30, 0.35, 0.40))
    [loop] = s["grashof"]
    assert (loop["type"], loop["shortest_link"], loop["longest_link"]) == ("double-crank", "ground", "rocker")
    assert s["output"]["full_rotation"] and s["output"]["swing_deg"] == 360.0 and s["output"]["max_deg"] is None
    assert s["time_ratio"] is None
    assert "turns through whole revolutions" in format_summary(s)[0]


@pytest.mark.parametrize(
    "lengths, kind, grashof",
    [
        ((0.40, 0.30, 0.10, 0.35), "double-rocker", True),  # the coupler shortest
        ((0.40, 0.30, 0.35, 0.30), "non-Grashof triple-rocker", False),  # s + l = 0.70 > 0.65 m
        ((0.40, 0.10, 0.35, 0.15), "change point", True),  # s + l = p + q = 0.50 m
        ((0.40, 0.35, 0.30, 0.10), "crank-rocker", True),  # the rocker shortest: it is the crank
    ],
)
def test_grashof_types_from_the_lengths(lengths, kind, grashof):
    """The loop's type from the standard rules, whether or not the crank can turn (the
    topology and the points alone)."""
    [loop] = grashof_loops(_four_bar(*lengths))
    assert (loop["type"], loop["grashof"]) == (kind, grashof)
    d, a, b, c = lengths
    assert [x["length_m"] for x in loop["links"]] == pytest.approx([a, b, c, d], abs=1e-15)


def test_a_crank_that_cannot_turn_is_a_clear_error():
    with pytest.raises(jc.ParameterError, match="assembled"):
        kinematic_summary(_four_bar(0.40, 0.30, 0.10, 0.35))


def test_watt_six_bar_has_two_four_bar_loops(summaries):
    """A crank-rocker O2-B-C-O4 (0.10, 0.35, 0.30, 0.40 m) and the second loop O4-D-E-O6
    through the ternary rocker: |O4 D| = 0.2, |D E| = 0.32, |E O6| = 0.25 and the ground
    |O4 O6| = hypot(0.35, 0.25) m, s + l = 0.630 > p + q = 0.57 m: a triple-rocker. The
    Stephenson six-bar has one: its other loops have five links."""
    first, second = summaries("watt-six-bar")["grashof"]
    assert (first["joints"], first["type"]) == (["O2", "B", "C", "O4"], "crank-rocker")
    assert [x["length_m"] for x in first["links"]] == pytest.approx([0.10, 0.35, 0.30, 0.40], abs=1e-15)
    assert second["joints"] == ["O4", "D", "E", "O6"]
    assert [x["body"] for x in second["links"]] == ["rocker", "link5", "output", "ground"]
    assert [x["length_m"] for x in second["links"]] == pytest.approx(
        [0.2, 0.32, 0.25, math.hypot(0.35, 0.25)], abs=1e-5
    )
    assert second["type"] == "non-Grashof triple-rocker" and not second["grashof"]
    [loop] = summaries("stephenson-six-bar")["grashof"]
    assert (loop["joints"], loop["type"]) == (["O2", "B", "C", "O4"], "crank-rocker")


# --------------------------------------------------------------------------- every mechanism, the lines, bad input


def _plain(x):
    """Whether ``x`` holds only JSON's plain Python types, every number finite."""
    if isinstance(x, dict):
        return all(isinstance(k, str) and _plain(v) for k, v in x.items())
    if isinstance(x, list):
        return all(_plain(v) for v in x)
    if isinstance(x, float):
        return math.isfinite(x)
    return x is None or type(x) in (str, int, bool)


@pytest.mark.parametrize("name", [*jc.PRESETS, "watt-six-bar", "stephenson-six-bar"])
def test_every_mechanism_gives_a_plain_finite_summary(summaries, name):
    s = summaries(name)
    assert _plain(s), s
    assert json.loads(json.dumps(s, allow_nan=False)) == s
    assert s["output"] is not None and s["transmission_angle"] is not None
    assert 0.0 <= s["transmission_angle"]["min_deg"] <= s["transmission_angle"]["max_deg"] <= 180.0
    for key in ("min_at_driver_deg", "max_at_driver_deg"):
        assert 0.0 <= s["output"][key] < 360.0 and 0.0 <= s["transmission_angle"][key] < 360.0
    assert s["time_ratio"]["ratio"] >= 1.0
    assert s["time_ratio"]["forward_stroke_deg"] + s["time_ratio"]["return_stroke_deg"] == pytest.approx(360.0)
    assert all(isinstance(line, str) and line for line in format_summary(s))


def test_format_summary_names_units(summaries):
    paper = format_summary(summaries("paper"))
    assert paper[0].startswith("output slider x: stroke 302.7 mm (min at 191.4 deg, max at 5.2 deg of the crank)")
    assert paper[1].startswith("time ratio 1.071") and "forward stroke 173.8 deg, return 186.2 deg" in paper[1]
    assert paper[2].startswith("transmission angle 75.6 .. 119.8 deg (min at 90.0 deg")
    assert paper[3].startswith("four-bar loops: none")
    rocker = format_summary(summaries("crank-rocker"))
    assert rocker[0].startswith("output rocker angle: swing 39.96 deg")
    assert rocker[-1] == "four-bar loop O2-A-B-O4: Grashof crank-rocker (s + l = 0.5 < p + q = 0.65 m)"
    watt = format_summary(summaries("watt-six-bar"))
    assert watt[-1] == "four-bar loop O4-D-E-O6: non-Grashof triple-rocker (s + l = 0.6301 > p + q = 0.57 m)"
    for line in paper[:3] + rocker + watt:
        assert any(unit in line for unit in (" mm", " deg", " m)")), line


@pytest.mark.parametrize("samples", [7, 0, -1, 100.0, True, "3600"])
def test_bad_samples_name_the_parameter_and_range(samples):
    with pytest.raises(jc.ParameterError, match=r"samples = .* valid range: an integer >= 8"):
        kinematic_summary(jc.preset("paper"), samples)


def test_not_a_mechanism_is_a_type_error():
    with pytest.raises(TypeError, match="expected a mechanism"):
        kinematic_summary("paper")


def test_samples_start_at_the_driver_initial_angle():
    """A driver started 30 deg on: the same motion, its driver angles 30 deg earlier."""
    mech = jc.set_parameter(jc.preset("paper"), "driver.initial_angle", math.radians(30.0))
    s, base = kinematic_summary(mech, 360), kinematic_summary(jc.preset("paper"), 360)
    assert s["driver_angle_start_deg"] == pytest.approx(30.0)
    assert s["output"]["stroke_m"] == pytest.approx(base["output"]["stroke_m"], rel=1e-12)
    assert _turn(s["output"]["max_at_driver_deg"] + 30.0, base["output"]["max_at_driver_deg"]) < 1e-9
    assert np.isclose(s["time_ratio"]["ratio"], base["time_ratio"]["ratio"], rtol=1e-12)


def test_a_driver_angle_is_printed_within_one_turn():
    """359.97 deg prints as 0.0 (the turn's start), not 360.0."""
    from jaxcrank.analysis.kinematic_summary import _at

    assert (_at(359.97), _at(359.94), _at(0.04)) == ("0.0", "359.9", "0.0")
