"""The quantities a design problem can minimise or bound, by the names ``summary.json`` gives them.

Two kinds:

- **metrics**: the headline metrics of the motion (``summary.json``'s ``metrics``:
  [`jaxcrank.physics.signals.metric_definitions`][]), for example
  ``rms_transmission_angle_error_deg`` (the paper's Eq. 19), ``peak_contact_force_B_N``,
  ``rms_driving_moment_deviation_N_m``, ``max_abs_slider_x_deviation_m``. A design problem
  measures them over one period of the steady-state orbit.
- **kinematics**: the ideal (zero-clearance) mechanism over one revolution of its driven
  body (``summary.json``'s ``kinematics``,
  [`jaxcrank.analysis.kinematic_summary.kinematic_summary`][]), as traceable functions of
  the mechanism's parameters: `KINEMATICS`.

Every value is in the unit its name ends with. The kinematic extremes are the vertex of
the parabola through the extreme sample and its two neighbours, as in the kinematic
summary: smooth in the design (the sample index is held, the values move), so their
gradients are exact for the sampled curve.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp

from jaxcrank.analysis.kinematic_summary import four_bar_cycles
from jaxcrank.physics.compiled import as_model
from jaxcrank.physics.frame import transmission_angle
from jaxcrank.physics.kinematics import centre_poses, ideal_poses
from jaxcrank.physics.linkage import GROUND
from jaxcrank.physics.params import ParameterError
from jaxcrank.physics.signals import metric_definitions

DEG = 180.0 / math.pi
_COLUMN = {"x": 0, "y": 1, "angle": 2}

#: the kinematic quantities (name -> meaning); which a mechanism has follows from its outputs and loops
KINEMATICS = {
    "kinematics.output.stroke_m": "the output's stroke, max - min of its centre's coordinate (a translating output)",
    "kinematics.output.min_m": "the output coordinate's smallest value over a revolution",
    "kinematics.output.max_m": "the output coordinate's largest value over a revolution",
    "kinematics.output.swing_deg": "the output's swing, max - min of its angle (an oscillating output)",
    "kinematics.output.min_deg": "the output angle's smallest value (unwrapped from its start)",
    "kinematics.output.max_deg": "the output angle's largest value (unwrapped from its start)",
    "kinematics.transmission_angle.min_deg": "the smallest transmission angle over a revolution, in [0, 180] deg",
    "kinematics.transmission_angle.max_deg": "the largest transmission angle over a revolution, in [0, 180] deg",
    "kinematics.transmission_angle.max_deviation_from_90_deg": "the largest |transmission angle - 90 deg|",
    "kinematics.grashof.margin_m": "the smallest p + q - (s + l) over the four-bar loops (>= 0: Grashof)",
}


def output_spec(mech) -> tuple[str, str] | None:
    """The output (body, coordinate) the kinematic summary measures: ``outputs.acceleration``,
    else the first of ``outputs.deviations``; None when the mechanism names none."""
    lk = as_model(mech).linkage
    spec = lk.outputs.acceleration or (lk.outputs.deviations[0] if lk.outputs.deviations else None)
    return None if spec is None else tuple(spec)


def kinematic_names(mech) -> tuple[str, ...]:
    """The `KINEMATICS` names ``mech`` has: the output's stroke (or swing) where it names an
    output, the transmission angle's where it defines one, the Grashof margin where it has a
    loop of four revolute joints."""
    model = as_model(mech)
    out = []
    spec = output_spec(model)
    if spec is not None:
        unit, size = ("deg", "swing") if spec[1] == "angle" else ("m", "stroke")
        out += [f"kinematics.output.{size}_{unit}", f"kinematics.output.min_{unit}", f"kinematics.output.max_{unit}"]
    if model.linkage.outputs.transmission is not None:
        out += [k for k in KINEMATICS if k.startswith("kinematics.transmission_angle.")]
    if loops(model):
        out.append("kinematics.grashof.margin_m")
    return tuple(out)


def quantity_names(mech) -> tuple[str, ...]:
    """Every quantity name of ``mech``: its headline metrics, then its kinematic quantities."""
    return tuple(metric_definitions(mech)) + kinematic_names(mech)


def check_quantity(mech, name: str, where: str) -> None:
    """Raise ParameterError, naming ``where`` (the file's entry) and the valid names, unless
    ``name`` is a quantity of ``mech``."""
    valid = quantity_names(mech)
    if name not in valid:
        raise ParameterError(f"{where}: unknown quantity {name!r}; valid for this mechanism: {', '.join(valid)}")


def loops(mech) -> list[list[tuple[str, str]]]:
    """The loops of four revolute joints and four links (``[(joint, body after it), ...]``
    each), from the description alone."""
    return four_bar_cycles(as_model(mech))


def _point(lk, joint: str, body: str):
    site = next(s for s in lk.connections[joint].sites() if s.body == body)
    p = (lk.ground if body == GROUND else lk.bodies[body].points)[site.point]
    return jnp.asarray(p.x, dtype=float), jnp.asarray(p.y, dtype=float)


def _length(a, b):
    d2 = (a[0] - b[0]) ** 2 + (a[1] - b[1]) ** 2
    pos = d2 > 0.0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, d2, 1.0)), 0.0)


def grashof_margin(mech) -> jax.Array:
    """The smallest ``p + q - (s + l)`` over the mechanism's four-bar loops, m (s, l the
    shortest and longest link, p, q the others; >= 0 where every loop is Grashof), traceable
    (a kink where two links swap order). NaN without a loop."""
    model = as_model(mech)
    lk, margins = model.linkage, []
    for cycle in loops(model):
        joints = [j for j, _ in cycle]
        lengths = jnp.stack(
            [_length(_point(lk, j, b), _point(lk, joints[(i + 1) % 4], b)) for i, (j, b) in enumerate(cycle)]
        )
        margins.append(jnp.sum(lengths) - 2.0 * (jnp.min(lengths) + jnp.max(lengths)))
    return jnp.min(jnp.stack(margins)) if margins else jnp.asarray(jnp.nan)


def _extreme(y, pick):
    """The extremum ``pick`` (jnp.argmin or jnp.argmax) of the periodic samples ``y``: the vertex
    of the parabola through the extreme sample and its neighbours (the index held, the values
    differentiable)."""
    n = y.shape[0]
    k = jax.lax.stop_gradient(pick(y))
    a, b, c = y[(k - 1) % n], y[k], y[(k + 1) % n]
    curvature = a - 2.0 * b + c
    flat = curvature == 0.0
    shift = jnp.where(flat, 0.0, jnp.clip(0.5 * (a - c) / jnp.where(flat, 1.0, curvature), -0.5, 0.5))
    return b - 0.25 * (a - c) * shift


def kinematic_values(mech, names, samples: int = 720) -> dict[str, jax.Array]:
    """The kinematic quantities ``names`` (of [`kinematic_names`][optim.quantities.kinematic_names]) of
    ``mech``, traceable: the ideal mechanism at ``samples`` equal driver angles over one revolution.

    Raises:
        ParameterError: a name ``mech`` does not have."""
    names = list(names)
    if not names:
        return {}
    model = as_model(mech)
    have = kinematic_names(model)
    bad = [n for n in names if n not in have]
    if bad:
        raise ParameterError(f"kinematic quantities {bad} are not defined for this mechanism; valid: {list(have)}")
    lk = model.linkage
    phis = lk.driver.initial_angle + 2.0 * math.pi * jnp.arange(samples, dtype=float) / samples

    def one(phi):
        q = centre_poses(model, ideal_poses(model, phi))
        return q, transmission_angle(model, q)

    q, mu = jax.vmap(one)(phis)
    out = {}
    spec = output_spec(model)
    if spec is not None and any(n.startswith("kinematics.output.") for n in names):
        y = q[:, 3 * model.tree.bodies.index(spec[0]) + _COLUMN[spec[1]]]
        unit, size = ("m", "stroke")
        if spec[1] == "angle":
            unwrapped = jnp.unwrap(jnp.append(y, y[0])) * DEG
            full = jnp.abs(unwrapped[-1] - unwrapped[0]) > 180.0
            y, unit, size = unwrapped[:-1], "deg", "swing"
        low, high = _extreme(y, jnp.argmin), _extreme(y, jnp.argmax)
        span = high - low
        if spec[1] == "angle":
            span = jnp.where(full, 360.0, span)
        out.update(
            {f"kinematics.output.{size}_{unit}": span, f"kinematics.output.min_{unit}": low},
        )
        out[f"kinematics.output.max_{unit}"] = high
    if any(n.startswith("kinematics.transmission_angle.") for n in names):
        deg = mu * DEG
        low, high = _extreme(deg, jnp.argmin), _extreme(deg, jnp.argmax)
        out["kinematics.transmission_angle.min_deg"] = low
        out["kinematics.transmission_angle.max_deg"] = high
        out["kinematics.transmission_angle.max_deviation_from_90_deg"] = jnp.maximum(90.0 - low, high - 90.0)
    if "kinematics.grashof.margin_m" in names:
        out["kinematics.grashof.margin_m"] = grashof_margin(model)
    return {n: out[n] for n in names}
