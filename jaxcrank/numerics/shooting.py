"""Shooting on the Poincare map: the one-revolution map and its Jacobian by forward
mode, Newton's method on the dynamic subspace, the tangent-growth revolution and the
batch means of long-run statistics. The building blocks of
[`jaxcrank.numerics.steady.steady_state`][] (see its module for the method).

States here are the scaled states of [`jaxcrank.physics.model.state_scales`][jaxcrank.physics.state.state_scales];
``z`` is a state without its two work entries (they never feed back), the works
restart at zero every map.
"""

from __future__ import annotations

import dataclasses
import math

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..physics import model, signals
from ..physics.linkage import AbstractMechanism as Mechanism
from ..physics.params import ParameterError
from .results import RESULTS
from .solve import Simulation, SolveOptions, lax_solver, simulate

#: the solve settings of :func:`steady_state`: tight tolerances keep the noise of the
#: adaptive steps in the one-revolution map (about 100 x rtol in scaled units) far below
#: ``newton_tol``
STEADY_DEFAULTS = SolveOptions(rtol=1e-10, atol=1e-10, max_steps=2_000_000)


def section_times(mech, revolutions):
    return jnp.arange(revolutions + 1, dtype=float) * mech.period


def dynamic_size(mech):
    """Entries of the state that feed back (all but the two works)."""
    return model.state_size(mech) - 2


def check_periodic_driver(mech) -> None:
    """Raise a [`ParameterError`][jaxcrank.physics.params.ParameterError] unless the driver prescribes a motion
    periodic in time with ``mech.period`` (a steady state needs a Poincare section)."""
    driver = mech.linkage().driver
    if not driver.prescribed:
        raise ParameterError(
            f"the steady state needs a driver that prescribes a periodic motion (constant speed or a speed "
            f"profile); this mechanism's {driver.name!r} driver does not"
        )


def check_arguments(
    settle_revolutions,
    max_period,
    recurrence_tol,
    newton_tol,
    max_newton,
    statistics_revolutions,
    batch_revolutions,
    samples_per_revolution,
):
    """Raise [`ParameterError`][jaxcrank.physics.params.ParameterError] naming the first argument of
    [`jaxcrank.numerics.steady.steady_state`][] out of its range."""
    for name, value, low in (
        ("settle_revolutions", settle_revolutions, 1),
        ("max_period", max_period, 1),
        ("max_newton", max_newton, 0),
        ("batch_revolutions", batch_revolutions, 1),
        ("samples_per_revolution", samples_per_revolution, 2),
    ):
        if not (isinstance(value, (int, np.integer)) and value >= low):
            raise ParameterError(f"{name} = {value!r} must be an integer >= {low}")
    if not (isinstance(statistics_revolutions, (int, np.integer)) and statistics_revolutions >= 2 * batch_revolutions):
        raise ParameterError(
            f"statistics_revolutions = {statistics_revolutions!r} must be an integer >= 2 * batch_revolutions "
            f"= {2 * batch_revolutions} (two batches at least)"
        )
    for name, value in (("recurrence_tol", recurrence_tol), ("newton_tol", newton_tol)):
        if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
            raise ParameterError(f"{name} = {value!r} must be a finite number > 0 (scaled units: clearances)")


