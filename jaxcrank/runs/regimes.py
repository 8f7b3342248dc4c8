"""Steady-state regime maps of large batches: which designs settle into a periodic
motion, and of which period.

[`classify`][jaxcrank.runs.regimes.classify] runs the first two steps of
[`jaxcrank.numerics.steady.steady_state`][] on every design of a batch:

1. **settle**: ``settle_revolutions`` revolutions from pins-centred rest, keeping the
   scaled state once per revolution (the Poincare section, t = nT);
2. **detect a period**: the smallest k <= ``max_period`` with
   ``max |y_N - y_{N-k}| <= recurrence_tol`` over the dynamic entries (coordinates,
   rates and approach-speed memories; the works are left out), the one test both use
   ([`jaxcrank.numerics.shooting.recurrence`][]).

A design is ``"periodic"`` with ``period_revolutions = k`` when its section recurs,
``"not periodic"`` otherwise; no Newton shooting, no Floquet multipliers (those need the
JAX path's forward-mode derivatives, one design at a time: run ``steady_state`` on the
designs of interest). The classification therefore differs from ``steady_state``'s in
two ways, both about designs at the edge:

- a section that is still settling, closest recurrence between ``recurrence_tol`` and
  100 x ``recurrence_tol``, is ``"not periodic"`` here; ``steady_state`` shoots it and
  may find an attracting orbit (raise ``settle_revolutions`` to settle such designs);
- a recurrence is ``"periodic"`` here even where ``steady_state``'s Newton would fail or
  find the orbit unstable (a section that recurs after the settle is one the motion has
  settled onto, so this needs a near-neutral orbit).

**Engines.** ``"kernel"`` ([`jaxcrank.numerics.kernel`][]: one design per CPU thread)
solves one revolution per call, each design continuing from its previous section state
with t restarting at 0: the equations are periodic in t with the crank period and the
crank angle is not a state entry, so this is the same map; only the step-size controller
restarts (at ``options.dt0``) every revolution, which moves the section points by the
solve's noise (about 100 x ``rtol`` scaled units), far below ``recurrence_tol``. The
works keep accumulating, as in one long solve. ``"xla"`` solves each design's settle in
one [`jaxcrank.simulate`][jaxcrank.numerics.solve.simulate] saving the section times
(``steady_state``'s settle), ``chunk`` designs in a ``jax.vmap`` batch. ``None`` (the
default): the kernel where a C compiler is available and the solver is tsit5, and, resuming,
the engine the run in ``out`` was started with, as for a sweep
([`jaxcrank.runs.engines.resolve`][]).

**Chaotic transients.** The two engines round differently (as any two compiled
programs do), and a design whose motion from rest is chaotic for some revolutions
amplifies that difference to O(1) before it settles: each engine may then land on
another attractor, or still be in the transient after ``settle_revolutions``, and
classify the design differently. The classification of such a design is a property of
the run, not of the design; its ``recurrence_distance_scaled`` and a longer settle tell
the two apart. Designs whose motion settles without a chaotic phase (pins staying in
contact) classify alike in both.

**Defaults** are ``steady_state``'s: 20 settle revolutions, ``max_period = 4``,
``recurrence_tol = 1e-3`` (scaled units: clearances and clearance x crank speed) and
`jaxcrank.numerics.shooting.STEADY_DEFAULTS` (tsit5, rtol = atol =
1e-10, ``max_steps`` = 2,000,000 for the whole settle of a design), so both see the
same sections up to the solve's noise. The kernel solves with tsit5 only, which is
``steady_state``'s default solver too.

The table has the sweep's layout and statuses ([`jaxcrank.runs.sweep`][]): ``index``,
the parameters with their units, ``status`` (``ok``, ``max_steps``, ``solver_failed``,
``non_finite``, ``invalid``) and ``message``, then ``regime``, ``period_revolutions``,
``recurrence_distance_scaled`` (the smallest ``max |y_N - y_{N-k}|`` over k <=
``max_period``, scaled units) and ``steps`` (accepted solver steps of the settle). A
failed design's regime cells are empty. With ``out`` the table is appended to
``out/table.csv`` after every chunk and ``resume=True`` skips the designs already there
(the sweep's files and checks: [`jaxcrank.runs.sweep_table`][]).
"""

from __future__ import annotations

