"""Calibrate a mechanism's parameters (clearances, restitution, friction, stiffness, ...)
against a measured trace, by least squares with the exact Jacobian.

**The model trace.** At a design x (values of the named parameters, SI), the model's signal
is computed where the machine runs for hours: on its **steady periodic orbit**
([`jaxcrank.numerics.steady.steady_state`][], warm-started from the last periodic design).
The orbit is solved once more from its start state
([`orbit_start`][jaxcrank.numerics.steady.orbit_start]), saving the state exactly at the
measured samples' instants within the revolution ([`optim.trace.phase_times`][]: the crank
angle modulo 360 deg), so no interpolation enters. For a period-k orbit the trace's revolutions
are matched to the orbit's in the rotation (of k) that fits best.

**The exact Jacobian.** ``jax.jacfwd`` of the signal at those instants through the solve, with
the orbit's start state differentiated by the implicit function theorem,
``dy*/dp = (I - M)^-1 dPhi^k/dp`` (M: the monodromy matrix): the derivative of the periodic
orbit itself, not of a run from rest. One compiled program per orbit structure (period and
dynamic subspace) serves every design.

**Not periodic.** A design with no attracting periodic orbit has no steady trace to compare
with. Its model trace is then a **window of a run from rest**: the revolution after
``window_revolutions`` revolutions from pins-centred rest (default: the settle's
``settle_revolutions``), with the Jacobian of that run. Such a motion does not repeat, so the
comparison depends on the revolution chosen; the result says so, and no parameter counts as
identified there. A fit that started periodic refuses steps out of the periodic regime.

**The fit.** Residuals ``(model - measured) / noise`` (``noise``: the measurement's noise
scale in the signal's unit, default the measured signal's RMS); bounded Levenberg-Marquardt
([`optim.least_squares.levenberg_marquardt`][]) in scaled variables (``ln(x / start)`` for a
parameter whose lower bound is positive, ``(x - start) / |start|`` otherwise); 95 % intervals,
singular values and identifiability from the Jacobian at the fit
([`optim.least_squares.intervals`][]).
"""

from __future__ import annotations

import dataclasses
import math
import sys
import time
from collections.abc import Sequence

import diffrax
import jax
import jax.numpy as jnp
import numpy as np

from jaxcrank.numerics import steady as S
from jaxcrank.numerics.shooting import SteadyOptions, lax_solver
from jaxcrank.numerics.solve import simulate
from jaxcrank.physics import model
from jaxcrank.physics.parameters import set_parameter, set_parameters
from jaxcrank.physics.params import ParameterError
from jaxcrank.runs.config import dumps

from .steady import warm_solve
from .trace import Trace, check_signal, model_signal, phase_times

#: the fit's steady-state settings: periods up to 2 revolutions; solves at rtol = atol = 1e-8 with
#: Newton to 1e-6 (scaled units; half the cost of the library's 1e-10, the model trace equal to about
#: 1e-6 of the signal); 2 revolutions of statistics where not periodic (only the Lyapunov exponent is
#: reported there); the orbit's own samples are only its metrics' (the trace is sampled at the
#: measured instants)
FIT_STEADY = SteadyOptions(
    max_period=2, newton_tol=1e-6, statistics_revolutions=2, batch_revolutions=1, samples_per_revolution=36
).replace(rtol=1e-8, atol=1e-8)
PERIODIC = "periodic"
#: compiled model-trace programs: (mechanism, parameters, signal, options, orbit structure, instants) -> program
_PROGRAMS: dict = {}


def forget_programs() -> None:
    """Drop every compiled model-trace program, so the next evaluation compiles its own
    (benchmarks that count compilation in each method's time)."""
    _PROGRAMS.clear()


