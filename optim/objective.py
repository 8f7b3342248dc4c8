"""The objectives of design problems, in one place: each kind a final Module of
[`AbstractObjective`][optim.objective.AbstractObjective].

An objective evaluates the RMS metrics of a mechanism (the names its description gives,
[`jaxcrank.physics.signals.rms_metrics`][], units in the name: the paper's Eq. 19
``rms_transmission_angle_error_deg`` among them for a mechanism with a transmission angle)
and decides how their gradient is taken. A problem ([`optim.problem`][]) combines them into its value.

[`Pathwise`][optim.objective.Pathwise]
    One solve from the pins-centred start over the evaluation window ``(t_start,
    t_end]``; the metrics over its samples and their exact gradient through the whole
    solve (reverse mode). Meaningful only for windows shorter than the impact chaos'
    horizon (a few ms on the paper preset): over the paper's window the gradient is
    ~1e27 (docs/numerics.md, "Gradients beyond the first impacts").
[`Ensemble`][optim.objective.Ensemble]
    The exact metrics of one forward solve over the window, with the
    ensemble-sensitivity gradient ([`optim.windows`][]): a trend estimate, finite on
    chaotic runs. Differentiated in forward mode by default (``window_adjoint =
    diffrax.ForwardMode()``, one tangent per design variable), which compiles several
    times faster than reverse mode for the few variables of a design problem; such an
    objective is differentiated with [`value_and_grad`][optim.objective.value_and_grad] (``jax.jacfwd``).
[`optim.steady.Steady`][]
    The metrics over one period of the steady periodic orbit, with the exact gradient
    of the implicit function theorem at the orbit ([`optim.steady`][]).

Eq. 19: ``F = sqrt(mean_n (alpha_n - alpha_ideal_n)^2)``, degrees, over samples at
equal crank-angle steps (the windowed objectives need a constant-speed driver, so equal
times are equal crank angles and the actual and ideal transmission angles are compared at
the same crank angle).
"""

from __future__ import annotations

import abc

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from jaxcrank.numerics.estimators import straight_through
from jaxcrank.numerics.solve import DEFAULTS
from jaxcrank.physics.linkage import AbstractMechanism as Mechanism
from jaxcrank.physics.params import ParameterError
from jaxcrank.physics.signals import rms_metrics

from . import windows as W

#: the paper's Eq. 19 metric (degrees)
EQ19 = "rms_transmission_angle_error_deg"


def safe_sqrt(x):
    """``sqrt(x)`` for ``x >= 0`` with a finite gradient at 0 (double where)."""
    pos = x > 0.0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, x, 1.0)), 0.0)


class AbstractObjective(eqx.Module):
    """How a design problem measures a mechanism: the RMS metrics and their gradient.

    Attributes:
        throw: a solve that cannot finish raises (True) or makes the metrics NaN
            (False: no host callback in the program, so JAX's persistent compilation
            cache can store it; the caller checks, as [`optim.optimize.optimize`][] does).
    """

    throw: eqx.AbstractVar[bool]

    @abc.abstractmethod
    def rms(self, mech: Mechanism) -> dict[str, Float[Array, ""]]:
        """The RMS metrics of ``mech`` ([`jaxcrank.physics.signals.rms_metrics`][]:
        name -> value in the unit of its name), differentiable with respect to the
        mechanism's parameters as the kind says. Needs a concrete ``driver.speed``."""

    @abc.abstractmethod
    def forward_mode(self) -> bool:
        """Whether the metrics are differentiated in forward mode
        ([`value_and_grad`][optim.objective.value_and_grad])."""

    @abc.abstractmethod
    def describe(self) -> dict:
        """The settings as a dict of plain values (``kind`` and the fields), for reports
        and the CLI's resolved configuration."""


def _check_window(t_start, t_end, samples_per_degree):
    if not 0.0 <= t_start < t_end:
        raise ParameterError(
            f"objective window must satisfy 0 <= t_start < t_end, got t_start = {t_start:g} s, t_end = {t_end:g} s"
        )
    if samples_per_degree <= 0:
        raise ParameterError(f"samples_per_degree = {samples_per_degree:g} must be positive")


def _fields(obj) -> dict:
    import dataclasses

    return {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj)}


