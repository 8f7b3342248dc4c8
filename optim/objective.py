"""The paper's Eq. 19 objective and a gradient of it that follows its trend.

``F = sqrt(mean_n (alpha_n - alpha_ideal_n)^2)``, degrees, over the samples of an
evaluation window ``(t_start, t_end]`` at equal crank-angle steps (the crank turns
at constant speed, so equal times are equal crank angles and the actual and ideal
transmission angles are compared at the same crank angle).

Two ways to evaluate it (``Objective.method``):

``"pathwise"``
    One solve from the pins-centred start to ``t_end``; F and its reverse-mode
    gradient through the whole solve. Exact, and meaningful only for windows
    shorter than the impact chaos' horizon (a few ms on the paper preset): over
    the paper's window the gradient is ~1e27 (README, "Known limitation").

``"ensemble"`` (default)
    The value is still the exact Eq. 19 (one forward solve); the gradient is the
    ensemble-sensitivity estimate (Lea, Allen & Haine, Tellus 52A, 2000): the
    forward solve gives the pins' state in their bearings at the start of K short
    windows spread over the evaluation window; each window is re-solved from that
    state (held fixed, carried over to the design being differentiated) with an
    implicit solver, in one ``vmap`` of per-window reverse-mode gradients, and the
    window gradients are summed. Finite, and a trend estimate rather than the
    derivative of a chaotic F: it leaves out how the statistics of the start states
    move with the design. Evidence and the measured choices: README, "Design
    optimisation"; ``python -m optim.scans``.
"""

from __future__ import annotations

import math
from typing import Literal, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

from jaxcrank import laws, model
from jaxcrank.outputs import transmission_angle_error
from jaxcrank.params import Mechanism, ParameterError
from jaxcrank.solve import simulate


class Objective(eqx.Module):
    """Settings of the Eq. 19 objective (all static: they fix array shapes).

    Attributes:
        t_start, t_end: evaluation window (t_start, t_end], s. Default: the second
            and third revolutions at 600 rpm, (0.1, 0.3] s.
        samples_per_degree: samples per degree of crank angle (the paper's ``s``
            points are ``360 * samples_per_degree`` per revolution).
        method: ``"ensemble"`` (trend-following gradient) or ``"pathwise"``.
        window: length of each ensemble window, s; rounded to whole sample steps
            and must divide the evaluation window.
        windows: number of ensemble windows, spread evenly over the evaluation
            window (0: all windows, tiling it).
        window_max_steps: step budget of each window (accepted + rejected); a
            window that exceeds it is left out of the ensemble (under ``vmap`` every
            window waits for the slowest, so one stuck window costs the whole budget).
        window_solver: solver of the ensemble windows. An L-stable one: an
            explicit solver's step sequence sits at its stability limit in stick
            phases (friction ramp) and the derivative of its discrete solution then
            blows up in about 1 % of windows (README, "Design optimisation";
            ``bench/window_gradients.py``). Default ``kvaerno5``; the linearly
            implicit ``rodas4`` gives the same gradients at rtol 1e-6 in a fraction
            of the time but its reverse mode moves by up to 1.5 % between rtol 1e-6
            and 1e-9 where kvaerno5's does not; kvaerno5's Newton iterations stall in
            some stick phases (5 of the paper window's 100 windows needed 17 000 to
            63 000 steps; ``window_max_steps`` leaves them out) (README, "Design
            optimisation").
        rtol, atol: solver tolerances on the scaled state.
        max_steps: step budget of the long solve.
    """

    t_start: float = eqx.field(static=True, default=0.1)
    t_end: float = eqx.field(static=True, default=0.3)
    samples_per_degree: float = eqx.field(static=True, default=10.0)
    method: Literal["ensemble", "pathwise"] = eqx.field(static=True, default="ensemble")
    window: float = eqx.field(static=True, default=2e-3)
    windows: int = eqx.field(static=True, default=25)
    window_max_steps: int = eqx.field(static=True, default=5_000)
    window_solver: str = eqx.field(static=True, default="kvaerno5")
    rtol: float = eqx.field(static=True, default=1e-6)
    atol: float = eqx.field(static=True, default=1e-6)
    max_steps: int = eqx.field(static=True, default=500_000)

    def __check_init__(self):
        if not 0.0 <= self.t_start < self.t_end:
            raise ParameterError(
                f"objective window must satisfy 0 <= t_start < t_end, got "
                f"t_start = {self.t_start:g} s, t_end = {self.t_end:g} s"
            )
        if self.samples_per_degree <= 0:
            raise ParameterError(f"samples_per_degree = {self.samples_per_degree:g} must be positive")
        if self.method not in ("ensemble", "pathwise"):
            raise ParameterError(f"objective method {self.method!r} is unknown; valid: 'ensemble', 'pathwise'")
        if self.method == "ensemble" and not 0.0 < self.window <= self.t_end - self.t_start:
            raise ParameterError(
                f"ensemble window = {self.window:g} s must be in (0, t_end - t_start = {self.t_end - self.t_start:g}] s"
            )

    def grid(self, mech: Mechanism):
        """(n_start, n_eval, n_window, dt): sample index of t_start, number of samples
        in (t_start, t_end], samples per ensemble window and the sample step, s.
        Needs a concrete crank speed (not a traced design variable)."""
        try:
            omega = float(mech.crank_speed)
        except (TypeError, jax.errors.ConcretizationTypeError):
            raise ParameterError(
                "the objective's sample grid needs a concrete crank_speed: build the "
                "mechanism inside the traced function from a fixed base design"
            ) from None
        dt = math.radians(1.0 / self.samples_per_degree) / omega
        n_start = int(round(self.t_start / dt))
        n_eval = int(round((self.t_end - self.t_start) / dt))
        n_window = max(1, int(round(self.window / dt)))
        if self.method == "ensemble" and n_eval % n_window:
            # shrink the window to the nearest divisor of the evaluation window
            k = max(1, round(n_eval / n_window))
            while n_eval % k:
                k += 1
            n_window = n_eval // k
        return n_start, n_eval, n_window, dt


