"""The steady state: the motion the mechanism settles into, its period and its stability.

The equations of motion are periodic in time with the crank period T = 2 pi / omega
(the crank turns at constant speed), so the state sampled once per revolution, at
t = n T (the crank back at its initial angle), is a **Poincare section**, and one
revolution is a map ``Phi: y(nT) -> y((n + 1) T)`` of the scaled state
([`state_scales`][jaxcrank.physics.state.state_scales]). [`steady_state`][jaxcrank.numerics.steady.steady_state]

1. **settles**: simulates ``settle_revolutions`` revolutions from pins-centred rest
   (or from ``warm_start``) and keeps the section points;
2. **detects a period**: the smallest k <= ``max_period`` whose section points recur,
   ``max |y_N - y_{N-k}| <= recurrence_tol`` ([`recurrence`][jaxcrank.numerics.shooting.recurrence]);
3. **shoots**: Newton's method on ``Phi^k(y) = y``, with the monodromy matrix
   ``M = dPhi^k/dy`` from forward-mode autodiff through the solve
   (``diffrax.ForwardMode``), until ``max |Phi^k(y) - y| <= newton_tol``;
4. **classifies**: ``periodic`` with ``period_revolutions = k`` when the orbit is
   found and attracting (every Floquet multiplier, an eigenvalue of M, inside the unit
   circle), ``not periodic`` otherwise. Not periodic, it measures the largest
   finite-time Lyapunov exponent from the growth of a tangent vector (renormalised each
   revolution) and the long-run statistics of the metrics (batch means over
   revolutions, 95 % confidence intervals) over ``statistics_revolutions``;
5. **checks the statistics run**: when that run's own section points recur (step 2's
   test), the motion settled late, and the solver shoots from its end (step 3). An
   attracting orbit found there makes the result ``periodic``; "not periodic" thus means
   not periodic within ``settle_revolutions + statistics_revolutions`` revolutions.

**Neutral directions.** The driver and dissipated work (energy flows that never feed
back; zero at every section state) and, with the frozen memory law only, an *idle*
approach-speed memory (a pin in contact all period: its multiplier is exactly 1, and the
solver holds it at the value the settle reached) are left out of the Newton and Floquet
problem. What is left is the **dynamic subspace** (``SteadyState.active``).

**Exact gradient.** [`orbit_start`][jaxcrank.numerics.steady.orbit_start] returns the section state y*(mech) with a
``jax.custom_jvp`` (implicit function theorem at the fixed point):
``dy*/dp = (I - M)^-1 dPhi^k/dp`` on the dynamic subspace, so ``jax.jvp`` / ``jax.jacfwd``
of any function of the steady state are exact (forward mode only).
[`steady_value_and_grad`][jaxcrank.numerics.steady.steady_value_and_grad] wraps it for a functional of one period of
the orbit. The building blocks (maps, Newton, batch means) live in [`jaxcrank.numerics.shooting`][];
the user's guide, with examples, is the docs' steady-state page.
"""

from __future__ import annotations

import math
import sys

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Complex, Float

from ..physics import model
from ..physics.linkage import AbstractMechanism as Mechanism
from ..physics.params import ParameterError
from . import shooting
from .results import RESULTS, Regime
from .shooting import STEADY_OPTIONS, SteadyOptions, period_solve  # noqa: F401 (SteadyOptions: also from here)
from .solve import Simulation, SolveOptions, simulate

NOT_PERIODIC = Regime.NOT_PERIODIC


class SteadyStateError(RuntimeError):
    """[`steady_state`][jaxcrank.numerics.steady.steady_state] could not finish; the message says what to change."""


