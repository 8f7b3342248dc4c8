"""Linkage descriptions: bad ones are refused with a one-line ParameterError naming the
joint, body or point; the TOML linkage printed in docs/your-own-mechanism.md is read and
run exactly as printed, and the page's names, overrides and error messages are what
jaxcrank gives."""

import copy
import json
import re
import tomllib
from pathlib import Path

import pytest
import tomli_w

import jaxcrank as jc
from jaxcrank import outputs
from jaxcrank.physics.guide import GuideClearance
from jaxcrank.runs import cli, config

PAGE = Path(__file__).resolve().parents[1] / "docs" / "your-own-mechanism.md"


def _page_block(language: str) -> str:
    """The first fenced code block of the page in ``language``, as printed."""
    found = re.search(rf"```{language}\n(.*?)```", PAGE.read_text(), flags=re.S)
    assert found, f"no {language} block on {PAGE.name}"
    return found.group(1)


def _page_linkage() -> dict:
    return tomllib.loads(_page_block("toml"))


# --------------------------------------------------------------------------- bad descriptions, in Python


def _crank_rocker(**changes):
    """The page's crank-rocker written in Python (keyword arguments of ``jc.Linkage``),
    with ``changes`` to its tables."""
    point = jc.Point
    parts = dict(
        bodies={
            "crank": jc.Body(0.5, 4.2e-4, {"O2": point(), "A": point(0.10, 0.0)}, point(0.05, 0.0)),
            "coupler": jc.Body(1.2, 1.2e-2, {"A": point(), "B": point(0.35, 0.0)}, point(0.175, 0.0)),
            "rocker": jc.Body(1.0, 7.5e-3, {"O4": point(), "B": point(0.30, 0.0)}, point(0.15, 0.0)),
        },
        ground={"O2": point(), "O4": point(0.40, 0.0)},
        connections={
            "O2": jc.Revolute(hole=jc.Site("ground", "O2"), pin=jc.Site("crank", "O2")),
            "A": jc.Revolute(hole=jc.Site("coupler", "A"), pin=jc.Site("crank", "A")),
            "B": jc.Revolute(hole=jc.Site("coupler", "B"), pin=jc.Site("rocker", "B")),
            "O4": jc.Revolute(hole=jc.Site("ground", "O4"), pin=jc.Site("rocker", "O4")),
        },
        joints={"O2": jc.Ideal(), "A": jc.Ideal(), "B": jc.Clearance(8e-3, 7.5e-3), "O4": jc.Ideal()},
        driver=jc.ConstantSpeed(body="crank", speed=62.83),
        outputs=jc.Outputs(deviations=(("rocker", "angle"),)),
    )
    for table, change in changes.items():
        parts[table] = {**parts[table], **change} if isinstance(change, dict) else change
    return parts


def _refused(build, *names_in_message):
    with pytest.raises(jc.ParameterError) as err:
        build()
    message = str(err.value)
    assert "\n" not in message, message
    for name in names_in_message:
        assert name in message, (name, message)
    return message


def test_the_python_crank_rocker_is_accepted():
    assert jc.Linkage(**_crank_rocker()).name == "linkage"


def test_a_joint_on_an_unknown_body():
    bad = jc.Revolute(hole=jc.Site("coupler", "B"), pin=jc.Site("rokker", "B"))
    _refused(lambda: jc.Linkage(**_crank_rocker(connections={"B": bad})), "joint 'B'", "unknown body 'rokker'")


def test_an_unknown_point():
    bad = jc.Revolute(hole=jc.Site("coupler", "C"), pin=jc.Site("rocker", "B"))
    _refused(lambda: jc.Linkage(**_crank_rocker(connections={"B": bad})), "joint 'B'", "'coupler'", "no point 'C'")


def _compiled(**changes):
    """The crank-rocker with ``changes``, compiled (where its structure and assembly are checked)."""
    return jc.compile_model(jc.Linkage(**_crank_rocker(**changes)))


def test_a_loop_of_ideal_joints_is_closed_in_the_dynamics():
    """With B ideal too the loop O2-A-B-O4 has no clearance joint: the coupler and the
    rocker follow the crank by a dyad, and no coordinate is left."""
    model = _compiled(joints={"B": jc.Ideal()})
    assert model.tree.n == 0 and {b for c in model.tree.closures for b in c.bodies} == {"coupler", "rocker"}