def eval_samples(mech: Mechanism, obj: Objective, throw: bool, grid):
    """One solve from the pins-centred start over the objective's sample ``grid``
    (:meth:`Objective.grid`, computed by the caller while the crank speed is still
    concrete): the simulation, the sample index of t_start and the
    transmission-angle errors (deg) at the samples in (t_start, t_end]."""
    n_start, n_eval, _, dt = grid
    ts = dt * jnp.arange(n_start + n_eval + 1)
    sim = simulate(mech, ts=ts, rtol=obj.rtol, atol=obj.atol, max_steps=obj.max_steps, throw=throw)
    return sim, n_start, transmission_angle_error(mech, sim.ts[n_start + 1 :], sim.ys[n_start + 1 :])


def pathwise_errors(mech: Mechanism, obj: Objective = Objective()):
    """Squared transmission-angle errors (deg^2) at the samples in (t_start, t_end]
    of one solve from the pins-centred start, and whether the solve succeeded
    (``throw=False``: batch callers report failures)."""
    sim, _, err = eval_samples(mech, obj, False, obj.grid(mech))
    return err**2, sim.ok & jnp.all(jnp.isfinite(err))


def pathwise(mech: Mechanism, obj: Objective = Objective()):
    """Eq. 19 from one solve from the pins-centred start, degrees (raises if the solve fails)."""
    _, _, err = eval_samples(mech, obj, True, obj.grid(mech))
    return jnp.sqrt(jnp.mean(err**2))


class Starts(NamedTuple):
    """Pin-in-bearing states at the start of the ensemble windows (no gradient), from :func:`reference`.

    Attributes: t (K,) s; eccentricity (K, 2, 2) m and eccentricity_rate (K, 2, 2)
    m/s for joints (B, C); rest (K, 4) the other state entries in SI units
    (approach-speed memories at B and C, m/s; driver and dissipated work, J); clearance
    (2,) m, of the design they were taken from.
    """

    t: jax.Array
    eccentricity: jax.Array
    eccentricity_rate: jax.Array
    rest: jax.Array
    clearance: jax.Array


def reference(mech: Mechanism, obj: Objective = Objective()):
    """One forward solve from the pins-centred start (no gradient): the Eq. 19
    value (degrees) and the :class:`Starts` of the ensemble windows."""
    grid = obj.grid(mech)
    mech = jax.lax.stop_gradient(mech)
    sim, n_start, err = eval_samples(mech, obj, True, grid)
    return jax.lax.stop_gradient(jnp.sqrt(jnp.mean(err**2))), window_starts(sim, n_start, grid, obj)


