"""Outputs as functions of a [`Simulation`][jaxcrank.numerics.solve.Simulation].

[`frames`][jaxcrank.analysis.outputs.frames] evaluates the model at every sample (accelerations come from the
vector field, not from finite differences); [`trajectory`][jaxcrank.analysis.outputs.trajectory] turns that into
named columns with units; [`summary_metrics`][jaxcrank.analysis.outputs.summary_metrics] gives the headline numbers of
[`jaxcrank.analysis.metrics`][] for a run's summary.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ..numerics.solve import Simulation
from ..physics import model
from ..physics.params import ParameterError
from .metrics import DEG, headline

_BODY_COLUMNS = (
    ("x", "m"),
    ("y", "m"),
    ("angle", "deg"),
    ("vx", "m/s"),
    ("vy", "m/s"),
    ("omega", "rad/s"),
    ("ax", "m/s^2"),
    ("ay", "m/s^2"),
    ("alpha", "rad/s^2"),
)
_JOINT_COLUMNS = (
    ("ecc_{}_x", "m"),
    ("ecc_{}_y", "m"),
    ("penetration_{}", "m"),
    ("force_{}_normal", "N"),
    ("force_{}_friction", "N"),
    ("slip_speed_{}", "m/s"),
    ("force_{}_x", "N"),
    ("force_{}_y", "N"),
)


def columns(mech) -> dict[str, str]:
    """Column name -> unit of [`trajectory`][jaxcrank.analysis.outputs.trajectory] for ``mech``, in CSV order:
    time; each body's centre-of-mass pose, velocity and acceleration (``<body>_x``,
    ``<body>_angle``, ``<body>_vx``, ``<body>_omega``, ``<body>_alpha``, ...) and the ideal
    mechanism's (``ideal_<body>_x``, ...); per joint ``<j>``: its eccentricity
    (``ecc_<j>_x``, ``ecc_<j>_y``, pin minus hole, m), penetration, normal and friction
    force (``force_<j>_normal``: an ideal joint's reaction magnitude), slip speed, and the
    force on its pin (or slider) side in the world frame (``force_<j>_x``,
    ``force_<j>_y``, N: a joint law's force, an ideal joint's reaction; the hole or guide
    side carries minus it); driving moments; transmission angles; energies."""
    model_ = model.compile_model(mech)
    tree = model_.tree
    out = {"t": "s"}
    for prefix in ("", "ideal_"):
        for b in tree.bodies:
            for k, unit in _BODY_COLUMNS:
                out[f"{prefix}{b}_{k}"] = unit
    for j in tree.joints:
        for pattern, unit in _JOINT_COLUMNS:
            out[pattern.format(j)] = unit
    out.update({"driving_moment": "N m", "ideal_driving_moment": "N m"})
    if model_.linkage.outputs.transmission is not None:
        out.update({"transmission_angle": "deg", "ideal_transmission_angle": "deg"})
    for k in ("kinetic_energy", "potential_energy", "contact_energy", "driver_work", "dissipated_work"):
        out[k] = "J"
    return out


@jax.jit
def _frames(mech, ts, ys):
    return jax.vmap(model.evaluate, in_axes=(None, 0, 0))(mech, ts, ys)


def frames(sim: Simulation) -> model.Frame:
    """The model evaluated at every sample time of ``sim``: a
    [`jaxcrank.physics.model.Frame`][jaxcrank.physics.frame.Frame] of arrays with a leading axis of length n (samples).

    One compiled program with the parameters traced, so every mechanism of the same
    structure and sample count reuses it."""
    return _frames(model.compile_model(sim.mechanism), sim.ts, sim.ys)


def frame_columns(mech, frames_: model.Frame) -> dict[str, Array]:
    """The named columns of [`trajectory`][jaxcrank.analysis.outputs.trajectory] from ``frames_``
    ([`frames`][jaxcrank.analysis.outputs.frames], or ``jax.vmap(model.evaluate)`` of any sample
    times) as JAX arrays: traceable (``jax.jacfwd`` through a solve), SI, angles in degrees;
    [`columns`][jaxcrank.analysis.outputs.columns] gives their order and units. A mechanism
    without a transmission angle gets zero transmission columns here (``columns`` leaves them out)."""
    tree = model.compile_model(mech).tree
    f = frames_
    cols = {"t": f.t}
    for prefix, q, qd, qdd in (("", f.q, f.qd, f.qdd), ("ideal_", f.ideal_q, f.ideal_qd, f.ideal_qdd)):
        for i, b in enumerate(tree.bodies):
            values = (q[..., i, 0], q[..., i, 1], q[..., i, 2] * DEG, qd[..., i, 0], qd[..., i, 1], qd[..., i, 2])
            values += (qdd[..., i, 0], qdd[..., i, 1], qdd[..., i, 2])
            for (k, _), v in zip(_BODY_COLUMNS, values):
                cols[f"{prefix}{b}_{k}"] = v
    for m, j in enumerate(tree.joints):
        values = (f.eccentricity[..., m, 0], f.eccentricity[..., m, 1], f.penetration[..., m], f.normal_force[..., m])
        values += (f.friction_force[..., m], f.slip_speed[..., m], f.joint_force[..., m, 0], f.joint_force[..., m, 1])
        for (pattern, _), v in zip(_JOINT_COLUMNS, values):
            cols[pattern.format(j)] = v
    cols.update(driving_moment=f.driving_moment, ideal_driving_moment=f.ideal_driving_moment)
    cols.update(
        transmission_angle=f.transmission_angle * DEG, ideal_transmission_angle=f.ideal_transmission_angle * DEG
    )
    for k in ("kinetic_energy", "potential_energy", "contact_energy", "driver_work", "dissipated_work"):
        cols[k] = getattr(f, k)
    return cols


def trajectory(sim: Simulation, frames_: model.Frame | None = None) -> dict[str, Float[np.ndarray, " n"]]:
    """Named output columns of a simulation (SI, angles in degrees;
    [`columns`][jaxcrank.analysis.outputs.columns] gives their units); ``frames_``: its
    [`frames`][jaxcrank.analysis.outputs.frames] where already evaluated."""
    mech = sim.mechanism
    cols = frame_columns(mech, frames(sim) if frames_ is None else frames_)
    return {k: np.asarray(cols[k]) for k in columns(mech)}


@jax.jit
def _closure_residuals(compiled, ts, ys):
    def one(t, y):
        s = model.unpack(compiled, y).deviation
        return model.closure_residuals(compiled, model.positions(compiled, s, t))

    return jax.vmap(one)(ts, ys)


def closure_residual(sim: Simulation) -> float:
    """The largest distance between the two sides of an ideal joint over the samples of
    ``sim``, m (0.0 for a mechanism without ideal joints): the loops of ideal joints close
    to rounding."""
    compiled = model.compile_model(sim.mechanism)
    if not compiled.structure.ideal_joints:
        return 0.0
    return float(jnp.max(_closure_residuals(compiled, sim.ts, sim.ys)))


def transmission_angle_error(mech, ts: Float[ArrayLike, " n"], ys: Float[ArrayLike, "n state"]) -> Float[Array, " n"]:
    """Actual minus ideal transmission angle at sample times ``ts`` (s) with scaled
    states ``ys``, degrees; compared at the same driver angle."""

    def one(t, y):
        f = model.evaluate(mech, t, y)
        return (f.transmission_angle - f.ideal_transmission_angle) * DEG

    return jax.vmap(one)(ts, ys)


def rms_transmission_error(sim: Simulation, t_start: Float[ArrayLike, ""] | None = None) -> Float[Array, ""]:
    """RMS of (actual - ideal) transmission angle over samples with t > t_start,
    degrees (paper Eq. 19; samples are at equal crank-angle steps when ``ts`` is
    equally spaced). Differentiable. Default ``t_start``: one revolution."""
    mech = sim.mechanism
    t_start = mech.period if t_start is None else t_start
    err = transmission_angle_error(mech, sim.ts, sim.ys)
    w = (sim.ts > t_start).astype(err.dtype)
    return jnp.sqrt(jnp.sum(w * err**2) / jnp.maximum(jnp.sum(w), 1.0))


_headline = jax.jit(headline)


def summary_metrics(sim: Simulation) -> dict[str, float]:
    """The headline metrics a solve tracked (``simulate(..., metrics_start=...)``,
    [`jaxcrank.numerics.tracking`][]) as Python floats: ``window_start_s``, every metric of
    the mechanism ([`jaxcrank.physics.signals.metric_definitions`][]) and the whole run's
    peak contact forces (``peak_contact_force_<joint>_whole_run_N``); units in the names.

    Raises:
        ValueError: if the solve did not track metrics.
    """
    if sim.metrics is None:
        raise ValueError("this simulation tracked no metrics: simulate with metrics_start=<window start, s>")
    return {k: float(v) for k, v in sim.metrics.items()}


def sample_metrics(sim: Simulation, t_start: Float[ArrayLike, ""]) -> dict[str, float]:
    """The headline metrics of the mechanism over the stored
    samples of ``sim`` with ``t > t_start`` (s), as Python floats: the peaks are
    maxima over the samples, not over the solve (for solves that were not tracked,
    e.g. another package's solution wrapped in a [`Simulation`][jaxcrank.numerics.solve.Simulation]).

    Raises:
        ParameterError: if no sample lies after ``t_start``.
    """
    f = frames(sim)
    t_start = float(t_start)
    if not bool(jnp.any(f.t > t_start)):
        raise ParameterError(
            f"metrics window: t_start = {t_start:g} s leaves no sample; the run ends at t = {float(f.t[-1]):g} s"
        )
    return {k: float(v) for k, v in _headline(sim.mechanism, f, t_start).items()}


def energy_balance(cols: dict[str, Float[np.ndarray, " n"]], i0: int = 0, i1: int = -1) -> dict[str, float]:
    """Work-energy balance between samples i0 and i1, J.

    ``residual = delta(kinetic + potential + contact) - (driver work - dissipated work)``.
    """
    e = cols["kinetic_energy"] + cols["potential_energy"] + cols["contact_energy"]
    d_energy = float(e[i1] - e[i0])
    w_drive = float(cols["driver_work"][i1] - cols["driver_work"][i0])
    w_diss = float(cols["dissipated_work"][i1] - cols["dissipated_work"][i0])
    return {
        "energy_change_J": d_energy,
        "driver_work_J": w_drive,
        "dissipated_work_J": w_diss,
        "residual_J": d_energy - (w_drive - w_diss),
    }