def test_a_body_fixed_twice_over():
    ground = {"O2": jc.Point(), "O4": jc.Point(0.40, 0.0), "X": jc.Point(0.40, 0.30)}
    second = jc.Revolute(hole=jc.Site("ground", "X"), pin=jc.Site("rocker", "B"))
    connections = {**_crank_rocker()["connections"], "X": second}
    joints = {**_crank_rocker()["joints"], "X": jc.Ideal()}
    message = _refused(lambda: _compiled(ground=ground, connections=connections, joints=joints), "'rocker'", "O4, X")
    assert "twice over" in message


def test_a_linkage_that_cannot_be_assembled_at_its_start_angle():
    coupler = jc.Body(1.2, 1.2e-2, {"A": jc.Point(), "B": jc.Point(0.70, 0.0)}, jc.Point(0.35, 0.0))
    message = _refused(lambda: _compiled(bodies={"coupler": coupler}), "A, B, O4")
    assert "cannot be assembled at its start angle 0 deg" in message


def test_a_crank_of_zero_length():
    """A driven body whose other joint sits on its ground pivot turns alone: refused, naming
    the body and its points."""
    crank = jc.Body(0.5, 4.2e-4, {"O2": jc.Point(), "A": jc.Point()}, jc.Point(0.05, 0.0))
    message = _refused(lambda: _compiled(bodies={"crank": crank}), "'crank'", "A", "'O2'")
    assert "zero length" in message


def test_a_driver_on_a_body_not_attached_to_the_ground():
    driver = jc.ConstantSpeed(body="coupler", speed=62.83)
    message = _refused(lambda: _compiled(driver=driver), "'coupler'")
    assert "not attached to the ground" in message
    _refused(lambda: jc.Linkage(**_crank_rocker(driver=jc.ConstantSpeed(body="wheel", speed=1.0))), "'wheel'")


def test_a_law_on_the_wrong_kind_of_joint():
    guide = GuideClearance(length=0.04, height=0.026, corner_radius=1e-3, clearance=2.5e-4)
    message = _refused(lambda: jc.Linkage(**_crank_rocker(joints={"B": guide})), "joint 'B'", "'guide_clearance'")
    assert "is revolute" in message
    pin = jc.Clearance(8e-3, 7.5e-3)
    _refused(lambda: jc.SliderCrank(joints={**jc.paper().joints, "guide": pin}).linkage(), "joint 'guide'", "prismatic")


def test_outputs_on_an_unknown_body_or_point():
    bad = jc.Outputs(deviations=(("rockr", "angle"),))
    _refused(lambda: jc.Linkage(**_crank_rocker(outputs=bad)), "'rockr'")
    vectors = (jc.BodyVector("coupler", "B", "C"), jc.BodyVector("rocker", "B", "O4"))
    _refused(lambda: jc.Linkage(**_crank_rocker(outputs=jc.Outputs(transmission=vectors))), "'coupler'", "'C'")


# --------------------------------------------------------------------------- the docs page


def test_the_pages_linkage_runs_as_printed(tmp_path):
    """The TOML block exactly as printed, through ``jaxcrank simulate --config`` for 5 ms:
    the run succeeds, and every column and metric name the page mentions is in its output."""
    path = tmp_path / "my_linkage.toml"
    path.write_text(_page_block("toml"))
    out = tmp_path / "run"
    argv = ["simulate", "--config", str(path), "--out", str(out), "--t1", "0.005", "--no-figures", "--quiet"]
    assert cli.main(argv) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["mechanism"] == "crank-rocker"
    text = PAGE.read_text()
    for name in re.findall(r"`((?:max_abs|rms|peak|max_penetration)_\w+)`", text):
        assert name in summary["metrics"], name
    columns = outputs.columns(config.load(path))
    column = r"(?:ideal_)?(?:rocker|coupler|crank)_\w+|ecc_\w+|penetration_\w+|force_\w+|slip_\w+"
    mentioned = re.findall(rf"`({column})`", text)
    assert mentioned
    for name in mentioned:
        assert name in columns, name


