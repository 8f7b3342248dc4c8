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
    the paper's window the gradient is ~1e27 (docs/numerics.md, "Gradients beyond
    the first impacts").

``"ensemble"`` (default)
    The value is still the exact Eq. 19 (one forward solve); the gradient is the
    ensemble-sensitivity estimate (Lea, Allen & Haine, Tellus 52A, 2000): the
    forward solve gives the pins' state in their bearings at the start of K short
    windows spread over the evaluation window; each window is re-solved from that
    state (held fixed, carried over to the design being differentiated) with an
    implicit solver, one after another, and the derivative of the windows' pooled
    Eq. 19 is the gradient. Finite, and a trend estimate rather than the derivative
    of a chaotic F: it leaves out how the statistics of the start states move with
    the design. Evidence and the measured choices: docs/optimisation.md;
    ``python -m optim.scans``.

The windows are differentiated in forward mode by default
(``Objective.window_gradient = "forward"``: ``diffrax.ForwardMode``, one tangent per
design variable), which compiles several times faster than reverse mode for the
few variables of a design problem (and runs slower per gradient; docs/optimisation.md).
Such an objective is differentiated with :func:`value_and_grad` (``jax.jacfwd``), not
``jax.grad``; ``"reverse"`` restores reverse mode.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Literal, NamedTuple

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Int, Real

