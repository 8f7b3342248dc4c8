"""The ``[objective]`` tables of config and problem files: the objective they describe
([`objective_from_config`][optim.objective_config.objective_from_config]) and the table of an
objective ([`objective_config`][optim.objective_config.objective_config]). The boundary between
files and the objective kinds ([`optim.objective`][], [`optim.ensemble`][], [`optim.steady`][])."""

from __future__ import annotations

import dataclasses

import diffrax

from jaxcrank.numerics.solve import DEFAULTS
from jaxcrank.physics.params import ParameterError

from .ensemble import WINDOW_DEFAULTS, Ensemble
from .objective import AbstractObjective, Pathwise, options_fields, options_from_fields
from .steady import STEADY_OBJECTIVE, Steady

__all__ = ["objective_config", "objective_from_config", "options_fields", "options_from_fields"]


def _check_keys(values: dict, valid: set) -> None:
    bad = set(values) - valid
    if bad:
        raise ParameterError(f"unknown [objective] keys {sorted(bad)}; valid: {sorted(valid)}")


def objective_from_config(section: dict) -> AbstractObjective:
    """The objective of an ``[objective]`` table: ``method`` ("ensemble" by default,
    "pathwise" or "steady_state") and the flat keys of that objective's
    ``describe()``: its fields, the solve's ``solver``/``rtol``/``atol``/``dt0``/``max_steps``
    (an ensemble's windows: the same with ``window_``; they follow the solve's rtol/atol
    unless given), and a steady state's settings; ``window_gradient`` ("forward" or
    "reverse") picks an ensemble's window adjoint, ``on_failure`` ("raise" or "nan") its
    ``throw``.

    Raises:
        ParameterError: for an unknown method, key or value (the message lists the valid ones)."""
    values = dict(section)
    kind = values.pop("method", "ensemble")
    kinds = {"ensemble": Ensemble, "pathwise": Pathwise, "steady_state": Steady}
    if kind not in kinds:
        raise ParameterError(f"objective method {kind!r} is unknown; valid: 'ensemble', 'pathwise', 'steady_state'")
    if "on_failure" in values:
        mode = values.pop("on_failure")
        if mode not in ("raise", "nan"):
            raise ParameterError(f"objective on_failure {mode!r} is unknown; valid: 'raise', 'nan'")
        values["throw"] = mode == "raise"
    if "window_gradient" in values:
        values["window_adjoint"] = values.pop("window_gradient")
    _check_keys(values, set(kinds[kind]().describe()) - {"kind"})
    if kind == "steady_state":
        if isinstance(values.get("trend"), dict):
            values["trend"] = objective_from_config(values["trend"])
        solve = options_from_fields(values, STEADY_OBJECTIVE.solve)
        steady = {k: values.pop(k) for k in list(values) if k not in ("trend", "throw")}
        return Steady(options=dataclasses.replace(STEADY_OBJECTIVE, solve=solve, **steady), **values)
    if "window_adjoint" in values:
        mode = values.pop("window_adjoint")
        adjoints = {"forward": diffrax.ForwardMode(), "reverse": diffrax.RecursiveCheckpointAdjoint()}
        if mode not in adjoints:
            raise ParameterError(f"objective window_gradient {mode!r} is unknown; valid: 'forward', 'reverse'")
        values["window_adjoint"] = adjoints[mode]
    values["options"] = options_from_fields(values, DEFAULTS)
    if kind == "ensemble":
        base = WINDOW_DEFAULTS.replace(rtol=values["options"].rtol, atol=values["options"].atol)
        values["window_options"] = options_from_fields(values, base, "window_")
    return kinds[kind](**values)


def objective_config(objective: AbstractObjective) -> dict:
    """The ``[objective]`` table of ``objective``
    ([`objective_from_config`][optim.objective_config.objective_from_config] reads it back)."""
    d = objective.describe()
    out = {"method": d.pop("kind")}
    if "window_adjoint" in d:
        out["window_gradient"] = d.pop("window_adjoint")
    out["on_failure"] = "raise" if d.pop("throw") else "nan"
    if "trend" in d:  # the steady-state objective's trend estimate: an [objective.trend] table
        d["trend"] = None if objective.trend is None else objective_config(objective.trend)
    return {**out, **d}
