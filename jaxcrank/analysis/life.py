"""Life: how a mechanism's worn joints wear over many cycles, by cycle averaging.

The geometry changes little in one crank revolution (a *cycle*), so the wear is computed
at frozen geometry and advanced over many cycles at once:

1. at the current profiles, the steady state ([`steady_state`][jaxcrank.numerics.steady.steady_state]):
   periodic, the wear over one period of the orbit divided by its revolutions; not
   periodic, the wear averaged over ``average_revolutions`` from the last section state
   (labelled ``not periodic``, with the batch means' 95 % interval of the worn volume);
2. the wear per cycle around every worn joint's hole and pin
   ([`jaxcrank.numerics.wear_run`][]), the rate r(P) of the profiles P;
3. a step of Delta N cycles by Heun's method, ``P + Delta N (r(P) + r(P + Delta N r(P))) / 2``,
   whose error estimate ``Delta N |r(P + Delta N r(P)) - r(P)| / 2`` (the deepest
   difference around each surface) is held below ``rtol`` times the joint's deepest wear
   plus ``atol``; Delta N grows or shrinks with the square root of the ratio (order 2);
4. repeat, warm-starting each steady state from the last, until ``cycles``.

[`life`][jaxcrank.analysis.life.life] returns every accepted point ([`Life`][jaxcrank.analysis.life.Life]): cycles,
profiles, wear depths and volumes, the effective clearances and the steady-state metrics;
[`cycles_to_limit`][jaxcrank.analysis.life.cycles_to_limit] reads the life to a metric's limit.
The exact gradients of a life run are in [`jaxcrank.analysis.life_gradient`][].
"""

from __future__ import annotations

import dataclasses
import math
import sys
from collections.abc import Callable

import jax.numpy as jnp
import numpy as np

from ..numerics import wear_run as nw
from ..numerics.results import RESULTS
from ..numerics.shooting import SteadyOptions
from ..numerics.solve import SolveOptions, simulate
from ..numerics.steady import SteadyState, steady_state
from ..physics.linkage import AbstractMechanism as Mechanism
from ..physics.params import ParameterError
from ..physics.wear import profile_on_grid


class LifeError(RuntimeError):
    """A life run could not go on; the message says what to change."""


@dataclasses.dataclass(frozen=True)
class LifeOptions:
    """Settings of [`life`][jaxcrank.analysis.life.life].

    Attributes:
        rtol: the step's error estimate of every profile, relative to its joint's deepest wear (> 0).
        atol: its absolute part, m (None: 1e-6 of the smallest worn joint's clearance).
        first_wear: the first step wears this fraction of the smallest clearance at the
            deepest point (> 0).
        max_growth: the most a step grows over the last one (> 1).
        max_steps: accepted and rejected steps at most.
        average_revolutions: not periodic: revolutions the wear is averaged over (>= 2).
        steady: the steady-state settings (statistics on failure by default, so that a
            motion that is not periodic gives statistics instead of an error; 10 million
            steps per solve, for the start-up in a worn hole).
        warm_settle: settle revolutions of a warm-started steady state (every one: the first
            starts from ``steady.settle_revolutions`` from rest at the tolerances of ``solve``).
        solve: the solve settings of the wear averaged over a motion that is not periodic.
    """

    rtol: float = 0.01
    atol: float | None = None
    first_wear: float = 0.02
    max_growth: float = 4.0
    max_steps: int = 200
    average_revolutions: int = 10
    steady: SteadyOptions = SteadyOptions(statistics_on_failure=True).replace(max_steps=10_000_000)
    warm_settle: int = 4
    solve: SolveOptions = SolveOptions(rtol=1e-8, atol=1e-8, max_steps=10_000_000)

    def __post_init__(self):
        for name, low in (("rtol", 0.0), ("first_wear", 0.0), ("max_growth", 1.0)):
            if not getattr(self, name) > low:
                raise ParameterError(f"{name} = {getattr(self, name)!r} must be > {low:g}")
        if self.atol is not None and not self.atol > 0.0:
            raise ParameterError(f"atol = {self.atol!r} m must be > 0 (or None)")
        for name, low in (("max_steps", 1), ("average_revolutions", 2), ("warm_settle", 1)):
            if not (isinstance(getattr(self, name), int) and getattr(self, name) >= low):
                raise ParameterError(f"{name} = {getattr(self, name)!r} must be an integer >= {low}")

    def replace(self, **changes) -> LifeOptions:
        return dataclasses.replace(self, **changes)


#: the default settings of [`life`][jaxcrank.analysis.life.life]
LIFE_OPTIONS = LifeOptions()


