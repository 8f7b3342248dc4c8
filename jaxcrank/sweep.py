"""Sweeps: many designs of one mechanism, one at a time or in ``vmap`` batches.

A sweep is a table of designs over named parameters (any name
:func:`jaxcrank.params.set_parameter` accepts: ``rod_length``,
``contact.restitution``, ``clearance_B``, ...), built by a sampler
(:func:`full_factorial`, :func:`latin_hypercube`, :func:`random_uniform`,
:func:`one_at_a_time`, :func:`monte_carlo`) and run by :func:`run`:

- each design is checked on the host first (an invalid one, e.g. a
  non-assemblable geometry, gets ``status = "invalid"`` and the parameter error as
  its message) and then solved with ``throw=False``, ``chunk`` designs at a time: a
  device given one design solves it alone, a device given several solves them in a
  ``vmap`` batch (memory stays bounded either way); a failed solve is reported in the
  ``status`` column (``max_steps``, ``solver_failed``, ``non_finite``) and its
  metric cells are left empty, never NaN;
- the table (``table.csv``, one row per design: index, parameters, status,
  headline metrics with their units in the column names) is appended after every
  batch, so a killed sweep resumed with ``resume=True`` only solves what is missing;
- a chunk is a ``jax.Array`` sharded over every device of every process of a
  ``jax.distributed`` job; each device solves its shard with its own compiled solve
  (no per-step collective; see :func:`_evaluate`);
- ``workers = N`` solves chunks in N local processes (one per CPU core), the way to
  use several cores of one machine: XLA compiles the solver loop into one
  single-threaded kernel (:mod:`jaxcrank.runtime`), and several host devices in one
  process do not run at the same time.

Which chunk is fastest depends on the device (``bench/bench_sweep.py``): on a CPU a
design solved alone (``chunk = 1`` per device, the default there) beats any ``vmap``
batch, which steps every member until the slowest one finishes and selects each
update per member; a GPU needs batches of thousands (default 1024 per device).

Reproducibility: a design's numbers do not depend on its batch mates, its position
in the batch, the batch size (>= 2), the number of devices, processes or workers
(with :mod:`jaxcrank.runtime`'s XLA options: no FMA contraction, which otherwise
rounds differently per lane and batch size). Solving alone (one design per device)
and in a batch are two compiled programs that round differently in the last bit,
which impact chaos amplifies (1e-5..1e-3 relative after 3 ms): a resumed sweep must
keep its chunk per device on the same side of that line.

The headline metrics are :data:`METRICS` (after the first revolution by default),
the same numbers ``jaxcrank simulate`` writes to ``summary.json``.
"""

from __future__ import annotations

import csv
import dataclasses
import functools
import itertools
import math
import multiprocessing
import os
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from pathlib import Path
from typing import Mapping, Sequence

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec as P
from tqdm.auto import tqdm

from . import config
from .outputs import frames, transmission_angle_deviation
from .params import Mechanism, ParameterError, get_parameter, parameter_unit, set_parameters
from .solve import SOLVERS, simulate

#: headline metrics (name -> meaning); units are the name's suffix
METRICS = {
    "max_abs_rod_x_deviation_m": "largest |rod-centre x - ideal|",
    "max_abs_slider_x_deviation_m": "largest |slider x - ideal|",
    "max_abs_slider_ax_deviation_m_s2": "largest |slider acceleration - ideal|",
    "peak_contact_force_B_N": "largest normal contact force at B",
    "peak_contact_force_C_N": "largest normal contact force at C",
    "peak_driving_moment_N_m": "largest |driving moment|",
    "rms_driving_moment_deviation_N_m": "RMS of driving moment - ideal driving moment",
    "rms_slider_x_deviation_m": "RMS of slider x - ideal",
    "rms_transmission_angle_error_deg": "RMS transmission-angle error (paper Eq. 19)",
    "max_abs_transmission_angle_error_deg": "largest |transmission angle - ideal|",
}

