"""Local sensitivities of the mean-square metrics by AD, in one call.

``sensitivities(mech)`` gives, at one design, the value of each of the mechanism's RMS
metrics ([`metric_names`][optim.sensitivity.metric_names]) and its gradient with respect to every parameter in
``names`` (any name [`jaxcrank.physics.parameters.set_parameter`][] accepts; default
[`default_parameters`][optim.sensitivity.default_parameters]), plus the normalised
elasticities ``(dm/dp) (p / m)`` (percent change of the metric per percent change
of the parameter), which [`optim.plots.plot_tornado`][] draws as a tornado chart.

The same care as the optimisation ([`optim.ensemble.Ensemble`][]): over the paper's
window the pathwise derivative of a chaotic trajectory is ~1e27 and meaningless;
the gradient here is the ensemble-sensitivity estimate. One solve at the design
gives the exact metric values and the pins' states in their bearings at the start
of K short windows; each window is re-solved from that state (carried over to the
perturbed design) with an implicit solver, the per-window sums of squares are
differentiated (forward mode by default, one tangent per parameter;
``Ensemble(window_adjoint=diffrax.RecursiveCheckpointAdjoint())`` for reverse-mode Jacobians), and the
ensemble mean is taken.

Valid for: time averages of squares, i.e. the RMS metrics (transmission-angle
error, the output deviations, driving-moment deviation, the joints' contact forces).
Not valid for: peaks (largest contact force, largest deviation,
largest acceleration): an extreme value over chaotic impacts has no trend-following
local derivative (use a sweep over a band, [`jaxcrank.runs.sweep`][], for those).
"""

from __future__ import annotations

from collections.abc import Sequence

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from jaxcrank.numerics.solve import Simulation
from jaxcrank.physics import model
from jaxcrank.physics.linkage import AbstractMechanism as Mechanism
from jaxcrank.physics.parameters import get_parameter, parameter_unit, set_parameters
from jaxcrank.physics.params import ParameterError
from jaxcrank.physics.signals import rms_metrics

from . import ensemble as W
from .ensemble import Ensemble
from .objective import EQ19

#: the joint-law parameters among the default parameters, each tied over the joints that have it
TIED_PARAMETERS = ("contact.restitution", "friction.coefficient", "hole_material.youngs_modulus")


def metric_names(mech: Mechanism) -> tuple[str, ...]:
    """The metrics whose gradient the ensemble estimate follows: the mechanism's RMS metrics
    ([`jaxcrank.physics.signals.rms_metrics`][], units in the suffix); the rows of the results below."""
    return rms_metrics(mech)


def default_parameters(mech: Mechanism) -> tuple[str, ...]:
    """The physical design and operating parameters of ``mech`` (not the smoothing widths):
    the description's own numbers (lengths, masses, inertias; not gravity), ``driver.speed``,
    ``clearance_<joint>`` of every clearance joint and the tied joint-law parameters of
    `TIED_PARAMETERS` that some joint has."""
    import dataclasses

    def number(v):
        return not isinstance(v, bool) and isinstance(v, float | int | np.floating | jax.Array) and np.ndim(v) == 0

    own = [f.name for f in dataclasses.fields(mech) if f.name != "gravity" and number(getattr(mech, f.name))]
    tree = model.compile_model(mech).tree
    names = [*own, "driver.speed", *(f"clearance_{j}" for j in tree.cut)]
    for name in TIED_PARAMETERS:
        try:
            get_parameter(mech, name)
        except ParameterError:
            continue
        names.append(name)
    return tuple(names)


def metric_values(sim: Simulation) -> Float[Array, " metrics"]:
    """The metrics of [`metric_names`][optim.sensitivity.metric_names] that a solve tracked
    (``simulate(..., metrics_start=...)``, [`jaxcrank.numerics.tracking`][]), stacked in that order, in their units."""
    return jnp.stack([sim.metrics[k] for k in metric_names(sim.mechanism)])


def window_sums(
    base: Mechanism, names, x: Float[ArrayLike, " params"], starts: W.Starts, i: Int[ArrayLike, ""], obj: Ensemble
) -> tuple[Float[Array, " metrics"], Bool[Array, ""]]:
    """Window ``i`` re-solved for ``base`` with ``names`` set to ``x`` (SI) from the
    carried-over start state ([`optim.ensemble.Ensemble.window_sums`][]): the sums of
    squares of the metrics' signals over its samples, stacked in the order of
    [`metric_names`][optim.sensitivity.metric_names] (units squared), and whether it finished."""
    sums, ok = obj.window_sums(set_parameters(base, names, x), starts, i, obj.grid(base))
    return jnp.stack([sums[k] for k in metric_names(base)]), ok


