"""What a solve can end in, and what regime a design is in: one enumeration each.

[`RESULTS`][jaxcrank.numerics.results.RESULTS] extends diffrax's own ``diffrax.RESULTS`` (as diffrax extends
optimistix's) with jaxcrank's outcomes. A [`Simulation`][jaxcrank.numerics.solve.Simulation], a
[`SteadyState`][jaxcrank.numerics.steady.SteadyState], each design of a sweep or regime map and each design
of the compiled kernel carry one of its items, or its integer code in a batch
([`code`][jaxcrank.numerics.results.code]). Tables name a code with a short label
([`status_label`][jaxcrank.numerics.results.status_label]: ``ok``, ``max_steps``, ``solver_failed``,
``non_finite``, ``invalid``) and give its message, which says what to change.

[`Regime`][jaxcrank.numerics.results.Regime] names the long-run motion a design settles into; its members
are strings, so they compare with and serialise as ``"periodic"``, ``"not periodic"``
and ``"failed"``.
"""

from __future__ import annotations

import enum

import diffrax
from jaxtyping import Array, Int


class RESULTS(diffrax.RESULTS):  # pyright: ignore[reportGeneralTypeIssues]
    """Outcome of a solve, a steady state or a design of a batch: diffrax's items
    (``successful``, ``max_steps_reached``, ``dt_min_reached``, ...) and jaxcrank's
    below. The message of each says what to change."""

    non_finite = (
        "the solve produced non-finite values (NaN/inf): check the parameters (a huge contact stiffness, "
        "a tiny memory_time) or tighten rtol/atol"
    )
    invalid_parameters = "the design's parameters are out of their ranges (the message names the parameter)"
    settle_max_steps = (
        "a revolution used all options.max_steps solver steps: raise options.max_steps, or loosen "
        "options.rtol/atol (the section is then noisier: raise newton_tol with them)"
    )
    solve_failed = (
        "a solve failed or produced non-finite values: check the contact parameters, or try "
        "options.solver=diffrax.Kvaerno5() or tighter options.rtol/atol"
    )
    newton_not_converged = (
        "Newton shooting did not reach newton_tol within max_newton iterations: raise max_newton or "
        "settle_revolutions (a closer start), or raise newton_tol above the map's noise (about 100 x options.rtol)"
    )
    newton_diverged = (
        "Newton shooting diverged (the residual grew or became non-finite): raise settle_revolutions so "
        "the settle ends closer to the orbit, or lower recurrence_tol so that only a clear recurrence is shot"
    )


class Regime(enum.StrEnum):
    """The long-run motion of a design (a string: ``Regime.PERIODIC == "periodic"``)."""

    PERIODIC = "periodic"
    """The Poincare section recurs (a period-k orbit)."""
    NOT_PERIODIC = "not periodic"
    """No recurrence within the revolutions searched (quasi-periodic, chaotic, or a long transient)."""
    FAILED = "failed"
    """The solve failed, so the regime is not known (see the result's message)."""


def code(item) -> Int[Array, ...]:
    """The integer code of a [`RESULTS`][jaxcrank.numerics.results.RESULTS] item (an array of codes for a
    batched item): what batches of designs store."""
    return item._value


#: item name by integer code
NAMES = {int(i._value): name for name, i in RESULTS._name_to_item.items()}


def item(value: int) -> RESULTS:
    """The [`RESULTS`][jaxcrank.numerics.results.RESULTS] item with integer code ``value`` (inverse of
    [`code`][jaxcrank.numerics.results.code]).

    Raises:
        ValueError: for a code that is no item's."""
    if int(value) not in NAMES:
        raise ValueError(f"status code {value} is no item of RESULTS (valid: 0 to {len(RESULTS) - 1})")
    return getattr(RESULTS, NAMES[int(value)])


#: short labels of a table's ``status`` column, by item name; every other failure of the
#: ODE solver (step size, rejected steps, ...) reads ``solver_failed``
LABELS = {
    "successful": "ok",
    "max_steps_reached": "max_steps",
    "non_finite": "non_finite",
    "invalid_parameters": "invalid",
}
#: every label a table's ``status`` column can hold
STATUSES = ("ok", "max_steps", "solver_failed", "non_finite", "invalid")


def status_label(value: int) -> str:
    """The table label (one of `STATUSES`) of the integer code ``value``.

    Raises:
        ValueError: for a code that is no item's."""
    item(value)  # raises for an unknown code
    return LABELS.get(NAMES[int(value)], "solver_failed")


def message(value: int) -> str:
    """The message of the integer code ``value`` (empty for ``successful``): what to change.

    Raises:
        ValueError: for a code that is no item's."""
    return RESULTS[item(value)]
