"""The compiled program of a command's solve, kept between processes.

[`simulate`][jaxcrank.runs.programs.simulate] runs [`jaxcrank.numerics.solve.simulate`][]
as a function of arrays: the mechanism's numbers enter as values
([`jaxcrank.numerics.solve.as_values`][]), so every design of one structure (the same
bodies, joints, laws and zeros) runs one program, and with a cache folder
([`jaxcrank.runs.cache.enable`][]) that program is stored ([`jaxcrank.runs.cache.exported`][]):
a later process, or a ``--set`` variant, loads it instead of tracing and compiling it.
While it compiles and while it solves, [`Phase`][jaxcrank.runs.programs.Phase] shows a sign of
life: the elapsed seconds on a terminal, a plain line per phase elsewhere.
"""

from __future__ import annotations

import sys
import threading
import time

#: seconds between the plain lines of a long phase when the output is not a terminal
PLAIN_EVERY_S = 30.0


class Phase:
    """A phase of a command shown on standard error while it runs (a context manager):
    ``"<label> ..."`` and the elapsed seconds, redrawn each second on a terminal; a line
    when it starts, one every `PLAIN_EVERY_S` seconds and one when it ends elsewhere (a
    log gets lines, not carriage returns). ``quiet`` shows nothing."""

    def __init__(self, label: str, quiet: bool = False, stream=None):
        self.label, self.quiet = label, quiet
        self.stream = sys.stderr if stream is None else stream
        self.seconds = 0.0
        self._stop = threading.Event()
        self._thread = None

    def _terminal(self) -> bool:
        return bool(getattr(self.stream, "isatty", lambda: False)())

    def _show(self):
        start, last = time.perf_counter(), time.perf_counter()
        while not self._stop.wait(1.0):
            elapsed = time.perf_counter() - start
            if self._terminal():
                print(f"\r{self.label} ... {elapsed:.0f} s", end="", file=self.stream, flush=True)
            elif elapsed - (last - start) >= PLAIN_EVERY_S:
                last = time.perf_counter()
                print(f"{self.label}: still running after {elapsed:.0f} s", file=self.stream, flush=True)

    def __enter__(self):
        self._start = time.perf_counter()
        if not self.quiet:
            print(f"{self.label} ...", end="" if self._terminal() else "\n", file=self.stream, flush=True)
            self._thread = threading.Thread(target=self._show, daemon=True)
            self._thread.start()
        return self

    def __exit__(self, *exc):
        self.seconds = time.perf_counter() - self._start
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
            end = "\r" if self._terminal() else ""
            state = "failed" if exc[0] is not None else "done"
            print(f"{end}{self.label}: {state} in {self.seconds:.1f} s", file=self.stream, flush=True)
        return False


