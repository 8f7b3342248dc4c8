"""A kinematic summary of a mechanism's ideal (zero-clearance) motion over one revolution
of its driven body: the output's stroke or swing and where its extremes fall, the
quick-return time ratio, the range of the transmission angle, and the Grashof type of
every four-bar loop. Sampled in the driver's angle, not in time
([`jaxcrank.physics.kinematics.ideal_poses`][], one jitted, vmapped evaluation in
float64), so it does not depend on the driver's speed law.
"""

from __future__ import annotations

import itertools
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..physics.compiled import Model, as_model
from ..physics.frame import transmission_angle
from ..physics.kinematics import centre_poses, ideal_poses
from ..physics.linkage import GROUND, AbstractMechanism, Linkage
from ..physics.params import ParameterError
from ..physics.topology import Skeleton

__all__ = ["format_summary", "four_bar_cycles", "grashof_loops", "kinematic_summary"]

DEG = 180.0 / math.pi
#: relative tolerance of a change-point four-bar: |(s + l) - (p + q)| <= CHANGE_POINT_RTOL (p + q)
CHANGE_POINT_RTOL = 1e-9
_COLUMN = {"x": 0, "y": 1, "angle": 2}


def kinematic_summary(mech: AbstractMechanism | Model, samples: int = 3600) -> dict:
    """The ideal mechanism over one revolution of its driven body, as a JSON-ready dict.

    The bodies are placed at ``samples`` equally spaced driver angles phi_k = phi_0 +
    360 deg k / ``samples`` (phi_0: the driver's initial angle). Each extremum (of the
    output, of the transmission angle) is the vertex of the parabola through the sample
    at the extreme and its two neighbours, so its driver angle is resolved far below the
    sample spacing (to O(spacing^2)) and its value to O(spacing^3); at a corner (a
    transmission angle reaching 0 or 180 deg) only to the sample spacing.

    Its entries:

    - ``mechanism``, ``driver_body``, ``driver_angle_start_deg`` (phi_0, deg),
      ``samples``;
    - ``output``: ``None`` where the mechanism names no output, else the output
      (``outputs.acceleration``, else the first of ``outputs.deviations``) with
      ``body``, ``coordinate`` (``"x"``/``"y"`` of its centre of mass, or ``"angle"``),
      ``full_rotation`` (an angle that turns through whole revolutions), and either
      ``stroke_m``, ``min_m``, ``max_m`` (a translation) or ``swing_deg``,
      ``min_deg``, ``max_deg`` (an angle, unwrapped from its value at phi_0), with
      ``min_at_driver_deg`` and ``max_at_driver_deg`` (the global extremes). A fully
      turning angle has ``swing_deg = 360`` and ``None`` for its extremes.
    - ``time_ratio``: ``None`` without output extremes, else the quick-return ratio
      at constant driver speed (the ratio of the times of the two strokes is the
      ratio of the driver angles they sweep): ``forward_stroke_deg`` (driver angle
      from the output's global minimum to its global maximum), ``return_stroke_deg``
      (from the maximum back to the minimum), ``ratio`` (the larger over the
      smaller, >= 1) and ``slower_stroke`` (``"forward"`` or ``"return"``, the one
      that sweeps the larger angle).
    - ``transmission_angle``: ``None`` where the mechanism defines none, else
      ``min_deg``, ``max_deg``, ``min_at_driver_deg``, ``max_at_driver_deg`` and
      ``max_deviation_from_90_deg``. The angle is the one of the
      ``ideal_transmission_angle`` output column
      ([`jaxcrank.physics.frame.transmission_angle`][]): between the two transmission
      directions, in [0, 180] deg (not folded into [0, 90]).
    - ``grashof``: [`grashof_loops`][jaxcrank.analysis.kinematic_summary.grashof_loops].

    Args:
        mech: any mechanism (a preset, a written-out linkage) or a compiled model.
        samples: driver angles over the revolution, an integer >= 8.

    Returns:
        Plain Python values (float, int, str, bool, list, dict, None), units in the keys;
        driver angles (``*_at_driver_deg``) in deg from phi_0, in [0, 360).

    Raises:
        ParameterError: ``samples`` is not an integer >= 8; the mechanism does not
            compile or assemble (from [`jaxcrank.physics.compiled.compile_model`][]), or
            its ideal poses are not finite at some driver angle.
        TypeError: ``mech`` is not a mechanism or a model.
    """
    if isinstance(samples, bool) or not isinstance(samples, (int, np.integer)) or samples < 8:
        raise ParameterError(f"samples = {samples!r} is outside its valid range: an integer >= 8")
    if not isinstance(mech, (AbstractMechanism, Model)):
        raise TypeError(f"expected a mechanism (jaxcrank.preset(...), jaxcrank.config.load(...)), got {mech!r}")
    n = int(samples)
    model = as_model(mech)
    lk = model.linkage
    phi0 = float(lk.driver.initial_angle)
    phis = phi0 + 2.0 * math.pi * np.arange(n, dtype=float) / n
    q, mu = (np.asarray(a) for a in _sample(_traced(model), jnp.asarray(phis)))
    bad = ~(np.all(np.isfinite(q), axis=1) & np.isfinite(mu))
    if bad.any():
        k = int(np.argmax(bad))
        raise ParameterError(
            f"the ideal mechanism {lk.name!r} does not assemble at driver angle {(phis[k] - phi0) * DEG:.6g} deg "
            f"from its initial angle (its ideal poses are not finite there)"
        )
    summary = {
        "mechanism": str(lk.name),
        "driver_body": str(lk.driver.body),
        "driver_angle_start_deg": phi0 * DEG,
        "samples": n,
        "output": None,
        "time_ratio": None,
        "transmission_angle": None,
        "grashof": grashof_loops(model),
    }
    spec = lk.outputs.acceleration or (lk.outputs.deviations[0] if lk.outputs.deviations else None)
    if spec is not None:
        summary["output"], summary["time_ratio"] = _output(model, q, tuple(spec))
    if lk.outputs.transmission is not None:
        angle = summary["transmission_angle"] = _extremes(mu * DEG, "deg")
        angle["max_deviation_from_90_deg"] = max(abs(angle["min_deg"] - 90.0), abs(angle["max_deg"] - 90.0))
    return summary


