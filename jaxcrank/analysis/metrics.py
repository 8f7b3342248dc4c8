"""Headline metrics of a run: the one definition used by ``jaxcrank simulate``'s
summary, sweep tables, sensitivities and design objectives.

A metric reduces one per-sample *signal* ([`signals`][jaxcrank.analysis.metrics.signals]) over the samples of a
window ``t > t_start``:

- ``max_abs``: the largest absolute value;
- ``max``: the largest value (penetrations: negative while separated);
- ``rms``: the root mean square over the window's samples.

Everything here is traceable (``jit``, ``vmap``, ``grad``); units are the suffix of
each name (``_m``, ``_N``, ``_deg``, ...).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ..physics import ideal
from ..physics.model import Frame

DEG = 180.0 / math.pi

#: per-sample signals (name -> meaning); units are the name's suffix
SIGNALS = {
    "rod_x_deviation_m": "rod-centre x minus ideal",
    "slider_x_deviation_m": "slider x minus ideal",
    "slider_ax_deviation_m_s2": "slider x acceleration minus ideal",
    "contact_force_B_N": "normal contact force at B (an ideal joint: its reaction's magnitude)",
    "contact_force_C_N": "normal contact force at C (an ideal joint: its reaction's magnitude)",
    "penetration_B_m": "penetration at B (negative while separated)",
    "penetration_C_m": "penetration at C (negative while separated)",
    "driving_moment_N_m": "moment that drives the crank",
    "driving_moment_deviation_N_m": "driving moment minus the ideal mechanism's",
    "transmission_angle_error_deg": "actual minus ideal transmission angle (paper Eq. 18)",
}


class Metric(NamedTuple):
    """How one headline metric is computed (its units are its name's suffix).

    Attributes:
        reduction: ``"max_abs"``, ``"max"`` or ``"rms"`` ([`reduce_signal`][jaxcrank.analysis.metrics.reduce_signal]).
        signal: the name of the per-sample signal it reduces (`SIGNALS`).
        meaning: what it measures, for people.
    """

    reduction: str
    signal: str
    meaning: str


#: headline metrics: name -> :class:`Metric`; units are the name's suffix
METRICS = {
    "max_abs_rod_x_deviation_m": Metric("max_abs", "rod_x_deviation_m", "largest |rod-centre x - ideal|"),
    "max_abs_slider_x_deviation_m": Metric("max_abs", "slider_x_deviation_m", "largest |slider x - ideal|"),
    "max_abs_slider_ax_deviation_m_s2": Metric(
        "max_abs",
        "slider_ax_deviation_m_s2",
        "largest |slider acceleration - ideal|",
    ),
    "peak_contact_force_B_N": Metric("max_abs", "contact_force_B_N", "largest normal contact force at B"),
    "peak_contact_force_C_N": Metric("max_abs", "contact_force_C_N", "largest normal contact force at C"),
    "max_penetration_B_m": Metric("max", "penetration_B_m", "largest penetration at B"),
    "max_penetration_C_m": Metric("max", "penetration_C_m", "largest penetration at C"),
    "peak_driving_moment_N_m": Metric("max_abs", "driving_moment_N_m", "largest |driving moment|"),
    "rms_driving_moment_deviation_N_m": Metric(
        "rms",
        "driving_moment_deviation_N_m",
        "RMS of driving moment - ideal driving moment",
    ),
    "rms_rod_x_deviation_m": Metric("rms", "rod_x_deviation_m", "RMS of rod-centre x - ideal"),
    "rms_slider_x_deviation_m": Metric("rms", "slider_x_deviation_m", "RMS of slider x - ideal"),
    "rms_transmission_angle_error_deg": Metric(
        "rms",
        "transmission_angle_error_deg",
        "RMS of actual - ideal transmission angle (paper Eq. 19)",
    ),
    "max_abs_transmission_angle_error_deg": Metric(
        "max_abs",
        "transmission_angle_error_deg",
        "largest |actual - ideal transmission angle|",
    ),
    "rms_contact_force_B_N": Metric("rms", "contact_force_B_N", "RMS normal contact force at B (bearing wear proxy)"),
    "rms_contact_force_C_N": Metric("rms", "contact_force_C_N", "RMS normal contact force at C (bearing wear proxy)"),
}

#: the metrics that are maxima: over a solve, :mod:`jaxcrank.numerics.tracking` takes them at
#: every accepted step
PEAK_METRICS = tuple(k for k, m in METRICS.items() if m.reduction in ("max_abs", "max"))

#: the metrics that are time averages of squares (deviations from the ideal mechanism,
#: contact forces): the ones whose gradient the ensemble estimate of
#: :mod:`optim.sensitivity` follows
RMS_METRICS = (
    "rms_transmission_angle_error_deg",
    "rms_rod_x_deviation_m",
    "rms_slider_x_deviation_m",
    "rms_driving_moment_deviation_N_m",
    "rms_contact_force_B_N",
    "rms_contact_force_C_N",
)
assert {k for k, m in METRICS.items() if m.reduction == "rms"} == set(RMS_METRICS)


def meanings() -> dict[str, str]:
    """Metric name -> what it measures (units in the name)."""
    return {k: m.meaning for k, m in METRICS.items()}


def transmission_angle_deviation(
    rod_angle: Float[ArrayLike, "*shape"], ideal_rod_angle: Float[ArrayLike, "*shape"]
) -> Float[Array, "*shape"]:
    """Actual minus ideal transmission angle, degrees, from the actual and ideal rod
    angles theta2 (rad, any matching shapes) at the same crank angle."""
    return (ideal.transmission_angle(rod_angle) - ideal.transmission_angle(ideal_rod_angle)) * DEG


def signals(frame: Frame) -> dict[str, Float[Array, "*samples"]]:
    """The per-sample signals of `SIGNALS` from a [`jaxcrank.physics.model.Frame`][jaxcrank.physics.frame.Frame]
    (one instant, or arrays of them along a leading axis), SI units and degrees."""
    q, qi = frame.q, frame.ideal_q
    return {
        "rod_x_deviation_m": q[..., 0] - qi[..., 0],
        "slider_x_deviation_m": q[..., 3] - qi[..., 3],
        "slider_ax_deviation_m_s2": frame.qdd[..., 3] - frame.ideal_qdd[..., 3],
        "contact_force_B_N": frame.normal_force_B,
        "contact_force_C_N": frame.normal_force_C,
        "penetration_B_m": frame.penetration_B,
        "penetration_C_m": frame.penetration_C,
        "driving_moment_N_m": frame.driving_moment,
        "driving_moment_deviation_N_m": frame.driving_moment - frame.ideal_driving_moment,
        "transmission_angle_error_deg": transmission_angle_deviation(q[..., 2], qi[..., 2]),
    }


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


def headline(frames: Frame, t_start: Float[ArrayLike, ""]) -> dict[str, Float[Array, ""]]:
    """`METRICS` over the samples of ``frames`` (a [`jaxcrank.physics.model.Frame`][jaxcrank.physics.frame.Frame]
    of arrays, e.g. [`jaxcrank.analysis.outputs.frames`][]) with time ``t > t_start`` (s).

    Returns a dict of scalars in the units of each name. Traceable. A window without
    samples gives 0 for ``max_abs`` and ``rms`` metrics and -inf for ``max`` ones:
    callers that may pass such a window check it first ([`window_samples`][jaxcrank.analysis.metrics.window_samples]).
    """
    window = frames.t > t_start
    sig = signals(frames)
    return {name: reduce_signal(m.reduction, sig[m.signal], window) for name, m in METRICS.items()}


def window_samples(ts: Float[ArrayLike, " n"], t_start: Float[ArrayLike, ""]) -> int:
    """Number of samples of ``ts`` (s, concrete) in the window ``t > t_start``."""
    return int(jnp.sum(jnp.asarray(ts) > t_start))


def rms_signals(frame: Frame) -> Float[Array, "*samples rms"]:
    """The signals behind `RMS_METRICS`, stacked in that order along the last axis
    ([`by_name`][jaxcrank.analysis.metrics.by_name] names the columns again)."""
    sig = signals(frame)
    return jnp.stack([sig[METRICS[k].signal] for k in RMS_METRICS], axis=-1)


def stack(names: Sequence[str], values) -> Float[Array, "*batch metrics"]:
    """The metrics ``names`` of a mapping ``values`` (metric name -> array) stacked along
    a new last axis, in the order of ``names``: the one way a vector of metrics is built."""
    return jnp.stack([values[k] for k in names], axis=-1)


def by_name(names: Sequence[str], vector: Float[ArrayLike, "*batch metrics"]) -> dict[str, Float[Array, "*batch"]]:
    """A vector of metrics (last axis in the order of ``names``, e.g. `RMS_METRICS`
    for [`rms_signals`][jaxcrank.analysis.metrics.rms_signals] ) as a dict metric name -> array: the one way a metric is
    read
    back out of a vector, so no caller indexes it by position.

    Raises:
        ValueError: if the last axis does not have one entry per name.
    """
    vector = jnp.asarray(vector)
    if vector.shape[-1] != len(names):
        raise ValueError(f"a vector of {vector.shape[-1]} metrics cannot hold the {len(names)} metrics {list(names)}")
    return {k: vector[..., j] for j, k in enumerate(names)}
