"""The ensemble-sensitivity machinery behind [`optim.objective.Ensemble`][] and
[`optim.sensitivity`][]: the sample grid of an evaluation window, the forward solves
that store the start states of K short windows, the windows re-solved from those
states (held fixed, carried over to the design being differentiated), and their
assembly.

Method: Lea, Allen & Haine, Tellus 52A (2000). One forward solve from the
pins-centred start gives the exact metrics over the evaluation window and the pins'
state in their bearings at the start of K short windows; each window is re-solved
from that state with an implicit solver, one after another, and the derivative of the
windows' pooled mean squares is the gradient: a trend estimate rather than the
derivative of a chaotic time average (it leaves out how the statistics of the start
states move with the design).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from jaxcrank.numerics.solve import Simulation, simulate
from jaxcrank.physics import model, signals
from jaxcrank.physics.linkage import AbstractMechanism as Mechanism
from jaxcrank.physics.linkage import ConstantSpeed, Revolute
from jaxcrank.physics.params import ParameterError
from jaxcrank.physics.safemath import safe_norm


class Grid(NamedTuple):
    """The sample grid of an evaluation window ``(t_start, t_end]`` at equal crank-angle steps.

    Attributes:
        n_start: sample index of t_start.
        n_eval: number of samples in (t_start, t_end].
        n_window: samples per ensemble window (a divisor of ``n_eval``).
        dt: the sample step, s.
    """

    n_start: int
    n_eval: int
    n_window: int
    dt: float


def sample_grid(
    mech: Mechanism, t_start: float, t_end: float, samples_per_degree: float, window: float | None = None
) -> Grid:
    """The [`Grid`][optim.windows.Grid] of the window ``(t_start, t_end]`` (s) with ``samples_per_degree``
    samples per degree of the driven body's angle; ``window`` (s) is the ensemble windows' length,
    rounded to whole sample steps and shrunk to divide the evaluation window.

    Raises:
        ParameterError: the driver is not a [`jaxcrank.ConstantSpeed`][jaxcrank.physics.linkage.ConstantSpeed]
            (equal times are equal driver angles only at constant speed), or ``mech.driver.speed``
            is not concrete (a traced design variable).
    """
    if not isinstance(mech.driver, ConstantSpeed):
        raise ParameterError(
            f"the windowed objectives sample at equal driver angles and need a constant-speed driver "
            f"(jaxcrank.ConstantSpeed), not {type(mech.driver).__name__}; use the steady-state objective"
        )
    try:
        omega = float(mech.driver.speed)
    except (TypeError, jax.errors.ConcretizationTypeError):
        raise ParameterError(
            "the objective's sample grid needs a concrete driver.speed: build the "
            "mechanism inside the traced function from a fixed base design"
        ) from None
    dt = math.radians(1.0 / samples_per_degree) / omega
    n_start = int(round(t_start / dt))
    n_eval = int(round((t_end - t_start) / dt))
    n_window = n_eval if window is None else max(1, int(round(window / dt)))
    if n_eval % n_window:
        # shrink the window to the nearest divisor of the evaluation window
        k = max(1, round(n_eval / n_window))
        while n_eval % k:
            k += 1
        n_window = n_eval // k
    return Grid(n_start, n_eval, n_window, dt)


def rms_signal_values(mech: Mechanism, ts: Float[ArrayLike, " n"], ys: Float[ArrayLike, "n state"]) -> dict:
    """The per-sample signals behind the mechanism's RMS metrics
    ([`jaxcrank.physics.signals.rms_metrics`][]) at sample times ``ts`` (s) with scaled states
    ``ys``: RMS metric name -> (n,) signal in the metric's unit (deg, m, N m, N)."""
    definitions = signals.metric_definitions(mech)
    names = signals.rms_metrics(mech)

    def one(t, y):
        sig = signals.signals(mech, model.evaluate(mech, t, y))
        return {name: sig[definitions[name].signal] for name in names}

    return jax.vmap(one)(jnp.asarray(ts), jnp.asarray(ys))


def stored_solve(mech: Mechanism, grid: Grid, options: dict, throw: bool) -> tuple[Simulation, int]:
    """One solve from the pins-centred start that stores every sample of ``grid``: the
    simulation and the sample index of t_start (the samples in (t_start, t_end] follow
    it). Differentiable in reverse mode. ``options``: ``rtol``, ``atol``, ``max_steps``."""
    ts = grid.dt * jnp.arange(grid.n_start + grid.n_eval + 1, dtype=float)
    return simulate(mech, ts=ts, throw=throw, **options), grid.n_start


class Starts(NamedTuple):
    """Pin-in-bearing states at the start of the ensemble windows (no gradient), from
    [`window_starts`][optim.windows.window_starts] .

    Attributes: t (K,) s; eccentricity (K, J, 2) m and eccentricity_rate (K, J, 2)
    m/s of the J clearance joints (the tree's cut joints, sorted); rest (K, aux) the other
    state entries in SI units (the joint laws' states, e.g. approach-speed memories in m/s;
    driver and dissipated work, J); clearance (J,) m, of the design they were taken from.
    """

    t: jax.Array
    eccentricity: jax.Array
    eccentricity_rate: jax.Array
    rest: jax.Array
    clearance: jax.Array