class SteadyState(eqx.Module):
    """The result of [`steady_state`][jaxcrank.numerics.steady.steady_state]. Scaled states as in
    [`jaxcrank.physics.model.state_scales`][jaxcrank.physics.state.state_scales] (lengths in clearances).

    Attributes:
        mechanism: the mechanism.
        result: [`RESULTS`][jaxcrank.numerics.results.RESULTS] item (``RESULTS.successful`` unless the solver failed).
        regime: [`Regime`][jaxcrank.numerics.results.Regime] ``PERIODIC`` or ``NOT_PERIODIC``.
        period_revolutions: k, the period in crank revolutions (0 when not periodic).
        residual: ``max |Phi^k(y*) - y*|`` over the dynamic subspace, scaled units (the
            recurrence distance of the settle's last section points when not periodic).
        newton_iterations: Newton steps taken.
        section_state: y*, the scaled state at t = 0 (crank at its initial angle) that
            starts the orbit; works zero. Not periodic: the last section point.
        monodromy: M = dPhi^k/dy at y* on the state entries before the works, shape
            (m, m), m = 2 n_dof + the joint laws' state entries (not periodic: the
            one-revolution map's).
        active: which of those m entries form the dynamic subspace (bool, (m,)).
        floquet_multipliers: eigenvalues of M on the dynamic subspace, complex, largest
            modulus first (per period of k revolutions; not periodic: finite-time, per
            revolution, at the last section point).
        neutral: names of the entries left out (idle memories, works).
        section_points: the section points of the settle, scaled, (settle + 1, state).
        orbit: one period of the orbit from y* (ts, ys, and its tracked metrics; not
            periodic: the last revolution of the statistics run).
        metrics: the headline metrics over one period (``orbit.metrics``; units in the
            names). Not periodic: the long-run statistics' point values.
        lyapunov_exponent_per_s: largest Lyapunov exponent, 1/s: periodic,
            ``ln max|mu| / (k T)`` from the multipliers; not periodic, the finite-time
            estimate from tangent growth.
        statistics: not periodic: metric -> ``{"value", "ci95_low", "ci95_high"}`` over
            the statistics revolutions (units in the names; a peak's value is the mean of the
            per-revolution peaks, and its ``max`` the largest of them); ``None`` when periodic.
        revolutions: solve counts in revolutions: ``settle``, ``shooting`` (with
            tangents), ``orbit``, ``statistics`` (with a tangent).
        options: the solve settings used.
        samples_per_revolution: sample times per revolution of the orbit and of its RMS metrics.
        note: why a motion is reported as not periodic though its section points recurred
            (``SteadyOptions.statistics_on_failure``: Newton shooting failed there); empty otherwise.
    """

    mechanism: Mechanism
    result: RESULTS
    regime: Regime = eqx.field(static=True)
    period_revolutions: int = eqx.field(static=True)
    residual: Float[Array, ""]
    newton_iterations: int = eqx.field(static=True)
    section_state: Float[Array, " state"]
    monodromy: Float[Array, "m m"]
    active: Bool[np.ndarray, " m"] = eqx.field(static=True, converter=lambda a: tuple(bool(v) for v in a))
    floquet_multipliers: Complex[Array, " d"]
    neutral: tuple = eqx.field(static=True)
    section_points: Float[Array, "revs state"]
    orbit: Simulation | None
    metrics: dict
    lyapunov_exponent_per_s: Float[Array, ""]
    statistics: dict | None
    revolutions: dict
    options: SolveOptions = eqx.field(static=True)
    samples_per_revolution: int = eqx.field(static=True)
    note: str = eqx.field(static=True, default="")

    @property
    def ok(self) -> bool:
        return bool(self.result == RESULTS.successful)

    @property
    def periodic(self) -> bool:
        return self.ok and self.regime == Regime.PERIODIC

    @property
    def multiplier_moduli(self) -> np.ndarray:
        """|Floquet multipliers|, largest first."""
        return np.abs(np.asarray(self.floquet_multipliers))


def _neutral_names(mech, active):
    n = 2 * model.n_dof(mech)
    names = [name for i, name in enumerate(model.law_state_names(mech)) if not active[n + i]]
    return tuple(names) + ("driver_work", "dissipated_work")