@eqx.filter_jit
def _sample(model: Model, phis):
    """Centre-of-mass poses (flattened per sample) and transmission angles (rad) of the ideal
    mechanism at the driver angles ``phis`` (rad)."""

    def one(phi):
        q = centre_poses(model, ideal_poses(model, phi))
        return q, transmission_angle(model, q)

    return jax.vmap(one)(phis)


def _traced(model: Model) -> Model:
    """``model`` with its Python floats as arrays: ``_sample`` compiles once per structure."""
    return jax.tree_util.tree_map(lambda x: jnp.asarray(x, dtype=float) if isinstance(x, float) else x, model)


def _extreme(y: np.ndarray, pick) -> tuple[float, float]:
    """(driver angle, deg in [0, 360), value) of the extremum ``pick`` (``np.argmin`` or
    ``np.argmax``) of the periodic samples ``y``: the vertex of the parabola through the
    extreme sample and its neighbours."""
    n = len(y)
    k = int(pick(y))
    a, b, c = float(y[(k - 1) % n]), float(y[k]), float(y[(k + 1) % n])
    curvature = a - 2.0 * b + c
    shift = 0.0 if curvature == 0.0 else min(0.5, max(-0.5, 0.5 * (a - c) / curvature))
    return ((k + shift) * 360.0 / n) % 360.0, b - 0.25 * (a - c) * shift


def _at(angle_deg: float) -> str:
    """A driver angle in [0, 360) deg to 0.1 deg (359.97 is 0.0, the turn's start, not 360.0)."""
    return f"{round(angle_deg, 1) % 360.0:.1f}"


def _extremes(y: np.ndarray, unit: str) -> dict:
    """The global minimum and maximum of the periodic samples ``y`` and their driver angles."""
    (low_at, low), (high_at, high) = _extreme(y, np.argmin), _extreme(y, np.argmax)
    return {f"min_{unit}": low, f"max_{unit}": high, "min_at_driver_deg": low_at, "max_at_driver_deg": high_at}


