"""Drawn malformed or unassemblable linkage descriptions (hypothesis), for
tests/test_descriptions.py and bench/fuzz_descriptions.py.

Each draw takes one of the docs' linkages (docs/linkages/*.toml) and breaks it one way,
chosen so that the result is certainly not a valid mechanism: a table or key taken away,
a name or a site that points nowhere, a value of the wrong type or out of its range, a
joint that joins a body to itself, a driver on a floating body, a second ideal pivot that
fixes a body twice over, a joint taken away (the ideal mechanism then moves with two
degrees of freedom), a link too long or too short to be assembled, a law for the other
kind of joint, an unknown law, a misplaced or misspelled branch, an empty file.
"""

from __future__ import annotations

import copy
import math
import tomllib
from pathlib import Path

from hypothesis import strategies as st

LINKAGES = Path(__file__).resolve().parents[1] / "docs" / "linkages"
NAMES = ("crank-rocker", "crank-shaper", "watt-six-bar", "stephenson-six-bar")


def base(name: str) -> dict:
    return tomllib.loads((LINKAGES / f"{name}.toml").read_text())


def _revolutes(d):
    return sorted(j for j, t in d["joints"].items() if t["type"] == "revolute")


def _clearance(d):
    return sorted(j for j, t in d["joints"].items() if t.get("law") == "clearance")


def _grounded(d, j):
    t = d["joints"][j]
    return t["type"] == "revolute" and "ground" in (t["hole"].split(".")[0], t["pin"].split(".")[0])


def _driven(d):
    return d["driver"]["body"]


BAD_NUMBERS = (math.nan, math.inf, -math.inf, -1.0, 0.0, "x", [1.0, 2.0], True)


@st.composite
def breakage(draw):
    """(linkage name, how it was broken, the broken description as a dict)."""
    name = draw(st.sampled_from(NAMES))
    d = base(name)
    kind = draw(st.sampled_from(sorted(KINDS)))
    how = KINDS[kind](draw, d)
    return name, f"{kind}: {how}", d


def _missing_table(draw, d):
    key = draw(st.sampled_from(["bodies", "joints", "driver"]))
    del d[key]
    return key


def _missing_body_key(draw, d):
    body = draw(st.sampled_from(sorted(d["bodies"])))
    key = draw(st.sampled_from(["mass", "inertia"]))
    del d["bodies"][body][key]
    return f"{body}.{key}"


def _missing_joint_key(draw, d):
    joint = draw(st.sampled_from(sorted(d["joints"])))
    keys = ["type", *(["hole", "pin"] if d["joints"][joint]["type"] == "revolute" else ["guide", "slider"])]
    key = draw(st.sampled_from(keys))
    del d["joints"][joint][key]
    return f"{joint}.{key}"


def _unknown_site(draw, d):
    joint = draw(st.sampled_from(sorted(d["joints"])))
    t = d["joints"][joint]
    key = draw(st.sampled_from(["hole", "pin"] if t["type"] == "revolute" else ["guide", "slider"]))
    body, point = t[key].split(".")
    if draw(st.booleans()):
        t[key] = f"{body}x.{point}"
    else:
        t[key] = f"{body}.{point}_nowhere"
    return f"{joint}.{key} = {t[key]}"


def _malformed_site(draw, d):
    joint = draw(st.sampled_from(sorted(d["joints"])))
    t = d["joints"][joint]
    key = "hole" if t["type"] == "revolute" else "guide"
    t[key] = draw(st.sampled_from(["nodot", "a.b.c", 3.0, ["x", "y"]]))
    return f"{joint}.{key} = {t[key]!r}"


def _bad_number(draw, d):
    body = draw(st.sampled_from(sorted(d["bodies"])))
    key = draw(st.sampled_from(["mass", "inertia"]))
    d["bodies"][body][key] = draw(st.sampled_from(BAD_NUMBERS))
    return f"{body}.{key} = {d['bodies'][body][key]!r}"


def _bad_point(draw, d):
    body = draw(st.sampled_from(sorted(d["bodies"])))
    point = draw(st.sampled_from(sorted(d["bodies"][body]["points"])))
    bad = [[1.0], [1.0, 2.0, 3.0], "p", [math.nan, 0.0], [0.0, "y"]]
    d["bodies"][body]["points"][point] = draw(st.sampled_from(bad))
    return f"{body}.points.{point} = {d['bodies'][body]['points'][point]!r}"