def carry_state(old: Mechanism, y: Float[Array, " state"], new: Mechanism) -> Float[Array, " state"]:
    """The scaled section state (t = 0) of ``old`` carried over to the design ``new`` (the
    same joints with clearance in both): each pin keeps its place and motion in its
    bearing relative to the clearance (eccentricities and their rates scaled by the ratio
    of the clearances, so a pin in contact stays in contact at nearly the same
    penetration); law states (m/s, s) and works (J) kept in SI units.

    Raises:
        ValueError: when the clearance joints' eccentricities do not determine the
            coordinates (see [`jaxcrank.physics.kinematics.state_from_eccentricities`][])."""
    d, dd = model.joint_eccentricities(old, 0.0, y)
    old_model, new_model = model.compile_model(old), model.compile_model(new)
    lk_old, lk_new, tree = old_model.linkage, new_model.linkage, old_model.tree
    ratio = jnp.stack([lk_new.joints[j].clearance / lk_old.joints[j].clearance for j in tree.cut])
    guess = y * model.state_scales(old) / model.state_scales(new)
    return model.state_from_eccentricities(
        new, 0.0, d * ratio[:, None], dd * ratio[:, None], model.auxiliary(old, y), guess=guess
    )


def _warm_state(mech, warm):
    """A scaled section state for ``mech`` from a previous [`SteadyState`][jaxcrank.numerics.steady.SteadyState] (its
    pin-in-bearing state carried over by [`carry_state`][jaxcrank.numerics.steady.carry_state] where the same joints
    have clearance) or a scaled state array."""
    if isinstance(warm, SteadyState):
        old, y = warm.mechanism, warm.section_state
        if model.compile_model(old).structure == model.compile_model(mech).structure:
            try:
                y = carry_state(old, y, mech)
            except ValueError:
                pass
    else:
        y = jnp.asarray(warm, dtype=float)
    if y.shape != (model.state_size(mech),):
        raise ParameterError(f"warm_start has state shape {y.shape}; this mechanism's is ({model.state_size(mech)},)")
    return y.at[-2:].set(0.0)


def steady_state(
    mech: Mechanism,
    options: SteadyOptions = STEADY_OPTIONS,
    *,
    warm_start=None,
    throw: bool = True,
    progress: bool = False,
) -> SteadyState:
    """The steady state of ``mech``: its periodic orbit and stability, or, when it has no
    attracting periodic orbit of period <= ``options.max_period``, its Lyapunov exponent
    and long-run statistics (module docstring).

    Args:
        mech: the mechanism.
        options: the settings ([`SteadyOptions`][jaxcrank.numerics.shooting.SteadyOptions]: settle, period search,
            Newton shooting, statistics, and the solves' ``SolveOptions``), e.g.
            ``SteadyOptions(settle_revolutions=40)`` or ``SteadyOptions().replace(rtol=1e-9)``.
        warm_start: a previous [`SteadyState`][jaxcrank.numerics.steady.SteadyState] (its pin-in-bearing state is
            carried over to ``mech`` physically; a periodic one also gives the period to
            shoot, after one period of settle) or a scaled state at t = 0. When shooting
            from it fails, the solver settles ``settle_revolutions`` from there and starts over.
        throw: raise [`SteadyStateError`][jaxcrank.numerics.steady.SteadyStateError] when the result is not
            ``RESULTS.successful``; with ``False`` inspect ``SteadyState.result``.
        progress: report each phase on standard error (settle with a progress bar,
            shooting, orbit, statistics), for command-line runs.

    Returns:
        a [`SteadyState`][jaxcrank.numerics.steady.SteadyState].

    Raises:
        ParameterError: for options that are not a ``SteadyOptions``, or a driver that is not periodic.
        SteadyStateError: with ``throw=True``, when a solve or the shooting failed.
    """
    if not isinstance(options, SteadyOptions):
        raise ParameterError(f"options = {options!r} must be a SteadyOptions (jaxcrank.SteadyOptions(...))")
    o = options
    shooting.check_periodic_driver(mech)
    counts = {"settle": 0, "shooting": 0, "orbit": 0, "statistics": 0}
    y0 = model.initial_state(mech) if warm_start is None else _warm_state(mech, warm_start)
    warm_k = warm_start.period_revolutions if isinstance(warm_start, SteadyState) and warm_start.periodic else 0
    say = _say if progress else (lambda text: None)
    out = _steady(
        mech, y0, warm_k, o.settle_revolutions, o.max_period, o.recurrence_tol, o.newton_tol, o.max_newton,
        o.statistics_revolutions, o.batch_revolutions, o.samples_per_revolution, o.solve, counts, say,
        o.statistics_on_failure,
    )  # fmt: skip
    if throw and out.result != RESULTS.successful:
        raise SteadyStateError(
            f"steady_state failed after {out.newton_iterations} Newton iterations (residual "
            f"{float(out.residual):.3g} scaled units, newton_tol {o.newton_tol:g}): {RESULTS[out.result]}"
        )
    return out