def window_starts(sim, n_start: int, grid, obj: Objective) -> Starts:
    """The :class:`Starts` of the ensemble windows of ``obj`` taken from a solve
    ``sim`` over the objective's sample ``grid`` (no gradient)."""
    _, n_eval, n_window, _ = grid
    mech = jax.lax.stop_gradient(sim.mechanism)
    tiles = n_eval // n_window
    k = tiles if obj.windows <= 0 else min(obj.windows, tiles)
    idx = n_start + n_window * ((jnp.arange(k) * tiles) // k)  # k windows spread evenly
    t0s, y0s = sim.ts[idx], sim.ys[idx]
    d, d_rate = jax.vmap(model.eccentricities, in_axes=(None, 0, 0))(mech, t0s, y0s)
    clearance = jnp.stack([mech.joint_B.clearance, mech.joint_C.clearance])
    rest = model.auxiliary(mech, y0s)  # SI: the scales change with the clearances
    return jax.lax.stop_gradient(Starts(t0s, d, d_rate, rest, clearance))


def start_state(mech: Mechanism, starts: Starts, i):
    """Scaled state of ``mech`` at window ``i``: the pins where ``starts`` had them
    in their bearings, moving the same way, with the same gap or penetration (a
    clearance change moves the pin radially by the change)."""
    d = starts.eccentricity[i]
    norm = laws.safe_norm(d, axis=-1)[:, None]
    direction = jnp.where(norm > 0.0, d / jnp.where(norm > 0.0, norm, 1.0), 0.0)
    clearance = jnp.stack([mech.joint_B.clearance, mech.joint_C.clearance])
    d = d + (clearance - starts.clearance)[:, None] * direction
    return model.state_from_eccentricities(mech, starts.t[i], d, starts.eccentricity_rate[i], starts.rest[i])


def _is_float(x):
    return isinstance(x, float) or (isinstance(x, jax.Array) and jnp.issubdtype(x.dtype, jnp.inexact))


def solve_window(mech: Mechanism, starts: Starts, i, n_window: int, dt: float, obj: Objective):
    """Window ``i`` re-solved for ``mech`` from :func:`start_state`: its sample
    times (n_window,) s, scaled states (zero where the solve failed, so a failed
    window is reported by the caller, not propagated as NaN) and whether it finished."""
    ts = starts.t[i] + dt * jnp.arange(n_window + 1)
    sim = simulate(
        mech,
        ts=ts,
        y0=start_state(mech, starts, i),
        solver=obj.window_solver,
        rtol=obj.rtol,
        atol=obj.atol,
        max_steps=obj.window_max_steps,
        throw=False,
    )
    ok = sim.ok & jnp.all(jnp.isfinite(sim.ys))
    # the requested times, not sim.ts: a failed diffrax solve fills its ts with inf
    return ts[1:], jnp.where(ok, sim.ys, 0.0)[1:], ok


def _window(mech: Mechanism, starts: Starts, i, n_window: int, dt: float, obj: Objective):
    ts, ys, ok = solve_window(mech, starts, i, n_window, dt, obj)
    sq = jnp.sum(transmission_angle_error(mech, ts, ys) ** 2)
    return jnp.where(ok, sq, 0.0), ok


def window_gradients(mech: Mechanism, starts: Starts, obj: Objective = Objective()):
    """Each window's sum of squared transmission-angle errors (deg^2), shape (K,),
    whether its solve succeeded (K,), and its gradient with respect to every
    parameter of ``mech`` (a Mechanism of (K,) arrays), each window re-solved from
    :func:`start_state`. The windows are one ``vmap`` of per-window reverse-mode
    gradients (``bench/window_gradients.py`` looks at their distribution)."""
    _, _, n_window, dt = obj.grid(mech)
    params, static = eqx.partition(mech, _is_float)
    params = jax.tree.map(lambda x: jax.lax.stop_gradient(jnp.asarray(x)), params)

    def one(p, i):
        return _window(eqx.combine(p, static), starts, i, n_window, dt, obj)

    (sq, ok), grads = jax.vmap(jax.value_and_grad(one, has_aux=True), in_axes=(None, 0))(
        params, jnp.arange(starts.t.shape[0])
    )
    return sq, ok, grads


def ensemble(mech: Mechanism, starts: Starts, obj: Objective = Objective()):
    """Eq. 19 assembled from the windows of :func:`window_gradients`, degrees;
    its reverse-mode gradient is the ensemble sum of the windows' gradients."""
    _, _, n_window, _ = obj.grid(mech)
    sq, ok, grads = window_gradients(mech, starts, obj)
    # A window the implicit solver cannot finish within its step budget (rare: a
    # stick phase under a large contact force) is left out of the ensemble.
    n_ok = jnp.sum(ok)
    n_ok = eqx.error_if(
        n_ok,
        n_ok < 0.5 * ok.shape[0],
        "jaxcrank: more than half of the ensemble windows failed; raise "
        "Objective.window_max_steps, loosen rtol/atol or shorten Objective.window",
    )
    w = ok.astype(sq.dtype)
    # First-order surrogate: value sum(sq), gradient the sum of the window gradients.
    params, _ = eqx.partition(mech, _is_float)
    sg = jax.lax.stop_gradient
    total = sg(jnp.sum(w * sq)) + sum(
        jnp.sum(sg(jnp.tensordot(w, g, axes=1)) * (jnp.asarray(p) - sg(p)))
        for p, g in zip(jax.tree.leaves(params), jax.tree.leaves(grads))
    )
    return jnp.sqrt(total / (n_window * n_ok))


def value(mech: Mechanism, obj: Objective = Objective()):
    """Eq. 19 value, degrees. With ``method="pathwise"`` its gradient is the exact
    derivative of the discrete solve; with ``"ensemble"`` the value is still the
    exact Eq. 19 (from :func:`reference`) and the gradient is the ensemble
    estimate ``d ensemble(mech, starts) / d mech`` with the starts held fixed
    (first order: do not take second derivatives of it)."""
    if obj.method == "pathwise":
        return pathwise(mech, obj)
    exact, starts = reference(mech, obj)
    estimate = ensemble(mech, starts, obj)
    sg = jax.lax.stop_gradient
    return exact + (estimate - sg(estimate))