class Pathwise(AbstractObjective):
    """The metrics over the window ``(t_start, t_end]`` of one solve from the
    pins-centred start, with their exact reverse-mode gradient (module docstring).

    Attributes:
        t_start: start of the evaluation window (t_start, t_end], s, >= 0.
        t_end: end of the evaluation window, s, > t_start.
        samples_per_degree: samples per degree of crank angle, > 0.
        rtol: relative solver tolerance on the scaled state, > 0.
        atol: absolute solver tolerance on the scaled state (scaled units), > 0.
        max_steps: step budget of the solve.
        throw: see [`AbstractObjective`][optim.objective.AbstractObjective].

    Raises:
        ParameterError: for an empty window or a non-positive sample density.
    """

    t_start: float = eqx.field(static=True, default=0.1)
    t_end: float = eqx.field(static=True, default=0.3)
    samples_per_degree: float = eqx.field(static=True, default=10.0)
    rtol: float = eqx.field(static=True, default=DEFAULTS.rtol)
    atol: float = eqx.field(static=True, default=DEFAULTS.atol)
    max_steps: int = eqx.field(static=True, default=DEFAULTS.max_steps)
    throw: bool = eqx.field(static=True, default=True)

    def __check_init__(self):
        _check_window(self.t_start, self.t_end, self.samples_per_degree)

    def grid(self, mech: Mechanism) -> W.Grid:
        """The sample grid ([`optim.windows.sample_grid`][])."""
        return W.sample_grid(mech, self.t_start, self.t_end, self.samples_per_degree)

    def solve(self, mech: Mechanism, throw: bool):
        """The stored solve ([`optim.windows.stored_solve`][]) and the sample index of t_start."""
        opts = dict(rtol=self.rtol, atol=self.atol, max_steps=self.max_steps)
        return W.stored_solve(mech, self.grid(mech), opts, throw)

    def evaluate(self, mech: Mechanism) -> tuple[dict[str, Float[Array, ""]], jax.Array]:
        """The RMS metrics and whether the solve succeeded, never raising (batch callers
        report failures; failed designs' metrics are NaN)."""
        sim, n0 = self.solve(mech, False)
        sig = W.rms_signal_values(mech, sim.ts[n0 + 1 :], sim.ys[n0 + 1 :])
        values = {k: safe_sqrt(jnp.mean(v**2)) for k, v in sig.items()}
        ok = sim.ok & jnp.all(jnp.stack([jnp.isfinite(v) for v in values.values()]))
        return {k: jnp.where(ok, v, jnp.nan) for k, v in values.items()}, ok

    def rms(self, mech: Mechanism) -> dict[str, Float[Array, ""]]:
        if not self.throw:
            return self.evaluate(mech)[0]
        sim, n0 = self.solve(mech, True)
        sig = W.rms_signal_values(mech, sim.ts[n0 + 1 :], sim.ys[n0 + 1 :])
        return {k: safe_sqrt(jnp.mean(v**2)) for k, v in sig.items()}

    def forward_mode(self) -> bool:
        return False

    def describe(self) -> dict:
        return {"kind": "pathwise", **_fields(self)}


