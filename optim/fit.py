"""[`fit`][optim.fit.fit]: the least-squares calibration of a mechanism's parameters against a
measured trace, and its result: the fitted values, their 95 % intervals, which of them the
trace determines, and the iteration history ([`optim.calibrate`][] computes the model trace and
its exact Jacobian; [`optim.least_squares`][] the steps and the intervals).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence

import numpy as np

from jaxcrank.numerics.shooting import SteadyOptions
from jaxcrank.physics.parameters import parameter_unit

from .calibrate import FIT_STEADY, PERIODIC, Calibration, Evaluation, FitParameter, say
from .least_squares import LM_SETTINGS, LMSettings, intervals, levenberg_marquardt
from .trace import Trace, trace_angles_deg


@dataclasses.dataclass
class FitResult:
    """What [`fit`][optim.fit.fit] found; [`summary`][optim.fit.FitResult.summary] is ``fit.json``.

    Attributes:
        parameters: the fitted [`FitParameter`][optim.calibrate.FitParameter]s (start and bounds).
        fitted: the fitted values, SI (p,).
        units: each parameter's SI unit, as written in names (``m``, ``1``, ``Pa``).
        start, final: the [`Evaluation`][optim.calibrate.Evaluation]s at the start and at the fit.
        intervals: the [`Intervals`][optim.least_squares.Intervals] at the fit.
        converged, stop_reason, history, iterations, evaluations: of the Levenberg-Marquardt run.
        cpu_seconds: process CPU time of the fit (compilation included), s.
        compile_seconds: wall time spent compiling the model-trace programs, s.
        noise: the residuals' noise scale, the signal's unit.
        angle_deg: the driven body's angle at each sample, deg (for plots).
        measured: the measured signal (n,).
        notes: what the result does not say, in words (not periodic, parameters at a bound, ...).
    """

    parameters: tuple
    fitted: np.ndarray
    units: list
    start: Evaluation
    final: Evaluation
    intervals: object
    converged: bool
    stop_reason: str
    history: list
    iterations: int
    evaluations: int
    cpu_seconds: float
    compile_seconds: float
    noise: float
    angle_deg: np.ndarray
    measured: np.ndarray
    signal: str
    notes: list

    def summary(self) -> dict:
        """The result as plain values (``fit.json``): per parameter its start, fitted value,
        standard error and 95 % interval (SI), relative half-width, identifiable flag and why
        not; the misfit (sum of squared normalised residuals) at the start and the fit and the
        RMS residual in the signal's unit; the regime and what the model trace was; the
        Jacobian's singular values and condition number; iterations, evaluations and CPU seconds."""
        iv = self.intervals
        params = {}
        for i, p in enumerate(self.parameters):
            value, se = float(self.fitted[i]), float(iv.standard_error[i])
            params[p.name] = {
                "unit": self.units[i],
                "start": p.start,
                "lower": p.lower,
                "upper": p.upper,
                "fitted": value,
                "standard_error": se if math.isfinite(se) else None,
                "ci95": [float(v) if math.isfinite(v) else None for v in iv.ci95[i]],
                "ci95_relative_halfwidth": (
                    float((iv.ci95[i, 1] - value) / abs(value)) if math.isfinite(se) and value != 0 else None
                ),
                "identifiable": bool(iv.identifiable[i]),
                "why_not": iv.reasons[i] or None,
            }
        n = self.measured.size
        return {
            "signal": self.signal,
            "samples": n,
            "noise_scale": self.noise,
            "parameters": params,
            "misfit_start": self.start.misfit,
            "misfit_final": self.final.misfit,
            "rms_residual_start": float(np.sqrt(np.mean((self.start.model - self.measured) ** 2))),
            "rms_residual_final": float(np.sqrt(np.mean((self.final.model - self.measured) ** 2))),
            "residual_variance": iv.residual_variance,
            "regime": self.final.regime,
            "period_revolutions": self.final.period_revolutions,
            "model_trace": self.final.source,
            "start_regime": self.start.regime,
            "singular_values": [float(s) for s in iv.singular_values],
            "condition_number": iv.condition_number if math.isfinite(iv.condition_number) else None,
            "rank": iv.rank,
            "correlation": [[float(c) if math.isfinite(c) else None for c in row] for row in iv.correlation],
            "converged": self.converged,
            "stop_reason": self.stop_reason,
            "iterations": self.iterations,
            "evaluations": self.evaluations,
            "cpu_seconds": self.cpu_seconds,
            "compile_seconds": self.compile_seconds,
            "notes": self.notes,
        }