import functools
import math
import types
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from jaxtyping import ArrayLike, Float, Shaped

from ..numerics import results, shooting
from ..numerics.results import RESULTS, Regime
from ..numerics.shooting import STEADY_DEFAULTS
from ..numerics.solve import SolveOptions
from ..physics import model
from ..physics.linkage import AbstractMechanism as Mechanism
from ..physics.parameters import set_parameters
from ..physics.params import ParameterError
from . import programs
from .sweep_design import STATUSES, split_valid
from .sweep_table import (
    append,
    atomic_write,
    csv_text,
    open_table,
    parameter_columns,
    read_table,
    run_identity,
    table_from_rows,
)

#: the regimes (``""``: the design failed or is invalid)
REGIMES = (Regime.PERIODIC, Regime.NOT_PERIODIC)
#: the text columns of a regime table
TEXT_COLUMNS = ("status", "message", "regime")
_TAIL = ["status", "message", "regime", "period_revolutions", "recurrence_distance_scaled", "steps"]


def columns(mech: Mechanism, names: Sequence[str]) -> list[str]:
    """Column names of a regime table over ``names`` of ``mech``: ``index``, one
    ``<name>_<unit>`` per parameter, ``status``, ``message``, ``regime``,
    ``period_revolutions``, ``recurrence_distance_scaled``, ``steps``."""
    return ["index"] + parameter_columns(mech, names) + _TAIL


def _check(settle_revolutions, max_period, recurrence_tol, options, chunk):
    for name, value, low in (("settle_revolutions", settle_revolutions, 1), ("max_period", max_period, 1)):
        if isinstance(value, bool) or not (isinstance(value, (int, np.integer)) and value >= low):
            raise ParameterError(f"{name} = {value!r} must be an integer >= {low}")
    ok_tol = isinstance(recurrence_tol, (int, float)) and not isinstance(recurrence_tol, bool)
    if not (ok_tol and math.isfinite(recurrence_tol) and recurrence_tol > 0):
        raise ParameterError(
            f"recurrence_tol = {recurrence_tol!r} must be a finite number > 0 (scaled units: clearances)"
        )
    if not isinstance(options, SolveOptions):
        raise ParameterError(f"options = {options!r} must be a jaxcrank.SolveOptions")
    if chunk is not None and (isinstance(chunk, bool) or not (isinstance(chunk, (int, np.integer)) and chunk >= 1)):
        raise ParameterError(f"chunk = {chunk!r} must be an integer >= 1 (or None for the default)")


def resolve_engine(
    engine: str | None, options: SolveOptions = STEADY_DEFAULTS, out=None, resume: bool = False, mechanism=None
) -> str:
    """``"kernel"`` or ``"xla"`` for ``engine`` ([`jaxcrank.runs.engines.resolve`][]: ``None``
    is the engine a resumed run in ``out`` was started with, else the kernel where a C
    compiler is available, the solver is tsit5 and every parameter of ``mechanism`` is a
    scalar; a worn joint's profiles are not).

    Raises:
        ParameterError: for an unknown engine, the kernel with another solver, no C
            compiler or a mechanism with array parameters, or a resumed run that was started
            with the other engine.
    """
    from . import engines

    settings = types.SimpleNamespace(options=options)
    engine = engines.resolve(engine, settings, 1, False, out, resume, mechanism)
    engines.check(engine, settings, 1, mechanism)
    return engine


def kernel_sections(base, names, xs, revolutions, options=STEADY_DEFAULTS, threads=None):
    """Section points of designs ``xs`` (n, len(names)) by the kernel, one call per
    revolution. Returns (sections (n, revolutions + 1, state) scaled, NaN after a
    failure; status codes (n,) of [`jaxcrank.numerics.results.RESULTS`][]; accepted steps (n,)). A
    design whose settle uses more than ``options.max_steps`` steps (accepted and
    rejected, over all revolutions) gets ``max_steps``."""
    from ..numerics.kernel import engine, source

    xs = np.atleast_2d(np.asarray(xs, dtype=float))
    n = len(xs)
    periods = np.array([float(set_parameters(base, list(names), [float(v) for v in x]).period) for x in xs])
    st = source.structure(base, names)
    y = engine.initial_states(base, names, xs)
    sections = np.full((n, revolutions + 1, y.shape[1]), np.nan)
    sections[:, 0] = y
    status, accepted, used = np.zeros(n, np.int64), np.zeros(n, np.int64), np.zeros(n, np.int64)
    o = options
    for r in range(revolutions):
        live = np.flatnonzero(status == engine.OK)
        if not live.size:
            break
        budget = max(int(np.max(o.max_steps - used[live])), 1)
        b = engine._run(st, xs[live], periods[live], np.zeros(live.size), 2, o.rtol, o.atol, o.dt0, budget, y[live],
                        threads)  # fmt: skip
        accepted[live] += b.steps
        used[live] += b.steps + b.rejected
        status[live] = np.where((b.status == engine.OK) & (used[live] > o.max_steps), engine.MAX_STEPS, b.status)
        y[live] = b.y
        sections[live, r + 1] = np.where((status[live] == engine.OK)[:, None], b.y, np.nan)
    return sections, status, accepted


