"""The objectives of design problems: each kind a final Module of
[`AbstractObjective`][optim.objective.AbstractObjective] (`Pathwise` here, `Ensemble` in
[`optim.ensemble`][], `Steady` in [`optim.steady`][]), and the ``[objective]`` tables of
config files that describe them ([`optim.objective_config`][]).

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
[`optim.ensemble.Ensemble`][]
    The exact metrics of one forward solve over the window, with the
    ensemble-sensitivity gradient ([`optim.ensemble`][]): a trend estimate, finite on
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
import dataclasses
import math
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from jaxcrank.numerics.solve import DEFAULTS, Simulation, SolveOptions, simulate, solver_from_name
from jaxcrank.physics import model, signals
from jaxcrank.physics.drivers import ConstantSpeed
from jaxcrank.physics.linkage import AbstractMechanism as Mechanism
from jaxcrank.physics.params import ParameterError

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
        """The settings as a dict of plain values: ``kind`` and the flat keys of an
        ``[objective]`` table (the fields, and the options objects' settings, the solver by
        name), for reports and the CLI's resolved configuration."""


def _check_window(t_start, t_end, samples_per_degree):
    if not 0.0 <= t_start < t_end:
        raise ParameterError(
            f"objective window must satisfy 0 <= t_start < t_end, got t_start = {t_start:g} s, t_end = {t_end:g} s"
        )
    if samples_per_degree <= 0:
        raise ParameterError(f"samples_per_degree = {samples_per_degree:g} must be positive")


def _fields(obj) -> dict:
    return {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj) if not f.name.endswith("options")}


#: the flat keys of a ``SolveOptions`` in an ``[objective]`` table
SOLVE_KEYS = ("solver", "rtol", "atol", "dt0", "max_steps")


def options_from_fields(values: dict, base: SolveOptions, prefix: str = "") -> SolveOptions:
    """``base`` changed by the flat keys ``prefix + SOLVE_KEYS`` of ``values``, which are
    popped (the inverse of [`options_fields`][optim.objective.options_fields]; the solver by name).

    Raises:
        ParameterError: for an unknown solver name or a setting out of its range."""
    changes = {k: values.pop(prefix + k) for k in SOLVE_KEYS if prefix + k in values}
    solver = changes.pop("solver", None)
    return base.replace(solver=None if solver is None else solver_from_name(solver), **changes)


def options_fields(options: SolveOptions, prefix: str = "") -> dict:
    """``options`` as plain values (the solver by name), each key prefixed: the flat keys
    of an ``[objective]`` table."""
    return {
        f"{prefix}solver": options.solver_name,
        f"{prefix}rtol": options.rtol,
        f"{prefix}atol": options.atol,
        f"{prefix}dt0": options.dt0,
        f"{prefix}max_steps": options.max_steps,
    }


class Grid(NamedTuple):
    """The sample grid of an evaluation window ``(t_start, t_end]`` at equal crank-angle steps.

    Attributes:
        n_start: sample index of t_start.
        n_eval: number of samples in (t_start, t_end].
        n_window: samples per ensemble window (a divisor of ``n_eval``).
        dt: the sample step, s.
    """

    n_start: int
    n_eval: int
    n_window: int
    dt: float


def sample_grid(
    mech: Mechanism, t_start: float, t_end: float, samples_per_degree: float, window: float | None = None
) -> Grid:
    """The [`Grid`][optim.objective.Grid] of the window ``(t_start, t_end]`` (s) with ``samples_per_degree``
    samples per degree of the driven body's angle; ``window`` (s) is the ensemble windows' length,
    rounded to whole sample steps and shrunk to divide the evaluation window.

    Raises:
        ParameterError: the driver is not a [`jaxcrank.ConstantSpeed`][jaxcrank.physics.drivers.ConstantSpeed]
            (equal times are equal driver angles only at constant speed), or ``mech.driver.speed``
            is not concrete (a traced design variable).
    """
    if not isinstance(mech.driver, ConstantSpeed):
        raise ParameterError(
            f"the windowed objectives sample at equal driver angles and need a constant-speed driver "
            f"(jaxcrank.ConstantSpeed), not {type(mech.driver).__name__}; use the steady-state objective"
        )
    try:
        omega = float(mech.driver.speed)
    except (TypeError, jax.errors.ConcretizationTypeError):
        raise ParameterError(
            "the objective's sample grid needs a concrete driver.speed: build the "
            "mechanism inside the traced function from a fixed base design"
        ) from None
    dt = math.radians(1.0 / samples_per_degree) / omega
    n_start = int(round(t_start / dt))
    n_eval = int(round((t_end - t_start) / dt))
    n_window = n_eval if window is None else max(1, int(round(window / dt)))
    if n_eval % n_window:
        # shrink the window to the nearest divisor of the evaluation window
        k = max(1, round(n_eval / n_window))
        while n_eval % k:
            k += 1
        n_window = n_eval // k
    return Grid(n_start, n_eval, n_window, dt)