def sensitivities(mech: Mechanism, names: Sequence[str] | None = None, obj: Ensemble = Ensemble()) -> dict:
    """Values, gradients and elasticities of the metrics of
    [`metric_names`][optim.sensitivity.metric_names] at ``mech`` over the objective's window (``obj``: window,
    ensemble windows, solver, tolerances), with respect to ``names`` (default
    [`default_parameters`][optim.sensitivity.default_parameters]).

    Returns a dict: ``names``, ``units`` (of each parameter), ``x`` (SI values),
    ``metrics`` (names, M of them), ``value`` (M,) exact metric values, ``gradient`` (M, P)
    in metric unit per parameter unit (0 for a metric that is 0 over every window),
    ``elasticity`` (M, P) dimensionless (0 for a metric whose value is 0),
    ``windows`` and ``windows_ok`` (ensemble size and how many finished)."""
    names = list(default_parameters(mech) if names is None else names)
    units = [parameter_unit(mech, n) for n in names]
    grid = obj.grid(mech)  # concrete sample grid of the design (crank speed may be a variable below)
    n_window, dt = grid.n_window, grid.dt
    # the metrics over the samples in (t_start, t_end] tracked during the solve, which
    # stores only the windows' starts
    sim = W.tracked_solve(mech, grid, obj.windows, obj.options, True)
    value = metric_values(sim)
    starts = W.window_starts(sim)
    x0 = jnp.array([get_parameter(mech, n) for n in names])

    # forward mode: one tangent per parameter; reverse mode: one cotangent per metric
    jacobian = jax.jacfwd if obj.forward_mode() else jax.jacrev

    def jac(i):
        def with_aux(x):
            sums, ok = window_sums(mech, names, x, starts, i, obj)
            return sums, (sums, ok)

        rows, (sums, ok) = jacobian(with_aux, has_aux=True)(x0)
        return sums, rows, ok

    sums, rows, ok = jax.jit(jax.vmap(jac))(jnp.arange(starts.t.shape[0]))
    sums, rows, ok = np.asarray(sums), np.asarray(rows), np.asarray(ok)
    n_ok = int(ok.sum())
    if n_ok < 0.5 * len(ok):
        raise RuntimeError(
            f"{len(ok) - n_ok} of {len(ok)} ensemble windows failed; raise "
            "Ensemble.window_options.max_steps, loosen rtol/atol or shorten Ensemble.window"
        )
    w = ok.astype(float)
    estimate = np.sqrt(np.einsum("k,kc->c", w, sums) / (n_window * n_ok))
    grad_sq = np.einsum("k,kcp->cp", w, rows) / (n_window * n_ok)
    # d sqrt(ms) = d ms / (2 sqrt(ms)); a metric that is zero over every window (no
    # contact in them) has a zero mean square and zero gradient: 0, not 0/0
    positive = estimate[:, None] > 0.0
    gradient = np.where(positive, grad_sq / np.where(positive, 2.0 * estimate[:, None], 1.0), 0.0)
    value = np.asarray(value)
    x = np.asarray(x0)
    nonzero = value[:, None] != 0.0
    return {
        "names": names,
        "units": units,
        "x": x,
        "metrics": list(metric_names(mech)),
        "value": value,
        "gradient": gradient,
        "elasticity": np.where(nonzero, gradient * x[None, :] / np.where(nonzero, value[:, None], 1.0), 0.0),
        "windows": int(len(ok)),
        "windows_ok": n_ok,
        "window_s": float(n_window * dt),
        "evaluation_window_s": (obj.t_start, obj.t_end),
        "starts": starts,
        "grid": grid,
    }


def window_gradients(mech: Mechanism, starts: W.Starts, obj: Ensemble = Ensemble()):
    """Each ensemble window's sum of squared transmission-angle errors (deg^2), shape
    (K,), whether its solve succeeded (K,), and its gradient with respect to every
    floating-point parameter of ``mech`` (a Mechanism of (K,) arrays), each window
    re-solved from the carried-over start state, one after another, each with its
    reverse-mode gradient whatever ``obj.window_adjoint`` (``bench/window_gradients.py``
    looks at their distribution)."""
    import dataclasses

    import diffrax
    import equinox as eqx

    obj = dataclasses.replace(obj, window_adjoint=diffrax.RecursiveCheckpointAdjoint())

    def is_float(x):
        return isinstance(x, float) or (isinstance(x, jax.Array) and jnp.issubdtype(x.dtype, jnp.inexact))

    grid = obj.grid(mech)  # the sample grid of the concrete design (crank speed)
    params, static = eqx.partition(mech, is_float)
    params = jax.tree.map(lambda x: jax.lax.stop_gradient(jnp.asarray(x)), params)

    def one(p, i):
        sums, ok = obj.window_sums(eqx.combine(p, static), starts, i, grid)
        return sums[EQ19], ok

    (sq, ok), grads = W.over_windows(lambda i: jax.value_and_grad(one, has_aux=True)(params, i), starts)
    return sq, ok, grads
