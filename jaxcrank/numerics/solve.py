"""Solving the equations of motion with diffrax.

Every numerical choice is an argument of [`simulate`][jaxcrank.numerics.solve.simulate] with a default; none
lives in the physics parameters. Tolerances act on the dimensionless state of
[`jaxcrank.physics.model.state_scales`][jaxcrank.physics.state.state_scales] (lengths in clearances, velocities in
clearance x crank speed), so ``rtol = atol = 1e-6`` asks for a local error of about
1e-6 of the clearance per step; impacts amplify it (the docs' benchmarks page gives
the measured global error).
"""

from __future__ import annotations

import dataclasses
import math
import numbers
import sys

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, ArrayLike, Float, Int

from .. import _private
from ..physics import model
from ..physics.linkage import AbstractMechanism as Mechanism
from ..physics.parameters import check_values
from ..physics.params import ParameterError
from . import tracking
from .linalg import DenseInverse
from .results import RESULTS
from .rosenbrock import Rodas4

#: Solver names, for text only (TOML files, the CLI): name -> diffrax solver class.
#: :func:`solver_from_name` turns a name into the instance the library takes.
SOLVERS = {
    "kvaerno5": diffrax.Kvaerno5,
    "kvaerno4": diffrax.Kvaerno4,
    "kvaerno3": diffrax.Kvaerno3,
    "rodas4": Rodas4,
    "tsit5": diffrax.Tsit5,
    "dopri5": diffrax.Dopri5,
    "dopri8": diffrax.Dopri8,
}


def solver_from_name(name: str) -> diffrax.AbstractAdaptiveSolver:
    """The diffrax solver named ``name`` (a key of `SOLVERS`): where text comes
    in (TOML files, the CLI). The implicit Runge-Kutta ones (Kvaerno) use diffrax's
    chord Newton method at the step-size controller's tolerances, with
    [`jaxcrank.numerics.linalg.DenseInverse`][] for its linear solves instead of
    lineax's LU, a LAPACK call that keeps XLA from compiling the solver loop into one
    kernel.

    Raises:
        ParameterError: for an unknown name (the message lists the valid ones).
    """
    if not isinstance(name, str) or name not in SOLVERS:
        raise ParameterError(f"solver {name!r} is unknown; valid: {', '.join(SOLVERS)}")
    cls = SOLVERS[name]
    if issubclass(cls, diffrax.AbstractImplicitSolver):
        chord = diffrax.with_stepsize_controller_tols(diffrax.VeryChord)(linear_solver=DenseInverse())
        return cls(root_finder=chord)
    return cls()


def solver_name(solver: diffrax.AbstractSolver) -> str:
    """The `SOLVERS` name of a solver instance (for text out: summaries, TOML),
    or its class name for a solver that has none."""
    for name, cls in SOLVERS.items():
        if type(solver) is cls:
            return name
    return type(solver).__name__