@dataclasses.dataclass(frozen=True)
class FitParameter:
    """One fitted parameter: a name [`jaxcrank.set_parameter`][jaxcrank.physics.parameters.set_parameter]
    accepts (``clearance_B``, ``contact.restitution``, ``joints.C.contact.stiffness``, ...), its
    start and bounds, SI.

    Raises:
        ParameterError: bounds not finite or not ordered, or a start outside them (the message
            names the parameter and the range)."""

    name: str
    start: float
    lower: float
    upper: float

    def __post_init__(self):
        values = (self.start, self.lower, self.upper)
        if not all(isinstance(v, (int, float)) and math.isfinite(v) for v in values):
            raise ParameterError(f"parameter {self.name!r}: start, lower and upper must be finite numbers: {values}")
        if not self.lower < self.upper:
            raise ParameterError(f"parameter {self.name!r}: lower = {self.lower:g} must be < upper = {self.upper:g}")
        if not self.lower <= self.start <= self.upper:
            raise ParameterError(
                f"parameter {self.name!r}: start = {self.start:g} is outside its bounds "
                f"[lower, upper] = [{self.lower:g}, {self.upper:g}]"
            )

    @property
    def log(self) -> bool:
        """Whether the fit works in ``ln(x / start)`` (a positive lower bound)."""
        return self.lower > 0

    @property
    def scale(self) -> float:
        return abs(self.start) if self.start != 0 else self.upper - self.lower

    def scaled(self, x) -> np.ndarray:
        """The fit's variable of SI value ``x``."""
        return np.log(np.asarray(x) / self.start) if self.log else (np.asarray(x) - self.start) / self.scale

    def si(self, u) -> np.ndarray:
        """The SI value of the fit's variable ``u``."""
        return self.start * np.exp(np.asarray(u)) if self.log else self.start + self.scale * np.asarray(u)


@dataclasses.dataclass(frozen=True)
class Evaluation:
    """The model trace at one design.

    Attributes:
        x: the design, SI (p,).
        model: the model's signal at the samples, the signal's unit (n,).
        residuals: ``(model - measured) / noise`` (n,).
        jacobian: d residuals / d x, 1 / SI unit of each parameter (n, p); None when not asked for.
        regime: ``"periodic"``, ``"not periodic"`` or ``"failed"``.
        period_revolutions: the orbit's period (0 when not periodic).
        shift: period k > 1: the orbit revolution the trace's first revolution is matched to.
        source: ``"steady orbit"``, ``"window of a run from rest"``, ``"failed"`` or ``"not computed"``
            (a refused trial step out of the periodic regime).
        lyapunov_exponent_per_s: of the steady state, 1/s.
    """

    x: np.ndarray
    model: np.ndarray
    residuals: np.ndarray
    jacobian: np.ndarray | None
    regime: str
    period_revolutions: int
    shift: int
    source: str
    lyapunov_exponent_per_s: float

    @property
    def misfit(self) -> float:
        """The sum of squared residuals (inf when not finite)."""
        m = float(np.sum(self.residuals**2))
        return m if math.isfinite(m) else math.inf

    def info(self) -> dict:
        return {"regime": self.regime, "period_revolutions": self.period_revolutions, "shift": self.shift}