@dataclasses.dataclass(frozen=True)
class SteadyOptions:
    """The settings of [`jaxcrank.numerics.steady.steady_state`][]: the one place their defaults live.

    Attributes:
        settle_revolutions: revolutions simulated from rest before shooting (>= 1).
        max_period: the longest period looked for, revolutions (>= 1).
        recurrence_tol: section points of the settle closer than this (max over the
            dynamic entries, scaled units: clearances and clearance x crank speed) mark
            a candidate period for shooting. When none does, the period with the closest
            recurrence is shot if it is within 100 x ``recurrence_tol`` (an orbit still
            settling), and a failure there means not periodic.
        newton_tol: Newton shooting stops at ``max |Phi^k(y) - y| <= newton_tol``,
            scaled units. Keep it above the map's noise, about 100 x ``solve.rtol``.
        max_newton: Newton iterations at most (0: only check the settle's end).
        statistics_revolutions: not periodic: revolutions of the Lyapunov and statistics
            run (>= 2 batches).
        batch_revolutions: revolutions per batch of the batch means (>= 1).
        samples_per_revolution: sample times per revolution of the orbit and of the RMS
            metrics (default 3600: 0.1 deg of crank angle; >= 2).
        solve: the settings of every solve (`STEADY_DEFAULTS`: tsit5, rtol = atol = 1e-10).
        statistics_on_failure: where Newton shooting fails for every candidate period (it
            does not converge or diverges, e.g. at the map's noise floor, or on an orbit
            that grazes a contact), report the long-run statistics as not periodic, with
            the reason in ``SteadyState.note`` (True), or a failed result naming what to
            change (False, the default).

    Raises:
        ParameterError: for a setting outside its range (the message names it).
    """

    settle_revolutions: int = 20
    max_period: int = 4
    recurrence_tol: float = 1e-3
    newton_tol: float = 1e-7
    max_newton: int = 8
    statistics_revolutions: int = 10
    batch_revolutions: int = 2
    samples_per_revolution: int = 3600
    solve: SolveOptions = STEADY_DEFAULTS
    statistics_on_failure: bool = False

    def __post_init__(self):
        check_arguments(
            self.settle_revolutions, self.max_period, self.recurrence_tol, self.newton_tol, self.max_newton,
            self.statistics_revolutions, self.batch_revolutions, self.samples_per_revolution,
        )  # fmt: skip
        if not isinstance(self.solve, SolveOptions):
            raise ParameterError(f"solve = {self.solve!r} must be a SolveOptions")

    def replace(self, **changes) -> SteadyOptions:
        """A copy with the given fields changed (``None`` values are ignored); ``solver``,
        ``rtol``, ``atol``, ``dt0`` and ``max_steps`` change ``solve``'s."""
        keys = ("solver", "rtol", "atol", "dt0", "max_steps")
        solve = self.solve.replace(**{k: changes.pop(k) for k in keys if k in changes})
        return dataclasses.replace(self, solve=solve, **{k: v for k, v in changes.items() if v is not None})


#: the default settings of [`jaxcrank.numerics.steady.steady_state`][]
STEADY_OPTIONS = SteadyOptions()


def full(z):
    return jnp.concatenate([z, jnp.zeros(2, dtype=z.dtype)])


@eqx.filter_jit
def one_map(mech, z, k, options):
    """Phi^k on the dynamic entries z (works start at zero): (z_end, result code, steps)."""
    sim = simulate(
        mech,
        ts=jnp.stack([0.0, k * mech.period]),
        y0=full(z),
        options=options,
        throw=False,
        adjoint=diffrax.ForwardMode(),
    )
    return sim.ys[-1, : z.shape[0]], sim.result, sim.num_steps


@eqx.filter_jit
def map_and_jacobian(mech, z, k, options):
    """(Phi^k(z), dPhi^k/dz, result) by forward mode."""

    def f(z_):
        out, result, _ = one_map(mech, z_, k, options)
        return out, (out, result)

    jac, (out, result) = jax.jacfwd(f, has_aux=True)(z)
    return out, jac, result


def period_solve(
    mech: Mechanism,
    y0: Float[Array, " state"],
    k: int = 1,
    *,
    options: SolveOptions = STEADY_DEFAULTS,
    samples_per_revolution: int = 3600,
    adjoint=None,
) -> Simulation:
    """k revolutions from the scaled state ``y0`` at t = 0 with the headline metrics
    tracked over t in (0, k T] ([`jaxcrank.numerics.tracking`][]) and the state stored
    at ``samples_per_revolution`` equal crank-angle steps per revolution (default 0.1
    deg, as ``jaxcrank simulate``). ``throw=False``: inspect ``.ok``. Forward mode
    (``adjoint`` defaults to ``diffrax.ForwardMode()``)."""
    ts = jnp.linspace(0.0, k * mech.period, k * samples_per_revolution + 1)
    adjoint = diffrax.ForwardMode() if adjoint is None else adjoint
    return simulate(
        mech,
        ts=ts,
        y0=y0,
        options=options.replace(solver=lax_solver(options)),
        metrics_start=0.0,
        throw=False,
        adjoint=adjoint,
    )