@dataclasses.dataclass(frozen=True)
class SolveOptions:
    """The numerical settings of a solve: the one place their defaults live
    ([`simulate`][jaxcrank.numerics.solve.simulate], sweeps, design objectives and the CLI all start from these).

    Attributes:
        solver: a diffrax adaptive solver instance (default ``diffrax.Tsit5()``);
            text names (TOML, CLI) go through [`solver_from_name`][jaxcrank.numerics.solve.solver_from_name].
        rtol: relative error tolerance on the dimensionless state
            ([`jaxcrank.physics.model.state_scales`][jaxcrank.physics.state.state_scales]), > 0.
        atol: absolute error tolerance on the dimensionless state (scaled units), > 0.
        dt0: initial step, s, > 0.
        max_steps: step budget (accepted and rejected steps), >= 1.

    Raises:
        ParameterError: for a solver that is not a diffrax adaptive solver instance
            (a name among them: the message says how to turn it into one) or a
            non-positive setting.
    """

    solver: diffrax.AbstractAdaptiveSolver = diffrax.Tsit5()
    rtol: float = 1e-6
    atol: float = 1e-6
    dt0: float = 1e-6
    max_steps: int = 500_000

    def __post_init__(self):
        if isinstance(self.solver, str):
            hint = f"solver_from_name({self.solver!r})" if self.solver in SOLVERS else "a diffrax solver instance"
            raise ParameterError(
                f"solver = {self.solver!r} is a name: pass {hint} (names, for text input: {', '.join(SOLVERS)})"
            )
        if not isinstance(self.solver, diffrax.AbstractAdaptiveSolver):
            raise ParameterError(
                f"solver = {self.solver!r} must be a diffrax adaptive solver instance, e.g. diffrax.Tsit5()"
            )
        for name in ("rtol", "atol", "dt0"):
            value = getattr(self, name)
            if isinstance(value, bool) or not (isinstance(value, numbers.Real) and math.isfinite(value) and value > 0):
                raise ParameterError(f"{name} = {value!r} must be a finite number > 0")
        steps = self.max_steps
        if isinstance(steps, bool) or not (isinstance(steps, numbers.Integral) and steps >= 1):
            raise ParameterError(f"max_steps = {self.max_steps!r} must be an integer >= 1")

    @classmethod
    def from_text(cls, solver: str | None = None, **changes) -> SolveOptions:
        """The defaults with ``changes``, the solver given by name (TOML files, the
        CLI; [`solver_from_name`][jaxcrank.numerics.solve.solver_from_name]). ``None`` values are ignored."""
        return DEFAULTS.replace(solver=None if solver is None else solver_from_name(solver), **changes)

    @property
    def solver_name(self) -> str:
        """The solver's name ([`solver_name`][jaxcrank.numerics.solve.SolveOptions.solver_name]), for text out."""
        return solver_name(self.solver)

    def replace(self, **changes) -> SolveOptions:
        """A copy with the given fields changed (``None`` values are ignored)."""
        return dataclasses.replace(self, **{k: v for k, v in changes.items() if v is not None})


DEFAULTS = SolveOptions()


class SimulationError(RuntimeError):
    """A solve could not finish; the message says what to change."""


class Simulation(eqx.Module):
    """The result of [`simulate`][jaxcrank.numerics.solve.simulate].

    Attributes:
        mechanism: the parameters that were simulated.
        ts: sample times, s, shape (n,) (the end time alone, shape (1,), when the
            samples were not saved; the ``save_ts`` of [`simulate`][jaxcrank.numerics.solve.simulate] when given).
        ys: scaled state at those times, shape (n, state size).
        result: a [`RESULTS`][jaxcrank.numerics.results.RESULTS] item (diffrax's result, promoted).
        num_steps: accepted steps. num_rejected: rejected steps.
        metrics: the headline metrics tracked during the solve
            ([`jaxcrank.numerics.tracking.finish`][]: name -> value, units in the name), or
            ``None`` when the solve did not track them (``metrics_start=None``).
    """

    mechanism: Mechanism
    ts: Float[Array, " n"]
    ys: Float[Array, "n state"]
    result: RESULTS
    num_steps: Int[Array, ""]
    num_rejected: Int[Array, ""]
    metrics: dict | None = None

    @property
    def ok(self):
        return self.result == RESULTS.successful


def step_size_controller(solver, rtol, atol):
    """The adaptive step-size controller [`simulate`][jaxcrank.numerics.solve.simulate] uses with ``solver``: PI
    control for implicit solvers, I control for explicit ones; RMS norm of the scaled
    error; ``rtol``, ``atol`` on the dimensionless state."""
    implicit = isinstance(solver, diffrax.AbstractImplicitSolver)
    # PI control damps step-size oscillation on stiff problems (Hairer & Wanner IV.8).
    pcoeff, icoeff = (0.3, 0.3) if implicit else (0.0, 1.0)
    return diffrax.PIDController(rtol=rtol, atol=atol, pcoeff=pcoeff, icoeff=icoeff, norm=optx.rms_norm)


def _with_tolerances(solver, controller):
    """An implicit solver's root finder with the controller's tolerances and norm
    filled in where it takes them from the controller (what ``diffeqsolve`` does for
    an implicit solver it sees; a [`MetricsTracking`][jaxcrank.numerics.tracking.MetricsTracking]
    wrapper hides the solver from that check)."""
    if not isinstance(solver, diffrax.AbstractImplicitSolver):
        return solver
    finder = solver.root_finder
    names = [n for n in ("rtol", "atol", "norm") if _private.is_stepsize_controller_tolerance(getattr(finder, n))]
    return eqx.tree_at(
        lambda s: tuple(getattr(s.root_finder, n) for n in names), solver, tuple(getattr(controller, n) for n in names)
    )


