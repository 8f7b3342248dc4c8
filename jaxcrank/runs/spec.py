"""Sweep specifications: a sweep read from a TOML file or dict (``jaxcrank sweep
SPEC.toml``), next to [`jaxcrank.runs.config`][] which reads the mechanism part.

The base mechanism of a spec is its ``mechanism`` key: a preset's name
(``mechanism = "four-bar"``, [`preset`][jaxcrank.physics.presets.preset]) or a ``[mechanism]``
table written as a mechanism's config file ([`jaxcrank.runs.config.from_dict`][]: its own
``mechanism = "four-bar"`` kind key, ``[mechanism.joints.B]`` tables, the ``clearance_<joint>``
and ``[mechanism.contact]`` shorthands); without it, the paper's slider-crank. On the
command line ``--mechanism``, ``--config`` or ``--design`` give it instead, and ``--set`` /
``--rpm`` change it ([`base_mechanism`][jaxcrank.runs.spec.base_mechanism]).

Every problem with a spec raises [`jaxcrank.ParameterError`][jaxcrank.physics.params.ParameterError] naming the key
and what is valid.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping

import numpy as np

from ..physics.linkage import AbstractMechanism as Mechanism
from ..physics.parameters import get_parameter, parameter_unit
from ..physics.params import ParameterError
from ..physics.presets import preset
from . import config
from .sampling import Tolerance, full_factorial, latin_hypercube, monte_carlo, one_at_a_time, random_uniform
from .sweep import Settings, metric_names

SAMPLINGS = ("grid", "lhs", "random", "oat", "monte_carlo")
_SPEC_KEYS = {"sampling", "samples", "points", "seed", "chunk", "metrics", "parameters", "simulation", "mechanism"}


@dataclasses.dataclass
class Spec:
    """A sweep read from TOML by [`load_spec`][jaxcrank.runs.spec.load_spec] (see ``jaxcrank sweep --help``)."""

    base: Mechanism
    sampling: str
    names: list[str]
    designs: np.ndarray
    settings: Settings
    chunk: int | None  # None: default_chunk()
    metrics: list[str]
    tolerances: dict[str, Tolerance]


_CHOOSERS = ("mechanism", "config", "design")


def spec_mechanism(value) -> Mechanism:
    """The mechanism of a spec's ``mechanism`` key: ``None`` (absent: the paper's
    slider-crank), a preset's name or a table as a config file holds it.

    Raises:
        ParameterError: for an unknown preset, a bad table or a value of another type.
    """
    if value is None:
        return preset("paper")
    if isinstance(value, str):
        return preset(value)
    if isinstance(value, Mapping):
        return config.from_dict(dict(value))
    raise ParameterError(
        f'mechanism = {value!r} must be a preset\'s name (e.g. mechanism = "four-bar") or a [mechanism] table'
    )


def base_mechanism(d: Mapping, arguments=None) -> Mechanism:
    """The base mechanism of the spec dict ``d`` on the command line: the one
    ``--mechanism``, ``--config`` or ``--design`` chooses when one of them is given (the
    spec must then have no ``mechanism`` key), else the spec's
    ([`spec_mechanism`][jaxcrank.runs.spec.spec_mechanism]); then ``--set KEY=VALUE`` and
    ``--rpm``. ``arguments``: the options of
    [`jaxcrank.runs.config.add_mechanism_arguments`][] (None: the spec's mechanism alone).

    Raises:
        ParameterError: a mechanism both in the spec and on the command line, or a bad
            mechanism, override or value (the message names it).
    """
    if arguments is not None and any(getattr(arguments, k, None) for k in _CHOOSERS):
        if d.get("mechanism") is not None:
            raise ParameterError(
                "the spec has a mechanism and --mechanism/--config/--design gives another: keep one of them"
            )
        return config.mechanism_from_arguments(arguments)
    mech = spec_mechanism(d.get("mechanism"))
    if arguments is None:
        return mech
    overrides = list(getattr(arguments, "overrides", None) or [])
    rpm = getattr(arguments, "rpm", None)
    if rpm is not None:
        if not mech.linkage().driver.prescribed:
            raise ParameterError("--rpm sets a prescribed driver's speed; this mechanism is driven by a torque")
        overrides.append(f"driver.speed={2.0 * math.pi * rpm / 60.0!r}")
    return config.apply_overrides(mech, overrides)


def spec_from_dict(d: Mapping, base: Mechanism | None = None) -> Spec:
    """Build a [`Spec`][jaxcrank.runs.spec.Spec] from a parsed TOML dict; every problem raises
    [`ParameterError`][jaxcrank.physics.params.ParameterError] naming the key.

    Args:
        d: the spec's tables.
        base: the base mechanism (default: the spec's own,
            [`spec_mechanism`][jaxcrank.runs.spec.spec_mechanism]).
    """
    bad = set(d) - _SPEC_KEYS
    if bad:
        raise ParameterError(f"unknown sweep spec keys {sorted(bad)}; valid: {sorted(_SPEC_KEYS)}")
    sampling = d.get("sampling", "grid")
    if sampling not in SAMPLINGS:
        raise ParameterError(f"sampling {sampling!r} is unknown; valid: {', '.join(SAMPLINGS)}")
    base = spec_mechanism(d.get("mechanism")) if base is None else base
    settings = Settings.from_text(dict(d.get("simulation", {})))
    valid = list(metric_names(base))
    metrics = list(d.get("metrics", valid))
    if set(metrics) - set(valid):
        raise ParameterError(f"unknown metrics {sorted(set(metrics) - set(valid))}; this mechanism's: {valid}")
    params = d.get("parameters", {})
    if not params:
        raise ParameterError("a sweep spec needs at least one [parameters.<name>] table")
    for name in params:
        parameter_unit(base, name)  # raises on unknown names
    n, seed = int(d.get("samples", 64)), int(d.get("seed", 0))
    tolerances = {}

    def rng(name, p):
        if "lower" not in p or "upper" not in p:
            raise ParameterError(f"[parameters.{name}] needs lower and upper for sampling = {sampling!r}")
        return float(p["lower"]), float(p["upper"])

    if sampling == "grid":
        levels = {}
        for name, p in params.items():
            if "values" in p:
                levels[name] = [float(v) for v in p["values"]]
            else:
                lo, hi = rng(name, p)
                levels[name] = np.linspace(lo, hi, int(p.get("points", 5))).tolist()
        names, designs = full_factorial(levels)
    elif sampling in ("lhs", "random"):
        ranges = {name: rng(name, p) for name, p in params.items()}
        names, designs = (latin_hypercube if sampling == "lhs" else random_uniform)(ranges, n, seed)
    elif sampling == "oat":
        ranges = {name: rng(name, p) for name, p in params.items()}
        names, designs = one_at_a_time(base, ranges, int(d.get("points", 11)))
    else:
        for name, p in params.items():
            if "tolerance" not in p:
                raise ParameterError(
                    f"[parameters.{name}] needs tolerance (and optionally nominal, "
                    "distribution) for sampling = 'monte_carlo'"
                )
            tolerances[name] = Tolerance(
                float(p.get("nominal", get_parameter(base, name))),
                float(p["tolerance"]),
                str(p.get("distribution", "uniform")),
            )
        names, designs = monte_carlo(tolerances, n, seed)
    return Spec(
        base, sampling, names, designs, settings, (int(d["chunk"]) if "chunk" in d else None), metrics, tolerances
    )


def load_spec(path, arguments=None) -> Spec:
    """Read a sweep spec TOML file (errors name the file); ``arguments``: command-line
    options that choose or change its mechanism
    ([`base_mechanism`][jaxcrank.runs.spec.base_mechanism])."""
    return config.load_toml(path, lambda d: spec_from_dict(d, base_mechanism(d, arguments)))