def _bad_clearance(draw, d):
    joint = draw(st.sampled_from(_clearance(d)))
    t = d["joints"][joint]
    case = draw(st.sampled_from(["pin larger", "pin equal", "negative pin", "restitution", "friction", "contact law"]))
    if case == "pin larger":
        t["pin_radius"] = t["hole_radius"] * 1.1
    elif case == "pin equal":
        t["pin_radius"] = t["hole_radius"]
    elif case == "negative pin":
        t["pin_radius"] = -1e-3
    elif case == "restitution":
        t["contact"] = {**t.get("contact", {}), "restitution": draw(st.sampled_from([0.0, 1.5, -0.2, math.nan]))}
    elif case == "friction":
        t["friction"] = {**t.get("friction", {}), "coefficient": draw(st.sampled_from([-0.1, math.inf]))}
    else:
        t["contact"] = {**t.get("contact", {}), "law": "springy"}
    return f"{joint}: {case}"


def _self_joint(draw, d):
    joint = draw(st.sampled_from([j for j in _revolutes(d) if not d["joints"][j]["pin"].startswith("ground.")]))
    t = d["joints"][joint]
    body = t["pin"].split(".")[0]
    t["hole"] = f"{body}.{sorted(d['bodies'][body]['points'])[0]}"
    return joint


def _floating_driver(draw, d):
    pivot = next(j for j in _revolutes(d) if _grounded(d, j) and _driven(d) in (d["joints"][j]["pin"].split(".")[0],))
    del d["joints"][pivot]
    return f"{pivot} removed, driver on {_driven(d)}"


def _driver_elsewhere(draw, d):
    grounded = {
        s.split(".")[0]
        for j in _revolutes(d)
        if _grounded(d, j)
        for s in (d["joints"][j]["hole"], d["joints"][j]["pin"])
    }
    choices = sorted(set(d["bodies"]) - grounded) + ["nobody"]
    d["driver"]["body"] = draw(st.sampled_from(choices))
    return d["driver"]["body"]


def _fixed_twice(draw, d):
    joint = draw(st.sampled_from([j for j in _revolutes(d) if _grounded(d, j)]))
    t = d["joints"][joint]
    moving = next(s for s in (t["hole"], t["pin"]) if not s.startswith("ground."))
    body = moving.split(".")[0]
    other = sorted(p for p in d["bodies"][body]["points"] if p != moving.split(".")[1])[0]
    d["ground"]["extra"] = [1.234, -0.567]
    d["joints"]["extra"] = {"type": "revolute", "hole": "ground.extra", "pin": f"{body}.{other}", "law": "ideal"}
    for j in (joint, "extra"):
        for key in ("hole_radius", "pin_radius", "contact", "friction", "memory"):
            d["joints"][j].pop(key, None)
        d["joints"][j]["law"] = "ideal"
    return f"{body} pinned to the ground at {joint} and at an extra pivot"


def _joint_removed(draw, d):
    pivot = {j for j in _revolutes(d) if _grounded(d, j) and _driven(d) in d["joints"][j]["pin"]}
    joint = draw(st.sampled_from(sorted(set(d["joints"]) - pivot)))
    del d["joints"][joint]
    return joint


#: per linkage, a change of one point that leaves a dyad's links unable to reach: a link
#: far longer than the loop, or a slot whose line passes farther from the lever's pivot
#: than the crank pin ever comes
UNREACHABLE = {
    "crank-rocker": [("bodies", "coupler", "points", "B", [0.70, 0.0]), ("ground", "O4", [1.5, 0.0])],
    "crank-shaper": [("joints", "slot", "guide", "lever.tip"), ("joints", "slot", "direction", 1.5708)],
    "watt-six-bar": [("bodies", "link5", "points", "E", [1.5, 0.0]), ("ground", "O6", [3.0, 2.0])],
    "stephenson-six-bar": [("bodies", "link5", "points", "F", [1.8, 0.0]), ("ground", "O4", [2.0, 0.0])],
}