def _xla_settle(base, names, x, revolutions, options):
    import jax.numpy as jnp

    from ..numerics.solve import simulate

    mech = set_parameters(base, names, x)
    ts = shooting.section_times(mech, revolutions)
    sim = simulate(mech, ts=ts, y0=model.initial_state(mech), options=options, throw=False)
    finite = jnp.all(jnp.isfinite(sim.ys))
    status = jnp.where(sim.ok & jnp.invert(finite), results.code(RESULTS.non_finite), results.code(sim.result))
    return sim.ys, status, sim.num_steps


@functools.cache
def _xla_compiled():
    import equinox as eqx
    import jax

    def batch(base, xs, names, revolutions, options):
        return jax.vmap(lambda x: _xla_settle(base, names, x, revolutions, options))(xs)

    return eqx.filter_jit(batch)


def _xla_batch(base, xs, names, revolutions, options):
    return _xla_compiled()(base, xs, names, revolutions, options)


def xla_sections(base, names, xs, revolutions, options=STEADY_DEFAULTS):
    """Section points, status codes and accepted steps of designs ``xs`` as
    [`kernel_sections`][jaxcrank.runs.regimes.kernel_sections] returns them, by the JAX
    path: ``steady_state``'s settle solve, the designs in one ``jax.vmap`` batch."""
    import jax.numpy as jnp

    xs = jnp.asarray(np.atleast_2d(xs), dtype=float)
    ys, status, steps = _xla_batch(base, xs, tuple(names), revolutions, options)
    ys, status = np.asarray(ys), np.asarray(status).astype(np.int64)
    return np.where((status == 0)[:, None, None], ys, np.nan), status, np.asarray(steps).astype(np.int64)