@dataclasses.dataclass(frozen=True)
class WearPoint:
    """The wear at one geometry (SI): per worn joint, the profiles' rates ``(hole, pin)``
    (m per cycle, Fourier coefficients) and the volumes' ``(hole, pin)`` (m^3 per cycle);
    where the motion is not periodic, ``volume_ci95[joint]``: the 95 % confidence interval
    ``(low, high)`` of the hole's volume rate over the averaged revolutions (m^3 per cycle;
    empty for a periodic orbit, whose rate is exact); the steady state's metrics (units in
    the names), its regime and the steady state."""

    rate: dict
    volume_rate: dict
    metrics: dict
    regime: str
    volume_ci95: dict
    steady: SteadyState


def wear_per_cycle(mech: Mechanism, options: LifeOptions = LIFE_OPTIONS, warm_start=None) -> WearPoint:
    """The wear per crank revolution of ``mech``'s worn joints at their current profiles
    (step 1-2 of the module's method).

    Raises:
        LifeError: when the steady state or the wear's solve fails (the message says what to change).
    """
    so = options.steady
    # a cold start settles from rest at the wear's looser tolerance first: a start-up in a worn hole is violent
    if warm_start is None:
        rest = simulate(mech, ts=jnp.array([0.0, so.settle_revolutions * float(mech.period)]), options=options.solve,
                        throw=False)  # fmt: skip
        warm_start = rest.ys[-1].at[-2:].set(0.0) if bool(rest.ok) else None
    if warm_start is not None:
        so = so.replace(settle_revolutions=options.warm_settle)
    steady = steady_state(mech, so, warm_start=warm_start, throw=False)
    if steady.result != RESULTS.successful:
        raise LifeError(
            f"the steady state failed ({RESULTS[steady.result]}): change LifeOptions.steady "
            "(e.g. more settle_revolutions, or a looser solve with a larger newton_tol)"
        )
    T = float(mech.period)
    if steady.periodic:
        k = steady.period_revolutions
        ws = nw.wear_solve(mech, steady.section_state, jnp.array([0.0, k * T]), options=steady.options)
        total, revolutions, per_rev = ws.wear[-1], k, None
    else:
        k = options.average_revolutions
        ts = jnp.arange(k + 1, dtype=float) * T
        ws = nw.wear_solve(mech, steady.section_state, ts, options=options.solve)
        total, revolutions, per_rev = ws.wear[-1] - ws.wear[0], k, np.diff(np.asarray(ws.wear), axis=0)
    if not bool(ws.ok):
        raise LifeError(
            f"the wear's solve failed ({RESULTS[ws.result]}): raise LifeOptions.solve.max_steps or loosen its rtol/atol"
        )
    out, vol, ci = {}, {}, {}
    per_joint = None if per_rev is None else nw.unpack_wear(mech, jnp.asarray(per_rev))
    for j, w in nw.unpack_wear(mech, total / revolutions).items():
        out[j] = (w.hole, w.pin)
        vol[j] = (float(w.hole_volume), float(w.pin_volume))
        if per_joint is not None:
            v = np.asarray(per_joint[j].hole_volume)
            half = 1.96 * float(np.std(v, ddof=1)) / math.sqrt(len(v))
            ci[j] = (float(np.mean(v)) - half, float(np.mean(v)) + half)
    metrics = {k_: float(v) for k_, v in steady.metrics.items()}
    return WearPoint(out, vol, metrics, str(steady.regime), ci, steady)