def window_start_indices(grid: Grid, windows: int) -> np.ndarray:
    """Sample indices of the starts of ``windows`` ensemble windows (0: all, tiling the
    evaluation window), spread evenly over the evaluation window."""
    tiles = grid.n_eval // grid.n_window
    k = tiles if windows <= 0 else min(windows, tiles)
    return grid.n_start + grid.n_window * ((np.arange(k) * tiles) // k)


def tracked_solve(mech: Mechanism, grid: Grid, windows: int, options: dict, throw: bool) -> Simulation:
    """One solve from the pins-centred start over ``grid`` that stores the state only at
    the ensemble windows' starts ([`window_start_indices`][optim.windows.window_start_indices]) and tracks the headline
    metrics over the samples in (t_start, t_end] during the solve
    ([`jaxcrank.numerics.tracking`][]): memory independent of the number of samples.
    Forward mode only. ``options``: ``rtol``, ``atol``, ``max_steps``."""
    ts = grid.dt * np.arange(grid.n_start + grid.n_eval + 1)
    return simulate(
        mech,
        ts=ts,
        save_ts=ts[window_start_indices(grid, windows)],
        metrics_start=(grid.n_start + 0.5) * grid.dt,  # between samples: no rounding decides membership
        throw=throw,
        **options,
    )


def window_starts(sim: Simulation) -> Starts:
    """The [`Starts`][optim.windows.Starts] of the ensemble windows from a
    [`tracked_solve`][optim.windows.tracked_solve] , whose
    stored samples are the windows' starts (no gradient)."""
    mech = jax.lax.stop_gradient(sim.mechanism)
    t0s, y0s = sim.ts, sim.ys
    d, d_rate = jax.vmap(model.joint_eccentricities, in_axes=(None, 0, 0))(mech, t0s, y0s)
    rest = model.auxiliary(mech, y0s)  # SI: the scales change with the clearances
    return jax.lax.stop_gradient(Starts(t0s, d, d_rate, rest, clearances(mech)))


def clearances(mech: Mechanism) -> Float[Array, " joints"]:
    """Radial clearance of each clearance joint (the tree's cut joints, sorted), m."""
    lk, tree = model.structure(mech)
    return jnp.stack([jnp.asarray(lk.joints[j].clearance, dtype=float) for j in tree.cut])


def start_state(mech: Mechanism, starts: Starts, i: Int[ArrayLike, ""]) -> Float[Array, " state"]:
    """Scaled state of ``mech`` at window ``i``: the pins where ``starts`` had them
    in their bearings, moving the same way, with the same gap or penetration (a
    clearance change moves a revolute joint's pin radially by the change; a prismatic
    joint's eccentricity is kept)."""
    lk, tree = model.structure(mech)
    d = starts.eccentricity[i]
    norm = safe_norm(d, axis=-1)[:, None]
    direction = jnp.where(norm > 0.0, d / jnp.where(norm > 0.0, norm, 1.0), 0.0)
    radial = jnp.asarray([isinstance(lk.connections[j], Revolute) for j in tree.cut], dtype=float)
    d = d + (radial * (clearances(mech) - starts.clearance))[:, None] * direction
    return model.state_from_eccentricities(mech, starts.t[i], d, starts.eccentricity_rate[i], starts.rest[i])


def solve_window(
    mech: Mechanism,
    starts: Starts,
    i: Int[ArrayLike, ""],
    grid: Grid,
    *,
    solver,
    adjoint,
    options: dict,
    max_steps: int,
) -> tuple[Float[Array, " window"], Float[Array, "window state"], Bool[Array, ""]]:
    """Window ``i`` re-solved for ``mech`` from [`start_state`][optim.windows.start_state] with ``solver`` and
    ``adjoint`` (diffrax): its sample times (n_window,) s, scaled states (zero where the
    solve failed, so a failed window is reported by the caller, not propagated as NaN)
    and whether it finished within ``max_steps``. ``options``: ``rtol``, ``atol``."""
    # local time from the window's start (the driver's angle carries the offset): diffrax then
    # sees concrete times and compiles no run-time checks of them (host callbacks, which
    # JAX's persistent compilation cache does not store)
    y0 = start_state(mech, starts, i)
    driver = mech.driver
    mech = eqx.tree_at(lambda m: m.driver.initial_angle, mech, driver.initial_angle + driver.speed * starts.t[i])
    ts = grid.dt * np.arange(grid.n_window + 1)
    sim = simulate(mech, ts=ts, y0=y0, solver=solver, max_steps=max_steps, throw=False, adjoint=adjoint, **options)
    ok = sim.ok & jnp.all(jnp.isfinite(sim.ys))
    # the requested times, not sim.ts: a failed diffrax solve fills its ts with inf
    return starts.t[i] + ts[1:], jnp.where(ok, sim.ys, 0.0)[1:], ok


def over_windows(fun, starts: Starts):
    """``fun(i)`` for every ensemble window ``i`` of ``starts``, stacked: one window
    after another (``jax.lax.map``). Under ``vmap`` every window would step as long as
    the slowest one; in sequence each takes its own steps, and the program compiles
    faster (measurements: docs/optimisation.md, "A gradient in seconds")."""
    return jax.lax.map(fun, jnp.arange(starts.t.shape[0]))


WINDOWS_FAILED = (
    "jaxcrank: more than half of the ensemble windows failed; raise "
    "Ensemble.window_max_steps, loosen rtol/atol or shorten Ensemble.window"
)


def windows_ok(ok: Bool[Array, " windows"], throw: bool) -> Float[Array, ""]:
    """The number of finished windows (a scalar); fewer than half of ``ok`` raises
    (``throw``) or makes it NaN."""
    n_ok = jnp.sum(ok, dtype=float)
    enough = n_ok >= 0.5 * ok.shape[0]
    if throw:
        return eqx.error_if(n_ok, ~enough, WINDOWS_FAILED)
    return jnp.where(enough, n_ok, jnp.nan)


def forward_adjoint() -> diffrax.ForwardMode:
    """The windows' default adjoint: forward mode, one tangent per design variable."""
    return diffrax.ForwardMode()