def test_the_pages_parameter_names_and_overrides_resolve(tmp_path):
    mech = config.from_dict(_page_linkage())
    table = PAGE.read_text().split("## Parameter names")[1].split("## Errors")[0]
    rows = [line.split("|")[1] for line in table.splitlines() if line.startswith("| `")]
    names = [n for row in rows for n in re.findall(r"`([\w.]+)`", row)]
    assert len(names) >= 15
    for name in names:
        jc.get_parameter(mech, name)
    overrides = re.findall(r"--set ([a-z][\w.]*=[^\s`]+)", table)
    assert len(overrides) == 4
    changed = config.apply_overrides(mech, overrides)
    assert abs(float(changed.joints["B"].clearance) - 2e-4) < 1e-15
    assert float(changed.bodies["rocker"].mass) == 1.5


#: the page's error table: (change to the page's linkage, the message the page prints)
def _errors():
    def set_(table_path, value):
        def change(d):
            *parents, key = table_path
            for p in parents:
                d = d[p]
            d[key] = value

        return change

    def fixed_twice(d):
        d["ground"]["X"] = [0.40, 0.30]
        d["joints"]["X"] = {"type": "revolute", "hole": "ground.X", "pin": "rocker.B", "law": "ideal"}
        d["joints"]["O4"] = {"type": "revolute", "hole": "ground.O4", "pin": "rocker.O4", "law": "ideal"}

    def empty(d):
        d.clear()

    def misplaced_branch(d):
        d["joints"]["O4"]["branch"] = "+"

    def guide_law(d):
        d["joints"]["B"] = {k: v for k, v in d["joints"]["B"].items() if k in ("type", "hole", "pin")}
        d["joints"]["B"].update(law="guide_clearance", length=0.04, height=0.026, clearance=2.5e-4)

    def rename(d):
        d["bodies"]["rocker"]["mas"] = d["bodies"]["rocker"].pop("mass")

    def lubricated_without_length(d):
        d["joints"]["B"].update(law="lubricated", viscosity=0.05)
        d["joints"]["B"].pop("length", None)

    def zero_crank(d):
        d["bodies"]["crank"]["points"]["A"] = list(d["bodies"]["crank"]["points"]["O2"])

    return [
        (set_(("joints", "B", "pin"), "rokker.B"), "a joint on a body that does not exist"),
        (set_(("joints", "B", "hole"), "coupler.C"), "a point a body does not have"),
        (empty, "a file that describes no mechanism"),
        (fixed_twice, "a body fixed twice over"),
        (misplaced_branch, "a branch where no dyad meets"),
        (set_(("bodies", "coupler", "points", "B"), [0.70, 0.0]), "links that cannot reach at the start"),
        (set_(("bodies", "coupler", "points", "B"), [0.10, 0.0]), "links that lock before a full turn"),
        (set_(("driver", "body"), "coupler"), "a driver on a body not pivoted on the ground"),
        (guide_law, "a law for the other kind of joint"),
        (set_(("outputs", "transmission"), [["coupler", "B", "C"], ["rocker", "B", "O4"]]), "an output on"),
        (set_(("bodies", "rocker", "mass"), -1.0), "a value out of its range"),
        (rename, "a key jaxcrank does not know"),
        (lubricated_without_length, "a key a law needs"),
        (zero_crank, "a crank of zero length"),
    ]


@pytest.mark.parametrize(("change", "problem"), _errors(), ids=[p for _, p in _errors()])
def test_the_pages_error_messages_are_what_jaxcrank_says(tmp_path, change, problem):
    """Each row of the page's error table, made from the page's linkage: reading it from a
    file raises a one-line ParameterError that starts with the file's name and contains
    the page's message (up to its "...")."""
    rows = PAGE.read_text().split("## Errors you may meet")[1]
    row = next(line for line in rows.splitlines() if line.startswith(f"| {problem}"))
    printed = re.findall(r"`([^`]+)`", row)[0].split(" ...")[0]
    data = copy.deepcopy(_page_linkage())
    change(data)
    path = tmp_path / "bad.toml"
    path.write_bytes(tomli_w.dumps(data).encode())
    message = _refused(lambda: config.load(path), str(path))
    assert printed in message, (printed, message)
