"""Outputs as functions of a [`Simulation`][jaxcrank.numerics.solve.Simulation].

[`frames`][jaxcrank.analysis.outputs.frames] evaluates the model at every sample (accelerations come from the
vector field, not from finite differences); [`trajectory`][jaxcrank.analysis.outputs.trajectory] turns that into
named columns with units; [`summary_metrics`][jaxcrank.analysis.outputs.summary_metrics] gives the headline numbers of
[`jaxcrank.analysis.metrics`][] for a run's summary.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ..numerics.solve import Simulation
from ..physics import ideal, model
from ..physics.params import ParameterError
from .metrics import DEG, headline, transmission_angle_deviation

# column name -> unit, in CSV order; the first block is the required set
COLUMNS = {
    "t": "s",
    "crank_angle": "deg",
    "rod_x": "m",
    "rod_vx": "m/s",
    "rod_ax": "m/s^2",
    "slider_x": "m",
    "slider_vx": "m/s",
    "slider_ax": "m/s^2",
    "ideal_rod_x": "m",
    "ideal_rod_vx": "m/s",
    "ideal_rod_ax": "m/s^2",
    "ideal_slider_x": "m",
    "ideal_slider_vx": "m/s",
    "ideal_slider_ax": "m/s^2",
    "ecc_B_x": "m",
    "ecc_B_y": "m",
    "ecc_C_x": "m",
    "ecc_C_y": "m",
    "force_B_normal": "N",
    "force_C_normal": "N",
    "driving_moment": "N m",
    "ideal_driving_moment": "N m",
    "transmission_angle": "deg",
    "ideal_transmission_angle": "deg",
    "rod_y": "m",
    "rod_vy": "m/s",
    "rod_ay": "m/s^2",
    "ideal_rod_y": "m",
    "ideal_rod_vy": "m/s",
    "ideal_rod_ay": "m/s^2",
    "rod_angle": "deg",
    "ideal_rod_angle": "deg",
    "penetration_B": "m",
    "penetration_C": "m",
    "force_B_friction": "N",
    "force_C_friction": "N",
    "slip_speed_B": "m/s",
    "slip_speed_C": "m/s",
    "kinetic_energy": "J",
    "potential_energy": "J",
    "contact_energy": "J",
    "driver_work": "J",
    "dissipated_work": "J",
}


@jax.jit
def _frames(mech, ts, ys):
    return jax.vmap(model.evaluate, in_axes=(None, 0, 0))(mech, ts, ys)


def frames(sim: Simulation) -> model.Frame:
    """The model evaluated at every sample time of ``sim``: a
    [`jaxcrank.physics.model.Frame`][jaxcrank.physics.frame.Frame] of arrays with a leading axis of length n (samples).

    One compiled program with the parameters traced, so every mechanism of the same
    structure and sample count reuses it."""
    return _frames(sim.mechanism, sim.ts, sim.ys)


def trajectory(sim: Simulation) -> dict[str, Float[np.ndarray, " n"]]:
    """Named output columns (units in `COLUMNS`; SI, angles in degrees)."""
    f = frames(sim)
    cols = {
        "t": f.t,
        "crank_angle": f.crank_angle * DEG,
        "rod_x": f.q[:, 0],
        "rod_vx": f.qd[:, 0],
        "rod_ax": f.qdd[:, 0],
        "slider_x": f.q[:, 3],
        "slider_vx": f.qd[:, 3],
        "slider_ax": f.qdd[:, 3],
        "ideal_rod_x": f.ideal_q[:, 0],
        "ideal_rod_vx": f.ideal_qd[:, 0],
        "ideal_rod_ax": f.ideal_qdd[:, 0],
        "ideal_slider_x": f.ideal_q[:, 3],
        "ideal_slider_vx": f.ideal_qd[:, 3],
        "ideal_slider_ax": f.ideal_qdd[:, 3],
        "ecc_B_x": f.eccentricity_B[:, 0],
        "ecc_B_y": f.eccentricity_B[:, 1],
        "ecc_C_x": f.eccentricity_C[:, 0],
        "ecc_C_y": f.eccentricity_C[:, 1],
        "force_B_normal": f.normal_force_B,
        "force_C_normal": f.normal_force_C,
        "driving_moment": f.driving_moment,
        "ideal_driving_moment": f.ideal_driving_moment,
        "transmission_angle": ideal.transmission_angle(f.q[:, 2]) * DEG,
        "ideal_transmission_angle": ideal.transmission_angle(f.ideal_q[:, 2]) * DEG,
        "rod_y": f.q[:, 1],
        "rod_vy": f.qd[:, 1],
        "rod_ay": f.qdd[:, 1],
        "ideal_rod_y": f.ideal_q[:, 1],
        "ideal_rod_vy": f.ideal_qd[:, 1],
        "ideal_rod_ay": f.ideal_qdd[:, 1],
        "rod_angle": f.q[:, 2] * DEG,
        "ideal_rod_angle": f.ideal_q[:, 2] * DEG,
        "penetration_B": f.penetration_B,
        "penetration_C": f.penetration_C,
        "force_B_friction": f.friction_force_B,
        "force_C_friction": f.friction_force_C,
        "slip_speed_B": f.slip_speed_B,
        "slip_speed_C": f.slip_speed_C,
        "kinetic_energy": f.kinetic_energy,
        "potential_energy": f.potential_energy,
        "contact_energy": f.contact_energy,
        "driver_work": f.driver_work,
        "dissipated_work": f.dissipated_work,
    }
    return {k: np.asarray(cols[k]) for k in COLUMNS}


def transmission_angle_error(mech, ts: Float[ArrayLike, " n"], ys: Float[ArrayLike, "n state"]) -> Float[Array, " n"]:
    """Actual minus ideal transmission angle at sample times ``ts`` (s) with scaled
    states ``ys``, degrees; compared at the same time, i.e. the same crank angle."""

    def one(t, y):
        return transmission_angle_deviation(model.evaluate(mech, t, y).q[2], ideal.positions(mech, t)[2])

    return jax.vmap(one)(ts, ys)


def rms_transmission_error(sim: Simulation, t_start: Float[ArrayLike, ""] | None = None) -> Float[Array, ""]:
    """RMS of (actual - ideal) transmission angle over samples with t > t_start,
    degrees (paper Eq. 19; samples are at equal crank-angle steps when ``ts`` is
    equally spaced). Differentiable. Default ``t_start``: one crank revolution."""
    mech = sim.mechanism
    t_start = mech.period if t_start is None else t_start
    err = transmission_angle_error(mech, sim.ts, sim.ys)
    w = (sim.ts > t_start).astype(err.dtype)
    return jnp.sqrt(jnp.sum(w * err**2) / jnp.maximum(jnp.sum(w), 1.0))


_headline = jax.jit(headline)


def summary_metrics(sim: Simulation) -> dict[str, float]:
    """The headline metrics a solve tracked (``simulate(..., metrics_start=...)``,
    [`jaxcrank.numerics.tracking`][]) as Python floats: ``window_start_s``, every metric of
    `jaxcrank.analysis.metrics.METRICS` and the whole run's peak contact forces
    (``peak_contact_force_{B,C}_whole_run_N``); units in the names.

    Raises:
        ValueError: if the solve did not track metrics.
    """
    if sim.metrics is None:
        raise ValueError("this simulation tracked no metrics: simulate with metrics_start=<window start, s>")
    return {k: float(v) for k, v in sim.metrics.items()}


def sample_metrics(sim: Simulation, t_start: Float[ArrayLike, ""]) -> dict[str, float]:
    """The headline metrics (`jaxcrank.analysis.metrics.METRICS`) over the stored
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
    return {k: float(v) for k, v in _headline(f, t_start).items()}


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


