"""Local sensitivities of the mean-square metrics by AD, in one call.

``sensitivities(mech)`` gives, at one design, the value of each metric in
`METRICS` and its gradient with respect to every parameter in ``names``
(any name [`jaxcrank.physics.params.set_parameter`][] accepts), plus the normalised
elasticities ``(dm/dp) (p / m)`` (percent change of the metric per percent change
of the parameter), which [`optim.plots.plot_tornado`][] draws as a tornado chart.

The same care as the optimisation ([`optim.objective.Ensemble`][]): over the paper's
window the pathwise derivative of a chaotic trajectory is ~1e27 and meaningless;
the gradient here is the ensemble-sensitivity estimate. One solve at the design
gives the exact metric values and the pins' states in their bearings at the start
of K short windows; each window is re-solved from that state (carried over to the
perturbed design) with an implicit solver, the per-window sums of squares are
differentiated (forward mode by default, one tangent per parameter;
``Ensemble(window_adjoint=diffrax.RecursiveCheckpointAdjoint())`` for reverse-mode Jacobians), and the
ensemble mean is taken.

Valid for: time averages of squares, i.e. the RMS metrics (transmission-angle
error, rod-centre and slider x deviation, driving-moment deviation, contact forces
at B and C). Not valid for: peaks (largest contact force, largest deviation,
largest acceleration): an extreme value over chaotic impacts has no trend-following
local derivative (use a sweep over a band, [`jaxcrank.runs.sweep`][], for those).
"""

from __future__ import annotations

from collections.abc import Sequence

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from jaxcrank import metrics
from jaxcrank.numerics.solve import Simulation
from jaxcrank.physics.params import Mechanism, get_parameter, parameter_unit, set_parameters

from . import windows as W
from .objective import Ensemble

#: metrics whose gradient the ensemble estimate follows: the RMS metrics of
#: :mod:`jaxcrank.analysis.metrics` (units in the suffix); the rows of the results below
METRICS = metrics.RMS_METRICS

#: default parameters: the physical design and operating parameters (not the smoothing widths)
PARAMETERS = (
    "crank_length",
    "rod_length",
    "offset",
    "rod_mass",
    "slider_mass",
    "rod_inertia",
    "crank_speed",
    "clearance_B",
    "clearance_C",
    "contact.restitution",
    "friction.coefficient",
    "rod_material.youngs_modulus",
)


def metric_values(sim: Simulation) -> Float[Array, " metrics"]:
    """`METRICS` that a solve tracked (``simulate(..., metrics_start=...)``,
    [`jaxcrank.numerics.tracking`][]), stacked in the order of `METRICS`, in their units."""
    return jnp.stack([sim.metrics[k] for k in METRICS])


def window_sums(
    base: Mechanism, names, x: Float[ArrayLike, " params"], starts: W.Starts, i: Int[ArrayLike, ""], obj: Ensemble
) -> tuple[Float[Array, " metrics"], Bool[Array, ""]]:
    """Window ``i`` re-solved for ``base`` with ``names`` set to ``x`` (SI) from the
    carried-over start state ([`optim.objective.Ensemble.window_sums`][]): the sums of
    squares of the metrics' signals over its samples, stacked in the order of
    `METRICS` (units squared), and whether it finished."""
    sums, ok = obj.window_sums(set_parameters(base, names, x), starts, i, obj.grid(base))
    return jnp.stack([sums[k] for k in METRICS]), ok


def sensitivities(mech: Mechanism, names: Sequence[str] = PARAMETERS, obj: Ensemble = Ensemble()) -> dict:
    """Values, gradients and elasticities of `METRICS` at ``mech`` over the
    objective's window (``obj``: window, ensemble windows, solver, tolerances).

    Returns a dict: ``names``, ``units`` (of each parameter), ``x`` (SI values),
    ``metrics`` (names), ``value`` (6,) exact metric values, ``gradient`` (6, P)
    in metric unit per parameter unit (0 for a metric that is 0 over every window),
    ``elasticity`` (6, P) dimensionless (0 for a metric whose value is 0),
    ``windows`` and ``windows_ok`` (ensemble size and how many finished)."""
    names = list(names)
    units = [parameter_unit(n) for n in names]
    grid = obj.grid(mech)  # concrete sample grid of the design (crank speed may be a variable below)
    n_window, dt = grid.n_window, grid.dt
    # the metrics over the samples in (t_start, t_end] tracked during the solve, which
    # stores only the windows' starts
    opts = dict(rtol=obj.rtol, atol=obj.atol, max_steps=obj.max_steps)
    sim = W.tracked_solve(mech, grid, obj.windows, opts, True)
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
            "Ensemble.window_max_steps, loosen rtol/atol or shorten Ensemble.window"
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
        "metrics": list(METRICS),
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
        return sums["rms_transmission_angle_error_deg"], ok

    (sq, ok), grads = W.over_windows(lambda i: jax.value_and_grad(one, has_aux=True)(params, i), starts)
    return sq, ok, grads