def _output(model: Model, q: np.ndarray, spec: tuple[str, str]) -> tuple[dict, dict | None]:
    """The ``output`` and ``time_ratio`` entries of the summary."""
    body, coordinate = spec
    y = q[:, 3 * model.tree.bodies.index(body) + _COLUMN[coordinate]]
    out = {"body": str(body), "coordinate": str(coordinate), "full_rotation": False}
    if coordinate == "angle":
        y = np.unwrap(np.append(y, y[0])) * DEG
        out["full_rotation"] = bool(abs(y[-1] - y[0]) > 180.0)
        y = y[:-1]
    unit, size = ("deg", "swing_deg") if coordinate == "angle" else ("m", "stroke_m")
    if out["full_rotation"]:
        keys = (size, f"min_{unit}", f"max_{unit}", "min_at_driver_deg", "max_at_driver_deg")
        return {**out, **dict(zip(keys, (360.0, None, None, None, None)))}, None
    ext = _extremes(y, unit)
    out.update({size: ext[f"max_{unit}"] - ext[f"min_{unit}"], **ext})
    forward = (ext["max_at_driver_deg"] - ext["min_at_driver_deg"]) % 360.0
    if not (out[size] > 0.0 and 0.0 < forward < 360.0):  # a constant output: no strokes
        return out, None
    back = 360.0 - forward
    ratio = {
        "ratio": max(forward, back) / min(forward, back),
        "forward_stroke_deg": forward,
        "return_stroke_deg": back,
        "slower_stroke": "forward" if forward >= back else "return",
    }
    return out, ratio


def grashof_loops(mech: AbstractMechanism | Model | Linkage) -> list[dict]:
    """Every loop of exactly four revolute joints and four links (the ground counts as a
    link; a loop with a prismatic joint is none) and its Grashof type, from the names and
    points alone: the mechanism need not assemble (a double-rocker is classified too).

    Its entries:

    - ``joints``: the four joint names around the loop;
    - ``links``: ``{"body", "length_m"}`` for the link between each joint and the
      next (the last closes the loop: the ground, in a loop through it); a length
      is the distance between the link's two joint points, m;
    - ``shortest_link``, ``longest_link``: body names;
    - ``s_plus_l_m``, ``p_plus_q_m``: shortest + longest, and the other two, m;
    - ``type``: ``"change point"`` (s + l = p + q within a relative 1e-9),
      ``"non-Grashof triple-rocker"`` (s + l > p + q), or, with s + l < p + q,
      ``"double-crank"`` (the ground is the shortest link), ``"crank-rocker"`` (the
      shortest link turns about a ground pivot) or ``"double-rocker"`` (the coupler
      is the shortest); a loop not through the ground is ``"Grashof"`` or
      ``"non-Grashof"``;
    - ``grashof``: whether s + l <= p + q (a change point included).

    Args:
        mech: a mechanism, a compiled model or a written-out linkage.

    Returns:
        One dict per loop, sorted by joint names; a loop through the ground starts at a
        ground pivot (the driven body's, where it is in the loop), away from the ground.
    """
    lk = _linkage(mech)
    return [_classify(lk, cycle) for cycle in four_bar_cycles(lk)]


def _linkage(mech) -> Linkage:
    return mech.linkage if isinstance(mech, Model) else mech if isinstance(mech, Linkage) else mech.linkage()


def four_bar_cycles(mech: AbstractMechanism | Model | Linkage) -> list[list[tuple[str, str]]]:
    """Every loop of four revolute joints and four distinct links, as ``[(joint, body after
    it), ...]`` around the loop (a loop through the ground starts at a ground pivot, the
    driven body's where it is in the loop), sorted by joint names; from the description alone.

    Args:
        mech: a mechanism, a compiled model or a written-out linkage.
    """
    sk = Skeleton.of(_linkage(mech))
    edges = [(j, *sk.ends(j)) for j, kind, *_ in sk.connections if kind == "revolute"]
    cycles = [_cycle(combo, sk.driver_body) for combo in itertools.combinations(edges, 4)]
    return sorted((c for c in cycles if c is not None), key=lambda c: [j for j, _ in c])


def _cycle(combo, driver: str) -> list[tuple[str, str]] | None:
    """The four joints of ``combo`` ((name, body, body) each) as a loop, ``[(joint, body
    after it), ...]``, or ``None`` where they are not one loop of four distinct links."""
    bodies = [b for _, a, c in combo for b in (a, c)]
    if len(set(bodies)) != 4 or any(bodies.count(b) != 2 for b in bodies):
        return None
    grounded = sorted((j for j in combo if GROUND in j[1:]), key=lambda j: (driver not in j[1:], j[0]))
    start = grounded[0] if grounded else min(combo)
    first, here = (start[2], start[1]) if start[2] == GROUND else (start[1], start[2])
    out, left = [(start[0], here)], [j for j in combo if j is not start]
    while left:
        step = next((j for j in left if here in j[1:]), None)
        if step is None:
            return None
        here = step[2] if step[1] == here else step[1]
        out.append((step[0], here))
        left.remove(step)
    return out if here == first else None