def _say(text: str) -> None:
    """One line of progress on standard error."""
    print(f"steady: {text}", file=sys.stderr, flush=True)


def _steady(mech, y0, warm_k, settle, max_period, recurrence_tol, newton_tol, max_newton, n_stats, batch, samples,
            options, counts, say, fallback=False):  # fmt: skip
    m = shooting.dynamic_size(mech)
    n_settle = warm_k if warm_k else settle
    say(f"settling {n_settle} revolution(s) from {'the warm start' if warm_k else 'rest'}")
    sim = simulate(mech, ts=shooting.section_times(mech, n_settle), y0=y0, options=options, throw=False,
                   progress=say is _say)  # fmt: skip
    counts["settle"] += n_settle
    section = sim.ys
    empty = dict(
        mechanism=mech, period_revolutions=0, newton_iterations=0, section_points=section, orbit=None, metrics={},
        lyapunov_exponent_per_s=jnp.asarray(0.0), statistics=None, revolutions=counts,
        monodromy=jnp.zeros((m, m)), active=np.ones(m, bool), floquet_multipliers=jnp.zeros(0, complex),
        neutral=(), section_state=section[-1].at[-2:].set(0.0), options=options, samples_per_revolution=samples,
    )  # fmt: skip
    if sim.result != RESULTS.successful or not bool(jnp.all(jnp.isfinite(section))):
        return SteadyState(
            result=shooting.failure(sim.result), regime=NOT_PERIODIC, residual=jnp.asarray(np.inf), **empty
        )
    z_end = section[-1, :m]
    distances = {}
    if warm_k:
        candidates = [warm_k]
    else:
        distances = dict(enumerate(shooting.recurrence(section, m, max_period, recurrence_tol)[1].tolist(), start=1))
        candidates = [k for k, d in distances.items() if d <= recurrence_tol]
    # a slowly settling orbit: shoot the closest recurrence; failing there means not periodic
    near = not candidates and bool(distances) and min(distances.values()) <= 100 * recurrence_tol
    if near:
        candidates = [min(distances, key=distances.get)]
    failure, note, tried = None, "", set()
    for k in candidates:
        found = _shoot(mech, z_end, k, newton_tol, max_newton, samples, options, counts, say, empty)
        tried.add(k)
        if isinstance(found, SteadyState):
            return found
        if found == "unstable":
            break  # an unstable orbit: the motion does not settle onto it
        failure = failure or found
    else:
        if failure is not None and not near:
            if warm_k:  # the warm start was too far: settle from there and start over
                say("shooting from the warm start failed: settling from there")
                return _steady(mech, section[-1], 0, settle, max_period, recurrence_tol, newton_tol, max_newton,
                               n_stats, batch, samples, options, counts, say, fallback)  # fmt: skip
            result, res, its = failure
            if not fallback:
                return SteadyState(
                    result=result, regime=NOT_PERIODIC, residual=res, **dict(empty, newton_iterations=its)
                )
            note = (
                f"Newton shooting for period(s) {sorted(tried)} failed (residual {float(res):.3g} scaled units after "
                f"{its} iteration(s)): {RESULTS[result]}; the value is the long-run statistics"
            )
    recurrence = float(jnp.max(jnp.abs(z_end - section[-2, :m])))
    say(f"no period up to {max_period} revolution(s): Lyapunov exponent and statistics over {n_stats} revolutions")
    jac, result, lyapunov, statistics, sections = shooting.not_periodic(
        mech, z_end, options, n_stats, batch, samples, counts
    )
    if result != RESULTS.successful:
        return SteadyState(result=result, regime=NOT_PERIODIC, residual=jnp.asarray(recurrence), **empty)
    z_last = sections[-1]
    # a late settler: the statistics run's own section points recur, so shoot from its end
    late = shooting.recurrence(sections, m, max_period, recurrence_tol)[1].tolist()
    for k in [k for k, d in enumerate(late, start=1) if d <= recurrence_tol and k not in tried]:
        say(f"the statistics run settled: its section points recur with period {k}")
        found = _shoot(mech, z_last, k, newton_tol, max_newton, samples, options, counts, say, empty)
        if isinstance(found, SteadyState):
            return found
        if found == "unstable":
            break
    active = ~shooting.idle(jac) | (np.arange(m) < 2 * model.n_dof(mech))
    orbit = period_solve(mech, shooting.full(z_last), 1, options=options, samples_per_revolution=samples)
    counts["orbit"] += 1
    fields = dict(empty, monodromy=jac, active=active, orbit=orbit if orbit.ok else None, statistics=statistics)
    fields.update(
        metrics={key: s["value"] for key, s in statistics.items()},
        floquet_multipliers=jnp.asarray(shooting.multipliers(jac, active)),
        neutral=_neutral_names(mech, active),
        lyapunov_exponent_per_s=jnp.asarray(lyapunov),
        note=note,
    )
    return SteadyState(result=RESULTS.successful, regime=NOT_PERIODIC, residual=jnp.asarray(recurrence), **fields)


