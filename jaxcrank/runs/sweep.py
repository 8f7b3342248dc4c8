"""Sweeps: many designs of one mechanism, one at a time or in ``vmap`` batches.

A sweep is a table of designs over named parameters (any name
:func:`jaxcrank.physics.params.set_parameter` accepts: ``rod_length``,
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
  batch, each batch in one ``write`` (a killed process leaves whole batches), so a
  killed sweep resumed with ``resume=True`` only solves what is missing; a table or
  ``designs.npy`` that is truncated, corrupted or from another sweep raises
  :class:`~jaxcrank.CorruptFileError` naming the file, never a silent restart;
- a chunk is a ``jax.Array`` sharded over every device of every process of a
  ``jax.distributed`` job; each device solves its shard with its own compiled solve
  (no per-step collective; see :func:`_evaluate`);
- ``workers = N`` solves chunks in N local processes (one per CPU core), the way to
  use several cores of one machine: XLA compiles the solver loop into one
  single-threaded kernel (:mod:`jaxcrank.numerics.runtime`), and several host devices in one
  process do not run at the same time.

Which chunk is fastest depends on the device (``bench/bench_sweep.py``): on a CPU a
design solved alone (``chunk = 1`` per device, the default there) beats any ``vmap``
batch, which steps every member until the slowest one finishes and selects each
update per member; a GPU needs batches of thousands (default: the largest batch that fits
in its free memory, :func:`default_chunk`).

Reproducibility: a design's numbers do not depend on its batch mates, its position
in the batch, the batch size (>= 2), the number of devices, processes or workers
(with :mod:`jaxcrank.numerics.runtime`'s XLA options: no FMA contraction, which otherwise
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
import io
import itertools
import math
import multiprocessing
import os
from collections.abc import Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from pathlib import Path

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding
from jax.sharding import PartitionSpec as P
from jaxtyping import Array, ArrayLike, Float, Int, Shaped
from tqdm.auto import tqdm

from . import config
from ..errors import CorruptFileError
from ..analysis.metrics import METRICS
from ..physics.params import Mechanism, ParameterError, parameter_unit, set_parameters
from ..numerics.solve import DEFAULTS, SolveOptions, simulate

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


@functools.lru_cache(maxsize=32)
def batch_bytes(base: Mechanism, names: tuple[str, ...], settings: Settings, batch: int) -> int:
    """Device memory, bytes, that XLA plans for solving ``batch`` designs in one ``vmap``
    batch on the default device (temporaries and outputs of the compiled program)."""
    names = tuple(names)
    params, static = eqx.partition(base, eqx.is_array)

    def shard(p, xs):
        b = eqx.combine(p, static)
        return jax.vmap(lambda x: simulate_design(b, names, x, settings))(xs)

    xs = jnp.zeros((batch, len(names)))
    memory = jax.jit(shard).lower(params, xs).compile().memory_analysis()
    return int(memory.temp_size_in_bytes + memory.output_size_in_bytes)


def chunk_that_fits(
    base: Mechanism, names: Sequence[str], settings: Settings, free_bytes: float, headroom: float = 0.8
) -> int:
    """The largest number of designs per device whose batch fits in ``headroom`` times
    ``free_bytes`` (bytes): XLA's memory plan of batches of 2 and 8 designs gives the
    fixed and the per-design bytes (a batch's memory grows about linearly with its size;
    the headroom covers the rest). At least 1."""
    names = tuple(names)
    two, eight = batch_bytes(base, names, settings, 2), batch_bytes(base, names, settings, 8)
    per_design = max((eight - two) / 6.0, 1.0)
    fixed = max(two - 2.0 * per_design, 0.0)
    return max(1, int((headroom * free_bytes - fixed) // per_design))


def free_device_bytes() -> int | None:
    """Free memory of the default device, bytes, where the backend reports it (GPUs);
    ``None`` on a CPU."""
    stats = jax.devices()[0].memory_stats() if jax.default_backend() != "cpu" else None
    if not stats or "bytes_limit" not in stats:
        return None
    return int(stats["bytes_limit"] - stats.get("bytes_in_use", 0))


def default_chunk(base: Mechanism | None = None, names: Sequence[str] = (), settings: Settings | None = None) -> int:
    """Designs per chunk when none is given: one per device on a CPU (each solved
    alone); elsewhere (a GPU needs large batches) the largest batch per device that fits
    its free memory (:func:`chunk_that_fits`, given the sweep), else 1024 per device."""
    if jax.default_backend() == "cpu":
        return jax.device_count()
    free = free_device_bytes()
    if base is None or settings is None or free is None:
        return 1024 * jax.device_count()
    return chunk_that_fits(base, names, settings, free) * jax.device_count()


def resolve_chunk(base: Mechanism, names: Sequence[str], settings: Settings, chunk: int | None = None) -> int:
    """The designs per chunk a sweep of ``names`` over ``base`` uses: ``chunk``
    (default :func:`default_chunk` for this sweep) rounded up to a multiple of the
    device count.

    Raises:
        ParameterError: for ``chunk < 1``.
    """
    chunk = default_chunk(base, names, settings) if chunk is None else int(chunk)
    if chunk < 1:
        raise ParameterError(f"chunk = {chunk} must be >= 1")
    n_dev = jax.device_count()
    return -(-chunk // n_dev) * n_dev


def check_chunk_fits(
    base: Mechanism, names: Sequence[str], settings: Settings, chunk: int, free_bytes: float | None
) -> None:
    """Raise :class:`ParameterError` naming ``chunk`` and the size that would fit when
    a batch of ``chunk`` designs per device needs more than ``free_bytes`` (no check
    when ``free_bytes`` is None, e.g. on a CPU, or for one design per device)."""
    if free_bytes is None or chunk <= 1:
        return
    need = batch_bytes(base, tuple(names), settings, chunk)
    if need > free_bytes:
        fits = chunk_that_fits(base, names, settings, free_bytes)
        raise ParameterError(
            f"chunk = {chunk} designs per device needs {need / 2**30:.2f} GiB of device memory, "
            f"{free_bytes / 2**30:.2f} GiB are free: use chunk <= {fits} per device"
        )


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
    local = xs[jax.process_index() * per : (jax.process_index() + 1) * per]
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
    return ["index"] + [f"{n}_{parameter_unit(n)}" for n in names] + ["status", "message"] + list(METRICS) + ["steps"]


def read_table(path) -> dict[str, Shaped[np.ndarray, " rows"]]:
    """A sweep table (CSV) as columns: numbers as float arrays (empty cells NaN),
    ``status`` and ``message`` as string arrays; rows sorted by ``index``.

    Raises:
        CorruptFileError: the file has no header, a row with more or fewer cells than
            the header (a truncated or corrupted file), a cell that is not a number
            where one belongs, an unknown status or a repeated index; the message
            names the file and the line.
    """
    path = Path(path)
    with open(path, newline="") as f:
        try:
            lines = list(csv.reader(f))
        except csv.Error as err:
            raise CorruptFileError(f"{path}: not a readable CSV table ({err})") from None
    if not lines or "index" not in lines[0] or "status" not in lines[0]:
        raise CorruptFileError(f"{path}: no sweep table header (index, ..., status, ...) on line 1")
    header, rows, seen = lines[0], [], set()
    for n, cells in enumerate(lines[1:], start=2):
        if len(cells) != len(header):
            raise CorruptFileError(
                f"{path}: line {n} has {len(cells)} cells where the header has "
                f"{len(header)}: the table is truncated or corrupted"
            )
        row = dict(zip(header, cells))
        for key, v in row.items():
            if key in ("status", "message"):
                continue
            try:
                float(v) if v != "" else None
            except ValueError:
                raise CorruptFileError(f"{path}: line {n}: {key} = {v!r} is not a number") from None
        if not row["index"].isdigit():
            raise CorruptFileError(f"{path}: line {n}: index = {row['index']!r} is not a design number")
        if row["status"] not in STATUSES:
            raise CorruptFileError(f"{path}: line {n}: unknown status {row['status']!r}")
        if row["index"] in seen:
            raise CorruptFileError(f"{path}: line {n}: design index {row['index']} appears twice")
        seen.add(row["index"])
        rows.append(row)
    return _table(rows)


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


def run(
    base: Mechanism,
    names: Sequence[str],
    designs: Float[ArrayLike, "designs params"],
    settings: Settings = Settings(),
    *,
    out=None,
    resume: bool = False,
    chunk: int | None = None,
    workers: int = 1,
    progress: bool = True,
    engine: str = "xla",
) -> dict[str, Shaped[np.ndarray, " designs"]]:
    """Simulate every design and return the table (as :func:`read_table`).

    Args:
        base: the mechanism every design starts from.
        names: parameter names (see :func:`jaxcrank.physics.params.set_parameter`).
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
        engine: ``"xla"`` (the compiled JAX solve above) or ``"kernel"`` (the
            per-trajectory C kernel of :mod:`jaxcrank.numerics.kernel`: tsit5 only, one
            design per CPU thread, ``workers`` must be 1; ``chunk`` is then the designs per
            kernel call and checkpoint, default :func:`jaxcrank.runs.engines.default_chunk`).
            Same table, statuses and resume; a resumed sweep keeps its engine (the two
            round differently, which impact chaos amplifies).
    """
    from . import engines

    engines.check(engine, settings, workers)
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
            raise ParameterError(
                f"{out} already holds a sweep (table.csv): pass resume=True (--resume) "
                "to continue it or choose another output directory"
            )
        if resume and (out / "designs.npy").exists():
            try:
                old = np.load(out / "designs.npy")
            except (ValueError, OSError, EOFError) as err:
                raise CorruptFileError(
                    f"{out / 'designs.npy'}: cannot be read ({err}); the sweep cannot be "
                    "resumed (move the directory away to start over)"
                ) from None
            if old.shape != designs.shape or not np.array_equal(old, designs):
                raise ParameterError(f"{out} holds a sweep over other designs: resume needs the same spec")
        if resume and path.exists():
            done = _resumable_rows(path, cols, names, designs)
        if writer:
            out.mkdir(parents=True, exist_ok=True)
            _atomic_write(out / "designs.npy", lambda f: np.save(f, designs))
            if not path.exists():
                _atomic_write(path, lambda f: f.write(_csv_text([cols]).encode()))
    rows: list[list] = []

    def emit(new_rows):
        rows.extend(new_rows)
        if path is not None and writer and new_rows:
            _append(path, _csv_text(new_rows))

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
    given = chunk is not None
    chunk = engines.default_chunk() if engine == "kernel" and chunk is None else chunk
    chunk = resolve_chunk(base, names, settings, chunk)
    if given and todo and engine == "xla":
        check_chunk_fits(base, names, settings, chunk // n_dev, free_device_bytes())
    if int(workers) < 1:
        raise ParameterError(f"workers = {workers} must be >= 1")
    if workers > 1 and jax.process_count() > 1:
        raise ParameterError("workers > 1 cannot be combined with a jax.distributed job: use processes instead")
    chunks = []
    for s in range(0, len(todo), chunk):
        idx = todo[s : s + chunk]
        xs = designs[idx]
        if len(idx) < chunk and engine == "xla":  # one compiled shape: pad with copies of the last design
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

    with tqdm(
        total=len(designs),
        initial=len(done) + len(invalid),
        desc="designs",
        unit="design",
        disable=not (progress and writer),
    ) as bar:
        if workers > 1 and chunks:
            run_in_workers(base, names, settings, chunks, int(workers), record)
        else:
            evaluate = _evaluate if engine == "xla" else engines.kernel_evaluate
            for idx, xs in chunks:
                record(idx, evaluate(base, names, settings, xs))
    if path is not None:
        if jax.process_count() > 1:
            from jax.experimental import multihost_utils

            multihost_utils.sync_global_devices("jaxcrank sweep table written")
        return read_table(path)
    return _table([dict(zip(cols, map(str, r))) for r in rows])


def _csv_text(rows) -> str:
    buf = io.StringIO()
    csv.writer(buf).writerows(rows)
    return buf.getvalue()


def _append(path: Path, text: str) -> None:
    """Append ``text`` with one ``write`` call on an ``O_APPEND`` descriptor, then fsync:
    a process killed at any point leaves the batch's rows either all in the table or
    none (the kernel finishes a write to a regular file that has started)."""
    data = text.encode()
    fd = os.open(path, os.O_WRONLY | os.O_APPEND)
    try:
        written = os.write(fd, data)
        while written < len(data):  # only on a full disk, which then raises
            written += os.write(fd, data[written:])
        os.fsync(fd)
    finally:
        os.close(fd)


def _atomic_write(path: Path, write) -> None:
    """Write a file through a temporary file and a rename: readers see the old file or
    the whole new one, never a part."""
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as f:
        write(f)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


def _resumable_rows(path: Path, cols, names, designs) -> set[int]:
    """Indices of the designs already in the table at ``path``, after checking that the
    table belongs to this sweep: its header, indices and parameter values (exact)."""
    table = read_table(path)
    with open(path, newline="") as f:
        header = next(csv.reader(f), None)
    if header != cols:
        raise CorruptFileError(
            f"{path}: its columns {header} are not this sweep's {cols}; the table is "
            "corrupted or from another sweep (move it away to start over)"
        )
    for k, i in enumerate(table.get("index", [])):
        if not 0 <= i < len(designs):
            raise CorruptFileError(f"{path}: design index {i} is outside this sweep's 0..{len(designs) - 1}")
        given = [table[c][k] for c in cols[1 : 1 + len(names)]]
        if not np.array_equal(given, designs[i], equal_nan=True):
            raise CorruptFileError(
                f"{path}: the row of design {i} holds parameters {given}, not this "
                f"sweep's {list(designs[i])}; the table is corrupted or from another sweep"
            )
    return {int(i) for i in table.get("index", [])}


_WORKER: dict = {}


def _worker_init(base_dict, names, settings):
    # a fresh (spawned) process: importing jaxcrank applies jaxcrank.numerics.runtime's XLA options
    _WORKER.update(base=config.from_dict(base_dict), names=names, settings=settings)


def _worker_solve(xs):
    return _evaluate(_WORKER["base"], _WORKER["names"], _WORKER["settings"], xs)


def run_in_workers(
    base, names, settings, chunks: Sequence[tuple[Sequence[int], Float[np.ndarray, "chunk params"]]], workers, record
):
    """Solve ``chunks`` in ``workers`` spawned processes, at most two chunks queued per
    worker, and ``record`` each as it finishes (the table is sorted when read)."""
    ctx = multiprocessing.get_context("spawn")  # a forked JAX runtime is not safe
    with ProcessPoolExecutor(
        workers, mp_context=ctx, initializer=_worker_init, initargs=(config.to_dict(base), list(names), settings)
    ) as pool:
        pending, queue = {}, iter(chunks)
        for idx, xs in itertools.islice(queue, 2 * workers):
            pending[pool.submit(_worker_solve, xs)] = idx
        while pending:
            finished, _ = wait(pending, return_when=FIRST_COMPLETED)
            for future in finished:
                record(pending.pop(future), future.result())
                for idx, xs in itertools.islice(queue, 1):
                    pending[pool.submit(_worker_solve, xs)] = idx


def summarize(table: Mapping[str, Shaped[np.ndarray, " designs"]], quantiles=(0.05, 0.5, 0.95)) -> dict:
    """Per metric over the ``ok`` designs: mean, std, min, max and quantiles; and
    the count of each status. Units as in the metric names."""
    ok = np.asarray(table["status"]) == "ok"
    out = {
        "designs": int(len(ok)),
        "status_counts": {s: int(np.sum(table["status"] == s)) for s in STATUSES},
        "metrics": {},
    }
    for k in METRICS:
        v = np.asarray(table[k])[ok]
        if v.size == 0:
            continue
        out["metrics"][k] = {
            "mean": float(v.mean()),
            "std": float(v.std(ddof=1)) if v.size > 1 else 0.0,
            "min": float(v.min()),
            "max": float(v.max()),
            **{f"q{int(round(q * 100)):02d}": float(np.quantile(v, q)) for q in quantiles},
        }
    return out
