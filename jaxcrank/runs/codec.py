"""Mechanisms as plain nested dicts (the tables of a TOML file) and back.

A dict names its kind with ``mechanism``: a preset class (``"slider-crank"``,
``"four-bar"``: its named dimensions at the top level) or ``"linkage"`` (a linkage
written out: ``[ground]``, ``[bodies.<name>]``, ``[joints.<name>]``, ``[outputs]``).
Every mechanism has ``[joints.<name>]`` tables (``law = "ideal"``, ``"clearance"``, ...
and the law's settings, with sub-tables ``contact``, ``friction``, ``memory``,
``pin_material``, ``hole_material``; a worn joint's profiles are lists), a ``[driver]`` table (``type =
"constant_speed"``, ``body``, ``speed``, ...) and ``gravity``. Points are ``[x, y]`` (m), poses ``[x, y, angle]``,
joint sites ``"body.point"``. Every value is SI.

[`to_dict`][jaxcrank.runs.codec.to_dict] and [`from_dict`][jaxcrank.runs.codec.from_dict] are inverse; the
conversion walks the equinox Modules' fields, so a new law or driver needs no code here, only its name
in its registry.
"""

from __future__ import annotations

import dataclasses
import math

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ..physics.compiled import compile_model
from ..physics.drivers import DRIVERS, AbstractDriver
from ..physics.joints import JOINT_LAWS, AbstractJointLaw
from ..physics.laws import CONTACT_LAWS, FRICTION_LAWS, AbstractContactLaw, AbstractFrictionLaw
from ..physics.linkage import AbstractMechanism, Body, BodyVector, Linkage, Outputs, Point, Pose
from ..physics.linkage import Site as _Site
from ..physics.memory import MEMORY_LAWS, AbstractMemoryLaw
from ..physics.params import ParameterError
from ..physics.presets import FourBar, SliderCrank

#: mechanism kinds by their name in a file
KINDS: dict[str, type[AbstractMechanism]] = {"slider-crank": SliderCrank, "four-bar": FourBar, "linkage": Linkage}
#: polymorphic parts: the key naming the class in a table, and the registry
_POLYMORPHIC = (
    (AbstractJointLaw, "law", JOINT_LAWS),
    (AbstractMemoryLaw, "law", MEMORY_LAWS),
    (AbstractDriver, "type", DRIVERS),
)
_NAMED_LAWS = ((AbstractContactLaw, CONTACT_LAWS), (AbstractFrictionLaw, FRICTION_LAWS))


def kind_of(mech: AbstractMechanism) -> str:
    """The file name of a mechanism's kind."""
    for name, cls in KINDS.items():
        if type(mech) is cls:
            return name
    raise ParameterError(f"{type(mech).__name__} has no name in a file; kinds: {', '.join(KINDS)}")


def _fields(obj) -> list[str]:
    return [f.name for f in dataclasses.fields(obj) if f.init]


def _field_plain(obj, k):
    """Field ``k`` of ``obj`` as TOML data (a list for the fields its class names in ``array_fields``)."""
    arrays = getattr(type(obj), "array_fields", ())
    return [float(x) for x in np.ravel(getattr(obj, k))] if k in arrays else _plain(getattr(obj, k))


def _plain(value):
    """A field's value as TOML data."""
    for base, _ in _NAMED_LAWS:
        if isinstance(value, base):
            return value.name
    for base, key, _ in _POLYMORPHIC:
        if isinstance(value, base):
            return {key: value.name, **{k: _field_plain(value, k) for k in _fields(value)}}
    if isinstance(value, Point):
        return [float(value.x), float(value.y)]
    if isinstance(value, Pose):
        return [float(value.x), float(value.y), float(value.angle)]
    if isinstance(value, _Site):
        return f"{value.body}.{value.point}"
    if isinstance(value, Outputs):
        return _outputs_plain(value)
    if isinstance(value, eqx.Module):
        return {k: _field_plain(value, k) for k in _fields(value) if getattr(value, k) is not None}
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, tuple):
        return [_plain(v) for v in value]
    if isinstance(value, (bool, str)):
        return value
    arr = np.asarray(value)
    if arr.ndim:
        raise ParameterError("only scalar parameters can be written to a file")
    return float(arr)