def _unreachable(draw, d):
    name = next(n for n in NAMES if base(n).get("name") == d.get("name"))
    changes = UNREACHABLE[name]
    chosen = changes if name == "crank-shaper" else [draw(st.sampled_from(changes))]
    for *path, value in chosen:
        node = d
        for part in path[:-1]:
            node = node[part]
        node[path[-1]] = value
    return "; ".join(".".join(map(str, c[:-1])) for c in chosen)


def _wrong_law(draw, d):
    joint = draw(st.sampled_from(sorted(d["joints"])))
    t = d["joints"][joint]
    for key in ("hole_radius", "pin_radius", "contact", "friction", "memory"):
        t.pop(key, None)
    if t["type"] == "revolute":
        t.update(law="guide_clearance", length=0.04, height=0.026, clearance=2.5e-4)
    else:
        t.update(law="clearance", hole_radius=8e-3, pin_radius=7.5e-3)
    return joint


def _unknown_law(draw, d):
    joint = draw(st.sampled_from(sorted(d["joints"])))
    d["joints"][joint]["law"] = draw(st.sampled_from(["rubber", "", "Ideal"]))
    return joint


def _bad_branch(draw, d):
    joint = draw(st.sampled_from(sorted(d["joints"])))
    d["joints"][joint]["branch"] = draw(st.sampled_from(["up", "0", 1.0]))
    return f"{joint}.branch = {d['joints'][joint]['branch']!r}"


def _misplaced_branch(draw, d):
    joint = draw(st.sampled_from([j for j in _revolutes(d) if _grounded(d, j)]))
    d["joints"][joint]["branch"] = "+"
    return joint


def _unknown_key(draw, d):
    where = draw(st.sampled_from(["top", "body", "joint", "driver"]))
    if where == "top":
        d["bodys"] = {}
    elif where == "body":
        d["bodies"][sorted(d["bodies"])[0]]["mas"] = 1.0
    elif where == "joint":
        d["joints"][sorted(d["joints"])[0]]["hole_radus"] = 1.0
    else:
        d["driver"]["sped"] = 1.0
    return where


def _bad_driver(draw, d):
    case = draw(st.sampled_from(["type", "speed", "initial_angle"]))
    if case == "type":
        d["driver"]["type"] = "steam"
    elif case == "speed":
        d["driver"]["speed"] = draw(st.sampled_from([0.0, -5.0, math.nan]))
    else:
        d["driver"]["initial_angle"] = math.inf
    return case


def _empty(draw, d):
    d.clear()
    return "empty"


def _no_kind(draw, d):
    d.pop("mechanism")
    d.pop("bodies")
    return "no mechanism line and no [bodies]"


def _bad_output(draw, d):
    case = draw(st.sampled_from(["body", "coordinate", "point", "shape"]))
    if case == "body":
        d["outputs"]["deviations"] = [["nobody", "angle"]]
    elif case == "coordinate":
        d["outputs"]["deviations"] = [[sorted(d["bodies"])[0], "z"]]
    elif case == "point":
        d["outputs"]["transmission"] = [[sorted(d["bodies"])[0], "nowhere", "nothing"], [sorted(d["bodies"])[0], 0.0]]
    else:
        d["outputs"]["transmission"] = [["a"]]
    return case


#: the ways a description is broken, by name
KINDS = {
    "missing table": _missing_table,
    "missing body key": _missing_body_key,
    "missing joint key": _missing_joint_key,
    "unknown site": _unknown_site,
    "malformed site": _malformed_site,
    "bad number": _bad_number,
    "bad point": _bad_point,
    "bad clearance": _bad_clearance,
    "joint on one body": _self_joint,
    "floating driven body": _floating_driver,
    "driver elsewhere": _driver_elsewhere,
    "fixed twice over": _fixed_twice,
    "joint removed": _joint_removed,
    "cannot be assembled": _unreachable,
    "law for the other kind": _wrong_law,
    "unknown law": _unknown_law,
    "bad branch": _bad_branch,
    "misplaced branch": _misplaced_branch,
    "unknown key": _unknown_key,
    "bad driver": _bad_driver,
    "empty file": _empty,
    "no kind": _no_kind,
    "bad output": _bad_output,
}


def copy_of(d: dict) -> dict:
    return copy.deepcopy(d)