class Calibration:
    """The model trace of a mechanism at the instants of a measured trace, with its exact
    Jacobian in the named parameters (module docstring).

    Args:
        base: the mechanism; the fitted parameters are set on it.
        parameters: the [`FitParameter`][optim.calibrate.FitParameter]s.
        trace: the measured [`Trace`][optim.trace.Trace].
        noise: the noise scale, the signal's unit (default: the measured signal's RMS).
        options: the steady-state settings (default `FIT_STEADY`).
        window_revolutions: not periodic: revolutions from rest before the window (default
            ``options.settle_revolutions``).
        check_bounds: set each parameter at its bounds on ``base`` first, so that a bound the
            mechanism refuses is named at once (default).

    Raises:
        ParameterError: an unknown signal column or parameter name (or a driver parameter:
            the driver's motion aligns the trace), a bound the mechanism refuses, a parameter
            named twice, fewer samples than parameters + 1, or a noise scale that is not > 0."""

    def __init__(
        self,
        base,
        parameters: Sequence[FitParameter],
        trace: Trace,
        *,
        noise: float | None = None,
        options: SteadyOptions = FIT_STEADY,
        window_revolutions: int | None = None,
        check_bounds: bool = True,
    ):
        self.base, self.parameters, self.trace, self.options = base, tuple(parameters), trace, options
        self.names = tuple(p.name for p in self.parameters)
        if not self.names:
            raise ParameterError("no parameter to fit: name at least one ([parameters.<name>] start, lower, upper)")
        if len(set(self.names)) != len(self.names):
            raise ParameterError(f"a parameter is named twice: {list(self.names)}")
        for p in self.parameters:
            if p.name.startswith("driver."):
                raise ParameterError(f"parameter {p.name!r}: the driver's motion aligns the trace; it is not fitted")
            # a bound the mechanism refuses is refused here, by name
            for value in (p.lower, p.upper) if check_bounds else (p.start,):
                try:
                    set_parameter(base, p.name, value)
                except ParameterError as err:
                    raise ParameterError(f"parameter {p.name!r} at {value:g}: {err}") from None
        check_signal(base, trace.signal)
        if trace.n <= len(self.names):
            raise ParameterError(
                f"trace {trace.signal!r}: {trace.n} samples for {len(self.names)} parameters; at least "
                f"{len(self.names) + 1} needed (many more for useful intervals)"
            )
        rms = float(np.sqrt(np.mean(trace.values**2)))
        self.noise = (rms if rms > 0 else 1.0) if noise is None else float(noise)
        if not (math.isfinite(self.noise) and self.noise > 0):
            raise ParameterError(f"noise = {noise!r} must be a finite number > 0 (the signal's unit)")
        self.window_revolutions = options.settle_revolutions if window_revolutions is None else int(window_revolutions)
        if self.window_revolutions < 1:
            raise ParameterError(f"window_revolutions = {window_revolutions!r} must be >= 1")
        self.phase, self.turns = phase_times(base, trace)
        self._instants, self._which = np.unique(self.phase, return_inverse=True)
        self._steady, self.last = {}, None
        try:  # what a compiled program bakes in: calibrations that agree on it share their programs
            mechanism = dumps(base)
        except (ParameterError, TypeError, ValueError):
            mechanism = id(self)
        self._identity = (mechanism, self.names, trace.signal, options, self.window_revolutions)
        self.evaluations, self.compile_seconds = 0, 0.0

    def mechanism(self, x):
        """The mechanism at SI design ``x`` (traceable)."""
        return set_parameters(self.base, self.names, x)

    def steady_at(self, x, again: bool = True) -> S.SteadyState:
        """The steady state at SI design ``x`` (the last few cached), warm-started from the last
        periodic one; a warm start that finds no orbit without a full settle is redone from rest
        (``again``; without it, such a design counts as not periodic)."""
        key = tuple(float(v) for v in np.asarray(x, dtype=float))
        if key not in self._steady:
            mech = self.mechanism(jnp.asarray(key))
            steady = warm_solve(
                lambda warm: S.steady_state(mech, self.options, warm_start=warm, throw=False),
                self.last,
                self.options.settle_revolutions,
                again=again,
            )
            if steady.periodic:
                self.last = steady
            if len(self._steady) >= 4:
                self._steady.pop(next(iter(self._steady)))
            self._steady[key] = steady
        return self._steady[key]

    def _values(self, mech, y0, ts, flat, revolutions: int):
        """The signal at ``ts[flat]`` of the solve from scaled state ``y0`` at t = 0 over
        ``revolutions`` revolutions (the window's: twice the steps the settle may take; traceable)."""
        o = self.options.solve
        o = o.replace(solver=lax_solver(o), max_steps=o.max_steps * (2 if revolutions > 2 else 1))
        sim = simulate(mech, ts=ts, y0=y0, options=o, throw=False, adjoint=diffrax.ForwardMode())
        frames = jax.vmap(model.evaluate, in_axes=(None, 0, 0))(mech, sim.ts[flat], sim.ys[flat])
        return jnp.where(sim.ok, model_signal(mech, frames, self.trace.signal), jnp.nan)

    def _program(self, steady: S.SteadyState | None, jacobian: bool, args):
        """The compiled signal (and Jacobian) at the measured instants: on the orbit of
        ``steady``'s period and dynamic subspace (args: design, section state, monodromy), or
        in the window of a run from rest (``steady`` None; args: design). Compiled at its first
        use (timed into ``compile_seconds``) and shared by calibrations of the same mechanism,
        parameters, signal, settings and sample instants."""
        k = steady.period_revolutions if steady is not None else 1
        period, u = float(self.base.period), self._instants
        if steady is None:
            needed = (self.window_revolutions * period + u)[None, :]
        else:
            needed = u[None, :] + period * np.arange(k, dtype=float)[:, None]
        key = (self._identity, k, steady.active if steady is not None else None, jacobian, needed.tobytes())
        if key not in _PROGRAMS:
            ts = np.unique(np.concatenate([[0.0], needed.ravel()]))
            flat = np.searchsorted(ts, needed.ravel())
            ts = jnp.asarray(ts)
            template = None
            if steady is not None:
                template = dataclasses.replace(
                    steady, mechanism=None, orbit=None, statistics=None, metrics={}, revolutions={}
                )

            def values(x, *orbit):
                mech = self.mechanism(x)
                if template is None:
                    y0 = model.initial_state(mech)
                else:
                    light = dataclasses.replace(template, section_state=orbit[0], monodromy=orbit[1])
                    y0 = S.orbit_start(mech, light)
                revolutions = self.window_revolutions + 1 if template is None else k
                return self._values(mech, y0, ts, flat, revolutions).reshape(needed.shape)

            f = values
            if jacobian:
                f = lambda x, *orbit: jax.jacfwd(lambda x_: (lambda v: (v, v))(values(x_, *orbit)), has_aux=True)(x)
            if len(_PROGRAMS) >= 8:
                _PROGRAMS.pop(next(iter(_PROGRAMS)))
            tic = time.perf_counter()
            _PROGRAMS[key] = jax.jit(f).lower(*args).compile()
            self.compile_seconds += time.perf_counter() - tic
        return _PROGRAMS[key]

    def evaluate(self, x, jacobian: bool = True, periodic_only: bool = False) -> Evaluation:
        """The model trace at SI design ``x``: on the steady orbit (periodic), in a window of a
        run from rest (not periodic), NaN (the solve failed); with the exact Jacobian when asked.
        ``periodic_only``: a design whose warm-started steady state is not periodic gets NaN at
        once (neither solved again from rest nor simulated: a trial step the fit refuses anyway)."""
        x = np.asarray(x, dtype=float)
        self.evaluations += 1
        steady = self.steady_at(x, again=not periodic_only)
        n, p = self.trace.n, x.size
        lyapunov = float(steady.lyapunov_exponent_per_s)
        if not steady.ok or (periodic_only and not steady.periodic):
            nan, jac = np.full(n, np.nan), np.full((n, p), np.nan) if jacobian else None
            regime = str(steady.regime) if steady.ok else "failed"
            return Evaluation(x, nan, nan, jac, regime, 0, 0, "not computed" if steady.ok else "failed", lyapunov)
        orbit = steady if steady.periodic else None
        args = (jnp.asarray(x),) + ((steady.section_state, steady.monodromy) if orbit is not None else ())
        out = self._program(orbit, jacobian, args)(*args)
        J, V = (np.asarray(out[0]), np.asarray(out[1])) if jacobian else (None, np.asarray(out))
        k = V.shape[0]
        best = None
        for shift in range(k):  # a period-k orbit: the rotation of its revolutions that fits best
            rows = (self.turns + shift) % k
            model_ = V[rows, self._which]
            residuals = (model_ - self.trace.values) / self.noise
            cost = float(np.sum(residuals**2))
            if best is None or (math.isfinite(cost) and not cost >= best[0]):
                jac = J[rows, self._which] / self.noise if J is not None else None
                best = (cost, shift, model_, residuals, jac)
        _, shift, model_, residuals, jac = best
        regime = PERIODIC if steady.periodic else str(steady.regime)
        source = "steady orbit" if steady.periodic else "window of a run from rest"
        return Evaluation(x, model_, residuals, jac, regime, int(steady.period_revolutions), shift, source, lyapunov)

    def misfit(self, x) -> float:
        """The sum of squared residuals at SI design ``x`` (no Jacobian; inf where the solve failed)."""
        return self.evaluate(x, jacobian=False).misfit