STATUSES = ("ok", "max_steps", "solver_failed", "non_finite", "invalid")
_MESSAGES = {
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
        solver, rtol, atol, max_steps: as in :func:`jaxcrank.simulate`.
    """

    revolutions: float = 4.0
    samples_per_revolution: int = 3600
    metrics_from_revolution: float = 1.0
    solver: str = "tsit5"
    rtol: float = 1e-6
    atol: float = 1e-6
    max_steps: int = 500_000

    def __post_init__(self):
        if not self.revolutions > 0:
            raise ParameterError(f"revolutions = {self.revolutions:g} must be > 0")
        if not 0 <= self.metrics_from_revolution < self.revolutions:
            raise ParameterError(f"metrics_from_revolution = {self.metrics_from_revolution:g} must be in "
                                 f"[0, revolutions = {self.revolutions:g})")
        if int(self.samples_per_revolution) < 4:
            raise ParameterError(f"samples_per_revolution = {self.samples_per_revolution} must be >= 4")
        if self.solver not in SOLVERS:
            raise ParameterError(f"solver {self.solver!r} is unknown; valid: {', '.join(SOLVERS)}")
        if not (self.rtol > 0 and self.atol > 0 and self.max_steps > 0):
            raise ParameterError("rtol, atol and max_steps must be positive")

    @property
    def n_samples(self) -> int:
        return int(round(self.revolutions * self.samples_per_revolution)) + 1


# ------------------------------------------------------------------ metrics
def headline(sim, t_start) -> dict[str, jax.Array]:
    """:data:`METRICS` of a simulation over samples with t > ``t_start`` (s);
    traceable (``vmap``), the same values as :func:`jaxcrank.outputs.metrics`."""
    f = frames(sim)
    late = sim.ts > t_start
    n = jnp.maximum(jnp.sum(late), 1)

    def peak(x):
        return jnp.max(jnp.where(late, jnp.abs(x), 0.0))

    def rms(x):
        return jnp.sqrt(jnp.sum(jnp.where(late, x**2, 0.0)) / n)

    ta = transmission_angle_deviation(f.q[:, 2], f.ideal_q[:, 2])
    return {
        "max_abs_rod_x_deviation_m": peak(f.q[:, 0] - f.ideal_q[:, 0]),
        "max_abs_slider_x_deviation_m": peak(f.q[:, 3] - f.ideal_q[:, 3]),
        "max_abs_slider_ax_deviation_m_s2": peak(f.qdd[:, 3] - f.ideal_qdd[:, 3]),
        "peak_contact_force_B_N": peak(f.normal_force_B),
        "peak_contact_force_C_N": peak(f.normal_force_C),
        "peak_driving_moment_N_m": peak(f.driving_moment),
        "rms_driving_moment_deviation_N_m": rms(f.driving_moment - f.ideal_driving_moment),
        "rms_slider_x_deviation_m": rms(f.q[:, 3] - f.ideal_q[:, 3]),
        "rms_transmission_angle_error_deg": rms(ta),
        "max_abs_transmission_angle_error_deg": peak(ta),
    }


def simulate_design(base: Mechanism, names: Sequence[str], x, settings: Settings = Settings()):
    """One design: ``base`` with ``names`` set to ``x`` (SI), simulated with
    ``throw=False``. Returns (metrics dict, status code (index into
    :data:`STATUSES`), accepted steps). Traceable; :func:`run` vmaps it."""
    mech = set_parameters(base, names, x)
    period = 2.0 * math.pi / mech.crank_speed
    ts = jnp.linspace(0.0, settings.revolutions, settings.n_samples) * period
    sim = simulate(mech, ts=ts, solver=settings.solver, rtol=settings.rtol, atol=settings.atol,
                   max_steps=settings.max_steps, throw=False)
    m = headline(sim, settings.metrics_from_revolution * period)
    finite = jnp.all(jnp.isfinite(sim.ys)) & jnp.all(jnp.isfinite(jnp.stack(list(m.values()))))
    status = jnp.where(sim.ok, jnp.where(finite, 0, 3),
                       jnp.where(sim.result == diffrax.RESULTS.max_steps_reached, 1, 2))
    return m, status, sim.num_steps


def validate(mech: Mechanism) -> Mechanism:
    """Re-check every parameter of ``mech`` (raises :class:`ParameterError` naming
    the parameter and its range): ``set_parameter`` does not re-validate."""
    return config.from_dict(config.to_dict(mech))


# ------------------------------------------------------------------ samplers
def _ranges(ranges: Mapping[str, Sequence[float]]):
    names = list(ranges)
    lo = np.array([float(ranges[n][0]) for n in names])
    hi = np.array([float(ranges[n][1]) for n in names])
    bad = [n for n, a, b in zip(names, lo, hi) if not a <= b]
    if bad:
        raise ParameterError(f"range of {bad[0]!r} must be (lower, upper) with lower <= upper")
    return names, lo, hi


def full_factorial(levels: Mapping[str, Sequence[float]]):
    """Every combination of the given levels: ``(names, designs (N, k))``, SI."""
    names = list(levels)
    return names, np.array(list(itertools.product(*[np.asarray(levels[n], float) for n in names])), float)


def latin_hypercube(ranges: Mapping[str, Sequence[float]], n: int, seed: int = 0):
    """``n`` Latin-hypercube samples in the box ``ranges`` (name -> (lower, upper)):
    each variable's range is cut into ``n`` equal strata, each used once."""
    names, lo, hi = _ranges(ranges)
    rng = np.random.default_rng(seed)
    u = (np.stack([rng.permutation(n) for _ in names], axis=1) + rng.random((n, len(names)))) / n
    return names, lo + u * (hi - lo)


def random_uniform(ranges: Mapping[str, Sequence[float]], n: int, seed: int = 0):
    """``n`` independent uniform samples in the box ``ranges``."""
    names, lo, hi = _ranges(ranges)
    return names, lo + np.random.default_rng(seed).random((n, len(names))) * (hi - lo)


def one_at_a_time(base: Mechanism, ranges: Mapping[str, Sequence[float]], points: int = 11):
    """One line per variable through ``base``: ``points`` equally spaced values of
    that variable over its range, the others at their ``base`` values."""
    names, lo, hi = _ranges(ranges)
    x0 = np.array([get_parameter(base, n) for n in names])
    rows = []
    for j in range(len(names)):
        for v in np.linspace(lo[j], hi[j], points):
            x = x0.copy()
            x[j] = v
            rows.append(x)
    return names, np.array(rows)


@dataclasses.dataclass(frozen=True)
class Tolerance:
    """A manufactured parameter: ``nominal`` (SI) within a band ``+-tolerance``.

    ``distribution = "uniform"``: uniform over the band; ``"normal"``: normal with
    the band as +-3 sigma (99.7 % of parts inside it, the usual process-capability
    reading of a tolerance)."""

    nominal: float
    tolerance: float
    distribution: str = "uniform"

    def __post_init__(self):
        if self.distribution not in ("uniform", "normal"):
            raise ParameterError(f"distribution {self.distribution!r} is unknown; valid: 'uniform', 'normal'")
        if not self.tolerance >= 0:
            raise ParameterError(f"tolerance = {self.tolerance:g} must be >= 0")

    @property
    def sigma(self) -> float:
        """Standard deviation, SI."""
        return self.tolerance / 3.0 if self.distribution == "normal" else self.tolerance / math.sqrt(3.0)

    def standard(self, rng, n):
        """``n`` draws of the standardised variable (band = [-1, 1] for uniform, 3 sigma = 1 for normal)."""
        return rng.uniform(-1.0, 1.0, n) if self.distribution == "uniform" else rng.standard_normal(n) / 3.0


def monte_carlo(tolerances: Mapping[str, Tolerance], n: int, seed: int = 0):
    """``n`` manufactured parts: every parameter drawn from its :class:`Tolerance`."""
    rng = np.random.default_rng(seed)
    names = list(tolerances)
    cols = [tolerances[k].nominal + tolerances[k].tolerance * tolerances[k].standard(rng, n) for k in names]
    return names, np.stack(cols, axis=1)


# ------------------------------------------------------------------ running
def _mesh():
    return Mesh(np.array(jax.devices()), ("designs",))


@functools.lru_cache(maxsize=16)
def _batch_fn(names: tuple[str, ...], settings: Settings, batched: bool):
    """The compiled solve of a device's shard: a ``vmap`` over its rows, or (``batched``
    False, a one-row shard) the single design's solve without a batch dimension, which
    on a CPU runs ~2.5x faster than a batch per design (``bench/bench_sweep.py``)."""
    def one(base, x):
        m, status, steps = simulate_design(base, names, x, settings)
        return jnp.stack([m[k] for k in METRICS]), status, steps

    def shard(base, xs):
        if batched:
            return jax.vmap(lambda x: one(base, x))(xs)
        return jax.tree_util.tree_map(lambda a: a[None], one(base, xs[0]))

    # filter_jit: the base's Python-float parameters are compile-time constants (only
    # the swept ones are traced), which XLA folds into the vector field: 1.3x faster
    # per solver step than tracing every parameter (measured, batch of 8 designs).
    return eqx.filter_jit(shard)


def default_chunk() -> int:
    """Designs per chunk when none is given: one per device on a CPU (solved alone),
    1024 per device elsewhere (a GPU needs large batches)."""
    per_device = 1 if jax.default_backend() == "cpu" else 1024
    return per_device * jax.device_count()


def _evaluate(base, names, settings, xs):
    """Metrics (n, len(METRICS)), status codes and steps of designs ``xs`` (n, k),
    with n a multiple of the global device count; every process gets all rows.

    The batch is a ``jax.Array`` sharded over all devices of all processes
    (``NamedSharding`` over a 1-D mesh); each addressable shard is solved by the
    same compiled executable (:func:`_batch_fn`) on its own device, dispatched asynchronously,
    and the results are assembled into sharded arrays again. Neither
    ``jit`` of the sharded batch (XLA then puts an all-reduce of the while loop's
    stop test in every solver step) nor ``shard_map`` (implicit diffrax solvers
    fail inside it, diffrax issue #765) is used; a shard also gets the same
    executable as a one-device run, so the table does not depend on the device
    count (impact chaos would amplify any last-bit difference)."""
    fn = _batch_fn(tuple(names), settings, len(xs) > jax.device_count())
    sharding = NamedSharding(_mesh(), P("designs"))  # rows over all devices of all processes
    per = len(xs) // jax.process_count()
    local = xs[jax.process_index() * per:(jax.process_index() + 1) * per]
    batch = jax.make_array_from_process_local_data(sharding, local, xs.shape)
    results = [fn(base, s.data) for s in batch.addressable_shards]  # async, one call per device
    outs = []
    for k, width in enumerate((len(METRICS), None, None)):
        shape = (len(xs), width) if width else (len(xs),)
        outs.append(jax.make_array_from_single_device_arrays(shape, sharding, [r[k] for r in results]))
    if jax.process_count() > 1:
        from jax.experimental import multihost_utils

        return tuple(np.asarray(o) for o in multihost_utils.process_allgather(outs, tiled=True))
    return tuple(np.asarray(o) for o in outs)


def columns(names: Sequence[str]) -> list[str]:
    """Column names of a sweep table over ``names``: ``index``, one ``<name>_<unit>``
    per parameter, ``status``, ``message``, :data:`METRICS`, ``steps``."""
    return (["index"] + [f"{n}_{parameter_unit(n)}" for n in names] + ["status", "message"]
            + list(METRICS) + ["steps"])


def read_table(path) -> dict[str, np.ndarray]:
    """A sweep table (CSV) as columns: numbers as float arrays (empty cells NaN),
    ``status`` and ``message`` as string arrays; rows sorted by ``index``."""
    with open(path, newline="") as f:
        return _table(list(csv.DictReader(f)))


def _table(rows: list[dict[str, str]]) -> dict[str, np.ndarray]:
    """Rows of CSV cells (strings) as columns sorted by ``index`` (see :func:`read_table`)."""
    if not rows:
        return {}
    rows = sorted(rows, key=lambda r: int(r["index"]))
    out = {}
    for key in rows[0]:
        vals = [r[key] for r in rows]
        if key in ("status", "message"):
            out[key] = np.array(vals, dtype=object)
        else:
            out[key] = np.array([float(v) if v != "" else np.nan for v in vals])
    out["index"] = out["index"].astype(int)
    return out


def run(base: Mechanism, names: Sequence[str], designs, settings: Settings = Settings(), *, out=None,
        resume: bool = False, chunk: int | None = None, workers: int = 1,
        progress: bool = True) -> dict[str, np.ndarray]:
    """Simulate every design and return the table (as :func:`read_table`).

    Args:
        base: the mechanism every design starts from.
        names: parameter names (see :func:`jaxcrank.params.set_parameter`).
        designs: (N, len(names)) parameter values, SI.
        settings: how each design is simulated.
        out: directory for ``table.csv`` and ``designs.npy``, appended after every
            batch; without it the table is only returned.
        resume: continue the sweep in ``out``: designs already in the table are
            not solved again (the designs must be the same, checked exactly).
        chunk: designs solved together (rounded up to a multiple of the device count;
            one per device: each solved alone, several: a ``vmap`` batch per device);
            bounds memory and is the checkpoint granularity. Default
            :func:`default_chunk`.
        workers: local processes that solve chunks in parallel (one per CPU core is
            the fastest on a CPU); 1 solves in this process. Not with ``jax.distributed``.
        progress: tqdm progress bar.
    """
    names = list(names)
    designs = np.atleast_2d(np.asarray(designs, dtype=float))
    if designs.shape[1] != len(names):
        raise ParameterError(f"designs must have one column per parameter {names}, got shape {designs.shape}")
    cols = columns(names)
    writer = jax.process_index() == 0
    path = None
    done: set[int] = set()
    if out is not None:
        out = Path(out)
        path = out / "table.csv"
        if path.exists() and not resume:
            raise ParameterError(f"{out} already holds a sweep (table.csv): pass resume=True (--resume) "
                                 "to continue it or choose another output directory")
        if resume and (out / "designs.npy").exists():
            old = np.load(out / "designs.npy")
            if old.shape != designs.shape or not np.array_equal(old, designs):
                raise ParameterError(f"{out} holds a sweep over other designs: resume needs the same spec")
        if resume and path.exists():
            done = {int(i) for i in read_table(path).get("index", [])}
        if writer:
            out.mkdir(parents=True, exist_ok=True)
            np.save(out / "designs.npy", designs)
            if not path.exists():
                with open(path, "w", newline="") as f:
                    csv.writer(f).writerow(cols)
    rows: list[list] = []

    def emit(new_rows):
        rows.extend(new_rows)
        if path is not None and writer:
            with open(path, "a", newline="") as f:
                csv.writer(f).writerows(new_rows)
                f.flush()
                os.fsync(f.fileno())

    def row(i, status, message="", metrics=None, steps=""):
        vals = [repr(float(v)) for v in designs[i]]
        m = [repr(float(v)) for v in metrics] if metrics is not None else [""] * len(METRICS)
        return [i] + vals + [status, message] + m + [steps]

    todo, invalid = [], []
    for i in range(len(designs)):
        if i in done:
            continue
        try:
            validate(set_parameters(base, names, [float(v) for v in designs[i]]))
            todo.append(i)
        except ParameterError as err:
            given = ", ".join(f"{n} = {v:g}" for n, v in zip(names, designs[i]))
            invalid.append(row(i, "invalid", f"{given}: {err}"))
    emit(invalid)

    # a multiple of the device count; one shape for every chunk (one compilation)
    n_dev = jax.device_count()
    chunk = default_chunk() if chunk is None else int(chunk)
    if chunk < 1:
        raise ParameterError(f"chunk = {chunk} must be >= 1")
    if int(workers) < 1:
        raise ParameterError(f"workers = {workers} must be >= 1")
    if workers > 1 and jax.process_count() > 1:
        raise ParameterError("workers > 1 cannot be combined with a jax.distributed job: use processes instead")
    chunk = -(-chunk // n_dev) * n_dev
    chunks = []
    for s in range(0, len(todo), chunk):
        idx = todo[s:s + chunk]
        xs = designs[idx]
        if len(idx) < chunk:  # one compiled shape: pad with copies of the last design
            xs = np.concatenate([xs, np.repeat(xs[-1:], chunk - len(idx), axis=0)])
        chunks.append((idx, xs))

    def record(idx, result):
        metrics, status, steps = result
        new = []
        for j, i in enumerate(idx):
            st = STATUSES[int(status[j])]
            new.append(row(i, st, _MESSAGES.get(st, ""), metrics[j] if st == "ok" else None, int(steps[j])))
        emit(new)
        bar.update(len(idx))

    with tqdm(total=len(designs), initial=len(done) + len(invalid), desc="designs", unit="design",
              disable=not (progress and writer)) as bar:
        if workers > 1 and chunks:
            _run_in_workers(base, names, settings, chunks, int(workers), record)
        else:
            for idx, xs in chunks:
                record(idx, _evaluate(base, names, settings, xs))
    if path is not None:
        if jax.process_count() > 1:
            from jax.experimental import multihost_utils

            multihost_utils.sync_global_devices("jaxcrank sweep table written")
        return read_table(path)
    return _table([dict(zip(cols, map(str, r))) for r in rows])


_WORKER: dict = {}


def _worker_init(base_dict, names, settings):
    # a fresh (spawned) process: importing jaxcrank applies jaxcrank.runtime's XLA options
    _WORKER.update(base=config.from_dict(base_dict), names=names, settings=settings)


def _worker_solve(xs):
    return _evaluate(_WORKER["base"], _WORKER["names"], _WORKER["settings"], xs)


def _run_in_workers(base, names, settings, chunks, workers, record):
    """Solve ``chunks`` in ``workers`` spawned processes, at most two chunks queued per
    worker, and ``record`` each as it finishes (the table is sorted when read)."""
    ctx = multiprocessing.get_context("spawn")  # a forked JAX runtime is not safe
    with ProcessPoolExecutor(workers, mp_context=ctx, initializer=_worker_init,
                             initargs=(config.to_dict(base), list(names), settings)) as pool:
        pending, queue = {}, iter(chunks)
        for idx, xs in itertools.islice(queue, 2 * workers):
            pending[pool.submit(_worker_solve, xs)] = idx
        while pending:
            finished, _ = wait(pending, return_when=FIRST_COMPLETED)
            for future in finished:
                record(pending.pop(future), future.result())
                for idx, xs in itertools.islice(queue, 1):
                    pending[pool.submit(_worker_solve, xs)] = idx


def summarize(table: Mapping[str, np.ndarray], quantiles=(0.05, 0.5, 0.95)) -> dict:
    """Per metric over the ``ok`` designs: mean, std, min, max and quantiles; and
    the count of each status. Units as in the metric names."""
    ok = np.asarray(table["status"]) == "ok"
    out = {"designs": int(len(ok)), "status_counts": {s: int(np.sum(table["status"] == s)) for s in STATUSES},
           "metrics": {}}
    for k in METRICS:
        v = np.asarray(table[k])[ok]
        if v.size == 0:
            continue
        out["metrics"][k] = {"mean": float(v.mean()), "std": float(v.std(ddof=1)) if v.size > 1 else 0.0,
                             "min": float(v.min()), "max": float(v.max()),
                             **{f"q{int(round(q * 100)):02d}": float(np.quantile(v, q)) for q in quantiles}}
    return out


# ------------------------------------------------------------------ spec (TOML)
SAMPLINGS = ("grid", "lhs", "random", "oat", "monte_carlo")
_SPEC_KEYS = {"sampling", "samples", "points", "seed", "chunk", "metrics", "parameters", "simulation", "mechanism"}


@dataclasses.dataclass
class Spec:
    """A sweep read from TOML by :func:`load_spec` (see ``jaxcrank sweep --help``)."""

    base: Mechanism
    sampling: str
    names: list[str]
    designs: np.ndarray
    settings: Settings
    chunk: int | None  # None: default_chunk()
    metrics: list[str]
    tolerances: dict[str, Tolerance]


def spec_from_dict(d: Mapping) -> Spec:
    """Build a :class:`Spec` from a parsed TOML dict; every problem raises
    :class:`ParameterError` naming the key."""
    bad = set(d) - _SPEC_KEYS
    if bad:
        raise ParameterError(f"unknown sweep spec keys {sorted(bad)}; valid: {sorted(_SPEC_KEYS)}")
    sampling = d.get("sampling", "grid")
    if sampling not in SAMPLINGS:
        raise ParameterError(f"sampling {sampling!r} is unknown; valid: {', '.join(SAMPLINGS)}")
    base = config.from_dict(d.get("mechanism", {}))
    sim = dict(d.get("simulation", {}))
    fields = {f.name for f in dataclasses.fields(Settings)}
    if set(sim) - fields:
        raise ParameterError(f"unknown [simulation] keys {sorted(set(sim) - fields)}; valid: {sorted(fields)}")
    settings = Settings(**sim)
    metrics = list(d.get("metrics", METRICS))
    if set(metrics) - set(METRICS):
        raise ParameterError(f"unknown metrics {sorted(set(metrics) - set(METRICS))}; valid: {list(METRICS)}")
    params = d.get("parameters", {})
    if not params:
        raise ParameterError("a sweep spec needs at least one [parameters.<name>] table")
    for name in params:
        parameter_unit(name)  # raises on unknown names
    n, seed = int(d.get("samples", 64)), int(d.get("seed", 0))
    tolerances = {}

    def rng(name, p):
        if "lower" not in p or "upper" not in p:
            raise ParameterError(f"[parameters.{name}] needs lower and upper for sampling = {sampling!r}")
        return float(p["lower"]), float(p["upper"])

    if sampling == "grid":
        levels = {}
        for name, p in params.items():
            if "values" in p:
                levels[name] = [float(v) for v in p["values"]]
            else:
                lo, hi = rng(name, p)
                levels[name] = np.linspace(lo, hi, int(p.get("points", 5))).tolist()
        names, designs = full_factorial(levels)
    elif sampling in ("lhs", "random"):
        ranges = {name: rng(name, p) for name, p in params.items()}
        names, designs = (latin_hypercube if sampling == "lhs" else random_uniform)(ranges, n, seed)
    elif sampling == "oat":
        ranges = {name: rng(name, p) for name, p in params.items()}
        names, designs = one_at_a_time(base, ranges, int(d.get("points", 11)))
    else:
        for name, p in params.items():
            if "tolerance" not in p:
                raise ParameterError(f"[parameters.{name}] needs tolerance (and optionally nominal, "
                                     "distribution) for sampling = 'monte_carlo'")
            tolerances[name] = Tolerance(float(p.get("nominal", get_parameter(base, name))), float(p["tolerance"]),
                                         str(p.get("distribution", "uniform")))
        names, designs = monte_carlo(tolerances, n, seed)
    return Spec(base, sampling, names, designs, settings, (int(d["chunk"]) if "chunk" in d else None), metrics, tolerances)


def load_spec(path) -> Spec:
    """Read a sweep spec TOML file (errors name the file)."""
    return config.load_toml(path, spec_from_dict)