def _shoot(mech, z, k, newton_tol, max_newton, samples, options, counts, say, empty):
    """Shoot for a period-``k`` orbit from the dynamic entries ``z``: a periodic
    [`SteadyState`][jaxcrank.numerics.steady.SteadyState] (or a failed one where its
    orbit's solve failed), ``"unstable"`` for an orbit with a multiplier on or outside the
    unit circle, or ``(result, residual, iterations)`` where Newton failed."""
    say(f"shooting for a period-{k} orbit (Newton, at most {max_newton} iterations of {k} revolution(s))")
    z, jac, active, res, its, result = shooting.shoot(mech, z, k, None, options, newton_tol, max_newton)
    counts["shooting"] += k * (its + 1)
    if result != RESULTS.successful:
        return (result, res, its)
    mult = shooting.multipliers(jac, active)
    lead = float(np.max(np.abs(mult), initial=0.0))
    if lead >= 1.0:
        return "unstable"
    say(f"periodic (residual {float(res):.2g} after {its} Newton iteration(s)): solving the orbit's metrics")
    orbit = period_solve(mech, shooting.full(z), k, options=options, samples_per_revolution=samples)
    counts["orbit"] += k
    if not orbit.ok:
        return SteadyState(result=shooting.failure(orbit.result), regime=NOT_PERIODIC, residual=res, **empty)
    fields = dict(empty, period_revolutions=k, newton_iterations=its, orbit=orbit, monodromy=jac, active=active)
    fields.update(
        metrics={key: v for key, v in orbit.metrics.items() if key != "window_start_s"},
        floquet_multipliers=jnp.asarray(mult),
        neutral=_neutral_names(mech, active),
        section_state=shooting.full(z),
        lyapunov_exponent_per_s=jnp.asarray(math.log(max(lead, 1e-300)) / (k * float(mech.period))),
    )
    return SteadyState(result=RESULTS.successful, regime=Regime.PERIODIC, residual=res, **fields)