def deviation_bounds(mech, max_penetration: Float[ArrayLike, ""]) -> dict[str, float]:
    """Largest |x deviation| of slider and rod centre that the loop closure allows, m.

    Args:
        mech: the mechanism (an ideal joint contributes no play).
        max_penetration: largest contact penetration of the run, m (>= 0).

    Closure, with ``d_B``, ``d_C`` the pin eccentricities (|d| <= rho = c + max_penetration
    at a clearance joint, 0 at an ideal one) and ``D = d_B - d_C`` (|D| <= play =
    rho_B + rho_C)::

        dx3 = -D_x + L2 (cos theta2 - cos theta2_ideal),   L2 (sin theta2 - sin theta2_ideal) = D_y
        dx2 = -d_Bx + (L2 / 2) (cos theta2 - cos theta2_ideal)

    ``|sin theta2_ideal| <= s_m = (L1 + |e|) / L2``, and the cosine changes most at the
    steepest point: ``L2 |cos theta2 - cos theta2_ideal| <= L2 g(|D_y|)`` with
    ``g(y) = sqrt(1 - s_m^2) - sqrt(1 - min(1, s_m + y / L2)^2)``, convex in y, so below
    its secant ``k |D_y|``, ``k = L2 g(play) / play`` (k -> tan theta2_max for small play).
    Hence ``|dx3| <= play sqrt(1 + k^2)`` (Cauchy-Schwarz) and
    ``|dx2| <= rho_B + k play / 2``. (The clearances alone are not a bound: the rod-angle
    change adds up to k times the y play.)

    Returns:
        ``{"slider_x_m": ..., "rod_x_m": ...}``, m.
    """
    pen = float(max_penetration)
    rho = {
        j: 0.0 if getattr(mech, f"joint_{j}").ideal else float(getattr(mech, f"joint_{j}").clearance) + pen
        for j in "BC"
    }
    play = rho["B"] + rho["C"]
    l2 = float(mech.rod_length)
    s_m = (float(mech.crank_length) + abs(float(mech.offset))) / l2
    s_hi = min(1.0, s_m + play / l2)
    k = l2 * (math.sqrt(1.0 - s_m**2) - math.sqrt(1.0 - s_hi**2)) / play if play > 0 else 0.0
    return {"slider_x_m": play * math.sqrt(1.0 + k**2), "rod_x_m": rho["B"] + k * play / 2.0}
