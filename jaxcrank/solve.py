"""Solving the equations of motion with diffrax.

Every numerical choice is an argument of :func:`simulate` with a default; none
lives in the physics parameters. Tolerances act on the dimensionless state of
:func:`jaxcrank.model.state_scales` (lengths in clearances, velocities in
clearance x crank speed), so ``rtol = atol = 1e-6`` asks for a local error of about
1e-6 of the clearance per step. The start-up impacts amplify it: over the first
10 ms of the paper run the slider position is 1.2 um off at 1e-6 and 7 nm off at
1e-7 (``bench/work_precision.py``); after that the motion is chaotic.
"""

from __future__ import annotations

import math
from typing import Any

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx

from . import model
from .linalg import DenseInverse
from .rosenbrock import Rodas4
from .params import Mechanism

SOLVERS = {
    "kvaerno5": diffrax.Kvaerno5,
    "kvaerno4": diffrax.Kvaerno4,
    "kvaerno3": diffrax.Kvaerno3,
    "rodas4": Rodas4,
    "tsit5": diffrax.Tsit5,
    "dopri5": diffrax.Dopri5,
    "dopri8": diffrax.Dopri8,
}
DEFAULT_SOLVER = "tsit5"


class SimulationError(RuntimeError):
    """A solve could not finish; the message says what to change."""


class Simulation(eqx.Module):
    """The result of :func:`simulate`.

    Attributes:
        mechanism: the parameters that were simulated.
        ts: sample times, s, shape (n,).
        ys: scaled state at the sample times, shape (n, state size).
        result: diffrax result code (``diffrax.RESULTS``).
        num_steps: accepted steps. num_rejected: rejected steps.
    """

    mechanism: Mechanism
    ts: jax.Array
    ys: jax.Array
    result: Any
    num_steps: jax.Array
    num_rejected: jax.Array

    @property
    def ok(self):
        return self.result == diffrax.RESULTS.successful


def make_solver(name: str = DEFAULT_SOLVER):
    """A diffrax solver by name (``SOLVERS``). The implicit Runge-Kutta ones (Kvaerno)
    use diffrax's chord Newton method at the step-size controller's tolerances, with
    :class:`jaxcrank.linalg.DenseInverse` for its linear solves instead of lineax's
    LU, a LAPACK call that keeps XLA from compiling the solver loop into one kernel."""
    if name not in SOLVERS:
        raise ValueError(f"solver {name!r} is unknown; valid names: {', '.join(SOLVERS)}")
    cls = SOLVERS[name]
    if issubclass(cls, diffrax.AbstractImplicitSolver):
        chord = diffrax.with_stepsize_controller_tols(diffrax.VeryChord)(linear_solver=DenseInverse())
        return cls(root_finder=chord)
    return cls()


def _controller(solver, rtol, atol):
    implicit = isinstance(solver, diffrax.AbstractImplicitSolver)
    # PI control damps step-size oscillation on stiff problems (Hairer & Wanner IV.8).
    pcoeff, icoeff = (0.3, 0.3) if implicit else (0.0, 1.0)
    return diffrax.PIDController(rtol=rtol, atol=atol, pcoeff=pcoeff, icoeff=icoeff, norm=optx.rms_norm)


@eqx.filter_jit
def _solve(mech, ts, y0, solver, controller, dt0, max_steps, adjoint, progress_meter):
    term = diffrax.ODETerm(model.vector_field)
    y0 = model.initial_state(mech) if y0 is None else y0
    sol = diffrax.diffeqsolve(
        term, solver, ts[0], ts[-1], dt0, y0, args=mech,
        saveat=diffrax.SaveAt(ts=ts), stepsize_controller=controller, adjoint=adjoint,
        max_steps=max_steps, throw=False, progress_meter=progress_meter,
    )
    return Simulation(mech, sol.ts, sol.ys, sol.result, sol.stats["num_accepted_steps"], sol.stats["num_rejected_steps"])


def sample_times(mech: Mechanism, t1=None, n_samples=None, t0=0.0):
    """Equally spaced sample times (equal crank-angle steps), s. Defaults: four
    revolutions (0.4 s at 600 rpm), one sample every 0.1 degree of crank angle."""
    period = 2.0 * math.pi / float(mech.crank_speed)
    t1 = 4.0 * period if t1 is None else float(t1)
    if n_samples is None:
        n_samples = int(round((t1 - t0) / period * 3600)) + 1
    return jnp.linspace(t0, t1, n_samples)


