"""Local sensitivities of the mean-square metrics by AD, in one call.

``sensitivities(mech)`` gives, at one design, the value of each metric in
:data:`METRICS` and its gradient with respect to every parameter in ``names``
(any name :func:`jaxcrank.params.set_parameter` accepts), plus the normalised
elasticities ``(dm/dp) (p / m)`` (percent change of the metric per percent change
of the parameter), which :func:`optim.plots.plot_tornado` draws as a tornado chart.

The same care as the optimisation (:mod:`optim.objective`): over the paper's
window the pathwise derivative of a chaotic trajectory is ~1e27 and meaningless;
the gradient here is the ensemble-sensitivity estimate. One solve at the design
gives the exact metric values and the pins' states in their bearings at the start
of K short windows; each window is re-solved from that state (carried over to the
perturbed design) with an implicit solver, the per-window sums of squares are
differentiated (forward mode by default, one tangent per parameter;
``Objective.window_gradient = "reverse"`` for reverse-mode Jacobians), and the
ensemble mean is taken.

Valid for: time averages of squared deviations, i.e. the RMS metrics
(transmission-angle error, rod-centre and slider x deviation, driving-moment
deviation). Not valid for: peaks (largest contact force, largest deviation,
largest acceleration): an extreme value over chaotic impacts has no trend-following
local derivative (use a sweep over a band, :mod:`jaxcrank.sweep`, for those).
"""

from __future__ import annotations

from collections.abc import Sequence

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from jaxcrank import metrics, model
from jaxcrank.params import Mechanism, get_parameter, parameter_unit, set_parameters
from jaxcrank.solve import Simulation, simulate

from .objective import Objective, forward_mode, solve_window, window_starts

#: metrics whose gradient the ensemble estimate follows: the RMS metrics of
#: :mod:`jaxcrank.metrics` (units in the suffix)
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


def deviations(mech: Mechanism, ts: Float[ArrayLike, " n"], ys: Float[ArrayLike, "n state"]) -> Float[Array, "n 4"]:
    """Per-sample deviations from the ideal mechanism behind :data:`METRICS`, shape
    (n, 4), in that order and in their units (deg, m, m, N m)."""
    return jax.vmap(lambda t, y: metrics.rms_signals(model.evaluate(mech, t, y)))(ts, ys)


def metric_values(sim: Simulation) -> Float[Array, " 4"]:
    """:data:`METRICS` that a solve tracked (``simulate(..., metrics_start=...)``,
    :mod:`jaxcrank.tracking`), shape (4,), in their units."""
    return jnp.stack([sim.metrics[k] for k in METRICS])


def window_sums(
    base: Mechanism,
    names,
    x: Float[ArrayLike, " params"],
    starts,
    i: Int[ArrayLike, ""],
    n_window: int,
    dt: float,
    obj: Objective,
    metrics=deviations,
) -> tuple[Float[Array, " metrics"], Bool[Array, ""]]:
    """Window ``i`` re-solved for ``base`` with ``names`` set to ``x`` (SI) from the
    carried-over start state: the sums of squared deviations over its samples,
    shape (4,), in the units of :data:`METRICS` squared, and whether it finished.

    ``metrics``: the per-sample quantities ``(mech, ts, ys) -> (n, M)`` whose squares
    are summed (default :func:`deviations`; :mod:`optim.design` adds contact forces)."""
    m = set_parameters(base, names, x)
    ts, ys, ok = solve_window(m, starts, i, n_window, dt, obj)
    return jnp.sum(metrics(m, ts, ys) ** 2, axis=0), ok


def sensitivities(mech: Mechanism, names: Sequence[str] = PARAMETERS, obj: Objective = Objective()) -> dict:
    """Values, gradients and elasticities of :data:`METRICS` at ``mech`` over the
    objective's window (``obj``: window, ensemble windows, solver, tolerances).

    Returns a dict: ``names``, ``units`` (of each parameter), ``x`` (SI values),
    ``metrics`` (names), ``value`` (4,) exact metric values, ``gradient`` (4, P)
    in metric unit per parameter unit, ``elasticity`` (4, P) dimensionless,
    ``windows`` and ``windows_ok`` (ensemble size and how many finished)."""
    names = list(names)
    units = [parameter_unit(n) for n in names]
    grid = obj.grid(mech)  # concrete sample grid of the design (crank speed may be a variable below)
    n_start, n_eval, n_window, dt = grid
    ts = dt * jnp.arange(n_start + n_eval + 1)
    # the metrics over the samples after t_start (index > n_start), tracked during the solve
    sim = simulate(mech, ts=ts, rtol=obj.rtol, atol=obj.atol, max_steps=obj.max_steps, metrics_start=ts[n_start])
    value = metric_values(sim)
    starts = window_starts(sim, n_start, grid, obj)
    x0 = jnp.array([get_parameter(mech, n) for n in names])

    # forward mode: one tangent per parameter; reverse mode: one cotangent per metric
    jacobian = jax.jacfwd if forward_mode(obj) else jax.jacrev

    def jac(i):
        def with_aux(x):
            sums, ok = window_sums(mech, names, x, starts, i, n_window, dt, obj)
            return sums, (sums, ok)

        rows, (sums, ok) = jacobian(with_aux, has_aux=True)(x0)
        return sums, rows, ok

    sums, rows, ok = jax.jit(jax.vmap(jac))(jnp.arange(starts.t.shape[0]))
    sums, rows, ok = np.asarray(sums), np.asarray(rows), np.asarray(ok)
    n_ok = int(ok.sum())
    if n_ok < 0.5 * len(ok):
        raise RuntimeError(
            f"{len(ok) - n_ok} of {len(ok)} ensemble windows failed; raise "
            "Objective.window_max_steps, loosen rtol/atol or shorten Objective.window"
        )
    w = ok.astype(float)
    estimate = np.sqrt(np.einsum("k,kc->c", w, sums) / (n_window * n_ok))
    grad_sq = np.einsum("k,kcp->cp", w, rows) / (n_window * n_ok)
    gradient = grad_sq / (2.0 * estimate[:, None])
    value = np.asarray(value)
    x = np.asarray(x0)
    return {
        "names": names,
        "units": units,
        "x": x,
        "metrics": list(METRICS),
        "value": value,
        "gradient": gradient,
        "elasticity": gradient * x[None, :] / value[:, None],
        "windows": int(len(ok)),
        "windows_ok": n_ok,
        "window_s": float(n_window * dt),
        "evaluation_window_s": (obj.t_start, obj.t_end),
        "starts": starts,
        "grid": grid,
    }