def _outputs_plain(o: Outputs) -> dict:
    def vec(v: BodyVector):
        return [v.body, v.start, v.end] if v.end is not None else [v.body, float(v.angle)]

    out = {"deviations": [list(d) for d in o.deviations]}
    if o.acceleration is not None:
        out["acceleration"] = list(o.acceleration)
    if o.transmission is not None:
        out["transmission"] = [vec(v) for v in o.transmission]
    return out


def to_dict(mech: AbstractMechanism) -> dict:
    """Nested plain-Python dict of every parameter (SI), ``mechanism`` naming its kind."""
    out = {"mechanism": kind_of(mech)}
    for name in _fields(mech):
        value = getattr(mech, name)
        if name == "joints":
            out[name] = {j: _plain(law) for j, law in value.items()}
        elif name == "connections":
            continue  # written into the joint tables
        else:
            out[name] = _plain(value)
    if isinstance(mech, Linkage):
        for j, conn in mech.connections.items():
            table = {"type": conn.kind}
            table.update({k: _plain(getattr(conn, k)) for k in _fields(conn) if getattr(conn, k) is not None})
            out["joints"][j] = {**table, **out["joints"][j]}
    return out


# --------------------------------------------------------------------------- from plain data


def _where(path: list[str]) -> str:
    return ".".join(path) if path else "top level"


def _number(value, path):
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ParameterError(f"{_where(path)} must be a number, got {value!r}")
    return float(value)


def _pair(value, n, path):
    if not (isinstance(value, (list, tuple)) and len(value) == n):
        raise ParameterError(f"{_where(path)} must be a list of {n} numbers, got {value!r}")
    numbers = [_number(v, path) for v in value]
    if not all(math.isfinite(v) for v in numbers):
        raise ParameterError(f"{_where(path)} must be a list of {n} finite numbers, got {value!r}")
    return numbers


def _registry_for(template):
    for base, key, registry in _POLYMORPHIC:
        if isinstance(template, base) or (isinstance(template, type) and issubclass(template, base)):
            return key, registry
    return None


def _build(cls, table: dict, template, path: list[str]):
    """An instance of Module ``cls`` from ``table``; missing fields keep ``template``'s values (or the defaults)."""
    if not isinstance(table, dict):
        raise ParameterError(f"[{_where(path)}] must be a table, got {table!r}")
    known = {f.name: f for f in dataclasses.fields(cls) if f.init}
    named_by = _registry_for(cls)  # the key that names the class in its table (law, type)
    kwargs = {}
    for k, v in table.items():
        if named_by is not None and k == named_by[0]:
            continue
        if k not in known:
            valid = f"valid keys: {', '.join(known)}" if known else f"the {cls.__name__} law takes no parameters"
            raise ParameterError(f"unknown parameter {_where([*path, k])}; {valid}")
        current = getattr(template, k, None) if template is not None and type(template) is cls else None
        if current is None and known[k].default is not dataclasses.MISSING:
            current = known[k].default
        if current is None and known[k].default_factory is not dataclasses.MISSING:
            current = known[k].default_factory()
        kwargs[k] = _convert(v, current, known[k], [*path, k])
    if template is not None and type(template) is cls:
        for k in known:
            if k not in kwargs:
                kwargs[k] = getattr(template, k)
    unset = [k for k, f in known.items() if k not in kwargs and f.default is dataclasses.MISSING]
    required = [k for k in unset if known[k].default_factory is dataclasses.MISSING]
    if required:
        what = f"the {named_by[0]} {table[named_by[0]]!r}" if named_by and named_by[0] in table else cls.__name__
        needs = f"needs {', '.join(required)} ({_where([*path, required[0]])} = ...); its keys: {', '.join(known)}"
        raise ParameterError(f"[{_where(path)}] {what} {needs}")
    try:
        return cls(**kwargs)
    except (ParameterError, TypeError) as err:
        raise ParameterError(f"[{_where(path)}] {err}") from None