def say(text: str) -> None:
    """One progress line on standard error."""
    print(f"fit: {text}", file=sys.stderr, flush=True)


def model_trace(
    base,
    names: Sequence[str],
    x,
    signal: str,
    *,
    angle_deg=None,
    time_s=None,
    options: SteadyOptions = FIT_STEADY,
) -> tuple[Trace, Evaluation]:
    """The model's own trace of ``signal`` at SI design ``x`` of the parameters ``names``, at
    the given crank angles (deg) or times (s): a noise-free synthetic measurement (tests,
    benchmarks), and the [`Evaluation`][optim.calibrate.Evaluation] it came from (its regime:
    a trace of a design that is not periodic is a window of a run from rest).

    Raises:
        ParameterError: as [`Calibration`][optim.calibrate.Calibration]."""
    where = np.asarray(angle_deg if time_s is None else time_s, dtype=float)
    blank = Trace(signal, np.zeros(where.size), time_s=time_s, angle_deg=None if time_s is not None else angle_deg)
    x = np.asarray(x, dtype=float)
    params = [FitParameter(n, float(v), float(v) - 1.0 - abs(v), float(v) + 1.0 + abs(v)) for n, v in zip(names, x)]
    ev = Calibration(base, params, blank, noise=1.0, options=options, check_bounds=False).evaluate(x, jacobian=False)
    return dataclasses.replace(blank, values=ev.model), ev
