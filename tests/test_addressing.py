"""One home for parameter addressing: every clearance joint of every preset (pins in
holes, dry or lubricated, and a slider with play in its guide) has its clearance set by
``clearance_<joint>`` through the library (``set_parameter``), the command line
(``--set``), a sweep spec and a design variable, and each route gives the same
mechanism, the joint's clearance the value asked for."""

import jax
import numpy as np
import pytest

import jaxcrank as jc
from jaxcrank.physics.parameters import set_parameter
from jaxcrank.runs import cli, config, spec
from optim import cli as optim_cli

CASES = [
    (name, joint)
    for name in jc.PRESETS
    for joint, law in sorted(jc.preset(name).joints.items())
    if not isinstance(law, jc.Ideal)
]


def test_every_preset_has_a_clearance_joint_and_a_guide_is_among_them():
    assert {name for name, _ in CASES} == set(jc.PRESETS)
    assert ("paper-guide", "guide") in CASES and ("paper-lubricated", "C") in CASES


@pytest.mark.parametrize("name, joint", CASES)
def test_a_clearance_is_set_the_same_way_by_every_route(name, joint):
    base = jc.preset(name)
    value = 0.5 * float(base.joints[joint].clearance)  # inside every law's range
    parameter = f"clearance_{joint}"

    library = set_parameter(base, parameter, value)
    assert float(library.joints[joint].clearance) == pytest.approx(value, rel=1e-12)

    args = _simulate_arguments(["--mechanism", name, "--set", f"{parameter}={value!r}"])
    command_line = config.mechanism_from_arguments(args)

    sweep = spec.spec_from_dict({"mechanism": name, "parameters": {parameter: {"values": [value]}}})
    assert sweep.names == [parameter]
    swept = jc.set_parameters(sweep.base, sweep.names, sweep.designs[0])

    problem, _ = optim_cli.build(
        {
            "problem": "tolerance",
            "mechanism": config.to_dict(base),
            "design": {
                "names": [parameter],
                "lower": [0.25 * value],
                "upper": [4.0 * value],
                "A": [],
                "b": [],
                "start": [value],
            },
        }
    )
    designed = problem.mechanism([value])

    for route, mech in (("--set", command_line), ("sweep spec", swept), ("design variable", designed)):
        assert float(mech.joints[joint].clearance) == pytest.approx(value, rel=1e-12), route
        leaves, structure = jax.tree.flatten(mech.joints[joint])
        expected, expected_structure = jax.tree.flatten(library.joints[joint])
        assert structure == expected_structure, route
        for leaf, want in zip(leaves, expected):  # leaves are numbers, or arrays (a worn joint's profiles)
            np.testing.assert_allclose(np.asarray(leaf, float), np.asarray(want, float), rtol=1e-15, err_msg=route)


def _simulate_arguments(argv):
    return cli.parser("simulate").parse_args(["simulate", *argv])
