"""Load and save a mechanism as TOML, and apply command-line overrides.

A file is the nested dict of [`jaxcrank.runs.codec`][]: ``mechanism`` names the kind (a
preset class such as ``"slider-crank"`` or ``"four-bar"`` with its dimensions at the top
level, or ``"linkage"`` for a linkage written out body by body), ``[joints.<name>]`` the
law of each joint, ``[driver]`` what turns it. Every value is SI. Unknown keys and wrong
types are errors.

Shorthands, in a file and on the command line alike (``jaxcrank simulate --set KEY=VALUE``):

- ``clearance_<joint>``: that joint's radial clearance, m (the pin shrinks, the hole stays);
- top-level ``[contact]``, ``[friction]``, ``[memory]``, ``[pin_material]``,
  ``[hole_material]`` tables (``--set contact.law=flores``): the same settings for every
  joint whose law has them.
"""

from __future__ import annotations

import dataclasses
import tomllib
from pathlib import Path

import tomli_w

from ..physics.joints import JOINT_LAWS
from ..physics.linkage import AbstractMechanism
from ..physics.parameters import TIED_PARTS as TIED
from ..physics.parameters import with_joint_clearance
from ..physics.params import ParameterError
from . import codec


def to_dict(mech: AbstractMechanism) -> dict:
    """Nested plain-Python dict of every parameter (SI) ([`jaxcrank.runs.codec.to_dict`][])."""
    return codec.to_dict(mech)


def _law_fields(table: dict) -> set[str]:
    """The parameters of the joint law a joint table names (none for an unknown law)."""
    cls = JOINT_LAWS.get(table.get("law", "ideal"))
    return {f.name for f in dataclasses.fields(cls) if f.init} if cls is not None else set()


def _expand(data: dict, base: AbstractMechanism | None) -> tuple[dict, dict]:
    """The tied tables of the module docstring written out as joint tables, and the
    ``clearance_<joint>`` shorthands (set afterwards, by the joints' laws:
    [`jaxcrank.physics.parameters.with_joint_clearance`][])."""
    data = dict(data)
    tied = {k: data.pop(k) for k in TIED if k in data}
    clearances = {k: data.pop(k) for k in list(data) if k.startswith("clearance_")}
    given = data.get("joints") or {}
    if not isinstance(given, dict):
        raise ParameterError(f"[joints] must be a table of joint tables, got {given!r}")
    given = dict(given)
    for j, t in given.items():
        if not isinstance(t, dict):
            raise ParameterError(f"[joints.{j}] must be a table, got {t!r}")
    for key, c in clearances.items():
        if isinstance(c, bool) or not isinstance(c, (int, float)):
            raise ParameterError(f"{key} must be a number (the joint's clearance, m), got {c!r}")
        table = given.get(key[len("clearance_") :], {})
        for field, what in (("pin_radius", "the pin radius"), ("clearance", "the clearance")):
            if field in table:
                raise ParameterError(f"{key} and joints.{key[len('clearance_') :]}.{field} both set {what}: give one")
        if "hole_radius" in table and "pin_radius" not in table and isinstance(table["hole_radius"], (int, float)):
            # a pin-in-hole law written here needs its pin to be built: the clearance gives it
            given[key[len("clearance_") :]] = {**table, "pin_radius": table["hole_radius"] - c}
            data["joints"] = given
    if not tied:
        return data, clearances
    kind = data.get("mechanism")
    if base is not None and kind not in (None, codec.kind_of(base)):
        base = None  # the data names a mechanism of another kind: the base does not apply
    if base is None and kind == "linkage":
        laws = {}  # a linkage written out: its joint tables are all there is
    else:
        if base is None:
            base = codec.from_dict({k: v for k, v in data.items() if k != "joints"})
        laws = codec.to_dict(base)["joints"]
    joints = {j: dict(t) for j, t in given.items()}
    for j, t in joints.items():
        laws[j] = codec.merge(laws.get(j, {}), t)
    for part, table in tied.items():
        if not isinstance(table, dict):
            raise ParameterError(f"[{part}] must be a table of parameters, got {table!r}")
        targets = [j for j, t in laws.items() if part in _law_fields(t)]
        if not targets:
            raise ParameterError(f"[{part}]: no joint has {part} settings (give a joint a clearance law first)")
        for j in targets:
            joints.setdefault(j, {})[part] = codec.merge(joints.get(j, {}).get(part, {}), table)
    data["joints"] = joints
    return data, clearances