def rms_signal_values(mech: Mechanism, ts: Float[ArrayLike, " n"], ys: Float[ArrayLike, "n state"]) -> dict:
    """The per-sample signals behind the mechanism's RMS metrics
    ([`jaxcrank.physics.signals.rms_metrics`][]) at sample times ``ts`` (s) with scaled states
    ``ys``: RMS metric name -> (n,) signal in the metric's unit (deg, m, N m, N)."""
    definitions = signals.metric_definitions(mech)
    names = signals.rms_metrics(mech)

    def one(t, y):
        sig = signals.signals(mech, model.evaluate(mech, t, y))
        return {name: sig[definitions[name].signal] for name in names}

    return jax.vmap(one)(jnp.asarray(ts), jnp.asarray(ys))


def stored_solve(mech: Mechanism, grid: Grid, options: SolveOptions, throw: bool) -> tuple[Simulation, int]:
    """One solve with ``options`` from the pins-centred start that stores every sample of
    ``grid``: the simulation and the sample index of t_start (the samples in (t_start,
    t_end] follow it). Differentiable in reverse mode."""
    ts = grid.dt * jnp.arange(grid.n_start + grid.n_eval + 1, dtype=float)
    return simulate(mech, ts=ts, throw=throw, options=options), grid.n_start


class Pathwise(AbstractObjective):
    """The metrics over the window ``(t_start, t_end]`` of one solve from the
    pins-centred start, with their exact reverse-mode gradient (module docstring).

    Attributes:
        t_start: start of the evaluation window (t_start, t_end], s, >= 0.
        t_end: end of the evaluation window, s, > t_start.
        samples_per_degree: samples per degree of crank angle, > 0.
        options: the solve's settings ([`jaxcrank.SolveOptions`][jaxcrank.numerics.solve.SolveOptions]).
        throw: see [`AbstractObjective`][optim.objective.AbstractObjective].

    Raises:
        ParameterError: for an empty window or a non-positive sample density.
    """

    t_start: float = eqx.field(static=True, default=0.1)
    t_end: float = eqx.field(static=True, default=0.3)
    samples_per_degree: float = eqx.field(static=True, default=10.0)
    options: SolveOptions = eqx.field(static=True, default=DEFAULTS)
    throw: bool = eqx.field(static=True, default=True)

    def __check_init__(self):
        _check_window(self.t_start, self.t_end, self.samples_per_degree)

    def grid(self, mech: Mechanism) -> Grid:
        """The sample grid ([`sample_grid`][optim.objective.sample_grid])."""
        return sample_grid(mech, self.t_start, self.t_end, self.samples_per_degree)

    def solve(self, mech: Mechanism, throw: bool):
        """The stored solve ([`stored_solve`][optim.objective.stored_solve]) and the sample index of t_start."""
        return stored_solve(mech, self.grid(mech), self.options, throw)

    def evaluate(self, mech: Mechanism) -> tuple[dict[str, Float[Array, ""]], jax.Array]:
        """The RMS metrics and whether the solve succeeded, never raising (batch callers
        report failures; failed designs' metrics are NaN)."""
        sim, n0 = self.solve(mech, False)
        sig = rms_signal_values(mech, sim.ts[n0 + 1 :], sim.ys[n0 + 1 :])
        values = {k: safe_sqrt(jnp.mean(v**2)) for k, v in sig.items()}
        ok = sim.ok & jnp.all(jnp.stack([jnp.isfinite(v) for v in values.values()]))
        return {k: jnp.where(ok, v, jnp.nan) for k, v in values.items()}, ok

    def rms(self, mech: Mechanism) -> dict[str, Float[Array, ""]]:
        if not self.throw:
            return self.evaluate(mech)[0]
        sim, n0 = self.solve(mech, True)
        sig = rms_signal_values(mech, sim.ts[n0 + 1 :], sim.ys[n0 + 1 :])
        return {k: safe_sqrt(jnp.mean(v**2)) for k, v in sig.items()}

    def forward_mode(self) -> bool:
        return False

    def describe(self) -> dict:
        return {"kind": "pathwise", **_fields(self), **options_fields(self.options)}


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
