"""A mechanism's signals and headline metrics, named from its own description.

A *signal* is one number per instant of a [`Frame`][jaxcrank.physics.frame.Frame]; a *metric* reduces one
signal over a window of time (``max_abs``, ``max`` or ``rms``). Which signals exist
follows from the description: a contact force for every joint, a penetration for every
joint with clearance, the deviations its [`Outputs`][jaxcrank.physics.linkage.Outputs] name, the driving moment
and (where defined) the transmission angle. Names carry the body and joint names and end
in their unit (``_m``, ``_N``, ``_deg``, ...): ``contact_force_B_N``,
``slider_x_deviation_m``, ``rocker_angle_deviation_deg``.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax.numpy as jnp
from jaxtyping import Array

from .compiled import Model, as_model
from .frame import Frame
from .linkage import AbstractMechanism

Mechanism = AbstractMechanism | Model

DEG = 180.0 / math.pi

_COORDINATE = {"x": (0, "x", "m", 1.0), "y": (1, "y", "m", 1.0), "angle": (2, "angle", "deg", DEG)}
_ACCELERATION = {
    "x": (0, "ax", "m_s2", 1.0),
    "y": (1, "ay", "m_s2", 1.0),
    "angle": (2, "angular_acceleration", "rad_s2", 1.0),
}


class Metric(NamedTuple):
    """How one headline metric is computed (its units are its name's suffix).

    Attributes:
        reduction: ``"max_abs"``, ``"max"`` or ``"rms"``.
        signal: the name of the per-sample signal it reduces.
        meaning: what it measures, for people.
    """

    reduction: str
    signal: str
    meaning: str


def _deviation_name(body: str, coordinate: str) -> str:
    _, label, unit, _ = _COORDINATE[coordinate]
    return f"{body}_{label}_deviation_{unit}"


def _acceleration_name(body: str, coordinate: str) -> str:
    _, label, unit, _ = _ACCELERATION[coordinate]
    return f"{body}_{label}_deviation_{unit}"


def _wrapped(angle):
    """An angle difference, rad, brought into [-pi, pi] (unchanged where it is already)."""
    return angle - 2.0 * math.pi * jnp.floor(angle / (2.0 * math.pi) + 0.5)


def signal_meanings(mech: Mechanism) -> dict[str, str]:
    """Signal name -> what it is, for this mechanism (units in the names)."""
    model = as_model(mech)
    lk, tree = model.linkage, model.tree
    out = {}
    for body, coord in lk.outputs.deviations:
        out[_deviation_name(body, coord)] = f"{body} {coord} minus ideal"
    if lk.outputs.acceleration is not None:
        body, coord = lk.outputs.acceleration
        out[_acceleration_name(body, coord)] = f"{body} {coord} acceleration minus ideal"
    for j in tree.joints:
        what = "normal contact force" if j in tree.cut else "reaction force magnitude (ideal joint)"
        out[f"contact_force_{j}_N"] = f"{what} at {j}"
    for j in tree.cut:
        out[f"penetration_{j}_m"] = f"penetration at {j} (negative while separated)"
    out["driving_moment_N_m"] = "moment that drives the mechanism"
    out["driving_moment_deviation_N_m"] = "driving moment minus the ideal mechanism's"
    if lk.outputs.transmission is not None:
        out["transmission_angle_error_deg"] = "actual minus ideal transmission angle"
    return out


def signals(mech: Mechanism, frame: Frame) -> dict[str, Array]:
    """The per-sample signals of [`signal_meanings`][jaxcrank.physics.signals.signal_meanings] from a
    [`Frame`][jaxcrank.physics.frame.Frame] (one instant, or arrays of them along a leading axis); SI units
    and degrees (angle deviations wrapped to [-180, 180] deg)."""
    model = as_model(mech)
    lk, tree = model.linkage, model.tree
    out = {}
    for body, coord in lk.outputs.deviations:
        i = tree.bodies.index(body)
        k, _, _, factor = _COORDINATE[coord]
        deviation = frame.q[..., i, k] - frame.ideal_q[..., i, k]
        out[_deviation_name(body, coord)] = (_wrapped(deviation) if coord == "angle" else deviation) * factor
    if lk.outputs.acceleration is not None:
        body, coord = lk.outputs.acceleration
        i = tree.bodies.index(body)
        k = _ACCELERATION[coord][0]
        out[_acceleration_name(body, coord)] = frame.qdd[..., i, k] - frame.ideal_qdd[..., i, k]
    for m, j in enumerate(tree.joints):
        out[f"contact_force_{j}_N"] = frame.normal_force[..., m]
    for j in tree.cut:
        out[f"penetration_{j}_m"] = frame.penetration[..., tree.joints.index(j)]
    out["driving_moment_N_m"] = frame.driving_moment
    out["driving_moment_deviation_N_m"] = frame.driving_moment - frame.ideal_driving_moment
    if lk.outputs.transmission is not None:
        out["transmission_angle_error_deg"] = (frame.transmission_angle - frame.ideal_transmission_angle) * DEG
    return out


def metric_definitions(mech: Mechanism) -> dict[str, Metric]:
    """Headline metric name -> [`Metric`][jaxcrank.physics.signals.Metric] for this mechanism; units are the
    name's suffix. Deviations get their largest and RMS values, the output link's
    acceleration deviation its largest, every joint its peak and RMS force, every
    clearance joint its largest penetration, the driver its peak moment and RMS
    deviation, the transmission angle its RMS and largest error."""
    model = as_model(mech)
    lk, tree = model.linkage, model.tree
    out = {}
    for body, coord in lk.outputs.deviations:
        sig = _deviation_name(body, coord)
        out[f"max_abs_{sig}"] = Metric("max_abs", sig, f"largest |{body} {coord} - ideal|")
    if lk.outputs.acceleration is not None:
        body, coord = lk.outputs.acceleration
        sig = _acceleration_name(body, coord)
        out[f"max_abs_{sig}"] = Metric("max_abs", sig, f"largest |{body} {coord} acceleration - ideal|")
    for j in tree.joints:
        out[f"peak_contact_force_{j}_N"] = Metric("max_abs", f"contact_force_{j}_N", f"largest normal force at {j}")
    for j in tree.cut:
        out[f"max_penetration_{j}_m"] = Metric("max", f"penetration_{j}_m", f"largest penetration at {j}")
    out["peak_driving_moment_N_m"] = Metric("max_abs", "driving_moment_N_m", "largest |driving moment|")
    out["rms_driving_moment_deviation_N_m"] = Metric(
        "rms", "driving_moment_deviation_N_m", "RMS of driving moment - ideal driving moment"
    )
    for body, coord in lk.outputs.deviations:
        sig = _deviation_name(body, coord)
        out[f"rms_{sig}"] = Metric("rms", sig, f"RMS of {body} {coord} - ideal")
    if lk.outputs.transmission is not None:
        out["rms_transmission_angle_error_deg"] = Metric(
            "rms", "transmission_angle_error_deg", "RMS of actual - ideal transmission angle (paper Eq. 19)"
        )
        out["max_abs_transmission_angle_error_deg"] = Metric(
            "max_abs", "transmission_angle_error_deg", "largest |actual - ideal transmission angle|"
        )
    for j in tree.joints:
        out[f"rms_contact_force_{j}_N"] = Metric("rms", f"contact_force_{j}_N", f"RMS normal force at {j} (wear proxy)")
    return out


def peak_metrics(mech: Mechanism) -> tuple[str, ...]:
    """The metrics that are maxima (taken at every accepted solver step by the tracking)."""
    return tuple(k for k, m in metric_definitions(mech).items() if m.reduction in ("max_abs", "max"))


def rms_metrics(mech: Mechanism) -> tuple[str, ...]:
    """The metrics that are time averages of squares (deviations, forces): the ones the
    ensemble gradient follows."""
    return tuple(k for k, m in metric_definitions(mech).items() if m.reduction == "rms")


def force_metrics(mech: Mechanism) -> tuple[str, ...]:
    """The peak contact-force metrics, whose whole-run maxima a tracked solve also keeps."""
    return tuple(f"peak_contact_force_{j}_N" for j in as_model(mech).tree.joints)


def rms_signals(mech: Mechanism, frame: Frame) -> Array:
    """The signals behind [`rms_metrics`][jaxcrank.physics.signals.rms_metrics], stacked in that order along the last
    axis."""
    sig = signals(mech, frame)
    defs = metric_definitions(mech)
    return jnp.stack([sig[defs[k].signal] for k in rms_metrics(mech)], axis=-1)


def peak_values(mech: Mechanism, frame: Frame) -> Array:
    """The values whose running maxima give [`peak_metrics`][jaxcrank.physics.signals.peak_metrics] (|signal| for
    ``max_abs``), stacked in that order."""
    sig = signals(mech, frame)
    defs = metric_definitions(mech)
    out = []
    for name in peak_metrics(mech):
        m = defs[name]
        out.append(jnp.abs(sig[m.signal]) if m.reduction == "max_abs" else sig[m.signal])
    return jnp.stack(out, axis=-1)


def initial_peaks(mech: Mechanism) -> Array:
    """Starting values of the running maxima (-inf for ``max`` metrics, 0 for ``max_abs``)."""
    defs = metric_definitions(mech)
    return jnp.array([-jnp.inf if defs[k].reduction == "max" else 0.0 for k in peak_metrics(mech)])