@eqx.filter_jit
def _solve(mech, ts, span, y0, solver, controller, dt0, max_steps, adjoint, progress_meter, metrics_start):
    """``mech``: the mechanism as given (kept in the result); ``ts``: the sample times to
    save (None: only the end state); ``span``: the first and last sample time and their
    count (the samples tracked metrics visit)."""
    term = diffrax.ODETerm(model.vector_field)
    compiled = model.compile_model(mech)
    y0 = model.initial_state(compiled) if y0 is None else y0
    first, last, count = span
    tracked = metrics_start is not None
    if tracked:
        solver = tracking.MetricsTracking(
            _with_tolerances(solver, controller), first, last, count, t_start=jnp.asarray(metrics_start, dtype=float)
        )
    saveat = (
        diffrax.SaveAt(ts=ts, solver_state=tracked) if ts is not None else diffrax.SaveAt(t1=True, solver_state=tracked)
    )
    sol = diffrax.diffeqsolve(
        term,
        solver,
        first,
        last,
        dt0,
        y0,
        args=compiled,
        saveat=saveat,
        stepsize_controller=controller,
        adjoint=adjoint,
        max_steps=max_steps,
        throw=False,
        progress_meter=progress_meter,
    )
    tracked_metrics = None
    if tracked:
        tracked_metrics = {
            "window_start_s": jnp.asarray(metrics_start, dtype=float),
            **tracking.finish(sol.solver_state[1], compiled),
        }
    return Simulation(
        mech,
        sol.ts,
        sol.ys,
        RESULTS.promote(sol.result),
        sol.stats["num_accepted_steps"],
        sol.stats["num_rejected_steps"],
        tracked_metrics,
    )


def as_values(mech: Mechanism) -> Mechanism:
    """``mech`` with every number that is not zero as a float64 array: the values of a
    compiled program, not constants in it, so one program serves every design of a
    structure (``simulate(as_values(mech), ...)`` compiles once for a loop over designs;
    the command line's programs are made so, and kept in the cache). Zeros stay numbers
    (a point on a body's axis, a driver starting at angle 0): known at trace time, they
    cost no operation ([`jaxcrank.physics.safemath`][]), and a design that makes one
    nonzero has a program of its own. [`simulate`][jaxcrank.numerics.solve.simulate] of a
    mechanism of plain numbers compiles them in as constants, which XLA can fold, and
    every design compiles anew."""

    def value(leaf):
        if isinstance(leaf, (float, np.floating)) and leaf != 0.0:
            return jnp.asarray(leaf, dtype=float)
        return leaf

    return jax.tree_util.tree_map(value, mech)


def lax_solver(options):
    """The solver of ``options`` with its Runge-Kutta stages in a plain ``lax`` loop:
    ``ForwardMode`` sets that on the solver it sees, but the metrics-tracking wrapper
    hides the solver from it, and the checkpointed default loop has no forward mode."""
    solver = options.solver
    if hasattr(solver, "scan_kind"):
        solver = eqx.tree_at(lambda s: s.scan_kind, solver, "lax", is_leaf=lambda x: x is None)
    return solver


def sample_times(mech: Mechanism, t1=None, n_samples=None, t0=0.0):
    """Equally spaced sample times (equal steps of the driver's nominal angle), s.
    Defaults: four revolutions (0.4 s at 600 rpm), one sample every 0.1 degree. With ``t1`` and
    ``n_samples`` given, the driver's period is not read (it may be traced: ``jax.grad`` with
    respect to the driver's speed); a default needs it concrete.

    Raises:
        ParameterError: a default needed while the driver's period is traced."""
    if t1 is not None and n_samples is not None:
        return jnp.linspace(t0, t1, n_samples)
    if isinstance(mech.period, jax.core.Tracer):
        raise ParameterError("the driver's speed is traced: give simulate t1 and n_samples (or ts), not its defaults")
    period = float(mech.period)
    t1 = 4.0 * period if t1 is None else t1
    if n_samples is None:
        n_samples = int(round((float(t1) - t0) / period * 3600)) + 1
    return jnp.linspace(t0, t1, n_samples)


