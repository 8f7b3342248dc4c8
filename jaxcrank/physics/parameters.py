"""Parameters by name: the one way sweeps, design problems, config files and the command
line address a number of a mechanism.

A name is a dotted path through the mechanism's fields and dict keys:

- a field of a preset: ``crank_length``, ``rod_mass``, ``gravity``;
- into a joint's law: ``joints.B.pin_radius``, ``joints.B.contact.restitution``;
- into the driver: ``driver.speed``, ``driver.initial_angle``;
- into a written-out linkage: ``bodies.rod.mass``, ``bodies.rod.points.C.x``.

Two shorthands:

- ``clearance_<joint>``: that joint's clearance, m, set as its law sets it (a pin in a
  hole: the pin shrinks and the hole stays; a slider in its guide: the gap on each side);
- ``contact.<field>``, ``friction.<field>``, ``memory.<field>`` (and any other part of a
  joint law): that field in every joint whose law has it, tied to one value.

Every function here is traceable in the value (``jax.grad``, ``jax.vmap``).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import equinox as eqx

from .linkage import AbstractMechanism
from .params import ParameterError

#: the parts of a joint law that a tied name (``contact.restitution``) sets in every joint
#: that has them; config files and the command line take them as top-level tables too
TIED_PARTS = ("contact", "friction", "memory", "pin_material", "hole_material")


def _step(obj, part: str):
    if isinstance(obj, dict):
        return obj[part]
    if isinstance(obj, eqx.Module) and part in {f for f in type(obj).__dataclass_fields__}:
        return getattr(obj, part)
    raise KeyError(part)


def _getter(path: Sequence[str]):
    def get(m):
        for part in path:
            m = _step(m, part)
        return m

    return get


def _clearance_joint(mech: AbstractMechanism, name: str) -> str | None:
    if not name.startswith("clearance_"):
        return None
    joint = name[len("clearance_") :]
    if joint not in mech.joints:
        raise ParameterError(f"unknown parameter {name!r}: the joints are {', '.join(sorted(mech.joints))}")
    if mech.joints[joint].ideal:
        raise ParameterError(f"{name!r}: joint {joint!r} is ideal; give it a clearance law first")
    return joint


def with_joint_clearance(mech: AbstractMechanism, joint: str, clearance) -> AbstractMechanism:
    """``mech`` with joint ``joint``'s clearance set as its law sets it
    ([`AbstractJointLaw.with_clearance`][jaxcrank.physics.joints.AbstractJointLaw.with_clearance]); m, traceable.

    Raises:
        ParameterError: an unknown or ideal joint, or a known value out of the law's range
            (the message names ``clearance_<joint>``).
    """
    _clearance_joint(mech, f"clearance_{joint}")
    law = mech.joints[joint].with_clearance(clearance, joint)
    return eqx.tree_at(lambda m: m.joints[joint], mech, law)


def _tied(mech: AbstractMechanism, name: str) -> list[tuple[str, ...]]:
    """The full paths a tied name (``contact.restitution``) stands for."""
    parts = name.split(".")
    if parts[0] not in TIED_PARTS:
        return []
    out = []
    for joint in sorted(mech.joints):
        path = ("joints", joint, *parts)
        try:
            _getter(path)(mech)
        except (KeyError, AttributeError):
            continue
        out.append(path)
    return out


def _paths(mech: AbstractMechanism, name: str) -> list[tuple[str, ...]]:
    tied = _tied(mech, name)
    if tied:
        return tied
    path = tuple(name.split("."))
    try:
        value = _getter(path)(mech)
    except (KeyError, AttributeError):
        raise ParameterError(
            f"unknown parameter {name!r}: use a field such as 'gravity', a dotted path such as "
            f"'joints.<joint>.contact.restitution' or 'driver.speed', 'clearance_<joint>', or a tied name such as "
            f"'contact.restitution' (joints: {', '.join(sorted(mech.joints))})"
        ) from None
    if isinstance(value, (str, bool, eqx.Module, dict)) or value is None:
        raise ParameterError(f"parameter {name!r} is not a number")
    return [path]


def parameter_value(mech: AbstractMechanism, name: str):
    """Value (SI) of parameter ``name`` of ``mech``, traceable (an array or a float); a
    tied name gives its first joint's value."""
    joint = _clearance_joint(mech, name)
    if joint is not None:
        return mech.joints[joint].clearance
    return _getter(_paths(mech, name)[0])(mech)


def get_parameter(mech: AbstractMechanism, name: str) -> float:
    """Current value (SI) of a parameter name, as a float."""
    return float(parameter_value(mech, name))


def _set(mech: AbstractMechanism, name: str, x) -> tuple[AbstractMechanism, list[tuple[str, ...]]]:
    """``mech`` with ``name`` set to ``x`` (not checked), and the paths that were set."""
    joint = _clearance_joint(mech, name)
    if joint is not None:
        return with_joint_clearance(mech, joint, x), []  # the law checks its clearance itself
    paths = _paths(mech, name)
    for path in paths:
        mech = eqx.tree_at(_getter(path), mech, x)
    return mech, paths