@eqx.filter_jit
def revolution_with_tangent(mech, z, v, options, samples):
    """One revolution from z (works zero) and the tangent pushed along: (z_end, v_end,
    metrics over the revolution, result)."""

    def f(z_):
        sim = period_solve(mech, full(z_), 1, options=options, samples_per_revolution=samples)
        return sim.ys[-1, : z_.shape[0]], (sim.metrics, sim.result)

    out, tangent, (metrics_, result) = jax.jvp(f, (z,), (v,), has_aux=True)
    return out, tangent, metrics_, result


def recurrence(section, m: int, max_period: int, tol: float) -> tuple[np.ndarray, np.ndarray]:
    """The period test on Poincare-section points: the smallest k <= ``max_period`` with
    ``max |y_N - y_{N-k}| <= tol`` over the first ``m`` (dynamic) entries, y_N the last point.

    Args:
        section: scaled section points, shape (..., N + 1, state) (leading axes: designs).
        m: the dynamic entries compared (the state before the works, ``dynamic_size``).
        max_period: the longest period looked for, revolutions (k <= min(max_period, N)).
        tol: recurrence tolerance, scaled units (clearances).

    Returns:
        ``(period, distances)``: the smallest such k (0: none; NaN distances never
        recur), shape (...); and ``max |y_N - y_{N-k}|`` for k = 1 .. min(max_period, N),
        shape (..., K), scaled units.
    """
    pts = np.asarray(section, dtype=float)[..., :m]
    ks = range(1, min(int(max_period), pts.shape[-2] - 1) + 1)
    last = pts[..., -1, :]
    gaps = [np.max(np.abs(last - pts[..., -1 - k, :]), axis=-1) for k in ks]
    distances = np.stack(gaps, axis=-1) if gaps else np.zeros(last.shape[:-1] + (0,))
    hit = distances <= tol
    period = np.where(hit.any(axis=-1), np.argmax(hit, axis=-1) + 1, 0)
    return period, distances


def failure(result):
    if result == RESULTS.max_steps_reached:
        return RESULTS.settle_max_steps
    return RESULTS.solve_failed


def idle(jac, tol=1e-9):
    """Memory entries whose row of M is a unit row (frozen over the map)."""
    m = jac.shape[0]
    eye = np.eye(m)
    return np.max(np.abs(np.asarray(jac) - eye), axis=1) <= tol


def newton_matrix(jac, active):
    """I - M on the active entries, the identity on the others."""
    act = jnp.asarray(active)
    a = jnp.eye(jac.shape[0]) - jac
    both = act[:, None] & act[None, :]
    return jnp.where(both, a, jnp.eye(jac.shape[0]))


def multipliers(jac, active):
    idx = np.flatnonzero(active)
    ev = np.linalg.eigvals(np.asarray(jac)[np.ix_(idx, idx)])
    return ev[np.argsort(-np.abs(ev), kind="stable")]


