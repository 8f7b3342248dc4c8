"""Outputs as functions of a :class:`~jaxcrank.solve.Simulation`.

:func:`frames` evaluates the model at every sample (accelerations come from the
vector field, not from finite differences); :func:`trajectory` turns that into
named columns with units; :func:`metrics` gives the headline numbers.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from . import ideal, model
from .solve import Simulation

DEG = 180.0 / math.pi

# column name -> unit, in CSV order; the first block is the required set
COLUMNS = {
    "t": "s",
    "crank_angle": "deg",
    "rod_x": "m", "rod_vx": "m/s", "rod_ax": "m/s^2",
    "slider_x": "m", "slider_vx": "m/s", "slider_ax": "m/s^2",
    "ideal_rod_x": "m", "ideal_rod_vx": "m/s", "ideal_rod_ax": "m/s^2",
    "ideal_slider_x": "m", "ideal_slider_vx": "m/s", "ideal_slider_ax": "m/s^2",
    "ecc_B_x": "m", "ecc_B_y": "m", "ecc_C_x": "m", "ecc_C_y": "m",
    "force_B_normal": "N", "force_C_normal": "N",
    "driving_moment": "N m", "ideal_driving_moment": "N m",
    "transmission_angle": "deg", "ideal_transmission_angle": "deg",
    "rod_y": "m", "rod_vy": "m/s", "rod_ay": "m/s^2",
    "ideal_rod_y": "m", "ideal_rod_vy": "m/s", "ideal_rod_ay": "m/s^2",
    "rod_angle": "deg", "ideal_rod_angle": "deg",
    "penetration_B": "m", "penetration_C": "m",
    "force_B_friction": "N", "force_C_friction": "N",
    "slip_speed_B": "m/s", "slip_speed_C": "m/s",
    "kinetic_energy": "J", "potential_energy": "J", "contact_energy": "J",
    "driver_work": "J", "dissipated_work": "J",
}


@jax.jit
def _frames(mech, ts, ys):
    return jax.vmap(model.evaluate, in_axes=(None, 0, 0))(mech, ts, ys)


def frames(sim: Simulation) -> model.Frame:
    """The model evaluated at every sample time (a :class:`model.Frame` of arrays).

    One compiled program (parameters traced, so every mechanism of the same
    structure and sample count reuses it): dispatched op by op instead, the first
    call in a process compiled each of the ~160 operations on its own, 5.6 s
    against 1.4 s (20 ms paper run, this 2-core machine)."""
    return _frames(sim.mechanism, sim.ts, sim.ys)


def trajectory(sim: Simulation) -> dict[str, np.ndarray]:
    """Named output columns (units in :data:`COLUMNS`; SI, angles in degrees)."""
    f = frames(sim)
    cols = {
        "t": f.t,
        "crank_angle": f.crank_angle * DEG,
        "rod_x": f.q[:, 0], "rod_vx": f.qd[:, 0], "rod_ax": f.qdd[:, 0],
        "slider_x": f.q[:, 3], "slider_vx": f.qd[:, 3], "slider_ax": f.qdd[:, 3],
        "ideal_rod_x": f.ideal_q[:, 0], "ideal_rod_vx": f.ideal_qd[:, 0], "ideal_rod_ax": f.ideal_qdd[:, 0],
        "ideal_slider_x": f.ideal_q[:, 3], "ideal_slider_vx": f.ideal_qd[:, 3], "ideal_slider_ax": f.ideal_qdd[:, 3],
        "ecc_B_x": f.eccentricity_B[:, 0], "ecc_B_y": f.eccentricity_B[:, 1],
        "ecc_C_x": f.eccentricity_C[:, 0], "ecc_C_y": f.eccentricity_C[:, 1],
        "force_B_normal": f.normal_force_B, "force_C_normal": f.normal_force_C,
        "driving_moment": f.driving_moment, "ideal_driving_moment": f.ideal_driving_moment,
        "transmission_angle": ideal.transmission_angle(f.q[:, 2]) * DEG,
        "ideal_transmission_angle": ideal.transmission_angle(f.ideal_q[:, 2]) * DEG,
        "rod_y": f.q[:, 1], "rod_vy": f.qd[:, 1], "rod_ay": f.qdd[:, 1],
        "ideal_rod_y": f.ideal_q[:, 1], "ideal_rod_vy": f.ideal_qd[:, 1], "ideal_rod_ay": f.ideal_qdd[:, 1],
        "rod_angle": f.q[:, 2] * DEG, "ideal_rod_angle": f.ideal_q[:, 2] * DEG,
        "penetration_B": f.penetration_B, "penetration_C": f.penetration_C,
        "force_B_friction": f.friction_force_B, "force_C_friction": f.friction_force_C,
        "slip_speed_B": f.slip_speed_B, "slip_speed_C": f.slip_speed_C,
        "kinetic_energy": f.kinetic_energy, "potential_energy": f.potential_energy,
        "contact_energy": f.contact_energy, "driver_work": f.driver_work,
        "dissipated_work": f.dissipated_work,
    }
    return {k: np.asarray(cols[k]) for k in COLUMNS}


def transmission_angle_deviation(rod_angle, ideal_rod_angle):
    """Actual minus ideal transmission angle, degrees, from the actual and ideal rod
    angles theta2 (rad, any matching shapes) at the same crank angle."""
    return (ideal.transmission_angle(rod_angle) - ideal.transmission_angle(ideal_rod_angle)) * DEG


def transmission_angle_error(mech, ts, ys):
    """Actual minus ideal transmission angle at sample times ``ts`` (s) with scaled
    states ``ys``, degrees; compared at the same time, i.e. the same crank angle."""
    def one(t, y):
        return transmission_angle_deviation(model.evaluate(mech, t, y).q[2], ideal.positions(mech, t)[2])

    return jax.vmap(one)(ts, ys)


def rms_transmission_error(sim: Simulation, t_start=None):
    """RMS of (actual - ideal) transmission angle over samples with t > t_start,
    degrees (paper Eq. 19; samples are at equal crank-angle steps when ``ts`` is
    equally spaced). Differentiable. Default ``t_start``: one crank revolution."""
    mech = sim.mechanism
    t_start = 2.0 * math.pi / mech.crank_speed if t_start is None else t_start
    err = transmission_angle_error(mech, sim.ts, sim.ys)
    w = (sim.ts > t_start).astype(err.dtype)
    return jnp.sqrt(jnp.sum(w * err**2) / jnp.maximum(jnp.sum(w), 1.0))


def metrics(cols: dict[str, np.ndarray], mech, t_start=None) -> dict[str, float]:
    """Headline metrics from :func:`trajectory` columns, after ``t_start`` (default:
    one revolution). Keys carry their units."""
    period = 2.0 * math.pi / float(mech.crank_speed)
    t_start = period if t_start is None else t_start
    late = cols["t"] > t_start
    if not np.any(late):
        late = np.ones_like(cols["t"], dtype=bool)

    def peak(x):
        return float(np.max(np.abs(x[late])))

    ta_err = cols["transmission_angle"] - cols["ideal_transmission_angle"]
    return {
        "window_start_s": float(t_start),
        "max_abs_rod_x_deviation_m": peak(cols["rod_x"] - cols["ideal_rod_x"]),
        "max_abs_slider_x_deviation_m": peak(cols["slider_x"] - cols["ideal_slider_x"]),
        "max_abs_slider_ax_deviation_m_s2": peak(cols["slider_ax"] - cols["ideal_slider_ax"]),
        "peak_contact_force_B_N": peak(cols["force_B_normal"]),
        "peak_contact_force_C_N": peak(cols["force_C_normal"]),
        "max_penetration_B_m": float(np.max(cols["penetration_B"][late])),
        "max_penetration_C_m": float(np.max(cols["penetration_C"][late])),
        "peak_driving_moment_N_m": peak(cols["driving_moment"]),
        "rms_transmission_angle_error_deg": float(np.sqrt(np.mean(ta_err[late] ** 2))),
        "peak_contact_force_B_whole_run_N": float(np.max(cols["force_B_normal"])),
        "peak_contact_force_C_whole_run_N": float(np.max(cols["force_C_normal"])),
    }


def energy_balance(cols: dict[str, np.ndarray], i0=0, i1=-1) -> dict[str, float]:
    """Work-energy balance between samples i0 and i1, J.

    ``residual = delta(kinetic + potential + contact) - (driver work - dissipated work)``.
    """
    e = cols["kinetic_energy"] + cols["potential_energy"] + cols["contact_energy"]
    d_energy = float(e[i1] - e[i0])
    w_drive = float(cols["driver_work"][i1] - cols["driver_work"][i0])
    w_diss = float(cols["dissipated_work"][i1] - cols["dissipated_work"][i0])
    return {"energy_change_J": d_energy, "driver_work_J": w_drive, "dissipated_work_J": w_diss,
            "residual_J": d_energy - (w_drive - w_diss)}


def deviation_bounds(mech, max_penetration) -> dict[str, float]:
    """Largest |x deviation| of slider and rod centre that the loop closure allows, m.

    Closure: ``dx3 = -d_Bx + d_Cx + L2 (cos theta2 - cos theta2_ideal)`` with
    ``L2 (sin theta2 - sin theta2_ideal) = d_By - d_Cy``, so with
    ``|d| <= c + max_penetration`` at each joint (play = sum of both):
    ``|dx3| <= play / cos(theta2_max)`` and ``|dx2| <= play / 2 + tan(theta2_max) play / 2``,
    where ``sin theta2_max = (L1 + |e|) / L2``. (The clearances alone are not a bound:
    the rod-angle change adds up to tan(theta2) times the y play.)
    """
    play = float(mech.joint_B.clearance + mech.joint_C.clearance) + 2.0 * float(max_penetration)
    th2max = math.asin((float(mech.crank_length) + abs(float(mech.offset))) / float(mech.rod_length))
    return {"slider_x_m": play / math.cos(th2max), "rod_x_m": play / 2.0 + math.tan(th2max) * play / 2.0}

