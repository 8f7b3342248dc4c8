"""Gradients of a life run: of a metric after N cycles, and of the cycles to a
metric's limit, with respect to any design parameters.

A life run ([`life`][jaxcrank.analysis.life.life]) is a chain of maps: at each point, the steady
orbit's start y*(p, P) (implicit function theorem at the fixed point,
[`orbit_start`][jaxcrank.numerics.steady.orbit_start]), the wear per cycle r(p, P) over that orbit
([`wear_solve`][jaxcrank.numerics.wear_run.wear_solve]) and its metrics; between points, Heun's step
``P' = P + dN (r(P) + r(P + dN r(P))) / 2`` (the slow map over cycles). Forward-mode
derivatives through the whole chain, at the run's accepted steps ``dN`` (held fixed), are
meant to give the derivative of what the run computed: the tangent of every profile and
metric is carried from point to point (the slow map's tangent linear model, one tangent
per design variable, ``jax.jacfwd``). Each point's steady state is the run's own, so a
gradient costs one orbit map and one wear period with tangents per point and predictor.

Every point of the run must be periodic (a motion that is not periodic has long-run
statistics, which carry no exact gradient). The docs' "Wear and life" page compares the
gradients with central differences of whole life runs.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from ..numerics import wear_run as nw
from ..numerics.shooting import period_solve
from ..numerics.steady import SteadyStateError, orbit_start
from .life import Life, advance, heun


class LifeTrace(NamedTuple):
    """A life run recomputed as functions of the design (traceable): per point, the
    steady orbit's tracked metrics (``metrics[name]``, an array over points, units in
    the names), the worn volumes (``volumes[joint]``, (points, 2) hole and pin, m^3) and
    the profiles (``profiles[i][joint] = (hole, pin)``, m)."""

    cycles: jax.Array
    metrics: dict
    volumes: dict
    profiles: list


def _at(mech, steady):
    """The wear per cycle and the orbit's metrics at a periodic steady state, differentiable."""
    if not steady.periodic:
        raise SteadyStateError(
            f"a life gradient needs every point periodic; a point is {steady.regime!r}: its long-run statistics "
            "carry no exact gradient"
        )
    y0 = orbit_start(mech, steady)
    k = steady.period_revolutions
    ws = nw.wear_solve(mech, y0, jnp.stack([0.0 * mech.period, k * mech.period]), options=steady.options)
    rate = {j: (w.hole / k, w.pin / k) for j, w in nw.unpack_wear(mech, ws.wear[-1]).items()}
    sim = period_solve(mech, y0, k, options=steady.options, samples_per_revolution=steady.samples_per_revolution)
    return rate, sim.metrics


def replay(build, params, run: Life) -> LifeTrace:
    """The run recomputed at ``build(params)`` through its points' steady states and its
    steps (traceable in ``params`` under ``jax.jvp``/``jax.jacfwd``).

    Args:
        build: ``params -> Mechanism`` with the run's worn joints (new profiles as the
            run's start), traceable.
        params: the design variables (the run is of ``build(params)`` at their values).
        run: a [`Life`][jaxcrank.analysis.life.Life] of that mechanism whose points are all periodic.

    Raises:
        SteadyStateError: a point or predictor that is not periodic."""
    base = build(params)
    prof = {j: (jnp.asarray(h), jnp.asarray(p)) for j, (h, p) in run.profiles[0].items()}
    rate, metrics = _at(nw.with_profiles(base, prof), run.points[0].steady)
    metric_rows, profiles = [metrics], [prof]
    for i, dn in enumerate(run.schedule):
        mid = advance(prof, rate, dn)
        r1, _ = _at(nw.with_profiles(base, mid), run.predictors[i].steady)
        prof = heun(prof, rate, r1, dn)
        rate, metrics = _at(nw.with_profiles(base, prof), run.points[i + 1].steady)
        metric_rows.append(metrics)
        profiles.append(prof)
    names = metric_rows[0].keys()
    stacked = {n: jnp.stack([jnp.asarray(m[n]) for m in metric_rows]) for n in names}
    volumes = {}
    for j in prof:
        rows = [nw.volumes(nw.with_profiles(base, p_))[j] for p_ in profiles]
        volumes[j] = jnp.stack([jnp.stack(r) for r in rows])
    return LifeTrace(jnp.asarray(run.cycles, dtype=float), stacked, volumes, profiles)


def life_value_and_grad(value, build, params, run: Life):
    """Value and exact gradient of a function of a life run.

    Args:
        value: ``LifeTrace -> scalar``, e.g. ``lambda tr: tr.metrics["rms_rocker_angle_deviation_deg"][-1]``
            (the metric after the run's cycles) or, with
            [`cycles_to_limit`][jaxcrank.analysis.life.cycles_to_limit] and the crossing's index from the run,
            the cycles to a limit.
        build: ``params -> Mechanism``, traceable.
        params: the design variables (an array or pytree of arrays).
        run: the [`Life`][jaxcrank.analysis.life.Life] of ``build(params)``, every point periodic.

    Returns:
        ``(value, gradient)``, the gradient with the structure of ``params`` (``jax.jacfwd``).

    Raises:
        SteadyStateError: a point of the run that is not periodic."""

    def f(p):
        out = value(replay(build, p, run))
        return out, out

    gradient, out = jax.jacfwd(f, has_aux=True)(params)
    return out, gradient


__all__ = ["LifeTrace", "life_value_and_grad", "replay"]