def _polymorphic(value, current, path):
    """A law/driver table: the class named by its key, else the current one's."""
    found = _registry_for(current) if current is not None else None
    if found is None:
        return None
    key, registry = found
    if isinstance(value, str):
        value = {key: value}
    name = value.get(key, current.name)
    if name not in registry:
        raise ParameterError(f"{_where([*path, key])} = {name!r} is unknown; valid: {', '.join(registry)}")
    cls = registry[name]
    return _build(cls, value, current if type(current) is cls else None, path)


def _convert(value, current, field, path):
    for base, registry in _NAMED_LAWS:
        if isinstance(current, base):
            if not isinstance(value, str) or value not in registry:
                raise ParameterError(f"{_where(path)} = {value!r} is unknown; valid names: {', '.join(registry)}")
            return registry[value]()
    built = _polymorphic(value, current, path)
    if built is not None:
        return built
    if isinstance(current, Point) or path[-1] == "centre_of_mass":
        return Point(*_pair(value, 2, path))
    if isinstance(current, Pose) or path[-1] == "guess":
        return Pose(*_pair(value, 3, path))
    if isinstance(current, eqx.Module):
        return _build(type(current), value, current, path)
    if isinstance(current, bool):
        if not isinstance(value, bool):
            raise ParameterError(f"{_where(path)} must be true or false, got {value!r}")
        return value
    if isinstance(current, str) or field.metadata.get("static", False) and isinstance(value, str):
        if not isinstance(value, str):
            raise ParameterError(f"{_where(path)} must be a string, got {value!r}")
        return value
    if isinstance(current, tuple) or np.ndim(current) == 1:  # a tuple, or an array field (a worn profile)
        if not isinstance(value, (list, tuple)):
            raise ParameterError(f"{_where(path)} must be a list of numbers, got {value!r}")
        numbers = tuple(_number(v, path) for v in value)
        return numbers if isinstance(current, tuple) else jnp.asarray(numbers, dtype=float)
    return _number(value, path)


def _site(value, path) -> _Site:
    if not (isinstance(value, str) and value.count(".") == 1):
        raise ParameterError(f"{_where(path)} must be 'body.point', got {value!r}")
    return _Site(*value.split("."))


def _outputs(table, path) -> Outputs:
    def vec(v, p):
        if isinstance(v, (list, tuple)) and len(v) == 3 and all(isinstance(x, str) for x in v):
            return BodyVector(v[0], v[1], v[2])
        if isinstance(v, (list, tuple)) and len(v) == 2 and isinstance(v[0], str):
            return BodyVector(v[0], angle=_number(v[1], p))
        raise ParameterError(f"{_where(p)} must be [body, start point, end point] or [body, angle], got {v!r}")

    if not isinstance(table, dict):
        raise ParameterError(f"[{_where(path)}] must be a table, got {table!r}")
    keys = ("deviations", "acceleration", "transmission")
    unknown = sorted(set(table) - set(keys))
    if unknown:
        raise ParameterError(f"unknown key {unknown[0]!r} in [{_where(path)}]; keys: {', '.join(keys)}")
    dev = tuple(tuple(d) for d in table.get("deviations", ()))
    acc = tuple(table["acceleration"]) if table.get("acceleration") else None
    trans = tuple(vec(v, [*path, "transmission"]) for v in table["transmission"]) if table.get("transmission") else None
    return Outputs(dev, acc, trans)


def merge(base: dict, changes: dict) -> dict:
    """``base`` updated by ``changes``, table by table. A table whose law or type (``law``, ``type``) changes is
    replaced, not merged (another law has other settings): ``base`` itself too. A change ``{x = ..}`` or
    ``{y = ..}`` of a point (a pair of numbers in ``base``) sets that coordinate, as the parameter name
    ``bodies.rod.points.C.x`` does."""
    if any(key in changes and key in base and changes[key] != base[key] for key in ("law", "type")):
        return dict(changes)
    out = dict(base)
    for k, v in changes.items():
        old = out.get(k)
        if isinstance(v, dict) and isinstance(old, dict):
            v = merge(old, v)
        elif isinstance(v, dict) and v and set(v) <= {"x", "y"} and isinstance(old, (list, tuple)) and len(old) == 2:
            v = [v.get("x", old[0]), v.get("y", old[1])]
        out[k] = v
    return out


#: a written-out linkage's joint table also holds the joint's geometry (read by `_connection`)
_CONNECTION_KEYS = ("type", "hole", "pin", "guide", "slider", "direction", "angle", "branch")