def _point(lk: Linkage, joint: str, body: str):
    site = next(s for s in lk.connections[joint].sites() if s.body == body)
    p = (lk.ground if body == GROUND else lk.bodies[body].points)[site.point]
    return float(p.x), float(p.y)


def _classify(lk: Linkage, cycle: list[tuple[str, str]]) -> dict:
    joints = [j for j, _ in cycle]
    links = []
    for i, (joint, body) in enumerate(cycle):
        (x0, y0), (x1, y1) = _point(lk, joint, body), _point(lk, joints[(i + 1) % 4], body)
        links.append({"body": body, "length_m": math.hypot(x1 - x0, y1 - y0)})
    lengths = [link["length_m"] for link in links]
    shortest, longest = min(lengths), max(lengths)
    short, long = lengths.index(shortest), lengths.index(longest)
    sl, pq = shortest + longest, sum(lengths) - shortest - longest
    names = [link["body"] for link in links]
    if abs(sl - pq) <= CHANGE_POINT_RTOL * pq:
        kind = "change point"
    elif GROUND not in names:
        kind = "Grashof" if sl < pq else "non-Grashof"
    elif sl > pq:
        kind = "non-Grashof triple-rocker"
    else:
        ground = names.index(GROUND)
        kind = {0: "double-crank", 2: "double-rocker"}.get((short - ground) % 4, "crank-rocker")
    return {
        "joints": joints,
        "links": links,
        "shortest_link": names[short],
        "longest_link": names[long],
        "s_plus_l_m": sl,
        "p_plus_q_m": pq,
        "type": kind,
        "grashof": kind == "change point" or sl < pq,
    }


def format_summary(summary: dict) -> list[str]:
    """Short human-readable lines of a [`kinematic_summary`][jaxcrank.analysis.kinematic_summary.kinematic_summary],
    units named (lengths in mm, angles in deg, driver angles in deg of the driven body from
    its initial angle).

    Raises:
        KeyError: ``summary`` is not a kinematic summary.
    """
    driver = summary["driver_body"]
    lines = []
    out = summary["output"]
    if out is None:
        lines.append("output: none named (outputs.acceleration or outputs.deviations)")
    elif out["full_rotation"]:
        lines.append(f"output {out['body']} {out['coordinate']}: turns through whole revolutions")
    else:
        low, high = _at(out["min_at_driver_deg"]), _at(out["max_at_driver_deg"])
        where = f"min at {low} deg, max at {high} deg of the {driver}"
        if out["coordinate"] == "angle":
            size = f"swing {out['swing_deg']:.2f} deg ({out['min_deg']:.2f} .. {out['max_deg']:.2f} deg; {where})"
        else:
            size = f"stroke {out['stroke_m'] * 1e3:.1f} mm ({where})"
        lines.append(f"output {out['body']} {out['coordinate']}: {size}")
    ratio = summary["time_ratio"]
    if ratio is not None:
        lines.append(
            f"time ratio {ratio['ratio']:.3f} at constant {driver} speed (forward stroke "
            f"{ratio['forward_stroke_deg']:.1f} deg, return {ratio['return_stroke_deg']:.1f} deg)"
        )
    mu = summary["transmission_angle"]
    if mu is not None:
        lines.append(
            f"transmission angle {mu['min_deg']:.1f} .. {mu['max_deg']:.1f} deg (min at {_at(mu['min_at_driver_deg'])}"
            f" deg, max at {_at(mu['max_at_driver_deg'])} deg of the {driver}; largest deviation from 90 deg: "
            f"{mu['max_deviation_from_90_deg']:.1f} deg)"
        )
    for loop in summary["grashof"]:
        sl, pq, kind = loop["s_plus_l_m"], loop["p_plus_q_m"], loop["type"]
        cond = f"s + l = {sl:.4g} {'<' if sl < pq else '>'} p + q = {pq:.4g} m"
        cond = f"s + l = p + q = {pq:.4g} m" if kind == "change point" else cond
        label = f"Grashof {kind}" if kind in ("crank-rocker", "double-crank", "double-rocker") else kind
        lines.append(f"four-bar loop {'-'.join(loop['joints'])}: {label} ({cond})")
    if not summary["grashof"]:
        lines.append("four-bar loops: none (no loop of four revolute joints)")
    return lines