def simulate(mech: Mechanism, t1=None, *, ts=None, n_samples=None, y0=None, solver=DEFAULT_SOLVER,
             rtol=1e-6, atol=1e-6, dt0=1e-6, max_steps=500_000, adjoint=None,
             progress=False, throw=True) -> Simulation:
    """Simulate the clearance mechanism from pins-centred rest relative to the
    ideal motion (or from ``y0``).

    Args:
        mech: the mechanism.
        t1: end time, s (default four revolutions). Ignored when ``ts`` is given.
        ts: sample times, s, increasing, starting at the initial time.
        n_samples: number of equally spaced samples (default one per 0.1 deg of crank).
        y0: scaled state at ``ts[0]`` (default :func:`jaxcrank.model.initial_state`,
            pins centred). Restart a run from ``sim.ys[i]`` at ``sim.ts[i]``.
        solver: a name in ``SOLVERS`` or a diffrax solver instance.
        rtol, atol: error tolerances on the dimensionless state.
        dt0: initial step, s.
        max_steps: step budget; exceeding it raises (``throw=True``).
        adjoint: diffrax adjoint (default ``RecursiveCheckpointAdjoint``, exact
            reverse-mode gradients of the discrete solve). For ``jax.jacfwd`` /
            ``jax.jvp`` pass ``diffrax.ForwardMode()``: with a few parameters it is
            the cheaper gradient (two parameters: 5.3x the forward solve against
            8.2x for reverse mode, ``bench/bench_solvers.py``).
        progress: show a tqdm progress bar (host callback; CLI runs).
        throw: raise :class:`SimulationError` when the solve fails or produces
            non-finite values. With ``throw=False`` inspect ``Simulation.ok``
            (batch sweeps).

    Works under ``jax.jit``, ``jax.grad`` and ``jax.vmap`` (with ``throw=True``
    inside a trace, failures raise through ``equinox.error_if``).
    """
    if ts is None:
        ts = sample_times(mech, t1, n_samples)
    ts = jnp.asarray(ts, dtype=float)
    if isinstance(solver, str):
        solver = make_solver(solver)
    controller = _controller(solver, rtol, atol)
    adjoint = diffrax.RecursiveCheckpointAdjoint() if adjoint is None else adjoint
    meter = diffrax.TqdmProgressMeter(refresh_steps=5000) if progress else diffrax.NoProgressMeter()
    sim = _solve(mech, ts, y0, solver, controller, dt0, max_steps, adjoint, meter)
    if throw:
        sim = check(sim, max_steps=max_steps)
    return sim


def check(sim: Simulation, max_steps=None) -> Simulation:
    """Raise :class:`SimulationError` with advice if ``sim`` failed or is not finite."""
    finite = jnp.all(jnp.isfinite(sim.ys))
    if isinstance(finite, jax.core.Tracer):  # inside jit/grad/vmap: fail at run time
        ys = eqx.error_if(sim.ys, sim.result != diffrax.RESULTS.successful,
                          "jaxcrank: the solve did not finish (step budget or step size); "
                          "raise max_steps, loosen rtol/atol or use a smoother friction law")
        ys = eqx.error_if(ys, jnp.invert(finite), "jaxcrank: the solve produced non-finite values")
        return eqx.tree_at(lambda s: s.ys, sim, ys)
    if sim.result == diffrax.RESULTS.max_steps_reached:
        raise SimulationError(
            f"the solver used all max_steps={max_steps} steps before reaching t1 = {float(sim.ts[-1]):g} s. "
            "Raise max_steps, shorten t1, loosen rtol/atol, or widen the friction ramp "
            "(friction.slip_speed - friction.stick_speed) to make the problem less stiff."
        )
    if sim.result != diffrax.RESULTS.successful:
        raise SimulationError(
            f"the solve failed: {sim.result.__str__()}. Try a tighter dt0, the implicit solver "
            "'kvaerno5', tighter rtol/atol, or check that the contact parameters are physical."
        )
    if not bool(finite):
        raise SimulationError(
            "the solve produced non-finite values (NaN/inf). Check the parameters (e.g. a huge "
            "stiffness or tiny memory_time), or tighten rtol/atol."
        )
    return sim
