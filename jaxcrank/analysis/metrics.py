"""Headline metrics of a run: the one definition used by ``jaxcrank simulate``'s
summary, sweep tables, sensitivities and design objectives.

A mechanism's metrics are named from its description
([`jaxcrank.physics.signals.metric_definitions`][]); each reduces one per-sample
*signal* over the samples of a window ``t > t_start``:

- ``max_abs``: the largest absolute value;
- ``max``: the largest value (penetrations: negative while separated);
- ``rms``: the root mean square over the window's samples.

Everything here is traceable (``jit``, ``vmap``, ``grad``); units are the suffix of
each name (``_m``, ``_N``, ``_deg``, ...).
"""

from __future__ import annotations

from collections.abc import Sequence

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ..physics.frame import Frame
from ..physics.signals import (
    DEG,
    Metric,
    force_metrics,
    metric_definitions,
    peak_metrics,
    rms_metrics,
    rms_signals,
    signal_meanings,
    signals,
)

__all__ = [
    "DEG",
    "Metric",
    "by_name",
    "force_metrics",
    "headline",
    "meanings",
    "metric_definitions",
    "peak_metrics",
    "reduce_signal",
    "rms_metrics",
    "rms_signals",
    "signal_meanings",
    "signals",
    "stack",
]


def meanings(mech) -> dict[str, str]:
    """Metric name -> what it measures, for ``mech`` (units in the names)."""
    return {k: m.meaning for k, m in metric_definitions(mech).items()}


def reduce_signal(reduction: str, x: Float[Array, " n"], window: Float[Array, " n"]) -> Float[Array, ""]:
    """One reduction of a signal ``x`` over the samples where ``window`` is true.

    Raises:
        ValueError: for an unknown reduction name.
    """
    if reduction == "max_abs":
        return jnp.max(jnp.where(window, jnp.abs(x), 0.0))
    if reduction == "max":
        return jnp.max(jnp.where(window, x, -jnp.inf))
    if reduction == "rms":
        n = jnp.maximum(jnp.sum(window), 1).astype(x.dtype)
        return jnp.sqrt(jnp.sum(jnp.where(window, x**2, 0.0)) / n)
    raise ValueError(f"unknown reduction {reduction!r}; valid: 'max_abs', 'max', 'rms'")


def headline(mech, frames: Frame, t_start: Float[ArrayLike, ""]) -> dict[str, Float[Array, ""]]:
    """The metrics of ``mech`` over the samples of ``frames`` (a
    [`Frame`][jaxcrank.physics.frame.Frame] of arrays, e.g. [`jaxcrank.analysis.outputs.frames`][]) with time
    ``t > t_start`` (s).

    Returns a dict of scalars in the units of each name. Traceable. A window without
    samples gives 0 for ``max_abs`` and ``rms`` metrics and -inf for ``max`` ones:
    callers that may pass such a window check it first.
    """
    window = frames.t > t_start
    sig = signals(mech, frames)
    return {name: reduce_signal(m.reduction, sig[m.signal], window) for name, m in metric_definitions(mech).items()}


def stack(names: Sequence[str], values) -> Float[Array, "*batch metrics"]:
    """The metrics ``names`` of a mapping ``values`` (metric name -> array) stacked along
    a new last axis, in the order of ``names``: the one way a vector of metrics is built."""
    return jnp.stack([values[k] for k in names], axis=-1)


def by_name(names: Sequence[str], vector: Float[ArrayLike, "*batch metrics"]) -> dict[str, Float[Array, "*batch"]]:
    """A vector of metrics (last axis in the order of ``names``, e.g. a mechanism's
    [`rms_metrics`][jaxcrank.physics.signals.rms_metrics] for
    [`rms_signals`][jaxcrank.physics.signals.rms_signals]) as a dict metric name -> array:
    the one way a metric is read back out of a vector, so no caller indexes it by position.

    Raises:
        ValueError: if the last axis does not have one entry per name.
    """
    vector = jnp.asarray(vector)
    if vector.shape[-1] != len(names):
        raise ValueError(f"a vector of {vector.shape[-1]} metrics cannot hold the {len(names)} metrics {list(names)}")
    return {k: vector[..., j] for j, k in enumerate(names)}