def _run_checks(module: eqx.Module) -> None:
    """Every ``__check_init__`` of ``module``'s classes, as its constructor ran them."""
    for cls in type(module).__mro__:
        if "__check_init__" in vars(cls):
            vars(cls)["__check_init__"](module)


def _checked(mech: AbstractMechanism, changed) -> AbstractMechanism:
    """``mech`` once every Module along the ``(name, paths)`` in ``changed`` passed its own
    checks again (``eqx.tree_at`` skips them; values that are JAX tracers are not checked:
    [`jaxcrank.physics.params`][])."""
    for name, paths in changed:
        for path in paths:
            node, modules = mech, [mech]
            for part in path[:-1]:
                node = _step(node, part)
                modules += [node] if isinstance(node, eqx.Module) else []
            try:
                for module in reversed(modules):
                    _run_checks(module)
            except ParameterError as err:
                raise ParameterError(str(err) if str(err).startswith(name) else f"{name}: {err}") from None
    return mech


def check_values(mech: AbstractMechanism) -> None:
    """Run every Module's own checks in ``mech`` again, as its constructors did (a mechanism changed
    with ``eqx.tree_at`` skipped them); values that are JAX tracers are not checked.

    Raises:
        ParameterError: a concrete value out of its range (the message names it)."""
    seen = set()

    def walk(node, path):
        if isinstance(node, eqx.Module) and id(node) not in seen:
            seen.add(id(node))
            try:  # the outer module first: its message names its own fields
                _run_checks(node)
            except ParameterError as err:
                raise ParameterError(f"{'.'.join(path)}: {err}" if path else str(err)) from None
            for field in dataclasses.fields(node):
                walk(getattr(node, field.name, None), [*path, field.name])
        elif isinstance(node, dict):
            for key, value in node.items():
                walk(value, [*path, str(key)])
        elif isinstance(node, (list, tuple)):
            for value in node:
                walk(value, path)

    walk(mech, [])


def set_parameter(mech: AbstractMechanism, name: str, x, *, check: bool = True) -> AbstractMechanism:
    """``mech`` with parameter ``name`` set to ``x`` (SI; traceable), checked as a mechanism
    built with that value is (a concrete value; a JAX tracer is not checked). ``check=False``
    sets it past those checks (a test of what a simulation does with a value out of range;
    ``jaxcrank.simulate`` checks again).

    Raises:
        ParameterError: for an unknown name, one that is not a number, or a concrete value out
            of its range (the message names the parameter and the range).
    """
    mech, paths = _set(mech, name, x)
    return _checked(mech, [(name, paths)]) if check else mech


def set_parameters(mech: AbstractMechanism, names: Sequence[str], values, *, check: bool = True) -> AbstractMechanism:
    """``mech`` with each parameter in ``names`` set to the matching entry of ``values``
    (SI; traceable), as [`set_parameter`][jaxcrank.physics.parameters.set_parameter]; checked
    once all are set (so that, e.g., a hole and its pin can grow together), unless ``check=False``.

    Raises:
        ParameterError: as ``set_parameter``."""
    changed = []
    for i, name in enumerate(names):
        mech, paths = _set(mech, name, values[i])
        changed.append((name, paths))
    return _checked(mech, changed) if check else mech


_UNITS = {
    "mass": "kg",
    "inertia": "kg_m2",
    "speed": "rad_s",
    "initial_speed": "rad_s",
    "initial_angle": "rad",
    "angle": "rad",
    "direction": "rad",
    "torque": "N_m",
    "gravity": "m_s2",
    "youngs_modulus": "Pa",
    "poisson_ratio": "1",
    "restitution": "1",
    "exponent": "1",
    "coefficient": "1",
    "min_approach_speed": "m_s",
    "stick_speed": "m_s",
    "slip_speed": "m_s",
    "v_ref": "m_s",
    "viscosity": "Pa_s",
    "film_start": "1",
    "film_end": "1",
}
_SUFFIX_UNITS = (("_length", "m"), ("_radius", "m"), ("_mass", "kg"), ("_inertia", "kg_m2"), ("_time", "s"))


def parameter_unit(mech: AbstractMechanism, name: str) -> str:
    """SI unit of a parameter name, written for column names: ``m``, ``kg``, ``kg_m2``,
    ``rad_s``, ``m_s``, ``m_s2``, ``Pa``, ``s``, ``rad`` or ``1`` (dimensionless).

    Raises:
        ParameterError: for an unknown name.
    """
    parameter_value(mech, name)  # raises on unknown names
    if name.startswith("clearance_"):
        return "m"
    last = name.rsplit(".", 1)[-1]
    if last in _UNITS:
        return _UNITS[last]
    for suffix, unit in _SUFFIX_UNITS:
        if last.endswith(suffix):
            return unit
    if last in ("x", "y", "offset", "length", "height", "clearance", "tau", "t_dwell"):
        return "s" if last in ("tau", "t_dwell") else "m"
    return "1"