@eqx.filter_custom_jvp
def _fixed_point(mech, z_star, jac, *, k, active, options):
    return jax.lax.stop_gradient(z_star)


@_fixed_point.def_jvp
def _fixed_point_jvp(primals, tangents, *, k, active, options):
    mech, z_star, jac = primals
    z_star, jac = jax.lax.stop_gradient(z_star), jax.lax.stop_gradient(jac)
    if tangents[0] is None:
        return z_star, jnp.zeros_like(z_star)
    _, dphi = eqx.filter_jvp(lambda m_: shooting.one_map(m_, z_star, k, options)[0], (mech,), (tangents[0],))
    dphi = jnp.where(jnp.asarray(active), dphi, 0.0)
    return z_star, jnp.linalg.solve(shooting.newton_matrix(jac, active), dphi)


def orbit_start(mech: Mechanism, steady: SteadyState) -> Float[Array, " state"]:
    """The orbit's section state y*(mech), scaled, works zero, differentiable in ``mech``
    by the implicit function theorem: under ``jax.jvp``/``jax.jacfwd`` its tangent is
    ``(I - M)^-1 dPhi^k/dp . dp`` on the dynamic subspace (idle memories and works held),
    with M = ``steady.monodromy`` at y*. The value is ``steady.section_state``.

    Args:
        mech: the mechanism of ``steady`` (possibly built from traced design variables).
        steady: a periodic [`SteadyState`][jaxcrank.numerics.steady.SteadyState] of that mechanism.

    Raises:
        SteadyStateError: when ``steady`` is not periodic (no orbit to differentiate).

    Forward mode only: reverse mode (``jax.grad``) is not supported."""
    if not steady.periodic:
        raise SteadyStateError(
            f"orbit_start needs a periodic steady state; this one is {steady.regime!r} "
            f"({RESULTS[steady.result] or 'successful'}): its long-run statistics carry no exact gradient"
        )
    m = shooting.dynamic_size(mech)
    z = _fixed_point(
        mech,
        steady.section_state[:m],
        steady.monodromy,
        k=steady.period_revolutions,
        active=steady.active,
        options=steady.options,
    )
    return shooting.full(z)


def steady_value_and_grad(objective, build, params, steady: SteadyState):
    """Value and exact gradient of a functional of one period of the periodic orbit.

    Args:
        objective: ``Simulation -> scalar``; it gets [`period_solve`][jaxcrank.numerics.shooting.period_solve] of one
            period
            from [`orbit_start`][jaxcrank.numerics.steady.orbit_start] (``.ts``, ``.ys``, tracked ``.metrics``, e.g.
            ``lambda sim: sim.metrics["rms_transmission_angle_error_deg"]``).
        build: ``params -> Mechanism``, traceable (e.g. a design problem's ``mechanism``).
        params: the design variables (an array or pytree of arrays).
        steady: the periodic [`SteadyState`][jaxcrank.numerics.steady.SteadyState] of ``build(params)``.

    Returns:
        ``(value, gradient)``, the gradient with the structure of ``params``
        (``jax.jacfwd``: one tangent per variable).

    Raises:
        SteadyStateError: when ``steady`` is not periodic."""

    def f(p):
        mech = build(p)
        sim = period_solve(
            mech,
            orbit_start(mech, steady),
            steady.period_revolutions,
            options=steady.options,
            samples_per_revolution=steady.samples_per_revolution,
        )
        value = objective(sim)
        return value, value

    gradient, value = jax.jacfwd(f, has_aux=True)(params)
    return value, gradient
