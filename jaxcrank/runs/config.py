"""Load and save a [`Mechanism`][jaxcrank.physics.params.Mechanism] as TOML, and apply
command-line overrides.

The file mirrors the pytree: top-level keys are the mechanism's scalar fields,
tables ``[joint_B]``, ``[joint_C]``, ``[crank_material]``, ``[rod_material]``,
``[slider_material]``, ``[contact]``, ``[friction]`` its parts. Every value is SI
(see [`Mechanism`][jaxcrank.physics.params.Mechanism]). Unknown keys and wrong types are errors.

The parameter names are the library's ([`jaxcrank.physics.params.set_parameter`][]):
besides the fields and dotted paths, the top-level keys ``clearance_B`` and
``clearance_C`` set a joint's radial clearance (m; the pin shrinks, the hole stays), in
a file and on the command line (``jaxcrank simulate --set clearance_B=2e-4``) alike.
"""

from __future__ import annotations

import dataclasses
import tomllib
from pathlib import Path

import numpy as np
import tomli_w

from ..physics.laws import CONTACT_LAWS, FRICTION_LAWS, AbstractContactLaw, AbstractFrictionLaw
from ..physics.params import Contact, Friction, Joint, Material, Mechanism, ParameterError

_PARTS = {
    "joint_B": Joint,
    "joint_C": Joint,
    "crank_material": Material,
    "rod_material": Material,
    "slider_material": Material,
    "contact": Contact,
    "friction": Friction,
}
# laws are Modules in Python and names in TOML / on the command line
_LAWS = {"contact": ("contact law", CONTACT_LAWS), "friction": ("friction law", FRICTION_LAWS)}
_BOOL_FIELDS = {"ideal"}
#: the library's clearance names (top-level keys here): radial clearance c = hole_radius - pin_radius, m
_CLEARANCES = {"clearance_B": "joint_B", "clearance_C": "joint_C"}


def _fields(cls):
    return [f.name for f in dataclasses.fields(cls)]


def _plain(value):
    if isinstance(value, (AbstractContactLaw, AbstractFrictionLaw)):
        return value.name
    if isinstance(value, (bool, str)):
        return value
    arr = np.asarray(value)
    if arr.ndim:
        raise ParameterError("only scalar parameters can be written to TOML")
    return float(arr)


def to_dict(mech: Mechanism) -> dict:
    """Nested plain-Python dict of every parameter (SI)."""
    out = {}
    for name in _fields(Mechanism):
        value = getattr(mech, name)
        if name in _PARTS:
            out[name] = {k: _plain(getattr(value, k)) for k in _fields(_PARTS[name])}
        else:
            out[name] = _plain(value)
    return out


def _convert(section: str, key: str, value):
    where = f"{section}.{key}" if section else key
    if key == "law" and section in _LAWS:
        what, registry = _LAWS[section]
        if not isinstance(value, str):
            raise ParameterError(f"{where} must be a string, got {value!r}")
        if value not in registry:
            raise ParameterError(f"{what} {value!r} is unknown; valid names: {', '.join(registry)}")
        return registry[value]()
    if key in _BOOL_FIELDS:
        if not isinstance(value, bool):
            raise ParameterError(f"{where} must be true or false, got {value!r}")
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ParameterError(f"{where} must be a number, got {value!r}")
    return float(value)


def from_dict(data: dict, base: Mechanism | None = None) -> Mechanism:
    """Build a validated Mechanism from a (possibly partial) nested dict; missing
    keys keep the values of ``base`` (default: the paper preset). The top-level keys
    ``clearance_B`` / ``clearance_C`` (m) set the pin radius to the joint's hole radius
    (the one ``data`` gives, else the base's) minus the clearance.

    Raises:
        ParameterError: for an unknown key, a wrong type or a value out of its range
            (a clearance outside (0, hole_radius), or given with that joint's pin_radius).
    """
    merged = to_dict(Mechanism() if base is None else base)
    clearances = {}
    for key, value in data.items():
        if key in _CLEARANCES:
            clearances[key] = _convert("", key, value)
        elif key in _PARTS:
            if not isinstance(value, dict):
                raise ParameterError(f"[{key}] must be a table of parameters, got {value!r}")
            for sub, v in value.items():
                if sub not in merged[key]:
                    raise ParameterError(
                        f"unknown parameter {key}.{sub}; valid keys in [{key}]: {', '.join(merged[key])}"
                    )
                merged[key][sub] = _convert(key, sub, v)
        elif key in merged:
            merged[key] = _convert("", key, value)
        else:
            valid = ", ".join([*merged, *_CLEARANCES])
            raise ParameterError(f"unknown parameter {key!r}; valid top-level keys: {valid}")
    for key, c in clearances.items():
        _set_clearance(merged, data, key, c)
    for section in _LAWS:  # the base's laws, written as names by to_dict
        if isinstance(merged[section]["law"], str):
            merged[section]["law"] = _convert(section, "law", merged[section]["law"])
    kwargs = {}
    for k, v in merged.items():
        if k not in _PARTS:
            kwargs[k] = v
            continue
        try:
            kwargs[k] = _PARTS[k](**v)
        except ParameterError as err:  # name the table: "youngs_modulus" alone does not say whose
            raise ParameterError(f"[{k}] {err}") from None
    return Mechanism(**kwargs)