def _progress(names, params):
    def line(row):
        x = [p.si(u) for p, u in zip(params, row["u"])]
        values = ", ".join(f"{n} = {v:.6g}" for n, v in zip(names, x))
        k = row.get("period_revolutions")
        where = row.get("regime", "?") + (f" ({k} rev)" if k else "")
        say(
            f"iteration {row['iteration']}: misfit {row['misfit']:.6g} (trial {row['trial_misfit']:.6g}, "
            f"{'accepted' if row['accepted'] else 'refused'}; damping {row['damping']:.2g}) {values}; trial {where}; "
            f"{row['cpu_s']:.1f} s CPU"
        )

    return line


#: a trace's first revolution whose RMS residual exceeds its last's by this factor is noted as a start-up
TRANSIENT_RATIO = 2.0


def _transient(turns: np.ndarray, residuals: np.ndarray) -> list[str]:
    """A note when the residuals (signal units) of the trace's first revolution exceed its last's
    by `TRANSIENT_RATIO` in RMS: a start-up the steady orbit does not have; else none."""
    if turns.max(initial=0) < 1 or not np.all(np.isfinite(residuals)):
        return []
    first, last = (float(np.sqrt(np.mean(residuals[turns == k] ** 2))) for k in (0, turns.max()))
    if not first > TRANSIENT_RATIO * last:
        return []
    return [
        f"the residuals fall over the trace (RMS {first:.4g} in its first revolution, {last:.4g} in its last, "
        f"revolution {turns.max() + 1}; signal units): it may begin with a start-up (a run from rest does) that "
        "the steady orbit does not have, which biases the fit and its intervals; fit the revolutions after it"
    ]


