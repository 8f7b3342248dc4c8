"""Running the designs of a sweep on the devices: the compiled solve of a device's shard,
the memory plan that sizes a batch ([`chunk_that_fits`][jaxcrank.runs.sweep_dispatch.chunk_that_fits]), and the dispatch
of a chunk
sharded over every device of every process ([`evaluate`][jaxcrank.runs.sweep_dispatch.evaluate])."""

from __future__ import annotations

import functools
from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding
from jax.sharding import PartitionSpec as P

from ..physics.linkage import AbstractMechanism as Mechanism
from ..physics.params import ParameterError
from .sweep_design import Settings, metric_names, simulate_design


def _mesh():
    return Mesh(np.array(jax.devices()), ("designs",))


@functools.lru_cache(maxsize=16)
def _batch_fn(names: tuple[str, ...], settings: Settings, batched: bool):
    """The compiled solve of a device's shard: a ``vmap`` over its rows, or (``batched``
    False, a one-row shard) the single design's solve without a batch dimension, which
    on a CPU runs ~2.5x faster than a batch per design (``bench/bench_sweep.py``)."""

    def one(base, x):
        m, status, steps = simulate_design(base, names, x, settings)
        return jnp.stack(list(m.values())), status, steps

    def shard(base, xs):
        if batched:
            return jax.vmap(lambda x: one(base, x))(xs)
        return jax.tree_util.tree_map(lambda a: a[None], one(base, xs[0]))

    # filter_jit: the base's Python-float parameters are compile-time constants (only
    # the swept ones are traced), which XLA folds into the vector field: 1.3x faster
    # per solver step than tracing every parameter (measured, batch of 8 designs).
    return eqx.filter_jit(shard)


#: batch_bytes' results by (the base's structure and parameter values, names, settings, batch):
#: a mechanism holds dicts (its joints), so it is no key of functools' caches itself
_BATCH_BYTES: dict = {}


def batch_bytes(base: Mechanism, names: tuple[str, ...], settings: Settings, batch: int) -> int:
    """Device memory, bytes, that XLA plans for solving ``batch`` designs in one ``vmap``
    batch on the default device (temporaries and outputs of the compiled program)."""
    names = tuple(names)
    leaves, treedef = jax.tree.flatten(base)
    key = (str(treedef), tuple(np.asarray(v).tobytes() for v in leaves), names, settings, int(batch))
    if key not in _BATCH_BYTES:
        _BATCH_BYTES[key] = _batch_bytes(base, names, settings, int(batch))
    return _BATCH_BYTES[key]


def _batch_bytes(base: Mechanism, names: tuple[str, ...], settings: Settings, batch: int) -> int:

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
    """A number of designs per device whose batch XLA plans within ``headroom`` times
    ``free_bytes`` (bytes), at least 1: the plans of batches of 2 and 8 designs give the
    fixed and the per-design bytes, and the chunk they predict is checked against XLA's
    plan of that batch and shrunk in proportion until it fits (a batch's memory can grow
    faster than linearly with its size)."""
    names = tuple(names)
    target = headroom * free_bytes
    two, eight = batch_bytes(base, names, settings, 2), batch_bytes(base, names, settings, 8)
    per_design = max((eight - two) / 6.0, 1.0)
    fixed = max(two - 2.0 * per_design, 0.0)
    chunk = max(1, int((target - fixed) // per_design))
    while chunk > 1:
        need = batch_bytes(base, names, settings, chunk)
        if need <= target:
            break
        chunk = max(1, min(chunk - 1, int(chunk * target / need)))
    return chunk


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
    its free memory ([`chunk_that_fits`][jaxcrank.runs.sweep_dispatch.chunk_that_fits], given the sweep), else 1024 per
    device."""
    if jax.default_backend() == "cpu":
        return jax.device_count()
    free = free_device_bytes()
    if base is None or settings is None or free is None:
        return 1024 * jax.device_count()
    return chunk_that_fits(base, names, settings, free) * jax.device_count()


def resolve_chunk(base: Mechanism, names: Sequence[str], settings: Settings, chunk: int | None = None) -> int:
    """The designs per chunk a sweep of ``names`` over ``base`` uses: ``chunk``
    (default [`default_chunk`][jaxcrank.runs.sweep_dispatch.default_chunk] for this sweep) rounded up to a multiple of
    the
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
    """Raise [`ParameterError`][jaxcrank.physics.params.ParameterError] naming ``chunk`` and the size that would fit
    when
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


def evaluate(base, names, settings, xs):
    """Metrics (n, metrics: [`metric_names`][jaxcrank.runs.sweep_design.metric_names] of ``base``), status
    codes and steps of designs ``xs`` (n, k),
    with n a multiple of the global device count; every process gets all rows.

    The batch is a ``jax.Array`` sharded over all devices of all processes
    (``NamedSharding`` over a 1-D mesh); each addressable shard is solved by the
    same compiled executable (`_batch_fn`) on its own device, dispatched asynchronously,
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
    for k, width in enumerate((len(metric_names(base)), None, None)):
        shape = (len(xs), width) if width else (len(xs),)
        outs.append(jax.make_array_from_single_device_arrays(shape, sharding, [r[k] for r in results]))
    if jax.process_count() > 1:
        from jax.experimental import multihost_utils

        return tuple(np.asarray(o) for o in multihost_utils.process_allgather(outs, tiled=True))
    return tuple(np.asarray(o) for o in outs)
