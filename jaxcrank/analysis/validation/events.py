"""The solve and event location the validation rigs share: one ``diffeqsolve`` with
dense output ([`dense_solve`][jaxcrank.analysis.validation.events.dense_solve]) and the zero crossings of a scalar
function of time,
bracketed on a grid and located by bisection ([`crossings`][jaxcrank.analysis.validation.events.crossings])."""

from __future__ import annotations

from collections.abc import Callable

import diffrax
import equinox as eqx
import numpy as np
from jaxtyping import Float


@eqx.filter_jit
def dense_solve(
    field, solver, t0, t1, dt0, y0, args, controller, max_steps: int, steps: bool = False, throw: bool = False
):
    """``diffrax.diffeqsolve`` of ``field`` (``f(t, y, args)``) from ``t0`` to ``t1`` (s)
    with dense output, saving the end state (or, ``steps=True``, every accepted step).
    A failure is returned in ``sol.result`` (``throw=True``: raised, as diffrax does)."""
    return diffrax.diffeqsolve(
        diffrax.ODETerm(field),
        solver,
        t0,
        t1,
        dt0,
        y0,
        args=args,
        saveat=diffrax.SaveAt(steps=True, dense=True) if steps else diffrax.SaveAt(t1=True, dense=True),
        stepsize_controller=controller,
        max_steps=max_steps,
        throw=throw,
    )


def crossings(
    g: Callable[[Float[np.ndarray, " n"]], Float[np.ndarray, " n"]],
    ts: Float[np.ndarray, " n"],
    values: Float[np.ndarray, " n"],
    upward: bool = True,
    bisections: int = 60,
) -> tuple[Float[np.ndarray, " k"], Float[np.ndarray, " k"]]:
    """Where ``g`` (s -> value, vectorised over an array of times) crosses zero upwards
    (from < 0 to >= 0; ``upward=False``: downwards), bracketed by the grid ``ts`` (s,
    increasing) with ``values = g(ts)``.

    Returns:
        ``(lo, hi)``, s: after ``bisections`` halvings, the bracket of each crossing,
        in time order; ``g(lo) < 0 <= g(hi)`` upwards, ``g(lo) >= 0 > g(hi)`` downwards.
    """
    ts, values = np.asarray(ts, dtype=float), np.asarray(values, dtype=float)
    if upward:
        idx = np.flatnonzero((values[:-1] < 0.0) & (values[1:] >= 0.0))
    else:
        idx = np.flatnonzero((values[:-1] >= 0.0) & (values[1:] < 0.0))
    lo, hi = ts[idx].copy(), ts[idx + 1].copy()
    for _ in range(bisections if idx.size else 0):
        mid = 0.5 * (lo + hi)
        mid_below = np.asarray(g(mid)) < 0.0
        step_lo = mid_below == upward  # the crossing lies above mid
        lo, hi = np.where(step_lo, mid, lo), np.where(step_lo, hi, mid)
    return lo, hi