class _PlainProgress:
    """[`progress`][jaxcrank.runs.programs.progress] for a stream that is not a terminal."""

    def __init__(self, total: int, initial: int, desc: str, unit: str, stream, every: float):
        self.total, self.n, self.desc, self.unit, self.stream = int(total), int(initial), desc, unit, stream
        self._step = max(1.0, every * self.total)
        self._next = (self.n // self._step + 1) * self._step

    def _line(self, text: str):
        print(f"{self.desc}: {text}", file=self.stream, flush=True)

    def __enter__(self):
        self._start = time.perf_counter()
        self._line(f"{self.n}/{self.total} {self.unit}s ...")
        return self

    def update(self, n: int = 1):
        self.n += int(n)
        if self.n >= self._next and self.n < self.total:
            self._next = (self.n // self._step + 1) * self._step
            elapsed, share = time.perf_counter() - self._start, 100 * self.n / max(self.total, 1)
            self._line(f"{self.n}/{self.total} {self.unit}s ({share:.0f} %) in {elapsed:.0f} s")

    def __exit__(self, *exc):
        state = "failed" if exc[0] is not None else "done"
        self._line(f"{state}, {self.n}/{self.total} {self.unit}s in {time.perf_counter() - self._start:.1f} s")
        return False


class _Silent:
    def __enter__(self):
        return self

    def update(self, n: int = 1):
        pass

    def __exit__(self, *exc):
        return False


def progress(
    total: int,
    *,
    initial: int = 0,
    desc: str = "",
    unit: str = "it",
    disable: bool = False,
    stream=None,
    every: float = 0.1,
):
    """The progress of ``total`` units of work, a context manager whose ``update(n)`` counts
    ``n`` more done (as a tqdm bar's): a tqdm bar when ``stream`` (default
    ``sys.stderr``) is a terminal; elsewhere (a log, a pipe) plain lines on it, no
    carriage returns: one when it starts, one each time another fraction ``every`` of
    ``total`` is done, and one when it ends (done or failed, with the seconds).
    ``initial``: the units already done (a resumed run); ``disable``: show nothing."""
    stream = sys.stderr if stream is None else stream
    if disable:
        return _Silent()
    if bool(getattr(stream, "isatty", lambda: False)()):
        from tqdm.auto import tqdm

        return tqdm(total=total, initial=initial, desc=desc, unit=unit, file=stream)
    return _PlainProgress(total, initial, desc, unit, stream, every)


def _split(mech, fold: bool = False):
    """The mechanism's values (float64 arrays, in leaf order) and what makes its program:
    its tree structure with the other leaves (zeros, names) in place. ``fold``: every
    number is part of the program (a constant XLA folds), none a value."""
    import jax

    from ..numerics.solve import as_values

    leaves, treedef = jax.tree_util.tree_flatten(mech if fold else as_values(mech))
    dynamic = tuple(i for i, leaf in enumerate(leaves) if isinstance(leaf, jax.Array))
    static = tuple(None if isinstance(leaf, jax.Array) else leaf for leaf in leaves)
    return [leaves[i] for i in dynamic], (treedef, static, dynamic)


def _join(values, program):
    """The mechanism ``_split`` took apart: ``values`` put
    back into ``program``'s ``(treedef, static, dynamic)``."""
    import jax

    treedef, static, dynamic = program
    leaves = list(static)
    for i, v in zip(dynamic, values):
        leaves[i] = v
    return jax.tree_util.tree_unflatten(treedef, leaves)


_COMPILED: dict = {}  # the last compiled solve of this process, by its key


def simulate(
    mech,
    t1: float,
    n_samples: int,
    options,
    metrics_start: float,
    *,
    quiet: bool = False,
    label: str | None = None,
    fold: bool = False,
):
    """[`jaxcrank.numerics.solve.simulate`][] of ``mech`` over ``n_samples`` equally spaced
    samples from 0 to ``t1`` (s), its metrics tracked after ``metrics_start`` (s), through
    the stored program where the cache folder holds one (or the one this process compiled
    last); phases shown on standard error (``label`` names the solve's phase). The
    mechanism's numbers are the program's inputs, so every design of its structure shares
    the program; ``fold``: they are compiled in as constants instead, which XLA can fold
    (a program per design).

    Returns:
        ``(simulation, seconds)``: the [`Simulation`][jaxcrank.numerics.solve.Simulation]
        and a dict of the phases' wall-clock seconds (``compile``, ``solve``) and whether
        the program came from the cache (``loaded``).

    Raises:
        SimulationError: where the solve cannot finish (with what to change).
    """
    import jax
    import jax.numpy as jnp

    from ..numerics import results, solve
    from ..physics.compiled import compile_model
    from . import cache

    compile_model(mech)  # the structure and the assembly, checked before anything is traced
    values, (treedef, static, dynamic) = _split(mech, fold)
    ts = solve.sample_times(mech, t1, n_samples)
    key = ("jaxcrank.simulate", treedef, static, dynamic, options.solver_name, options.rtol, options.atol)
    key += (options.dt0, options.max_steps, int(n_samples))

    def run(values, ts, metrics_start):
        sim = solve.simulate(
            _join(values, (treedef, static, dynamic)),
            ts=ts,
            options=options,
            metrics_start=metrics_start,
            throw=False,
        )
        return sim.ts, sim.ys, results.code(sim.result), sim.num_steps, sim.num_rejected, sim.metrics

    args = (values, ts, jnp.asarray(metrics_start, dtype=float))
    program, loaded, seconds = _COMPILED.get(key, (None, True, 0.0))
    if program is None:
        loaded = cache.stored(key, *args)
        if loaded:
            doing = "loading the compiled solve from the cache"
        elif cache.folder() is not None:
            doing = "compiling this linkage's solve (first run; later runs load it from the cache)"
        else:
            doing = "compiling this linkage's solve (no cache: --no-cache)"
        with Phase(doing, quiet) as compiling:
            program = cache.exported(run, key, *args).lower(*args).compile()
        seconds = compiling.seconds
        _COMPILED.clear()  # the last program only: a rerun of the same run (a new window) reuses it
        _COMPILED[key] = (program, loaded, 0.0)
    with Phase(label or f"solving {t1:g} s of motion", quiet) as solving:
        out = program(*args)
        jax.block_until_ready(out)
    sim = solve.Simulation(mech, out[0], out[1], results.item(int(out[2])), out[3], out[4], out[5])
    sim = solve.check(sim, max_steps=options.max_steps, t1=t1)
    return sim, {"compile": seconds, "solve": solving.seconds, "loaded": bool(loaded)}


def frames(sim, *, quiet: bool = False):
    """[`jaxcrank.analysis.outputs.frames`][] of a simulation (every output at every
    sample), through the stored program where the cache folder holds one.

    Returns:
        ``(frames, seconds)``: the [`Frame`][jaxcrank.physics.frame.Frame] of arrays, and the
        wall-clock seconds of its compilation (or loading) and evaluation.
    """
    import jax

    from ..physics import model
    from . import cache

    values, (treedef, static, dynamic) = _split(sim.mechanism)
    key = ("jaxcrank.frames", treedef, static, dynamic)

    def run(values, ts, ys):
        compiled = model.compile_model(_join(values, (treedef, static, dynamic)))
        return tuple(jax.vmap(model.evaluate, in_axes=(None, 0, 0))(compiled, ts, ys))  # a tuple: stored as is

    args = (values, sim.ts, sim.ys)
    with Phase("evaluating the outputs at every sample", quiet) as phase:
        out = model.Frame(*cache.exported(run, key, *args)(*args))
        jax.block_until_ready(out)
    return out, phase.seconds