def shoot(mech, z, k, active, options, newton_tol, max_newton):
    """Newton on Phi^k(z) = z, from z. ``active``: the dynamic subspace (None: the
    entries whose row of M at the first iterate is not a unit row, plus s and s').
    Returns (z, M at z, active, residual, iterations, RESULTS item)."""
    best = None
    for it in range(max_newton + 1):
        out, jac, result = map_and_jacobian(mech, z, k, options)
        if result != RESULTS.successful:
            return z, jac, active, jnp.asarray(np.inf), it, failure(result)
        if active is None:
            active = ~idle(jac) | (np.arange(z.shape[0]) < 2 * model.n_dof(mech))
        r = jnp.where(jnp.asarray(active), out - z, 0.0)
        res = float(jnp.max(jnp.abs(r)))
        if not math.isfinite(res) or (best is not None and res > 1e3 * best) or res > 1e3:
            res = res if math.isfinite(res) else float(np.finfo(float).max)
            return z, jac, active, jnp.asarray(res), it, RESULTS.newton_diverged
        best = res if best is None else min(best, res)
        if res <= newton_tol:
            return z, jac, active, jnp.asarray(res), it, RESULTS.successful
        if it == max_newton:
            return z, jac, active, jnp.asarray(res), it, RESULTS.newton_not_converged
        z = z + jnp.linalg.solve(newton_matrix(jac, active), r)
    raise AssertionError("unreachable")


def batch_means(values: np.ndarray, batch: int, rms: bool) -> dict:
    """Long-run value of a per-revolution metric with a 95 % confidence interval from
    batch means (Student t over ``len(values) // batch`` batches of ``batch``
    consecutive revolutions, the first revolutions dropped to fill whole batches).

    ``rms``: the values are per-revolution RMS values, combined as mean squares (the
    long-run RMS is ``sqrt(mean of squares)``; the interval is the square root of the
    mean square's). Otherwise the mean of the values (e.g. per-revolution peaks), and ``max``,
    the largest of them all (the peak over the run). Returns ``{"value", "ci95_low",
    "ci95_high"}`` (and ``max``) in the metric's unit. Needs at least two batches."""
    from scipy import stats

    values = np.asarray(values, dtype=float)
    n_batches = values.size // batch
    if n_batches < 2:
        raise ParameterError(f"batch means need at least 2 batches of {batch} revolutions, got {values.size}")
    x = values[values.size - n_batches * batch :] ** (2 if rms else 1)
    means = x.reshape(n_batches, batch).mean(axis=1)
    mean = float(means.mean())
    half = float(stats.t.ppf(0.975, n_batches - 1) * means.std(ddof=1) / math.sqrt(n_batches))
    if rms:
        return {
            "value": math.sqrt(mean),
            "ci95_low": math.sqrt(max(mean - half, 0.0)),
            "ci95_high": math.sqrt(mean + half),
        }
    return {"value": mean, "ci95_low": mean - half, "ci95_high": mean + half, "max": float(values.max())}


def not_periodic(mech, z, options, statistics_revolutions, batch_revolutions, samples, counts):
    """Finite-time multipliers at z, Lyapunov exponent and long-run statistics.
    Returns (jac, result, lyapunov 1/s, statistics, sections): ``sections`` the dynamic
    entries (scaled) at z and after each revolution, shape (statistics_revolutions + 1, m)."""
    _, jac, result = map_and_jacobian(mech, z, 1, options)
    counts["shooting"] += 1
    if result != RESULTS.successful:
        return jac, failure(result), None, None, None
    v = jnp.ones_like(z) / math.sqrt(z.shape[0])
    logs, per_rev, sections = [], [], [z]
    for _ in range(statistics_revolutions):
        z, v, metrics_, result = revolution_with_tangent(mech, z, v, options, samples)
        counts["statistics"] += 1
        norm = float(jnp.linalg.norm(v))
        if result != RESULTS.successful or not (math.isfinite(norm) and norm > 0):
            return jac, failure(result), None, None, None
        logs.append(math.log(norm))
        v = v / norm
        sections.append(z)
        per_rev.append({k: float(val) for k, val in metrics_.items() if k != "window_start_s"})
    lyapunov = float(np.mean(logs)) / float(mech.period)
    rms = set(signals.rms_metrics(mech))
    statistics = {key: batch_means([r[key] for r in per_rev], batch_revolutions, key in rms) for key in per_rev[0]}
    return jac, RESULTS.successful, lyapunov, statistics, jnp.stack(sections)
