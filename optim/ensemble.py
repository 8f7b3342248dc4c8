"""The ensemble objective: the exact metrics of one forward solve over an evaluation
window, with the ensemble-sensitivity gradient ([`Ensemble`][optim.ensemble.Ensemble]), and its machinery,
shared with [`optim.sensitivity`][]: the forward solve that stores the start states of K
short windows, the windows re-solved from those states (held fixed, carried over to the
design being differentiated), and their assembly.

Method: Lea, Allen & Haine, Tellus 52A (2000). One forward solve from the
pins-centred start gives the exact metrics over the evaluation window and the pins'
state in their bearings at the start of K short windows; each window is re-solved
from that state with an implicit solver, one after another, and the derivative of the
windows' pooled mean squares is the gradient: a trend estimate rather than the
derivative of a chaotic time average (it leaves out how the statistics of the start
states move with the design).
"""

from __future__ import annotations

from typing import NamedTuple

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from jaxcrank.numerics.estimators import straight_through
from jaxcrank.numerics.solve import DEFAULTS, Simulation, SolveOptions, simulate
from jaxcrank.physics import model
from jaxcrank.physics.linkage import AbstractMechanism as Mechanism
from jaxcrank.physics.linkage import Revolute
from jaxcrank.physics.params import ParameterError
from jaxcrank.physics.safemath import safe_norm
from jaxcrank.physics.signals import rms_metrics

from .objective import (
    AbstractObjective,
    Grid,
    _check_window,
    _fields,
    options_fields,
    rms_signal_values,
    safe_sqrt,
    sample_grid,
)

#: the windows' default solve settings: Rodas4 (L-stable), 5 000 steps per window
WINDOW_DEFAULTS = SolveOptions.from_text("rodas4", max_steps=5_000)


class Starts(NamedTuple):
    """Pin-in-bearing states at the start of the ensemble windows (no gradient), from
    [`window_starts`][optim.ensemble.window_starts] .

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


def tracked_solve(mech: Mechanism, grid: Grid, windows: int, options: SolveOptions, throw: bool) -> Simulation:
    """One solve from the pins-centred start over ``grid`` that stores the state only at
    the ensemble windows' starts ([`window_start_indices`][optim.ensemble.window_start_indices]) and tracks the headline
    metrics over the samples in (t_start, t_end] during the solve
    ([`jaxcrank.numerics.tracking`][]): memory independent of the number of samples.
    Forward mode only. ``options``: the solve's settings."""
    ts = grid.dt * np.arange(grid.n_start + grid.n_eval + 1)
    return simulate(
        mech,
        ts=ts,
        save_ts=ts[window_start_indices(grid, windows)],
        metrics_start=(grid.n_start + 0.5) * grid.dt,  # between samples: no rounding decides membership
        throw=throw,
        options=options,
    )


def window_starts(sim: Simulation) -> Starts:
    """The [`Starts`][optim.ensemble.Starts] of the ensemble windows from a
    [`tracked_solve`][optim.ensemble.tracked_solve] , whose
    stored samples are the windows' starts (no gradient)."""
    mech = jax.lax.stop_gradient(sim.mechanism)
    t0s, y0s = sim.ts, sim.ys
    d, d_rate = jax.vmap(model.joint_eccentricities, in_axes=(None, 0, 0))(mech, t0s, y0s)
    rest = model.auxiliary(mech, y0s)  # SI: the scales change with the clearances
    return jax.lax.stop_gradient(Starts(t0s, d, d_rate, rest, clearances(mech)))


def clearances(mech: Mechanism) -> Float[Array, " joints"]:
    """Radial clearance of each clearance joint (the tree's cut joints, sorted), m."""
    compiled = model.compile_model(mech)
    lk, tree = compiled.linkage, compiled.tree
    return jnp.stack([jnp.asarray(lk.joints[j].clearance, dtype=float) for j in tree.cut])