from jaxcrank import laws, model
from jaxcrank.analysis.outputs import transmission_angle_error
from jaxcrank.numerics.estimators import straight_through
from jaxcrank.numerics.solve import DEFAULTS, Simulation, simulate
from jaxcrank.physics.params import Mechanism, ParameterError


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
            window that exceeds it is left out of the ensemble.
        window_solver: solver of the ensemble windows. An L-stable one: an
            explicit solver's step sequence sits at its stability limit in stick
            phases (friction ramp) and the derivative of its discrete solution then
            blows up in about 1 % of windows. Default the linearly implicit
            ``rodas4``; ``kvaerno5`` gives the same gradients but its Newton
            iterations stall in some stick phases (``window_max_steps`` leaves such
            windows out). Measurements: docs/optimisation.md, "The gradient";
            ``bench/window_gradients.py``.
        window_gradient: ``"forward"`` (``diffrax.ForwardMode``; differentiate with
            :func:`value_and_grad` or ``jax.jacfwd``) or ``"reverse"``
            (``jax.grad``). The ensemble method only; pathwise is always reverse.
        on_failure: ``"raise"`` (a failed long solve, or more than half of the
            ensemble windows failing, raises when the program runs; a host callback)
            or ``"nan"`` (the value is NaN instead, and the program holds no host
            callback, so JAX's persistent compilation cache can store it; the caller
            must check, as :func:`optim.optimize.optimize` does).
        rtol, atol: solver tolerances on the scaled state (default: :data:`jaxcrank.numerics.solve.DEFAULTS`).
        max_steps: step budget of the long solve (default: :data:`jaxcrank.numerics.solve.DEFAULTS`).
    """

    t_start: float = eqx.field(static=True, default=0.1)
    t_end: float = eqx.field(static=True, default=0.3)
    samples_per_degree: float = eqx.field(static=True, default=10.0)
    method: Literal["ensemble", "pathwise"] = eqx.field(static=True, default="ensemble")
    window: float = eqx.field(static=True, default=2e-3)
    windows: int = eqx.field(static=True, default=25)
    window_max_steps: int = eqx.field(static=True, default=5_000)
    window_solver: str = eqx.field(static=True, default="rodas4")
    window_gradient: Literal["forward", "reverse"] = eqx.field(static=True, default="forward")
    on_failure: Literal["raise", "nan"] = eqx.field(static=True, default="raise")
    rtol: float = eqx.field(static=True, default=DEFAULTS.rtol)
    atol: float = eqx.field(static=True, default=DEFAULTS.atol)
    max_steps: int = eqx.field(static=True, default=DEFAULTS.max_steps)

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
        if self.window_gradient not in ("forward", "reverse"):
            raise ParameterError(
                f"objective window_gradient {self.window_gradient!r} is unknown; valid: 'forward', 'reverse'"
            )
        if self.on_failure not in ("raise", "nan"):
            raise ParameterError(f"objective on_failure {self.on_failure!r} is unknown; valid: 'raise', 'nan'")
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


def eval_samples(mech: Mechanism, obj: Objective, throw: bool, grid) -> tuple[Simulation, int, Float[Array, " eval"]]:
    """One solve from the pins-centred start over the objective's sample ``grid``
    (:meth:`Objective.grid`, computed by the caller while the crank speed is still
    concrete) that stores every sample, for the pathwise method's reverse-mode
    gradient: the simulation, the sample index of t_start and the
    transmission-angle errors (deg) at the samples in (t_start, t_end]."""
    sim, n_start = stored_solve(mech, obj, throw, grid)
    return sim, n_start, transmission_angle_error(mech, sim.ts[n_start + 1 :], sim.ys[n_start + 1 :])


def stored_solve(mech: Mechanism, obj: Objective, throw: bool, grid) -> tuple[Simulation, int]:
    """One solve from the pins-centred start that stores every sample of the objective's
    ``grid`` (:meth:`Objective.grid`): the simulation and the sample index of t_start
    (the samples in (t_start, t_end] follow it). Differentiable in reverse mode."""
    n_start, n_eval, _, dt = grid
    ts = dt * jnp.arange(n_start + n_eval + 1, dtype=float)
    return simulate(mech, ts=ts, rtol=obj.rtol, atol=obj.atol, max_steps=obj.max_steps, throw=throw), n_start


def pathwise_errors(mech: Mechanism, obj: Objective = Objective()) -> tuple[Float[Array, " eval"], Bool[Array, ""]]:
    """Squared transmission-angle errors (deg^2) at the samples in (t_start, t_end]
    of one solve from the pins-centred start, and whether the solve succeeded
    (``throw=False``: batch callers report failures)."""
    sim, _, err = eval_samples(mech, obj, False, obj.grid(mech))
    return err**2, sim.ok & jnp.all(jnp.isfinite(err))


def pathwise(mech: Mechanism, obj: Objective = Objective()) -> Float[Array, ""]:
    """Eq. 19 from one solve from the pins-centred start, degrees (if the solve fails:
    raises, or NaN with ``obj.on_failure = "nan"``)."""
    sim, _, err = eval_samples(mech, obj, obj.on_failure == "raise", obj.grid(mech))
    return _nan_unless(sim.ok, jnp.sqrt(jnp.mean(err**2)))


def _nan_unless(ok, x):
    return jnp.where(ok, x, jnp.nan)


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


def window_start_indices(grid, obj: Objective) -> np.ndarray:
    """Sample indices (on the objective's ``grid``, :meth:`Objective.grid`) of the
    starts of the K ensemble windows, spread evenly over the evaluation window."""
    n_start, n_eval, n_window, _ = grid
    tiles = n_eval // n_window
    k = tiles if obj.windows <= 0 else min(obj.windows, tiles)
    return n_start + n_window * ((np.arange(k) * tiles) // k)


def tracked_solve(mech: Mechanism, obj: Objective, throw: bool, grid) -> Simulation:
    """One solve from the pins-centred start over the objective's sample ``grid``
    (:meth:`Objective.grid`) that stores the state only at the ensemble windows'
    starts (:func:`window_start_indices`) and tracks the RMS metrics over the samples
    in (t_start, t_end] during the solve (:mod:`jaxcrank.numerics.tracking`): memory independent
    of the number of samples. Forward mode only (no reverse-mode gradient through it)."""
    n_start, n_eval, _, dt = grid
    ts = dt * np.arange(n_start + n_eval + 1)
    return simulate(
        mech,
        ts=ts,
        save_ts=ts[window_start_indices(grid, obj)],
        metrics_start=(n_start + 0.5) * dt,  # between samples: no rounding decides membership
        rtol=obj.rtol,
        atol=obj.atol,
        max_steps=obj.max_steps,
        throw=throw,
    )


def reference(mech: Mechanism, obj: Objective = Objective()) -> tuple[Float[Array, ""], Starts]:
    """One forward solve from the pins-centred start (no gradient, :func:`tracked_solve`):
    the Eq. 19 value (degrees) and the :class:`Starts` of the ensemble windows."""
    grid = obj.grid(mech)
    mech = jax.lax.stop_gradient(mech)
    sim = tracked_solve(mech, obj, obj.on_failure == "raise", grid)
    exact = _nan_unless(sim.ok, sim.metrics["rms_transmission_angle_error_deg"])
    return jax.lax.stop_gradient(exact), window_starts(sim)


def window_starts(sim: Simulation) -> Starts:
    """The :class:`Starts` of the ensemble windows from a :func:`tracked_solve`, whose
    stored samples are the windows' starts (no gradient)."""
    mech = jax.lax.stop_gradient(sim.mechanism)
    t0s, y0s = sim.ts, sim.ys
    d, d_rate = jax.vmap(model.eccentricities, in_axes=(None, 0, 0))(mech, t0s, y0s)
    clearance = jnp.stack([mech.joint_B.clearance, mech.joint_C.clearance])
    rest = model.auxiliary(mech, y0s)  # SI: the scales change with the clearances
    return jax.lax.stop_gradient(Starts(t0s, d, d_rate, rest, clearance))


def start_state(mech: Mechanism, starts: Starts, i: Int[ArrayLike, ""]) -> Float[Array, " state"]:
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


def solve_window(
    mech: Mechanism, starts: Starts, i: Int[ArrayLike, ""], n_window: int, dt: float, obj: Objective
) -> tuple[Float[Array, " window"], Float[Array, "window state"], Bool[Array, ""]]:
    """Window ``i`` re-solved for ``mech`` from :func:`start_state`: its sample
    times (n_window,) s, scaled states (zero where the solve failed, so a failed
    window is reported by the caller, not propagated as NaN) and whether it finished."""
    # local time from the window's start (the crank angle carries the offset): diffrax then
    # sees concrete times and compiles no run-time checks of them (host callbacks, which
    # JAX's persistent compilation cache does not store)
    y0 = start_state(mech, starts, i)
    mech = eqx.tree_at(lambda m: m.initial_crank_angle, mech, mech.initial_crank_angle + mech.crank_speed * starts.t[i])
    ts = dt * np.arange(n_window + 1)
    sim = simulate(
        mech,
        ts=ts,
        y0=y0,
        solver=obj.window_solver,
        rtol=obj.rtol,
        atol=obj.atol,
        max_steps=obj.window_max_steps,
        throw=False,
        adjoint=diffrax.ForwardMode() if obj.window_gradient == "forward" else None,
    )
    ok = sim.ok & jnp.all(jnp.isfinite(sim.ys))
    # the requested times, not sim.ts: a failed diffrax solve fills its ts with inf
    return starts.t[i] + ts[1:], jnp.where(ok, sim.ys, 0.0)[1:], ok


def _window(mech: Mechanism, starts: Starts, i, n_window: int, dt: float, obj: Objective):
    ts, ys, ok = solve_window(mech, starts, i, n_window, dt, obj)
    sq = jnp.sum(transmission_angle_error(mech, ts, ys) ** 2)
    return jnp.where(ok, sq, 0.0), ok


def window_gradients(
    mech: Mechanism, starts: Starts, obj: Objective = Objective()
) -> tuple[Float[Array, " windows"], Bool[Array, " windows"], Mechanism]:
    """Each window's sum of squared transmission-angle errors (deg^2), shape (K,),
    whether its solve succeeded (K,), and its gradient with respect to every
    parameter of ``mech`` (a Mechanism of (K,) arrays), each window re-solved from
    :func:`start_state`, one after another (:func:`over_windows`), each with its
    reverse-mode gradient (``bench/window_gradients.py`` looks at their distribution);
    always reverse mode, whatever ``obj.window_gradient``."""
    _, _, n_window, dt = obj.grid(mech)
    obj = dataclasses.replace(obj, window_gradient="reverse")
    params, static = eqx.partition(mech, _is_float)
    params = jax.tree.map(lambda x: jax.lax.stop_gradient(jnp.asarray(x)), params)

    def one(p, i):
        return _window(eqx.combine(p, static), starts, i, n_window, dt, obj)

    (sq, ok), grads = over_windows(lambda i: jax.value_and_grad(one, has_aux=True)(params, i), starts)
    return sq, ok, grads


WINDOWS_FAILED = (
    "jaxcrank: more than half of the ensemble windows failed; raise "
    "Objective.window_max_steps, loosen rtol/atol or shorten Objective.window"
)


def windows_ok(ok: Bool[Array, " windows"], obj: Objective) -> Real[Array, ""]:
    """The number of finished windows (a scalar); fewer than half of ``ok`` raises
    (``obj.on_failure = "raise"``) or makes it NaN (``"nan"``)."""
    n_ok = jnp.sum(ok, dtype=float)
    enough = n_ok >= 0.5 * ok.shape[0]
    if obj.on_failure == "raise":
        return eqx.error_if(n_ok, ~enough, WINDOWS_FAILED)
    return jnp.where(enough, n_ok, jnp.nan)


def over_windows(fun, starts: Starts):
    """``fun(i)`` for every ensemble window ``i`` of ``starts``, stacked: one window
    after another (``jax.lax.map``). Under ``vmap`` every window would step as long as
    the slowest one; in sequence each takes its own steps, and the program compiles
    faster (measurements: docs/optimisation.md, "A gradient in seconds")."""
    return jax.lax.map(fun, jnp.arange(starts.t.shape[0]))


def ensemble(mech: Mechanism, starts: Starts, obj: Objective = Objective()) -> Float[Array, ""]:
    """Eq. 19 pooled over the ensemble windows re-solved for ``mech`` from the fixed
    ``starts``, degrees. Its derivative (forward or reverse mode, as
    ``obj.window_gradient``) is the ensemble sum of the windows' derivatives.

    A window the implicit solver cannot finish within its step budget (rare: a
    stick phase under a large contact force) is left out; more than half failing
    is an error (:func:`windows_ok`)."""
    _, _, n_window, dt = obj.grid(mech)
    sq, ok = over_windows(lambda i: _window(mech, starts, i, n_window, dt, obj), starts)
    n_ok = windows_ok(ok, obj)
    return jnp.sqrt(jnp.sum(jnp.where(ok, sq, 0.0)) / (n_window * n_ok))


def value(mech: Mechanism, obj: Objective = Objective()) -> Float[Array, ""]:
    """Eq. 19 value, degrees. With ``method="pathwise"`` its gradient is the exact
    derivative of the discrete solve; with ``"ensemble"`` the value is still the
    exact Eq. 19 (from :func:`reference`) and the gradient is the ensemble
    estimate ``d ensemble(mech, starts) / d mech`` with the starts held fixed
    (first order: do not take second derivatives of it)."""
    if obj.method == "pathwise":
        return pathwise(mech, obj)
    exact, starts = reference(mech, obj)
    return straight_through(exact, ensemble(mech, starts, obj))


def forward_mode(obj: Objective) -> bool:
    """Whether an objective with settings ``obj`` is differentiated in forward mode."""
    return obj.method == "ensemble" and obj.window_gradient == "forward"


def value_and_grad(fun, forward: bool):
    """``fun``'s value and gradient with respect to its first argument (a vector),
    by ``jax.jacfwd`` (``forward``: one tangent per entry) or ``jax.value_and_grad``.
    ``fun`` returns a scalar."""
    if not forward:
        return jax.value_and_grad(fun)

    def both(x, *args):
        def with_value(x):
            v = fun(x, *args)
            return v, v

        grad, v = jax.jacfwd(with_value, has_aux=True)(x)
        return v, grad

    return both