def classify(
    base: Mechanism,
    names: Sequence[str],
    designs: Float[ArrayLike, "designs params"],
    *,
    settle_revolutions: int = 20,
    max_period: int = 4,
    recurrence_tol: float = 1e-3,
    options: SolveOptions = STEADY_DEFAULTS,
    engine: str | None = None,
    out=None,
    resume: bool = False,
    chunk: int | None = None,
    threads: int | None = None,
    progress: bool = True,
) -> dict[str, Shaped[np.ndarray, " designs"]]:
    """The steady-state regime of every design (module docstring): its table as columns
    ([`columns`][jaxcrank.runs.regimes.columns]; numbers as float arrays, empty cells NaN,
    ``status``, ``message`` and ``regime`` as strings; rows by ``index``).

    Args:
        base: the mechanism every design starts from.
        names: parameter names (see [`jaxcrank.physics.parameters.set_parameter`][]).
        designs: (N, len(names)) parameter values, SI.
        settle_revolutions: revolutions from rest, integer >= 1 (default 20, as ``steady_state``).
        max_period: the longest period looked for, revolutions, >= 1 (periods up to
            min(max_period, settle_revolutions) are tested, as ``steady_state`` does).
        recurrence_tol: recurrence tolerance, scaled units, > 0 (default 1e-3).
        options: solve settings (default `jaxcrank.numerics.shooting.STEADY_DEFAULTS`;
            ``max_steps`` is the step budget of a design's whole settle).
        engine: ``"kernel"`` (tsit5 only), ``"xla"`` or ``None`` (the default:
            [`resolve_engine`][jaxcrank.runs.regimes.resolve_engine]).
        out: directory for ``table.csv`` and ``designs.npy``, appended after every chunk.
        resume: continue the classification in ``out`` (the same designs, checked exactly).
        chunk: designs per engine call and per checkpoint, >= 1 (default: kernel 16 per
            thread, xla 1).
        threads: kernel threads (default: the CPUs this process may use).
        progress: show the progress on standard error
            ([`jaxcrank.runs.programs.progress`][]: a bar on a terminal, a line every 10 %
            of the designs in a log).

    Raises:
        ParameterError: for an argument out of its range (the message names it), an
            engine that cannot run here, or ``out`` holding a table without ``resume``.
        CorruptFileError: for a table or ``designs.npy`` in ``out`` that is truncated,
            corrupted or from other designs.
    """
    _check(settle_revolutions, max_period, recurrence_tol, options, chunk)
    engine = resolve_engine(engine, options, out, resume, base)
    names = list(names)
    designs = np.atleast_2d(np.asarray(designs, dtype=float))
    if designs.ndim != 2 or designs.shape[1] != len(names):
        raise ParameterError(f"designs must have one column per parameter {names}, got shape {designs.shape}")
    cols = columns(base, names)
    settings = dict(settle_revolutions=settle_revolutions, max_period=max_period, recurrence_tol=recurrence_tol)
    settings.update(solver=options.solver_name, rtol=options.rtol, atol=options.atol, max_steps=options.max_steps)
    identity = run_identity(base, settings)
    path, done = open_table(out, resume, designs, cols, names, TEXT_COLUMNS, identity=identity)
    if out is not None:
        from .engines import ENGINE_FILE

        atomic_write(Path(out) / ENGINE_FILE, lambda f: f.write(engine.encode()))
    rows: list[list] = []

    def emit(new_rows):
        rows.extend(new_rows)
        if path is not None and new_rows:
            append(path, csv_text(new_rows))

    def row(i, status, message="", regime="", period="", distance="", steps=""):
        return [i] + [repr(float(v)) for v in designs[i]] + [status, message, regime, period, distance, steps]

    todo, invalid = split_valid(base, names, designs, done)
    emit([row(i, "invalid", message) for i, message in invalid])
    if chunk is None:
        from .engines import default_chunk

        chunk = default_chunk() if engine == "kernel" else 1
    m = shooting.dynamic_size(base)
    with programs.progress(
        len(designs), initial=len(done) + len(invalid), desc="designs", unit="design", disable=not progress
    ) as bar:
        for s in range(0, len(todo), chunk):
            idx = todo[s : s + chunk]
            xs = designs[idx]
            if engine == "kernel":
                sections, status, steps = kernel_sections(base, names, xs, settle_revolutions, options, threads)
            else:  # one compiled shape: pad with copies of the last design
                pad = np.concatenate([xs, np.repeat(xs[-1:], chunk - len(idx), axis=0)])
                sections, status, steps = (a[: len(idx)] for a in xla_sections(base, names, pad, settle_revolutions,
                                                                               options))  # fmt: skip
            period, distances = shooting.recurrence(sections, m, max_period, recurrence_tol)
            new = []
            for j, i in enumerate(idx):
                st = results.status_label(status[j])
                if st != "ok":
                    new.append(row(i, st, results.message(status[j]), steps=int(steps[j])))
                    continue
                k = int(period[j])
                regime = REGIMES[0] if k else REGIMES[1]
                new.append(row(i, "ok", "", regime, k, repr(float(np.min(distances[j]))), int(steps[j])))
            emit(new)
            bar.update(len(idx))
    if path is not None:
        return read_table(path, TEXT_COLUMNS)
    return table_from_rows([dict(zip(cols, map(str, r))) for r in rows], TEXT_COLUMNS)


def summarize(table: Mapping[str, Shaped[np.ndarray, " designs"]]) -> dict:
    """Counts of a regime table: designs, per status, per regime and per period
    (``"period_revolutions"``: k -> number of periodic designs)."""
    status, regime = np.asarray(table["status"]), np.asarray(table["regime"])
    periods = np.asarray(table["period_revolutions"])[regime == "periodic"].astype(int)
    return {
        "designs": int(len(status)),
        "status_counts": {s: int(np.sum(status == s)) for s in STATUSES},
        "regime_counts": {r: int(np.sum(regime == r)) for r in REGIMES},
        "period_counts": {str(k): int(np.sum(periods == k)) for k in sorted(set(periods.tolist()))},
    }