def start_state(mech: Mechanism, starts: Starts, i: Int[ArrayLike, ""]) -> Float[Array, " state"]:
    """Scaled state of ``mech`` at window ``i``: the pins where ``starts`` had them
    in their bearings, moving the same way, with the same gap or penetration (a
    clearance change moves a revolute joint's pin radially by the change; a prismatic
    joint's eccentricity is kept)."""
    compiled = model.compile_model(mech)
    lk, tree = compiled.linkage, compiled.tree
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
    adjoint,
    options: SolveOptions,
) -> tuple[Float[Array, " window"], Float[Array, "window state"], Bool[Array, ""]]:
    """Window ``i`` re-solved for ``mech`` from [`start_state`][optim.ensemble.start_state] with ``options``
    and ``adjoint`` (diffrax): its sample times (n_window,) s, scaled states (zero where the
    solve failed, so a failed window is reported by the caller, not propagated as NaN)
    and whether it finished within ``options.max_steps``."""
    # local time from the window's start (the driver's angle carries the offset): diffrax then
    # sees concrete times and compiles no run-time checks of them (host callbacks, which
    # JAX's persistent compilation cache does not store)
    y0 = start_state(mech, starts, i)
    driver = mech.driver
    mech = eqx.tree_at(lambda m: m.driver.initial_angle, mech, driver.initial_angle + driver.speed * starts.t[i])
    ts = grid.dt * np.arange(grid.n_window + 1)
    sim = simulate(mech, ts=ts, y0=y0, options=options, throw=False, adjoint=adjoint)
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
    "Ensemble.window_options.max_steps, loosen rtol/atol or shorten Ensemble.window"
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


