"""One design of a sweep: how it is simulated (:class:`Settings`), its solve
(:func:`simulate_design`) and its status codes (:data:`STATUSES`)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import diffrax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, Int

from . import config
from ..analysis.metrics import METRICS
from ..physics.params import Mechanism, ParameterError, set_parameters
from ..numerics.solve import DEFAULTS, SolveOptions, simulate

#: Status of a design in a sweep table; :func:`simulate_design` returns an index into it.
STATUSES = ("ok", "max_steps", "solver_failed", "non_finite", "invalid")
#: What a failed design's ``message`` cell says, per status.
MESSAGES = {
    "max_steps": "the solver used its whole step budget: raise max_steps, shorten the run or loosen rtol/atol",
    "solver_failed": "the solve failed (step size): try solver='kvaerno5' or check the contact parameters",
    "non_finite": "the solve produced non-finite values: check stiffness, memory_time and tolerances",
}


@dataclasses.dataclass(frozen=True)
class Settings:
    """How every design of a sweep is simulated.

    Attributes:
        revolutions: simulated crank revolutions from the pins-centred start
            (default 4: the paper run, 0.4 s at 600 rpm).
        samples_per_revolution: output samples per revolution (3600: every 0.1 deg,
            as ``jaxcrank simulate``); peaks are taken over these samples.
        metrics_from_revolution: metrics cover t > this many revolutions (default 1).
        solver, rtol, atol, max_steps: the fields of :class:`jaxcrank.numerics.solve.SolveOptions`
            (same defaults), flat here so a sweep spec's ``[simulation]`` table names them.

    Raises:
        ParameterError: for a setting out of its range.
    """

    revolutions: float = 4.0
    samples_per_revolution: int = 3600
    metrics_from_revolution: float = 1.0
    solver: str = DEFAULTS.solver
    rtol: float = DEFAULTS.rtol
    atol: float = DEFAULTS.atol
    max_steps: int = DEFAULTS.max_steps

    def __post_init__(self):
        for name in ("revolutions", "samples_per_revolution", "metrics_from_revolution", "rtol", "atol", "max_steps"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) or not math.isfinite(v):
                raise ParameterError(f"{name} = {v!r} must be a finite number")
        if not self.revolutions > 0:
            raise ParameterError(f"revolutions = {self.revolutions:g} must be > 0")
        if not 0 <= self.metrics_from_revolution < self.revolutions:
            raise ParameterError(
                f"metrics_from_revolution = {self.metrics_from_revolution:g} must be in "
                f"[0, revolutions = {self.revolutions:g})"
            )
        if int(self.samples_per_revolution) < 4:
            raise ParameterError(f"samples_per_revolution = {self.samples_per_revolution} must be >= 4")
        _ = self.options  # validates solver, rtol, atol and max_steps

    @property
    def options(self) -> SolveOptions:
        """The solver settings as :class:`jaxcrank.numerics.solve.SolveOptions`."""
        return DEFAULTS.replace(solver=self.solver, rtol=self.rtol, atol=self.atol, max_steps=self.max_steps)

    @property
    def n_samples(self) -> int:
        """Number of output samples, the start included."""
        return int(round(self.revolutions * self.samples_per_revolution)) + 1

    def sample_times(self, mech: Mechanism) -> Float[Array, " samples"]:
        """The output sample times of ``mech``'s run, s (traceable in the crank speed)."""
        return jnp.linspace(0.0, self.revolutions, self.n_samples) * mech.period

    def metrics_start(self, mech: Mechanism) -> Float[ArrayLike, ""]:
        """Start of the metrics window, s: the metrics cover samples with t > this."""
        return self.metrics_from_revolution * mech.period


def simulate_design(
    base: Mechanism, names: Sequence[str], x: Float[ArrayLike, " params"], settings: Settings = Settings()
) -> tuple[dict[str, Float[Array, ""]], Int[Array, ""], Int[Array, ""]]:
    """One design: ``base`` with ``names`` set to ``x`` (SI), simulated with
    ``throw=False``. Returns (metrics dict, status code (index into
    :data:`STATUSES`), accepted steps). Traceable; :func:`run` vmaps it."""
    mech = set_parameters(base, names, x)
    # metrics tracked during the solve: no sample is stored (memory per design is
    # independent of samples_per_revolution)
    sim = simulate(
        mech,
        settings.revolutions * mech.period,
        n_samples=settings.n_samples,
        options=settings.options,
        throw=False,
        metrics_start=settings.metrics_start(mech),
        save_samples=False,
    )
    m = {k: sim.metrics[k] for k in METRICS}
    finite = jnp.all(jnp.isfinite(sim.ys)) & jnp.all(jnp.isfinite(jnp.stack(list(m.values()))))
    status = jnp.where(
        sim.ok, jnp.where(finite, 0, 3), jnp.where(sim.result == diffrax.RESULTS.max_steps_reached, 1, 2)
    )
    return m, status, sim.num_steps


def validate(mech: Mechanism) -> Mechanism:
    """Re-check every parameter of ``mech`` (raises :class:`ParameterError` naming
    the parameter and its range): ``set_parameter`` does not re-validate."""
    return config.from_dict(config.to_dict(mech))