class Ensemble(AbstractObjective):
    """The exact metrics over the window ``(t_start, t_end]`` of one forward solve, with
    the ensemble-sensitivity gradient of K short windows re-solved from the forward
    solve's states ([`optim.windows`][]; a trend estimate, first order: do not take
    second derivatives of it).

    Attributes:
        t_start: start of the evaluation window (t_start, t_end], s (default 0.1: the
            window is the second and third revolutions at 600 rpm).
        t_end: end of the evaluation window, s (default 0.3).
        samples_per_degree: samples per degree of crank angle, > 0.
        window: length of each ensemble window, s; rounded to whole sample steps and
            shrunk to divide the evaluation window; in (0, t_end - t_start].
        windows: number of ensemble windows, spread evenly (0: all, tiling the window).
        window_max_steps: step budget of each window; a window that exceeds it is left
            out of the ensemble (more than half failing is an error, or NaN).
        window_solver: solver of the windows (a name of
            `jaxcrank.numerics.solve.SOLVERS` or a diffrax solver instance). An
            L-stable one: an explicit solver's step sequence sits at its stability limit
            in stick phases and the derivative of its discrete solution then blows up in
            about 1 % of windows (docs/optimisation.md, "The gradient").
        window_adjoint: diffrax adjoint of the windows: ``diffrax.ForwardMode()``
            (differentiate with [`value_and_grad`][optim.objective.value_and_grad] / ``jax.jacfwd``) or
            ``diffrax.RecursiveCheckpointAdjoint()`` (``jax.grad``).
        rtol: relative solver tolerance on the scaled state, > 0.
        atol: absolute solver tolerance on the scaled state (scaled units), > 0.
        max_steps: step budget of the long solve.
        throw: see [`AbstractObjective`][optim.objective.AbstractObjective].

    Raises:
        ParameterError: for an empty window, a window outside it, or an adjoint that is
            neither forward nor reverse mode.
    """

    t_start: float = eqx.field(static=True, default=0.1)
    t_end: float = eqx.field(static=True, default=0.3)
    samples_per_degree: float = eqx.field(static=True, default=10.0)
    window: float = eqx.field(static=True, default=2e-3)
    windows: int = eqx.field(static=True, default=25)
    window_max_steps: int = eqx.field(static=True, default=5_000)
    window_solver: object = eqx.field(static=True, default="rodas4")
    window_adjoint: diffrax.AbstractAdjoint = eqx.field(static=True, default=diffrax.ForwardMode())
    rtol: float = eqx.field(static=True, default=DEFAULTS.rtol)
    atol: float = eqx.field(static=True, default=DEFAULTS.atol)
    max_steps: int = eqx.field(static=True, default=DEFAULTS.max_steps)
    throw: bool = eqx.field(static=True, default=True)

    def __check_init__(self):
        _check_window(self.t_start, self.t_end, self.samples_per_degree)
        if not 0.0 < self.window <= self.t_end - self.t_start:
            raise ParameterError(
                f"ensemble window = {self.window:g} s must be in (0, t_end - t_start = {self.t_end - self.t_start:g}] s"
            )
        if not isinstance(self.window_adjoint, diffrax.ForwardMode | diffrax.RecursiveCheckpointAdjoint):
            raise ParameterError(
                f"window_adjoint = {self.window_adjoint!r} is not supported; valid: diffrax.ForwardMode() "
                "or diffrax.RecursiveCheckpointAdjoint()"
            )

    def grid(self, mech: Mechanism) -> W.Grid:
        """The sample grid with the ensemble windows ([`optim.windows.sample_grid`][])."""
        return W.sample_grid(mech, self.t_start, self.t_end, self.samples_per_degree, self.window)

    def _options(self) -> dict:
        return dict(rtol=self.rtol, atol=self.atol, max_steps=self.max_steps)

    def reference(self, mech: Mechanism) -> tuple[dict[str, Float[Array, ""]], W.Starts]:
        """One forward solve (no gradient, [`optim.windows.tracked_solve`][]): the
        exact RMS metrics (NaN where the solve failed and ``throw`` is False) and the
        [`Starts`][optim.windows.Starts] of the ensemble windows."""
        grid = self.grid(mech)
        mech = jax.lax.stop_gradient(mech)
        sim = W.tracked_solve(mech, grid, self.windows, self._options(), self.throw)
        exact = {k: jnp.where(sim.ok, sim.metrics[k], jnp.nan) for k in rms_metrics(mech)}
        return jax.lax.stop_gradient(exact), W.window_starts(sim)

    def window_sums(
        self, mech: Mechanism, starts: W.Starts, i, grid: W.Grid | None = None
    ) -> tuple[dict[str, Float[Array, ""]], jax.Array]:
        """Window ``i`` re-solved for ``mech`` from the carried-over start state: the
        sums of squares of the RMS metrics' signals over its samples (units squared; 0
        where the window failed) and whether it finished. ``grid``: the sample grid of
        the base design (default [`grid`][optim.objective.Ensemble.grid] of ``mech``, which needs a concrete
        ``driver.speed``)."""
        grid = self.grid(mech) if grid is None else grid
        ts, ys, ok = W.solve_window(
            mech,
            starts,
            i,
            grid,
            solver=self.window_solver,
            adjoint=self.window_adjoint,
            options=dict(rtol=self.rtol, atol=self.atol),
            max_steps=self.window_max_steps,
        )
        sig = W.rms_signal_values(mech, ts, ys)
        return {k: jnp.where(ok, jnp.sum(v**2), 0.0) for k, v in sig.items()}, ok

    def pooled(self, mech: Mechanism, starts: W.Starts) -> dict[str, Float[Array, ""]]:
        """The RMS metrics pooled over the windows re-solved for ``mech`` from the fixed
        ``starts``; their derivative is the ensemble sum of the windows' derivatives."""
        n_window = self.grid(mech).n_window
        sums, ok = W.over_windows(lambda i: self.window_sums(mech, starts, i), starts)
        n_ok = W.windows_ok(ok, self.throw)
        return {k: safe_sqrt(jnp.sum(jnp.where(ok, v, 0.0)) / (n_window * n_ok)) for k, v in sums.items()}

    def rms(self, mech: Mechanism) -> dict[str, Float[Array, ""]]:
        exact, starts = self.reference(mech)
        surrogate = self.pooled(mech, starts)
        return {k: straight_through(exact[k], surrogate[k]) for k in rms_metrics(mech)}

    def forward_mode(self) -> bool:
        return isinstance(self.window_adjoint, diffrax.ForwardMode)

    def describe(self) -> dict:
        d = {"kind": "ensemble", **_fields(self)}
        d["window_adjoint"] = "forward" if self.forward_mode() else "reverse"
        if not isinstance(d["window_solver"], str):
            d["window_solver"] = type(d["window_solver"]).__name__
        return d


def eq19(objective: AbstractObjective, mech: Mechanism) -> Float[Array, ""]:
    """Eq. 19 of ``mech`` by ``objective``, degrees."""
    return objective.rms(mech)[EQ19]


def value_and_grad(fun, forward: bool):
    """``fun``'s value and gradient with respect to its first argument (a vector),
    by ``jax.jacfwd`` (``forward``: one tangent per entry) or ``jax.value_and_grad``.
    ``fun`` returns a scalar."""
    if not forward:
        return jax.value_and_grad(fun)

    def both(x, *args):
        def with_value(x):
            v = fun(x, *args)
            return v, v

        grad, v = jax.jacfwd(with_value, has_aux=True)(x)
        return v, grad

    return both