class Ensemble(AbstractObjective):
    """The exact metrics over the window ``(t_start, t_end]`` of one forward solve, with
    the ensemble-sensitivity gradient of K short windows re-solved from the forward
    solve's states (module docstring; a trend estimate, first order: do not take
    second derivatives of it).

    Attributes:
        t_start: start of the evaluation window (t_start, t_end], s (default 0.1: the
            window is the second and third revolutions at 600 rpm).
        t_end: end of the evaluation window, s (default 0.3).
        samples_per_degree: samples per degree of crank angle, > 0.
        window: length of each ensemble window, s; rounded to whole sample steps and
            shrunk to divide the evaluation window; in (0, t_end - t_start].
        windows: number of ensemble windows, spread evenly (0: all, tiling the window).
        window_options: the windows' solve settings (default `WINDOW_DEFAULTS`: Rodas4,
            5 000 steps). A window that exceeds its ``max_steps`` is left out of the
            ensemble (more than half failing is an error, or NaN). Keep the solver
            L-stable: an explicit solver's step sequence sits at its stability limit in
            stick phases and the derivative of its discrete solution then blows up in about
            1 % of windows (docs/optimisation.md, "The gradient").
        window_adjoint: diffrax adjoint of the windows: ``diffrax.ForwardMode()``
            (differentiate with [`value_and_grad`][optim.objective.value_and_grad] / ``jax.jacfwd``) or
            ``diffrax.RecursiveCheckpointAdjoint()`` (``jax.grad``).
        options: the forward solve's settings ([`jaxcrank.SolveOptions`][jaxcrank.numerics.solve.SolveOptions]).
        throw: see [`AbstractObjective`][optim.objective.AbstractObjective].

    Raises:
        ParameterError: for an empty window, a window outside it, or an adjoint that is
            neither forward nor reverse mode.
    """

    t_start: float = eqx.field(static=True, default=0.1)
    t_end: float = eqx.field(static=True, default=0.3)
    samples_per_degree: float = eqx.field(static=True, default=10.0)
    window: float = eqx.field(static=True, default=2e-3)
    windows: int = eqx.field(static=True, default=25)
    window_options: SolveOptions = eqx.field(static=True, default=WINDOW_DEFAULTS)
    window_adjoint: diffrax.AbstractAdjoint = eqx.field(static=True, default=diffrax.ForwardMode())
    options: SolveOptions = eqx.field(static=True, default=DEFAULTS)
    throw: bool = eqx.field(static=True, default=True)

    def __check_init__(self):
        _check_window(self.t_start, self.t_end, self.samples_per_degree)
        if not 0.0 < self.window <= self.t_end - self.t_start:
            raise ParameterError(
                f"ensemble window = {self.window:g} s must be in (0, t_end - t_start = {self.t_end - self.t_start:g}] s"
            )
        if not isinstance(self.window_adjoint, diffrax.ForwardMode | diffrax.RecursiveCheckpointAdjoint):
            raise ParameterError(
                f"window_adjoint = {self.window_adjoint!r} is not supported; valid: diffrax.ForwardMode() "
                "or diffrax.RecursiveCheckpointAdjoint()"
            )

    def grid(self, mech: Mechanism) -> Grid:
        """The sample grid with the ensemble windows ([`optim.objective.sample_grid`][])."""
        return sample_grid(mech, self.t_start, self.t_end, self.samples_per_degree, self.window)

    def reference(self, mech: Mechanism) -> tuple[dict[str, Float[Array, ""]], Starts]:
        """One forward solve (no gradient, [`tracked_solve`][optim.ensemble.tracked_solve]): the
        exact RMS metrics (NaN where the solve failed and ``throw`` is False) and the
        [`Starts`][optim.ensemble.Starts] of the ensemble windows."""
        grid = self.grid(mech)
        mech = jax.lax.stop_gradient(mech)
        sim = tracked_solve(mech, grid, self.windows, self.options, self.throw)
        exact = {k: jnp.where(sim.ok, sim.metrics[k], jnp.nan) for k in rms_metrics(mech)}
        return jax.lax.stop_gradient(exact), window_starts(sim)

    def window_sums(
        self, mech: Mechanism, starts: Starts, i, grid: Grid | None = None
    ) -> tuple[dict[str, Float[Array, ""]], jax.Array]:
        """Window ``i`` re-solved for ``mech`` from the carried-over start state: the
        sums of squares of the RMS metrics' signals over its samples (units squared; 0
        where the window failed) and whether it finished. ``grid``: the sample grid of
        the base design (default [`grid`][optim.ensemble.Ensemble.grid] of ``mech``, which needs a concrete
        ``driver.speed``)."""
        grid = self.grid(mech) if grid is None else grid
        ts, ys, ok = solve_window(mech, starts, i, grid, adjoint=self.window_adjoint, options=self.window_options)
        sig = rms_signal_values(mech, ts, ys)
        return {k: jnp.where(ok, jnp.sum(v**2), 0.0) for k, v in sig.items()}, ok

    def pooled(self, mech: Mechanism, starts: Starts) -> dict[str, Float[Array, ""]]:
        """The RMS metrics pooled over the windows re-solved for ``mech`` from the fixed
        ``starts``; their derivative is the ensemble sum of the windows' derivatives."""
        n_window = self.grid(mech).n_window
        sums, ok = over_windows(lambda i: self.window_sums(mech, starts, i), starts)
        n_ok = windows_ok(ok, self.throw)
        return {k: safe_sqrt(jnp.sum(jnp.where(ok, v, 0.0)) / (n_window * n_ok)) for k, v in sums.items()}

    def rms(self, mech: Mechanism) -> dict[str, Float[Array, ""]]:
        exact, starts = self.reference(mech)
        surrogate = self.pooled(mech, starts)
        return {k: straight_through(exact[k], surrogate[k]) for k in rms_metrics(mech)}

    def forward_mode(self) -> bool:
        return isinstance(self.window_adjoint, diffrax.ForwardMode)

    def describe(self) -> dict:
        d = {"kind": "ensemble", **_fields(self), **options_fields(self.options)}
        d["window_adjoint"] = "forward" if self.forward_mode() else "reverse"
        return {**d, **options_fields(self.window_options, "window_")}
