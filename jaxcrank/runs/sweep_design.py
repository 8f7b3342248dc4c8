"""One design of a sweep: how it is simulated ([`SweepSettings`][jaxcrank.runs.sweep_design.SweepSettings]), its solve
([`simulate_design`][jaxcrank.runs.sweep_design.simulate_design]) and its status: a code of
[`jaxcrank.numerics.results.RESULTS`][], labelled in tables by
[`status_label`][jaxcrank.numerics.results.status_label]."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, Int

from ..numerics import results
from ..numerics.results import RESULTS
from ..numerics.solve import DEFAULTS, SolveOptions, simulate
from ..physics.linkage import AbstractMechanism as Mechanism
from ..physics.parameters import set_parameters
from ..physics.params import ParameterError
from ..physics.signals import metric_definitions
from . import config

#: the labels of a sweep table's ``status`` column
STATUSES = results.STATUSES


def metric_names(mech: Mechanism) -> tuple[str, ...]:
    """The headline metrics a sweep over ``mech`` reports, in table order: every metric of
    [`jaxcrank.physics.signals.metric_definitions`][] (units in the names). A swept
    parameter never changes them (names come from the description, values are numbers)."""
    return tuple(metric_definitions(mech))


#: the ``[simulation]`` keys of a sweep spec that are :class:`jaxcrank.numerics.solve.SolveOptions` fields
SOLVE_KEYS = ("solver", "rtol", "atol", "max_steps")


@dataclasses.dataclass(frozen=True)
class SweepSettings:
    """How every design of a sweep is simulated (also reachable as ``Settings``).

    Attributes:
        revolutions: simulated crank revolutions from the pins-centred start
            (default 4: the paper run, 0.4 s at 600 rpm).
        samples_per_revolution: output samples per revolution (3600: every 0.1 deg,
            as ``jaxcrank simulate``); peaks are taken over these samples.
        metrics_from_revolution: metrics cover t > this many revolutions (default 1).
        options: the solver settings ([`jaxcrank.numerics.solve.SolveOptions`][],
            default `jaxcrank.numerics.solve.DEFAULTS`).

    Raises:
        ParameterError: for a setting out of its range.
    """

    revolutions: float = 4.0
    samples_per_revolution: int = 3600
    metrics_from_revolution: float = 1.0
    options: SolveOptions = DEFAULTS

    def __post_init__(self):
        for name in ("revolutions", "samples_per_revolution", "metrics_from_revolution"):
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
        if not isinstance(self.options, SolveOptions):
            raise ParameterError(f"options = {self.options!r} must be a jaxcrank.SolveOptions")

    @classmethod
    def from_text(cls, table: Mapping) -> SweepSettings:
        """Settings from a sweep spec's ``[simulation]`` table: the fields above but
        ``options``, and the solver settings `SOLVE_KEYS` (the solver by name).

        Raises:
            ParameterError: for an unknown key (the message lists the valid ones) or a
                value out of its range.
        """
        own = [f.name for f in dataclasses.fields(cls) if f.name != "options"]
        valid = sorted(own + list(SOLVE_KEYS))
        if set(table) - set(valid):
            raise ParameterError(f"unknown [simulation] keys {sorted(set(table) - set(valid))}; valid: {valid}")
        solve_changes = {k: table[k] for k in SOLVE_KEYS if k in table}
        for k, v in solve_changes.items():
            if v is None:
                raise ParameterError(f"{k} = {v!r} must be set")
        options = SolveOptions.from_text(**solve_changes)
        return cls(**{k: table[k] for k in own if k in table}, options=options)

    def to_text(self) -> dict:
        """The flat ``[simulation]`` table of [`from_text`][jaxcrank.runs.sweep_design.SweepSettings.from_text] (solver
        by name)."""
        return {
            "revolutions": self.revolutions,
            "samples_per_revolution": self.samples_per_revolution,
            "metrics_from_revolution": self.metrics_from_revolution,
            "solver": self.options.solver_name,
            "rtol": self.options.rtol,
            "atol": self.options.atol,
            "max_steps": self.options.max_steps,
        }

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
    base: Mechanism, names: Sequence[str], x: Float[ArrayLike, " params"], settings: SweepSettings | None = None
) -> tuple[dict[str, Float[Array, ""]], Int[Array, ""], Int[Array, ""]]:
    """One design: ``base`` with ``names`` set to ``x`` (SI), simulated with
    ``throw=False``. Returns (metrics dict in the order of
    [`metric_names`][jaxcrank.runs.sweep_design.metric_names], status code (of
    [`jaxcrank.numerics.results.RESULTS`][]: the solve's result, or ``non_finite``), accepted
    steps). Traceable; `run` vmaps it."""
    settings = SweepSettings() if settings is None else settings
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
    m = {k: sim.metrics[k] for k in metric_names(mech)}
    finite = jnp.all(jnp.isfinite(sim.ys)) & jnp.all(jnp.isfinite(jnp.stack(list(m.values()))))
    status = jnp.where(sim.ok & jnp.invert(finite), results.code(RESULTS.non_finite), results.code(sim.result))
    return m, status, sim.num_steps


def validate(mech: Mechanism) -> Mechanism:
    """Re-check every parameter of ``mech`` (raises [`ParameterError`][jaxcrank.physics.params.ParameterError] naming
    the parameter and its range): ``set_parameter`` does not re-validate."""
    return config.from_dict(config.to_dict(mech))


#: The name sweeps have used for :class:`SweepSettings`.
Settings = SweepSettings


def split_valid(
    base: Mechanism, names: Sequence[str], designs: np.ndarray, done: set[int] = frozenset()
) -> tuple[list[int], list[tuple[int, str]]]:
    """The designs (rows of ``designs``, SI values of ``names`` on ``base``) not in ``done``,
    split by [`validate`][jaxcrank.runs.sweep_design.validate]: the indices to solve, and
    ``(index, message)`` of the invalid ones, the message giving the values and the error."""
    todo, invalid = [], []
    for i in range(len(designs)):
        if i in done:
            continue
        try:
            validate(set_parameters(base, list(names), [float(v) for v in designs[i]]))
            todo.append(i)
        except ParameterError as err:
            given = ", ".join(f"{n} = {v:g}" for n, v in zip(names, designs[i]))
            invalid.append((i, f"{given}: {err}"))
    return todo, invalid
