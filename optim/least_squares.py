"""Bounded nonlinear least squares on the host: Levenberg-Marquardt with an exact Jacobian,
and confidence intervals of the fitted parameters from that Jacobian.

[`levenberg_marquardt`][optim.least_squares.levenberg_marquardt] minimises ``|r(u)|^2`` over a box
of (scaled) variables u. Each iteration solves the damped normal equations
``(J^T J + lambda D) du = -J^T r`` (D: the diagonal of J^T J, Marquardt's scaling) as a
least-squares problem, projects the trial point onto the box, and keeps it when the sum of
squares falls (Nielsen's damping update from the ratio of the actual to the predicted
reduction). A trial whose residuals are not finite, or that ``admissible`` refuses (e.g. a
design that left the periodic regime), is refused like one that does not reduce the misfit.

[`intervals`][optim.least_squares.intervals]: the covariance ``s^2 (J^T J)^-1`` with
``s^2 = |r|^2 / (n - p)``, Student-t 95 % intervals, the singular values of the Jacobian with
its columns scaled to unit length (their ratio is the condition number), and which parameters
the data do not determine.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable

import numpy as np
from scipy import stats

from jaxcrank.physics.params import ParameterError


@dataclasses.dataclass(frozen=True)
class LMSettings:
    """Levenberg-Marquardt's settings.

    Attributes:
        max_iterations: trial steps at most (accepted or refused), >= 1.
        ftol: stop when an accepted step lowers the sum of squares by less than ``ftol`` times it,
            or when the next step's predicted reduction is below that (before evaluating it): the
            misfit's own noise (the steady state is solved to a tolerance) is of that order.
        xtol: stop when a step is shorter than ``xtol (xtol + |u|)`` (scaled variables).
        gtol: stop when the projected gradient ``|J^T r|_inf`` is below ``gtol`` times the sum of squares.
        damping: the first damping ``lambda`` (relative to Marquardt's scaling).

    Raises:
        ParameterError: a setting out of its range (the message names it).
    """

    max_iterations: int = 30
    ftol: float = 1e-6
    xtol: float = 1e-8
    gtol: float = 1e-10
    damping: float = 1e-3

    def __post_init__(self):
        if not (isinstance(self.max_iterations, int) and self.max_iterations >= 1):
            raise ParameterError(f"max_iterations = {self.max_iterations!r} must be an integer >= 1")
        for key in ("ftol", "xtol", "gtol", "damping"):
            value = getattr(self, key)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ParameterError(f"{key} = {value!r} must be a finite number > 0")


#: the default settings
LM_SETTINGS = LMSettings()


@dataclasses.dataclass
class LMResult:
    """The outcome of [`levenberg_marquardt`][optim.least_squares.levenberg_marquardt].

    Attributes:
        u: the final variables; residuals, jacobian, info: there.
        misfit: the final sum of squares ``|r|^2``.
        converged: a stopping test was met (not the iteration limit, nor a damping that grew without bound).
        stop_reason: which test, in words.
        history: one dict per iteration (``iteration``, ``misfit``, ``trial_misfit``,
            ``accepted``, ``damping``, ``step``, ``cpu_s`` and ``u``).
        evaluations: calls of the residual function.
    """

    u: np.ndarray
    residuals: np.ndarray
    jacobian: np.ndarray
    info: dict
    misfit: float
    converged: bool
    stop_reason: str
    history: list
    evaluations: int


def _sum_squares(r) -> float:
    return float(np.dot(r, r)) if np.all(np.isfinite(r)) else math.inf


def levenberg_marquardt(
    fun: Callable,
    u0,
    lower,
    upper,
    settings: LMSettings | None = None,
    *,
    admissible: Callable | None = None,
    progress: Callable | None = None,
) -> LMResult:
    """Minimise ``|r(u)|^2`` for ``lower <= u <= upper`` (module docstring).

    Args:
        fun: ``(u, info at the iterate or None at the start) -> (r, J, info)``: residuals (n,),
            their Jacobian (n, p) and a dict for the history and ``admissible``; non-finite
            residuals mark a failed evaluation (or one not worth finishing: a refused trial).
        u0: the start, inside the box.
        lower, upper: the bounds (p,).
        settings: [`LMSettings`][optim.least_squares.LMSettings] (default `LM_SETTINGS`).
        admissible: ``(info at the iterate, info at the trial) -> bool``; False refuses the trial.
        progress: called with each iteration's history dict (e.g. to print a line).

    Returns:
        an [`LMResult`][optim.least_squares.LMResult].

    Raises:
        ParameterError: a start outside the box or whose residuals are not finite."""
    settings = LM_SETTINGS if settings is None else settings
    lower, upper = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
    u = np.asarray(u0, dtype=float)
    if np.any(u < lower) or np.any(u > upper):
        raise ParameterError(f"the start {u.tolist()} is outside the bounds {lower.tolist()} .. {upper.tolist()}")
    tic = time.process_time()
    r, J, info = fun(u, None)
    cost, evaluations = _sum_squares(r), 1
    if not math.isfinite(cost):
        raise ParameterError(f"the residuals at the start are not finite ({info})")
    lam, nu, history = settings.damping, 2.0, []
    stop, converged = f"the iteration limit ({settings.max_iterations})", False
    for it in range(1, settings.max_iterations + 1):
        g = J.T @ r
        free = ~(((u <= lower) & (g > 0)) | ((u >= upper) & (g < 0)))  # not held by a bound
        if np.max(np.abs(np.where(free, g, 0.0)), initial=0.0) <= settings.gtol * max(cost, 1e-300):
            stop, converged = "the projected gradient vanished (gtol)", True
            break
        d = np.maximum(np.sum(J * J, axis=0), 1e-12 * max(np.max(np.sum(J * J, axis=0)), 1e-300))
        a = np.vstack([J, np.diag(np.sqrt(lam * d))])
        step = np.linalg.lstsq(a, np.concatenate([-r, np.zeros(u.size)]), rcond=None)[0]
        trial = np.clip(u + step, lower, upper)
        step = trial - u
        predicted = cost - float(np.sum((r + J @ step) ** 2))
        newton = np.clip(u + np.linalg.lstsq(J, -r, rcond=None)[0], lower, upper) - u  # undamped
        if cost - float(np.sum((r + J @ newton) ** 2)) <= settings.ftol * cost:
            stop, converged = "the predicted reduction fell below ftol", True
            break
        r_t, J_t, info_t = fun(trial, info)
        evaluations += 1
        cost_t = _sum_squares(r_t)
        ok = math.isfinite(cost_t) and (admissible is None or admissible(info, info_t))
        rho = (cost - cost_t) / predicted if ok and predicted > 0 else -1.0
        accepted = rho > 1e-4
        row = {
            "iteration": it,
            "misfit": cost_t if accepted else cost,
            "trial_misfit": cost_t,
            "accepted": accepted,
            "damping": lam,
            "step": float(np.linalg.norm(step)),
            "cpu_s": time.process_time() - tic,
            "u": (trial if accepted else u).tolist(),
            **{k: v for k, v in info_t.items() if isinstance(v, (str, int, float))},
        }
        history.append(row)
        if progress is not None:
            progress(row)
        small = np.linalg.norm(step) <= settings.xtol * (settings.xtol + np.linalg.norm(u))
        if accepted:
            drop = cost - cost_t
            u, r, J, info, cost = trial, r_t, J_t, info_t, cost_t
            lam, nu = lam * max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3), 2.0
            if drop <= settings.ftol * max(cost, 1e-300) or small:
                stop = "the step vanished (xtol)" if small else "the misfit stopped falling (ftol)"
                converged = True
                break
        else:
            lam, nu = lam * nu, 2.0 * nu
            if small or lam > 1e16:
                stop = "the step vanished (xtol)" if small else "no step lowers the misfit (damping without bound)"
                converged = bool(small)
                break
    return LMResult(u, r, J, info, cost, converged, stop, history, evaluations)


@dataclasses.dataclass
class Intervals:
    """Confidence intervals of least-squares estimates from the Jacobian at the fit.

    Attributes:
        standard_error: per parameter, SI (inf where the data do not determine it).
        ci95: (p, 2) lower and upper ends of the 95 % intervals, SI.
        covariance: (p, p), SI.
        correlation: (p, p).
        singular_values: of the Jacobian with unit-length columns, largest first.
        condition_number: largest over smallest singular value (inf when rank deficient).
        rank: numerical rank of the Jacobian.
        residual_variance: ``s^2 = |r|^2 / (n - p)``.
        identifiable: per parameter, whether the data determine it (finite interval no wider than
            ``max_relative_halfwidth`` of the value, full rank).
        reasons: per parameter, why not ("" when identifiable).
    """

    standard_error: np.ndarray
    ci95: np.ndarray
    covariance: np.ndarray
    correlation: np.ndarray
    singular_values: np.ndarray
    condition_number: float
    rank: int
    residual_variance: float
    identifiable: list
    reasons: list


def intervals(
    jacobian, residuals, x, names, *, at_bound=None, max_relative_halfwidth: float = 0.5, rank_tol: float = 1e-10
) -> Intervals:
    """Covariance and 95 % intervals of the estimates ``x`` (module docstring).

    Args:
        jacobian: d residuals / d x at the fit, (n, p), x in SI units.
        residuals: at the fit, (n,).
        x: the estimates, SI (p,).
        names: the parameters' names, for the reasons.
        at_bound: per parameter, whether it ended on a bound (its interval assumes an interior optimum).
        max_relative_halfwidth: an interval wider than this fraction of the value on each side
            marks the parameter as not identifiable.
        rank_tol: singular values below ``rank_tol`` times the largest count as zero.

    Raises:
        ParameterError: fewer residuals than parameters + 1."""
    J, r, x = np.asarray(jacobian, dtype=float), np.asarray(residuals, dtype=float), np.asarray(x, dtype=float)
    n, p = J.shape
    if n <= p:
        raise ParameterError(f"{n} samples for {p} parameters: a fit with intervals needs at least {p + 1}")
    norms = np.linalg.norm(J, axis=0)
    seen = norms > 0  # a zero column: a parameter the residuals do not depend on
    _, sv, vt = np.linalg.svd(J / np.where(seen, norms, 1.0), full_matrices=False)
    rank = int(np.sum(sv > rank_tol * max(sv[0], 1e-300)))
    s2 = float(r @ r) / (n - p)
    cov, corr = np.full((p, p), np.inf), np.full((p, p), np.nan)
    if 0 < rank == int(seen.sum()):  # the others' covariance, as if the unseen ones were held
        _, sv_seen, vt_seen = np.linalg.svd(J[:, seen] / norms[seen], full_matrices=False)
        block = s2 * ((vt_seen.T / sv_seen**2) @ vt_seen) / np.outer(norms[seen], norms[seen])
        cov[np.ix_(seen, seen)] = block
        corr[np.ix_(seen, seen)] = block / np.sqrt(np.outer(np.diag(block), np.diag(block)))
    se = np.sqrt(np.diag(cov))
    half = stats.t.ppf(0.975, n - p) * se
    ci = np.stack([x - half, x + half], axis=1)
    null = vt[-1] if rank < p or sv[-1] < 1e-3 * sv[0] else None  # the direction the data barely see
    identifiable, reasons = [], []
    for i in range(p):
        why = ""
        if norms[i] == 0:
            why = "the trace does not depend on it (its Jacobian column is zero)"
        elif rank < int(seen.sum()) and null is not None and abs(null[i]) > 0.1:
            partners = [names[j] for j in range(p) if j != i and abs(null[j]) > 0.1]
            why = "the Jacobian is rank deficient: the trace sees it only in a combination" + (
                f" with {', '.join(partners)}" if partners else ""
            )
        elif not math.isfinite(se[i]):
            why = "its standard error is not finite"
        elif half[i] > max_relative_halfwidth * abs(x[i]):
            rel = half[i] / abs(x[i]) if x[i] != 0 else math.inf
            why = f"its 95 % interval is +-{100 * rel:.3g} % of the value (over {100 * max_relative_halfwidth:g} %)"
            if null is not None and abs(null[i]) > 0.3:
                partners = [names[j] for j in range(p) if j != i and abs(null[j]) > 0.3]
                why += " (nearly collinear with " + ", ".join(partners) + ")" if partners else ""
        if not why and at_bound is not None and at_bound[i]:
            why = "it ended on a bound: the interval assumes an interior optimum"
        identifiable.append(not why)
        reasons.append(why)
    cond = float(sv[0] / sv[-1]) if rank == p and sv[-1] > 0 else math.inf
    return Intervals(se, ci, cov, corr, sv, cond, rank, s2, identifiable, reasons)