def _joint_law(table, path, linkage=False):
    """The law of a joint table (a linkage's: its geometry keys left to `_connection`)."""
    if not isinstance(table, dict):
        raise ParameterError(f"[{_where(path)}] must be a table, got {table!r}")
    if linkage:
        table = {k: v for k, v in table.items() if k not in _CONNECTION_KEYS}
    return _polymorphic(dict(table, law=table.get("law", "ideal")), JOINT_LAWS["ideal"](), path)


def _connection(table, path):
    from ..physics.linkage import Prismatic, Revolute

    kind = table.get("type")
    if kind == "revolute":
        for key in ("hole", "pin"):
            if key not in table:
                raise ParameterError(f"[{_where(path)}] a revolute joint needs {key} = 'body.point'")
        return Revolute(
            hole=_site(table["hole"], [*path, "hole"]),
            pin=_site(table["pin"], [*path, "pin"]),
            branch=_branch(table, path),
        )
    if kind == "prismatic":
        for key in ("guide", "slider"):
            if key not in table:
                raise ParameterError(f"[{_where(path)}] a prismatic joint needs {key} = 'body.point'")
        return Prismatic(
            guide=_site(table["guide"], [*path, "guide"]),
            slider=_site(table["slider"], [*path, "slider"]),
            direction=_number(table.get("direction", 0.0), [*path, "direction"]),
            angle=_number(table.get("angle", 0.0), [*path, "angle"]),
            branch=_branch(table, path),
        )
    raise ParameterError(f"{_where([*path, 'type'])} must be 'revolute' or 'prismatic', got {kind!r}")


def _branch(table, path) -> str | None:
    from ..physics.linkage import BRANCHES

    value = table.get("branch")
    if value is not None and value not in BRANCHES:
        raise ParameterError(f"{_where([*path, 'branch'])} = {value!r} must be one of {', '.join(map(repr, BRANCHES))}")
    return value


def _body(table, path) -> Body:
    if not isinstance(table, dict):
        raise ParameterError(f"[{_where(path)}] must be a table, got {table!r}")
    unknown = sorted(set(table) - {"mass", "inertia", "points", "centre_of_mass", "guess"})
    if unknown:
        raise ParameterError(
            f"unknown key {_where([*path, unknown[0]])}; keys: mass, inertia, points, centre_of_mass, guess"
        )
    for key in ("mass", "inertia"):
        if key not in table:
            raise ParameterError(f"[{_where(path)}] needs {key}")
    points = {p: Point(*_pair(v, 2, [*path, "points", p])) for p, v in (table.get("points") or {}).items()}
    try:
        return Body(
            mass=_number(table["mass"], [*path, "mass"]),
            inertia=_number(table["inertia"], [*path, "inertia"]),
            points=points,
            centre_of_mass=Point(*_pair(table.get("centre_of_mass", [0.0, 0.0]), 2, [*path, "centre_of_mass"])),
            guess=Pose(*_pair(table["guess"], 3, [*path, "guess"])) if "guess" in table else None,
        )
    except ParameterError as err:
        raise ParameterError(f"[{_where(path)}] {err}") from None


def _linkage(data: dict) -> Linkage:
    known = {"ground", "bodies", "joints", "driver", "outputs", "gravity", "name"}
    unknown = sorted(set(data) - known)
    if unknown:
        raise ParameterError(f"unknown parameter {unknown[0]!r}; a linkage has {', '.join(sorted(known))}")
    for key in ("bodies", "joints", "driver"):
        if key not in data:
            raise ParameterError(f"a linkage needs a [{key}] table")
    joints = data["joints"]
    for key in ("bodies", "joints"):
        if not isinstance(data[key], dict) or not all(isinstance(t, dict) for t in data[key].values()):
            raise ParameterError(f"[{key}] must hold one table per {key[:-1]} ([{key}.<name>]), got {data[key]!r}")
    connections = {j: _connection(t, ["joints", j]) for j, t in joints.items()}
    for j, t in joints.items():  # a law for the other kind of joint, named before its settings are read
        law = JOINT_LAWS.get(t.get("law", "ideal"))
        if law is not None and connections[j].kind not in law.kinds:
            raise ParameterError(
                f"joint {j!r} is {connections[j].kind} but its law {law.name!r} is for {' and '.join(law.kinds)} joints"
            )
    kwargs = dict(
        ground={k: Point(*_pair(v, 2, ["ground", k])) for k, v in (data.get("ground") or {}).items()},
        bodies={b: _body(t, ["bodies", b]) for b, t in data["bodies"].items()},
        connections=connections,
        joints={j: _joint_law(t, ["joints", j], linkage=True) for j, t in joints.items()},
        driver=_driver(data["driver"], ["driver"]),
        outputs=_outputs(data.get("outputs", {}), ["outputs"]),
        gravity=_number(data.get("gravity", 9.81), ["gravity"]),
        name=str(data.get("name", "linkage")),
    )
    return Linkage(**kwargs)