@dataclasses.dataclass
class Life:
    """A life run ([`life`][jaxcrank.analysis.life.life]): every accepted point.

    Attributes:
        mechanism: the mechanism as it started (its profiles the start's).
        cycles: cycles (crank revolutions) at each point, from 0.
        profiles: per point, ``joint -> (hole, pin)`` profiles (m, Fourier coefficients).
        points: per point, its [`WearPoint`][jaxcrank.analysis.life.WearPoint].
        predictors: per step, the [`WearPoint`][jaxcrank.analysis.life.WearPoint] at its predictor.
        schedule: the accepted steps, cycles (``cycles[i + 1] - cycles[i]``).
        rejected: steps rejected by the error control.
        options: the settings.
    """

    mechanism: Mechanism
    cycles: list
    profiles: list
    points: list
    predictors: list
    schedule: list
    rejected: int
    options: LifeOptions

    def mechanism_at(self, i: int) -> Mechanism:
        """The mechanism with the profiles of point ``i``."""
        return nw.with_profiles(self.mechanism, self.profiles[i])

    def row(self, i: int, grid: int = 720) -> dict:
        """Point ``i`` as a dict: ``cycles``; per worn joint j, ``<j>_hole_max_depth_m``,
        ``<j>_pin_max_depth_m``, ``<j>_hole_volume_m3``, ``<j>_pin_volume_m3``,
        ``<j>_clearance_m`` (the new clearance plus both deepest wears: the most the
        gap opens), ``<j>_hole_wear_m3_per_cycle`` and its 95 % confidence interval over the averaged
        revolutions where the motion is not periodic (``..._ci95_low``, ``..._ci95_high``; a periodic
        orbit's rate is exact: both are the rate); ``regime``; the steady state's metrics."""
        angles = jnp.linspace(0.0, 2.0 * math.pi, grid, endpoint=False)
        point = self.points[i]
        mech = self.mechanism_at(i)
        vols = nw.volumes(mech)
        row = {"cycles": float(self.cycles[i])}
        for j, (hole, pin) in self.profiles[i].items():
            dh = float(jnp.max(profile_on_grid(hole, angles)))
            dp = float(jnp.max(profile_on_grid(pin, angles)))
            row[f"{j}_hole_max_depth_m"] = dh
            row[f"{j}_pin_max_depth_m"] = dp
            row[f"{j}_hole_volume_m3"] = float(vols[j][0])
            row[f"{j}_pin_volume_m3"] = float(vols[j][1])
            row[f"{j}_clearance_m"] = float(mech.joints[j].clearance) + max(dh, 0.0) + max(dp, 0.0)
            row[f"{j}_hole_wear_m3_per_cycle"] = point.volume_rate[j][0]
            low, high = point.volume_ci95.get(j, (point.volume_rate[j][0],) * 2)
            row[f"{j}_hole_wear_m3_per_cycle_ci95_low"], row[f"{j}_hole_wear_m3_per_cycle_ci95_high"] = low, high
        row["regime"] = point.regime
        row.update(point.metrics)
        return row

    def rows(self, grid: int = 720) -> list[dict]:
        """[`row`][jaxcrank.analysis.life.Life.row] of every point."""
        return [self.row(i, grid) for i in range(len(self.cycles))]


def _max_depth(profile, angles):
    return jnp.max(jnp.abs(profile_on_grid(profile, angles)))


def advance(profiles, rate, dn):
    """Euler's step of the profiles: ``P + dn r`` (traceable; Heun's predictor)."""
    return {j: (h + dn * rate[j][0], p + dn * rate[j][1]) for j, (h, p) in profiles.items()}


def heun(profiles, r0, r1, dn):
    """Heun's step of the profiles: ``P + dn (r0 + r1) / 2`` (traceable)."""
    return {
        j: (h + 0.5 * dn * (r0[j][0] + r1[j][0]), p + 0.5 * dn * (r0[j][1] + r1[j][1]))
        for j, (h, p) in profiles.items()
    }


def _error_ratio(profiles, r0, r1, dn, rtol, atol, angles):
    """The step's error estimate over its tolerance, the largest over the surfaces: each
    surface's deepest ``dn |r1 - r0| / 2`` against ``atol + rtol x`` its joint's deepest wear."""
    ratio = 0.0
    for j, pair in profiles.items():
        size = max(float(_max_depth(surface, angles)) for surface in pair)
        for s in range(2):
            err = 0.5 * dn * float(_max_depth(r1[j][s] - r0[j][s], angles))
            ratio = max(ratio, err / (atol + rtol * size))
    return ratio


