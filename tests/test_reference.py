"""The paper's reference values come from one packaged data file that names its source."""

import pytest

import jaxcrank as jc
from jaxcrank import reference


def test_data_file_names_its_source_and_places():
    data = reference.load()
    assert "Offset Slider-crank" in data["source"]["title"]
    for section in ("table_1", "deviations", "optimisation"):
        assert data[section]["where"]


def test_paper_preset_matches_table_1():
    t = reference.load()["table_1"]
    m = jc.paper()
    assert (m.crank_length, m.rod_length) == (t["crank_length_m"], t["rod_length_m"])
    assert (m.crank_mass, m.rod_mass, m.slider_mass) == (t["crank_mass_kg"], t["rod_mass_kg"], t["slider_mass_kg"])
    assert (m.crank_inertia, m.rod_inertia, m.slider_inertia) == (
        t["crank_inertia_kg_m2"],
        t["rod_inertia_kg_m2"],
        t["slider_inertia_kg_m2"],
    )
    for joint in (m.joints["B"], m.joints["C"]):
        assert (joint.pin_radius, joint.hole_radius) == (t["pin_radius_m"], t["hole_radius_m"])
    assert m.driver.speed == pytest.approx(t["crank_speed_rpm"] * 2 * 3.141592653589793 / 60, rel=1e-15)


def test_optimisation_reference_used_by_the_optimiser_cli():
    from optim import presets
    from optim.presets import paper_problem

    opt = reference.load()["optimisation"]
    assert presets.PAPER_OPTIMUM_DEG == opt["optimum_deg"] == 0.097966
    assert presets.PAPER_REDUCTION_PCT == opt["reduction_percent"]
    problem = paper_problem()
    assert tuple(problem.lower) == (opt["crank_length_bounds_m"][0], opt["rod_length_bounds_m"][0])
    assert tuple(problem.upper) == (opt["crank_length_bounds_m"][1], opt["rod_length_bounds_m"][1])


def test_unknown_key_names_what_exists():
    with pytest.raises(KeyError, match="optimum_deg"):
        reference.value("optimisation", "optimum")
    with pytest.raises(KeyError, match="table_1"):
        reference.value("table1", "crank_length_m")