def _set_clearance(merged: dict, data: dict, key: str, c: float) -> None:
    """Set ``merged``'s pin radius of the joint that ``key`` (``clearance_B`` / ``clearance_C``)
    names to ``hole_radius - c``; the hole radius is the one ``data`` sets, else the base's."""
    joint = _CLEARANCES[key]
    if "pin_radius" in data.get(joint, {}):
        raise ParameterError(f"{key} and {joint}.pin_radius both set the pin radius: give one of them")
    hole = merged[joint]["hole_radius"]
    if not 0.0 < c < hole:
        raise ParameterError(
            f"{key} = {c:g} m is out of range: the radial clearance must lie in (0, {joint}.hole_radius = {hole:g} m)"
        )
    merged[joint]["pin_radius"] = hole - c


def load_toml(path, build):
    """``build(dict)`` of a TOML file; ParameterErrors (and malformed TOML) name the file."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as err:
        raise ParameterError(f"{path}: malformed TOML: {err}") from None
    try:
        return build(data)
    except ParameterError as err:
        raise ParameterError(f"{path}: {err}") from None


def load(path) -> Mechanism:
    """Read a TOML config; raises ParameterError naming the file on malformed input."""
    return load_toml(path, from_dict)


def load_design(path) -> Mechanism:
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


def dumps(mech: Mechanism) -> str:
    header = (
        "# jaxcrank mechanism, SI units (m, kg, s, rad, N, Pa); crank_speed in rad/s.\n"
        "# Pass back with `jaxcrank simulate --config FILE` to reproduce a run.\n"
    )
    return header + tomli_w.dumps(to_dict(mech))


def save(mech: Mechanism, path) -> None:
    Path(path).write_text(dumps(mech))


def parse_override(text: str) -> tuple[list[str], object]:
    """``"contact.law=flores"`` -> (["contact", "law"], "flores"); values are TOML literals
    (numbers, true/false) or bare strings."""
    if "=" not in text:
        raise ParameterError(f"override {text!r} must look like key=value, e.g. rod_length=0.41")
    key, raw = text.split("=", 1)
    try:
        value = tomllib.loads(f"v = {raw.strip()}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw.strip()
    return key.strip().split("."), value


def apply_overrides(mech: Mechanism, overrides: list[str]) -> Mechanism:
    """Apply ``key=value`` overrides (dotted keys for tables; ``clearance_B`` /
    ``clearance_C`` in m, see [`from_dict`][jaxcrank.runs.config.from_dict]) and re-validate.

    Raises:
        ParameterError: on a malformed override, an unknown name or an invalid value.
    """
    data: dict = {}
    for text in overrides:
        path, value = parse_override(text)
        if len(path) == 1:
            data[path[0]] = value
        elif len(path) == 2:
            data.setdefault(path[0], {})[path[1]] = value
        else:
            raise ParameterError(f"override key {'.'.join(path)!r} is too deep; use table.key=value")
    return from_dict(data, base=mech)


def add_mechanism_arguments(p, command: str) -> None:
    """Add the options that choose the mechanism a command runs on to the argparse parser
    ``p``: ``--config FILE`` or ``--design RESULT_JSON``, ``--set KEY=VALUE`` (repeatable)
    and ``--rpm``; ``command`` names the command in their help.
    [`mechanism_from_arguments`][jaxcrank.runs.config.mechanism_from_arguments] reads them back."""
    base = p.add_mutually_exclusive_group()
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
        help="override a parameter (SI), as the library names it, e.g. --set rod_length=0.41 "
        "--set clearance_B=2e-4 --set contact.law=flores (repeatable)",
    )
    p.add_argument("--rpm", type=float, help="crank speed in rev/min (sets crank_speed in rad/s)")


def mechanism_from_arguments(args) -> Mechanism:
    """The mechanism of [`add_mechanism_arguments`][jaxcrank.runs.config.add_mechanism_arguments]' options: the
    paper's unless ``--config`` or ``--design`` says otherwise, then ``--set`` and ``--rpm``.

    Raises:
        ParameterError: a bad file, override or value (the message names it).
    """
    import math

    from ..physics.params import paper

    if args.design:
        mech = load_design(args.design)
    else:
        mech = load(args.config) if args.config else paper()
    overrides = list(args.overrides)
    if args.rpm is not None:
        overrides.append(f"crank_speed={2.0 * math.pi * args.rpm / 60.0!r}")
    return apply_overrides(mech, overrides)