def life(
    mech: Mechanism,
    cycles: float,
    options: LifeOptions = LIFE_OPTIONS,
    *,
    schedule=None,
    progress: bool = False,
    on_point: Callable[[Life], None] | None = None,
    resume: Life | None = None,
    warm_start=None,
) -> Life:
    """The life of ``mech``'s worn joints over ``cycles`` crank revolutions by cycle
    averaging (the module's method).

    Args:
        mech: a mechanism with at least one [`Worn`][jaxcrank.physics.wear.Worn] joint (its profiles the start's).
        cycles: crank revolutions to run (> 0).
        options: the settings ([`LifeOptions`][jaxcrank.analysis.life.LifeOptions]).
        schedule: fixed steps in cycles to take instead of the error control (e.g. a
            run's ``schedule``, to compare runs at the same steps); they end the run.
        progress: print a line per accepted step on standard error.
        on_point: called with the run so far after every accepted point (checkpoints).
        resume: an unfinished run of the same mechanism and options to carry on.
        warm_start: a steady state (or scaled state) to start the first steady state from.

    Returns:
        a [`Life`][jaxcrank.analysis.life.Life].

    Raises:
        ParameterError: no worn joint, or ``cycles`` not positive.
        LifeError: a steady state or wear solve that fails, or a step that shrinks below one cycle.
    """
    joints = nw.worn_joints(mech)
    if not joints:
        raise ParameterError('life needs a worn joint: give a clearance joint law = "worn" (jaxcrank.Worn)')
    if not cycles > 0:
        raise ParameterError(f"cycles = {cycles!r} must be > 0")
    angles = jnp.linspace(0.0, 2.0 * math.pi, 720, endpoint=False)
    c_min = min(float(mech.joints[j].clearance) for j in joints)
    atol = options.atol if options.atol is not None else 1e-6 * c_min
    if resume is not None:
        run = resume
    else:
        first = wear_per_cycle(mech, options, warm_start=warm_start)
        run = Life(mech, [0.0], [nw.profiles_of(mech)], [first], [], [], 0, options)
        if on_point is not None:
            on_point(run)
    steps = list(schedule) if schedule is not None else None
    deepest = max(float(_max_depth(r, angles)) for pair in run.points[0].rate.values() for r in pair)
    dn = run.schedule[-1] if run.schedule else options.first_wear * c_min / max(deepest, 1e-300)
    attempts = 0
    while (run.cycles[-1] < cycles * (1 - 1e-12)) if steps is None else (len(run.schedule) < len(steps)):
        if attempts >= options.max_steps:
            raise LifeError(
                f"life took {attempts} steps without reaching {cycles:g} cycles: raise LifeOptions.max_steps"
            )
        attempts += 1
        n, prof, point = run.cycles[-1], run.profiles[-1], run.points[-1]
        if steps is not None:
            dn = float(steps[len(run.schedule)])
        else:
            dn = min(dn, cycles - n)
        if dn < 1.0:
            raise LifeError(
                f"the step in cycles fell below one cycle at {n:g} cycles: the wear changes the motion within a "
                "cycle; lower the wear coefficients or loosen LifeOptions.rtol"
            )
        mid = nw.with_profiles(mech, advance(prof, point.rate, dn))
        pred = wear_per_cycle(mid, options, warm_start=point.steady)
        new = heun(prof, point.rate, pred.rate, dn)
        ratio = _error_ratio(new, point.rate, pred.rate, dn, options.rtol, atol, angles)
        if steps is None and ratio > 1.0:
            run.rejected += 1
            dn *= max(0.2, 0.9 / math.sqrt(ratio))
            continue
        after = wear_per_cycle(nw.with_profiles(mech, new), options, warm_start=pred.steady)
        run.cycles.append(n + dn)
        run.profiles.append(new)
        run.points.append(after)
        run.predictors.append(pred)
        run.schedule.append(dn)
        if progress:
            print(
                f"life: {n + dn:.4g} cycles ({after.regime}), step {dn:.3g}, error ratio {ratio:.2g}", file=sys.stderr
            )
        if on_point is not None:
            on_point(run)
        dn *= min(options.max_growth, 0.9 / math.sqrt(max(ratio, 1e-12)))
    return run


def crossing_index(values, limit: float) -> int | None:
    """The first point whose value reaches ``limit`` (concrete values), or None."""
    idx = np.flatnonzero(np.asarray(values, dtype=float) >= limit)
    return int(idx[0]) if idx.size else None


def cycles_to_limit(cycles, values, limit: float, index: int | None = None):
    """The cycles at which ``values`` (a metric at each point of a run, in order) first
    reaches ``limit``, interpolated linearly between that point and the one before;
    ``inf`` when it never does. Traceable in ``values`` when ``index`` (the first point
    at or above the limit, [`crossing_index`][jaxcrank.analysis.life.crossing_index] of the concrete
    values) is given."""
    c = jnp.asarray(cycles, dtype=float)
    v = jnp.asarray(values)
    i = crossing_index(v, limit) if index is None else index
    if i is None:
        return jnp.asarray(np.inf)
    if i == 0:
        return c[0] + 0.0 * v[0]
    frac = (limit - v[i - 1]) / (v[i] - v[i - 1])
    return c[i - 1] + frac * (c[i] - c[i - 1])


__all__ = [
    "LIFE_OPTIONS",
    "Life",
    "LifeError",
    "LifeOptions",
    "WearPoint",
    "crossing_index",
    "cycles_to_limit",
    "heun",
    "life",
    "wear_per_cycle",
]