def _driver(table, path) -> AbstractDriver:
    if not isinstance(table, dict) or table.get("type") not in DRIVERS:
        kind = table.get("type") if isinstance(table, dict) else table
        raise ParameterError(f"{_where([*path, 'type'])} = {kind!r}: valid driver types are {', '.join(DRIVERS)}")
    return _build(DRIVERS[table["type"]], table, None, path)


def from_dict(data: dict, base: AbstractMechanism | None = None) -> AbstractMechanism:
    """Build a validated mechanism from a nested dict. With ``base``, ``data`` holds
    changes to it ([`merge`][jaxcrank.runs.codec.merge]d into [`to_dict`][jaxcrank.runs.codec.to_dict] of
    ``base``) unless it names another kind; without, missing keys of a preset take its
    defaults (the paper's slider-crank when no ``mechanism`` is named), a joint's among
    them: a joint table that names no other law completes the preset's law of that joint.
    Data with ``[bodies]`` tables and no ``mechanism`` is a linkage written out. The
    mechanism is compiled ([`jaxcrank.physics.compiled.compile_model`][]): its structure and
    assembly are checked here.

    Raises:
        ParameterError: for an unknown kind or key, a wrong type, a value out of its range (the message names
            the table and key), or a structure or assembly that does not hold together."""
    mech = _mechanism(data, base)
    compile_model(mech)
    return mech


def _mechanism(data: dict, base: AbstractMechanism | None) -> AbstractMechanism:
    if "mechanism" not in data and "bodies" in data and (base is None or isinstance(base, Linkage)):
        data = {"mechanism": "linkage", **data}
    kind = data.get("mechanism")
    if kind is not None and kind not in KINDS:
        raise ParameterError(f"mechanism = {kind!r} is unknown; kinds: {', '.join(KINDS)}")
    if base is not None and kind in (None, kind_of(base)):
        data = merge(to_dict(base), data)
        kind = kind_of(base)
    kind = kind or "slider-crank"
    rest = {k: v for k, v in data.items() if k != "mechanism"}
    if KINDS[kind] is Linkage:
        return _linkage(rest)
    cls = KINDS[kind]
    default = cls()
    if "joints" in rest:
        joints = rest["joints"]
        if not isinstance(joints, dict):
            raise ParameterError(f"[joints] must be a table of joint tables, got {joints!r}")
        unknown = sorted(set(joints) - set(default.joints))
        if unknown:
            raise ParameterError(f"unknown joint {unknown[0]!r}; joints: {', '.join(sorted(default.joints))}")
        rest["joints"] = {
            j: _joint_law(_onto(_plain(default.joints[j]), joints.get(j)), ["joints", j]) for j in default.joints
        }
    known = set(_fields(default))
    kwargs = {}
    for k, v in rest.items():
        if k not in known:
            raise ParameterError(f"unknown parameter {k!r}; valid top-level keys: {', '.join(sorted(known))}")
        kwargs[k] = v if k == "joints" else _convert(v, getattr(default, k), _field(default, k), [k])
    return cls(**kwargs)


def _onto(default: dict, given):
    """A joint table given for a preset, completed by the preset's law table (one naming another law replaces it)."""
    return default if given is None else merge(default, given) if isinstance(given, dict) else given


def _field(obj, name):
    return next(f for f in dataclasses.fields(obj) if f.name == name)