def _check_equally_spaced(ts):
    if ts.shape[0] < 2:
        raise ParameterError(f"tracking metrics needs at least 2 sample times, got {ts.shape[0]}")
    if isinstance(ts, jax.core.Tracer):
        return  # built by a traced caller (sweeps): equally spaced by construction
    steps = jnp.diff(ts)
    if not bool(jnp.all(jnp.abs(steps - steps[0]) <= 1e-9 * jnp.abs(steps[0]))):
        raise ParameterError("tracking metrics (metrics_start) needs equally spaced sample times ts")


def simulate(
    mech: Mechanism,
    t1=None,
    *,
    ts: Float[ArrayLike, " n"] | None = None,
    n_samples=None,
    y0: Float[ArrayLike, " state"] | None = None,
    options: SolveOptions = DEFAULTS,
    adjoint=None,
    progress=False,
    throw=True,
    metrics_start=None,
    save_samples=True,
    save_ts: Float[ArrayLike, " m"] | None = None,
) -> Simulation:
    """Simulate a mechanism with clearance joints from pins-centred rest relative to the
    ideal motion (or from ``y0``).

    Args:
        mech: the mechanism.
        t1: end time, s (default four revolutions). Ignored when ``ts`` is given.
        ts: sample times, s, increasing, starting at the initial time. Without it,
            ``n_samples`` equally spaced times from 0 to ``t1``.
        n_samples: number of equally spaced samples (default one per 0.1 deg of the
            driven body's nominal rotation).
        y0: scaled state at ``ts[0]`` (default
            [`jaxcrank.physics.model.initial_state`][jaxcrank.physics.state.initial_state] ,
            pins centred). Restart a run from ``sim.ys[i]`` at ``sim.ts[i]``.
        options: the numerical settings ([`SolveOptions`][jaxcrank.numerics.solve.SolveOptions]: solver,
            rtol, atol, dt0, max_steps); change one with ``DEFAULTS.replace(rtol=1e-8)``, or
            name the solver with ``SolveOptions.from_text("rodas4")``.
        adjoint: diffrax adjoint (default ``RecursiveCheckpointAdjoint``, exact
            reverse-mode gradients of the discrete solve). For ``jax.jacfwd`` /
            ``jax.jvp`` pass ``diffrax.ForwardMode()``: with a few parameters it is
            the cheaper gradient.
        progress: show a tqdm progress bar where standard error is a terminal (host
            callback; CLI runs); elsewhere nothing (the caller prints its phases).
        metrics_start: when given (s), the solve tracks the headline metrics over
            ``t > metrics_start`` ([`jaxcrank.numerics.tracking`][]: peaks at every accepted
            step, RMS over the sample times, which must then be equally spaced) into
            ``Simulation.metrics``. Forward mode only (no reverse-mode gradient
            through the tracking).
        save_samples: store the state at every sample time (default); ``False``
            keeps only the end state (with ``metrics_start``: memory independent of
            the number of samples).
        save_ts: store the state at these times only, s (increasing, within the
            solve's span), instead of at every sample time: e.g. a few restart points
            of a solve whose metrics are tracked over all of ``ts``.
        throw: raise [`SimulationError`][jaxcrank.numerics.solve.SimulationError] when the solve fails or produces
            non-finite values. With ``throw=False`` inspect ``Simulation.ok``
            (batch sweeps).

    Works under ``jax.jit``, ``jax.grad`` and ``jax.vmap`` (with ``throw=True``
    inside a trace, failures raise through ``equinox.error_if``).
    """
    check_values(mech)  # its numbers, as its constructors check them (eqx.tree_at skips those)
    model.compile_model(mech)  # the description's structure and assembly, checked before anything is traced
    if ts is None and not save_samples and metrics_start is not None:
        # only the span: no array of sample times is built (traceable in t1)
        if n_samples is None:
            raise ParameterError("simulate(save_samples=False, ts=None) needs n_samples")
        last = 4.0 * mech.period if t1 is None else t1
        span = (jnp.asarray(0.0), jnp.asarray(last, dtype=float), int(n_samples))
    else:
        ts = sample_times(mech, t1, n_samples) if ts is None else ts
        ts = jnp.asarray(ts, dtype=float)
        span = (ts[0], ts[-1], int(ts.shape[0]))
    if not isinstance(options, SolveOptions):
        raise ParameterError(f"options = {options!r} must be a SolveOptions (jaxcrank.SolveOptions(rtol=..., ...))")
    solver, rtol, atol, dt0, max_steps = options.solver, options.rtol, options.atol, options.dt0, options.max_steps
    controller = step_size_controller(solver, rtol, atol)
    adjoint = diffrax.RecursiveCheckpointAdjoint() if adjoint is None else adjoint
    if metrics_start is not None and isinstance(adjoint, diffrax.ForwardMode):
        solver = lax_solver(options)  # the tracking wrapper hides the solver from ForwardMode
    # a bar on a terminal only: elsewhere (a log, a pipe) its carriage-return redraws would fill it with lines
    bar = progress and bool(getattr(sys.stderr, "isatty", lambda: False)())
    meter = diffrax.TqdmProgressMeter(refresh_steps=5000) if bar else diffrax.NoProgressMeter()
    if metrics_start is not None:
        metrics_start = jnp.asarray(metrics_start, dtype=float)  # traced: one compilation for any window
        if ts is not None:
            _check_equally_spaced(ts)
        elif span[2] < 2:
            raise ParameterError(f"tracking metrics needs n_samples >= 2, got {span[2]}")
    saved = ts if save_samples else None
    if save_ts is not None:
        saved = jnp.atleast_1d(jnp.asarray(save_ts, dtype=float))
    sim = _solve(mech, saved, span, y0, solver, controller, dt0, max_steps, adjoint, meter, metrics_start)
    if throw:
        sim = check(sim, max_steps=max_steps, t1=span[1])
    return sim