def fit(
    base,
    parameters: Sequence[FitParameter],
    trace: Trace,
    *,
    noise: float | None = None,
    options: SteadyOptions = FIT_STEADY,
    settings: LMSettings = LM_SETTINGS,
    window_revolutions: int | None = None,
    max_relative_halfwidth: float = 0.5,
    progress: bool = False,
    calibration: Calibration | None = None,
    on_iteration: Callable[[dict], None] | None = None,
) -> FitResult:
    """Fit ``parameters`` of ``base`` to ``trace`` by bounded Levenberg-Marquardt with the exact
    Jacobian through the steady orbit ([`optim.calibrate`][]).

    Args:
        base: the mechanism.
        parameters: the [`FitParameter`][optim.calibrate.FitParameter]s (start, bounds; SI).
        trace: the measured [`Trace`][optim.trace.Trace].
        noise: the measurement's noise scale, the signal's unit (default: the measured RMS).
        options: the steady-state settings (default `FIT_STEADY`).
        settings: the [`LMSettings`][optim.least_squares.LMSettings].
        window_revolutions: not periodic: revolutions from rest before the compared window.
        max_relative_halfwidth: a 95 % interval wider than this fraction of the value marks a
            parameter as not identifiable.
        progress: one line per iteration on standard error.
        calibration: a [`Calibration`][optim.calibrate.Calibration] of the same problem to reuse
            (its compiled programs and last orbit); the other arguments but ``settings`` are then its.
        on_iteration: called after every iteration with ``iteration``, ``accepted``, ``misfit``
            (of the iterate) and ``design`` (name -> SI value of the iterate): a checkpoint.

    Returns:
        a [`FitResult`][optim.fit.FitResult].

    Raises:
        ParameterError: bad input ([`Calibration`][optim.calibrate.Calibration] names it), or
            residuals that are not finite at the start (the start's solve failed)."""
    tic = time.process_time()
    cal = calibration or Calibration(
        base, parameters, trace, noise=noise, options=options, window_revolutions=window_revolutions
    )
    params, names = cal.parameters, cal.names
    seen = {}

    def fun(u, current):
        x = np.array([p.si(v) for p, v in zip(params, u)])
        ev = cal.evaluate(x, periodic_only=current is not None and current["regime"] == PERIODIC)
        seen.setdefault("start", ev)
        dxdu = np.array([p.si(v) if p.log else p.scale for p, v in zip(params, u)])
        return ev.residuals, ev.jacobian * dxdu, {**ev.info(), "evaluation": ev}

    def admissible(current, trial):  # a periodic fit stays periodic: elsewhere the trace is not the orbit's
        return trial["regime"] == PERIODIC or current["regime"] != PERIODIC

    if progress:
        say(f"{', '.join(names)} against {trace.signal} ({trace.n} samples): the start (settling from rest, compiling)")
    u0 = np.array([p.scaled(p.start) for p in params])
    lower = np.array([p.scaled(p.lower) for p in params])
    upper = np.array([p.scaled(p.upper) for p in params])
    line = _progress(names, params) if progress else None

    def each(row):
        if line is not None:
            line(row)
        if on_iteration is not None:
            design = {n: float(p.si(v)) for n, p, v in zip(names, params, row["u"])}
            on_iteration(
                {"iteration": row["iteration"], "accepted": row["accepted"], "misfit": row["misfit"], "design": design}
            )

    res = levenberg_marquardt(fun, u0, lower, upper, settings, admissible=admissible, progress=each)
    final: Evaluation = res.info["evaluation"]
    x = final.x
    at_bound = [bool(np.isclose(v, p.lower, rtol=1e-9) or np.isclose(v, p.upper, rtol=1e-9)) for p, v in zip(params, x)]
    iv = intervals(
        final.jacobian, final.residuals, x, names, at_bound=at_bound, max_relative_halfwidth=max_relative_halfwidth
    )
    notes, converged, stop = [], res.converged, res.stop_reason
    if final.regime != PERIODIC:
        converged, stop = False, f"not periodic at the last design ({res.stop_reason})"
        why = (
            f"not periodic at the fitted design: the model trace is the revolution after {cal.window_revolutions} "
            f"revolutions from rest, not a steady orbit; the motion does not repeat (largest Lyapunov exponent "
            f"{final.lyapunov_exponent_per_s:.3g} /s), so the comparison depends on the revolution chosen and on "
            "rounding, and the intervals from its Jacobian do not describe the parameters"
        )
        notes.append(why)
        iv.identifiable = [False] * len(names)
        iv.reasons = [why] * len(names)
    if final.period_revolutions > 1:
        notes.append(
            f"period {final.period_revolutions} orbit: the trace's first revolution is matched to the orbit's "
            f"revolution {final.shift}"
        )
    if not converged:
        notes.append(f"not converged: {stop}")
    notes += _transient(cal.turns, final.residuals * cal.noise)
    for name, ok, why in zip(names, iv.identifiable, iv.reasons):
        if not ok and final.regime == PERIODIC:
            notes.append(f"{name} not identifiable: {why}")
    if not converged and final.regime == PERIODIC:  # the intervals are a minimum's; this one is not known to be
        why = f"the fit did not converge ({stop}): the interval is the last iterate's, not a minimum's"
        iv.reasons = [why if ok else f"{why}; {reason}" for ok, reason in zip(iv.identifiable, iv.reasons)]
        iv.identifiable = [False] * len(names)
    rows = []
    for row in res.history:
        x_row = [p.si(u) for p, u in zip(params, row["u"])]
        rows.append({**{k: v for k, v in row.items() if k != "u"}, **dict(zip(names, (float(v) for v in x_row)))})
    if progress:
        say(f"{stop}: misfit {seen['start'].misfit:.6g} -> {final.misfit:.6g}")
    return FitResult(
        parameters=params,
        fitted=np.asarray(x, dtype=float),
        units=[parameter_unit(base if calibration is None else cal.base, n) for n in names],
        start=seen["start"],
        final=final,
        intervals=iv,
        converged=converged,
        stop_reason=stop,
        history=rows,
        iterations=len(res.history),
        evaluations=res.evaluations,
        cpu_seconds=time.process_time() - tic,
        compile_seconds=cal.compile_seconds,
        noise=cal.noise,
        angle_deg=trace_angles_deg(cal.base, cal.trace),
        measured=cal.trace.values,
        signal=cal.trace.signal,
        notes=notes,
    )