def from_dict(data: dict, base: AbstractMechanism | None = None) -> AbstractMechanism:
    """Build a validated mechanism from a (possibly partial) nested dict with the
    shorthands of the module docstring; missing keys keep the values of ``base``
    (default: the defaults of the kind ``mechanism`` names, the paper's slider-crank
    when none).

    Raises:
        ParameterError: for an unknown key, a wrong type or a value out of its range.
    """
    data, clearances = _expand(data, base)
    mech = codec.from_dict(data, base)
    for key, c in clearances.items():
        mech = with_joint_clearance(mech, key[len("clearance_") :], float(c))
    return mech


def load_toml(path, build):
    """``build(dict)`` of a TOML file; ParameterErrors (and a file that cannot be read or is malformed TOML)
    name the file."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as err:
        raise ParameterError(f"{path}: malformed TOML: {err}") from None
    except OSError as err:
        raise ParameterError(f"{path}: cannot be read: {err.strerror or err}") from None
    try:
        return build(data)
    except ParameterError as err:
        raise ParameterError(f"{path}: {err}") from None


def _described(data: dict) -> AbstractMechanism:
    """The mechanism a file describes: it names its kind (``mechanism = ...``), or writes a
    linkage out (``[bodies]`` tables).

    Raises:
        ParameterError: for a file that describes no mechanism, or a bad one.
    """
    if "mechanism" not in data and "bodies" not in data:
        found = f"its keys: {', '.join(sorted(data))}" if data else "it is empty"
        raise ParameterError(
            f'the file describes no mechanism ({found}): start it with mechanism = "linkage" and write the linkage '
            "out ([ground], [bodies.<name>], [joints.<name>], [driver]), or name a preset's kind "
            f"(mechanism = {' or '.join(repr(k) for k in codec.KINDS if k != 'linkage')}) and its dimensions"
        )
    return from_dict(data)


def load(path) -> AbstractMechanism:
    """Read a TOML file describing a mechanism (see the module docstring).

    Raises:
        ParameterError: naming the file: malformed TOML, a file that describes no
            mechanism, or a bad description.
    """
    return load_toml(path, _described)


def load_design(path) -> AbstractMechanism:
    """The final design of a ``jaxcrank optimize`` run: the mechanism in the ``final_mechanism``
    table of its ``result.json`` (SI, as [`to_dict`][jaxcrank.runs.config.to_dict] writes it).

    Raises:
        ParameterError: naming the file if it is not JSON or has no valid ``final_mechanism``.
    """
    import json

    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except json.JSONDecodeError as err:
        raise ParameterError(f"{path}: not a JSON file: {err}") from None
    if not isinstance(data, dict) or not isinstance(data.get("final_mechanism"), dict):
        raise ParameterError(f"{path}: no 'final_mechanism' table; pass the result.json of a `jaxcrank optimize` run")
    try:
        return from_dict(data["final_mechanism"])
    except ParameterError as err:
        raise ParameterError(f"{path}: {err}") from None


def dumps(mech: AbstractMechanism) -> str:
    header = (
        "# jaxcrank mechanism, SI units (m, kg, s, rad, N, Pa); angular speeds in rad/s.\n"
        "# Pass back with `jaxcrank simulate --config FILE` to reproduce a run.\n"
    )
    return header + tomli_w.dumps(to_dict(mech))


def save(mech: AbstractMechanism, path) -> None:
    Path(path).write_text(dumps(mech))


def parse_override(text: str) -> tuple[list[str], object]:
    """``"contact.law=flores"`` -> (["contact", "law"], "flores"); values are TOML literals
    (numbers, true/false, lists) or bare strings."""
    if "=" not in text:
        raise ParameterError(f"override {text!r} must look like key=value, e.g. joints.<joint>.contact.restitution=0.5")
    key, raw = text.split("=", 1)
    try:
        value = tomllib.loads(f"v = {raw.strip()}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw.strip()
    return key.strip().split("."), value


def apply_overrides(mech: AbstractMechanism, overrides: list[str]) -> AbstractMechanism:
    """Apply ``key=value`` overrides (dotted keys for tables, e.g.
    ``joints.B.contact.restitution=0.5``; the shorthands ``clearance_<joint>`` (m) and
    ``contact.<key>``, see [`from_dict`][jaxcrank.runs.config.from_dict]) and re-validate.

    Raises:
        ParameterError: on a malformed override, an unknown name or an invalid value.
    """
    if not overrides:
        return mech
    data: dict = {}
    for text in overrides:
        path, value = parse_override(text)
        node = data
        for part in path[:-1]:
            node = node.setdefault(part, {})
            if not isinstance(node, dict):
                raise ParameterError(f"override {text!r}: {part!r} is a value, not a table")
        node[path[-1]] = value
    return from_dict(data, base=mech)


def angle_deg(text: str) -> float:
    """An ``--angle`` in degrees (an argparse type): finite, reduced to [0, 360).

    Raises:
        argparse.ArgumentTypeError: not a finite number."""
    import argparse
    import math

    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number (deg)") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{text!r} must be a finite angle (deg)")
    return value % 360.0


def check_resume(out: Path, resume: bool) -> None:
    """The check of a command's ``--resume``, before it creates anything: a run can only be
    continued in a directory that exists.

    Raises:
        ParameterError: ``resume`` with no directory ``out``.
    """
    if resume and not Path(out).is_dir():
        raise ParameterError(f"--resume: {out} does not exist; there is no run to continue (drop --resume)")


def add_mechanism_arguments(p, command: str) -> None:
    """Add the options that choose the mechanism a command runs on to the argparse parser
    ``p``: ``--mechanism NAME``, ``--config FILE`` or ``--design RESULT_JSON``, ``--set
    KEY=VALUE`` (repeatable) and ``--rpm``; ``command`` names the command in their help.
    [`mechanism_from_arguments`][jaxcrank.runs.config.mechanism_from_arguments] reads them back."""
    from ..physics.presets import PRESETS

    base = p.add_mutually_exclusive_group()
    base.add_argument(
        "--mechanism",
        metavar="NAME",
        choices=sorted(PRESETS),
        help=f"{command} a preset mechanism: {', '.join(PRESETS)} (default: paper)",
    )
    base.add_argument("--config", type=Path, help="TOML file of parameters (see config.toml of any run)")
    base.add_argument(
        "--design",
        type=Path,
        metavar="RESULT_JSON",
        help=f"{command} the final design of a `jaxcrank optimize` run, e.g. --design runs/optimize/result.json",
    )
    p.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a parameter (SI), as the library names it, e.g. --set gravity=0 --set "
        "contact.law=flores --set clearance_<joint>=2e-4 --set joints.<joint>.law=ideal (repeatable)",
    )
    p.add_argument("--rpm", type=float, help="speed of the driven body in rev/min (sets driver.speed in rad/s)")


def mechanism_from_arguments(args) -> AbstractMechanism:
    """The mechanism of [`add_mechanism_arguments`][jaxcrank.runs.config.add_mechanism_arguments]' options: the
    paper's unless ``--mechanism``, ``--config`` or ``--design`` says otherwise, then
    ``--set`` and ``--rpm``.

    Raises:
        ParameterError: a bad file, override or value (the message names it).
    """
    import math

    from ..physics.presets import preset

    if getattr(args, "design", None):
        mech = load_design(args.design)
    elif getattr(args, "config", None):
        mech = load(args.config)
    else:
        mech = preset(getattr(args, "mechanism", None) or "paper")
    overrides = list(args.overrides)
    if args.rpm is not None:
        if not mech.linkage().driver.prescribed:
            raise ParameterError("--rpm sets a prescribed driver's speed; this mechanism is driven by a torque")
        overrides.append(f"driver.speed={2.0 * math.pi * args.rpm / 60.0!r}")
    return apply_overrides(mech, overrides)