def _progress(sim: Simulation, t1) -> str:
    """Where a failed solve stopped, as a clause: the requested end time ``t1`` (s;
    None: not known) and the last sample time the solve reached (after a failure
    diffrax fills the samples it did not reach with inf)."""
    ts = np.asarray(sim.ts)
    reached = ts[np.isfinite(ts)]
    wanted = "the end time" if t1 is None else f"the requested end time t1 = {float(t1):g} s"
    if reached.size == 0:
        return f"before reaching {wanted} (it saved no sample)"
    return (
        f"before reaching {wanted} (the last sample it reached is t = {float(reached[-1]):g} s, "
        f"sample {reached.size} of {ts.size})"
    )


def check(sim: Simulation, max_steps=None, t1=None) -> Simulation:
    """Raise [`SimulationError`][jaxcrank.numerics.solve.SimulationError] with advice if ``sim`` failed or is not
    finite.

    Args:
        sim: a solve made with ``throw=False``.
        max_steps: the step budget it had (named in the message).
        t1: the requested end time, s (named in the message with the time the
            solve reached).

    Returns ``sim`` unchanged when it succeeded (inside a trace: with run-time checks).
    """
    finite = jnp.all(jnp.isfinite(sim.ys))
    if isinstance(finite, jax.core.Tracer):  # inside jit/grad/vmap: fail at run time
        ys = eqx.error_if(
            sim.ys,
            sim.result != RESULTS.successful,
            "jaxcrank: the solve did not finish (step budget or step size); "
            "raise max_steps, loosen rtol/atol or use a smoother friction law",
        )
        ys = eqx.error_if(ys, jnp.invert(finite), "jaxcrank: the solve produced non-finite values")
        return eqx.tree_at(lambda s: s.ys, sim, ys)
    if sim.result == RESULTS.max_steps_reached:
        raise SimulationError(
            f"the solver used all max_steps={max_steps} steps {_progress(sim, t1)}. "
            "Raise max_steps, shorten t1, loosen rtol/atol, or widen the friction ramp "
            "(friction.slip_speed - friction.stick_speed) to make the problem less stiff."
        )
    if sim.result != RESULTS.successful:
        raise SimulationError(
            f"the solve failed ({sim.result.__str__()}) {_progress(sim, t1)}. "
            "Try a tighter dt0, the implicit solver "
            "'kvaerno5', tighter rtol/atol, or check that the contact parameters are physical."
        )
    if not bool(finite):
        raise SimulationError(
            "the solve produced non-finite values (NaN/inf). Check the parameters (e.g. a huge "
            "stiffness or tiny memory_time), or tighten rtol/atol."
        )
    return sim
