"""Sweep specifications: a sweep read from a TOML file or dict (``jaxcrank sweep
SPEC.toml``), next to [`jaxcrank.runs.config`][] which reads the mechanism part.

Every problem with a spec raises [`jaxcrank.ParameterError`][jaxcrank.physics.params.ParameterError] naming the key
and what is valid.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

import numpy as np

from ..analysis.metrics import METRICS
from ..physics.params import Mechanism, ParameterError, get_parameter, parameter_unit
from . import config
from .sampling import Tolerance, full_factorial, latin_hypercube, monte_carlo, one_at_a_time, random_uniform
from .sweep import Settings

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


def spec_from_dict(d: Mapping) -> Spec:
    """Build a [`Spec`][jaxcrank.runs.spec.Spec] from a parsed TOML dict; every problem raises
    [`ParameterError`][jaxcrank.physics.params.ParameterError] naming the key."""
    bad = set(d) - _SPEC_KEYS
    if bad:
        raise ParameterError(f"unknown sweep spec keys {sorted(bad)}; valid: {sorted(_SPEC_KEYS)}")
    sampling = d.get("sampling", "grid")
    if sampling not in SAMPLINGS:
        raise ParameterError(f"sampling {sampling!r} is unknown; valid: {', '.join(SAMPLINGS)}")
    base = config.from_dict(d.get("mechanism", {}))
    settings = Settings.from_text(dict(d.get("simulation", {})))
    metrics = list(d.get("metrics", METRICS))
    if set(metrics) - set(METRICS):
        raise ParameterError(f"unknown metrics {sorted(set(metrics) - set(METRICS))}; valid: {list(METRICS)}")
    params = d.get("parameters", {})
    if not params:
        raise ParameterError("a sweep spec needs at least one [parameters.<name>] table")
    for name in params:
        parameter_unit(name)  # raises on unknown names
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


def load_spec(path) -> Spec:
    """Read a sweep spec TOML file (errors name the file)."""
    return config.load_toml(path, spec_from_dict)
