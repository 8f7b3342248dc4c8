"""Compiled programs that outlive the process.

A design gradient takes seconds to run but tens of seconds to trace and compile.
Two caches, both on disk, make a second process skip that work:

- JAX's persistent compilation cache ([`enable`][jaxcrank.runs.cache.enable]) keeps XLA's compiled
  executables. JAX stores only programs without host callbacks, so programs meant
  for it are traced under [`checks_as_nan`][jaxcrank.runs.cache.checks_as_nan].
- [`exported`][jaxcrank.runs.cache.exported] keeps the traced program itself (``jax.export``, serialised
  StableHLO), keyed by everything that decides it: the caller's key, the argument
  shapes, the versions of jaxcrank's sources and of JAX, equinox and diffrax, the
  backend and ``XLA_FLAGS``. A hit skips tracing; with the compilation cache also
  warm, the program is ready in about a second.

Both live under one folder ([`enable`][jaxcrank.runs.cache.enable]'s ``path``); deleting it is always safe.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import importlib.metadata
import os
import pickle
import sys
import warnings
from pathlib import Path

import jax
from jax import export as jax_export

from .. import _private

#: Environment variable naming the cache folder; ``0`` or ``off`` turns caching off.
ENV = "JAXCRANK_CACHE_DIR"

_folder: Path | None = None


def default_dir() -> Path:
    """``$XDG_CACHE_HOME/jaxcrank/xla`` (``~/.cache/jaxcrank/xla`` by default)."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "jaxcrank" / "xla"


def enable(path: str | os.PathLike | None = None) -> Path | None:
    """Turn on both caches for this process.

    Args:
        path: the cache folder. Default: ``$JAXCRANK_CACHE_DIR``, else a folder the
            user already gave JAX (``JAX_COMPILATION_CACHE_DIR``), else [`default_dir`][jaxcrank.runs.cache.default_dir]
            .

    Returns the folder in use, or None when ``$JAXCRANK_CACHE_DIR`` is ``0`` or ``off``
    (and no ``path`` is given).

    Raises:
        OSError: the folder cannot be created.
    """
    global _folder
    env = os.environ.get(ENV, "")
    if path is None and env.lower() in ("0", "off"):
        return None
    if path is None:
        path = env or os.environ.get("JAX_COMPILATION_CACHE_DIR") or default_dir()
    path = Path(path)
    path.mkdir(parents=True, exist_ok=True)
    jax.config.update("jax_compilation_cache_dir", str(path))
    _folder = path
    return path


def disable() -> None:
    """Turn off this module's store of traced programs for the rest of the process, and
    JAX's compilation cache for the compilations JAX has not yet looked up in it."""
    global _folder
    _folder = None
    jax.config.update("jax_compilation_cache_dir", None)


def arguments(p) -> None:
    """Add ``--cache-dir DIR`` and ``--no-cache`` to the argparse parser ``p`` of a command
    that compiles programs ([`use`][jaxcrank.runs.cache.use] reads them back)."""
    p.add_argument(
        "--cache-dir",
        type=Path,
        default=None,
        help="where compiled programs are kept between runs (default: $JAXCRANK_CACHE_DIR, else ~/.cache/jaxcrank/xla)",
    )
    p.add_argument("--no-cache", action="store_true", help="compile every program afresh and keep none")


def use(args, command: str) -> Path | None:
    """The cache of [`arguments`][jaxcrank.runs.cache.arguments]: turned on
    ([`enable`][jaxcrank.runs.cache.enable]), or off with ``--no-cache``
    ([`disable`][jaxcrank.runs.cache.disable]); an unusable folder is reported on standard
    error and the command goes on without a cache. Returns the folder in use, or None."""
    if getattr(args, "no_cache", False):
        disable()
        return None
    try:
        return enable(getattr(args, "cache_dir", None))
    except OSError as err:
        print(f"jaxcrank {command}: no compilation cache ({err}); pass --cache-dir DIR or --no-cache", file=sys.stderr)
        return None


def folder() -> Path | None:
    """The folder [`enable`][jaxcrank.runs.cache.enable] set, or None."""
    return _folder


@contextlib.contextmanager
def checks_as_nan():
    """While tracing inside this block, equinox's run-time checks (``equinox.error_if``,
    which diffrax uses on traced times) turn the checked value into NaN when they
    fail, instead of compiling a host callback that raises. Such programs can be
    cached; the caller must check their results for NaN.

    Equinox offers this only process-wide (``EQX_ON_ERROR=nan``, read once at its
    import); `jaxcrank._private.equinox_checks_as_nan` sets its module setting
    for the block.
    JAX keeps the traces of inner jitted functions for the process, checks included:
    inside jaxcrank's solve these are only diffrax's checks of the sample times that
    [`jaxcrank.numerics.solve.simulate`][] builds (increasing, within the span), which cannot fail.
    """
    with _private.equinox_checks_as_nan():
        yield


def checks_as_nan_from_now() -> None:
    """For the rest of the process, trace equinox's run-time checks as
    [`checks_as_nan`][jaxcrank.runs.cache.checks_as_nan] does: every program traced from now on
    has no host callback, so JAX's compilation cache keeps it (a command whose solves all run
    with ``throw=False`` and check their results on the host: ``jaxcrank optimize`` with the
    steady-state objective). Programs traced before keep their checks."""
    _private.equinox_checks_as_nan_from_now()


def checking_as_nan() -> bool:
    """Whether programs traced now have equinox's checks as NaN (no host callback)."""
    return _private.equinox_checking_as_nan()


@functools.cache
def _environment() -> bytes:
    """What every exported program depends on besides its own key: jaxcrank's and
    optim's sources, the versions of the packages that trace them, backend, flags."""
    h = hashlib.sha256()
    root = Path(__file__).resolve().parents[2]
    for package in ("jaxcrank", "optim"):
        for f in sorted((root / package).rglob("*.py")):
            h.update(f.relative_to(root).as_posix().encode())
            h.update(f.read_bytes())
    for dist in ("jax", "jaxlib", "equinox", "diffrax", "lineax", "optimistix", "optax"):
        try:
            h.update(f"{dist}={importlib.metadata.version(dist)};".encode())
        except importlib.metadata.PackageNotFoundError:
            h.update(f"{dist}=none;".encode())
    h.update(jax.default_backend().encode())
    h.update(os.environ.get("XLA_FLAGS", "").encode())
    h.update(str(jax.config.jax_enable_x64).encode())
    return h.digest()


def _key(key, args) -> str | None:
    shapes = [(tuple(a.shape), str(a.dtype)) for a in args]
    try:
        spec = pickle.dumps((key, shapes), protocol=4)
    except (pickle.PicklingError, TypeError, AttributeError):
        return None  # a key that cannot be written down: no exported program
    return hashlib.sha256(_environment() + spec).hexdigest()


def stored(key, *args) -> bool:
    """Whether the cache folder holds a traced program for ``key`` and the argument shapes
    of ``args`` ([`exported`][jaxcrank.runs.cache.exported] would load it)."""
    digest = None if _folder is None else _key(key, jax.tree_util.tree_leaves(args))
    return digest is not None and (_folder / "exported" / f"{digest}.bin").exists()


def exported(fun, key, *args):
    """``fun`` jitted, its trace loaded from the cache folder when an earlier process
    stored one under the same ``key`` and argument shapes, else traced now (under
    [`checks_as_nan`][jaxcrank.runs.cache.checks_as_nan]) and stored. Without a cache folder, or with a key pickle
    cannot write: ``jax.jit(fun)``, traced under [`checks_as_nan`][jaxcrank.runs.cache.checks_as_nan] at its first call.

    Args:
        fun: a function of arrays returning arrays (no host callbacks).
        key: a picklable value that, with the argument shapes, decides ``fun``'s
            program (e.g. the frozen problem definition it closes over).
        args: the arguments' shapes and dtypes (arrays or ``jax.ShapeDtypeStruct``).

    Returns a jitted callable taking arguments of those shapes. A program that still
    holds a host callback (an inner jitted function this process traced before, outside
    [`checks_as_nan`][jaxcrank.runs.cache.checks_as_nan]) is not stored, only jitted.
    """
    digest = None if _folder is None else _key(key, jax.tree_util.tree_leaves(args))
    if digest is None:
        return _under_checks_as_nan(jax.jit(fun))
    path = _folder / "exported" / f"{digest}.bin"
    if path.exists():
        try:
            return jax.jit(jax_export.deserialize(bytearray(path.read_bytes())).call)
        except Exception:  # noqa: BLE001 - a damaged or foreign file: trace again and replace it
            pass
    with checks_as_nan():
        try:
            program = jax_export.export(jax.jit(fun))(*args)
        except NotImplementedError:
            # a host callback is left in the program: an inner jitted function traced
            # earlier in this process, outside checks_as_nan, is reused from JAX's trace
            # cache. Such a program cannot be stored; it runs uncached.
            return _under_checks_as_nan(jax.jit(fun))
    blob = program.serialize()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_bytes(blob)
        tmp.replace(path)
    except OSError as err:  # an unwritable or full cache folder costs the next run a trace, not this run
        warnings.warn(f"jaxcrank: could not store the traced program in {path.parent} ({err})", stacklevel=2)
    # the program as a later process reads it back, so both compile the same module
    return jax.jit(jax_export.deserialize(bytearray(blob)).call)


def _under_checks_as_nan(jitted):
    """``jitted``, traced (at its first call or ``.lower``) under [`checks_as_nan`][jaxcrank.runs.cache.checks_as_nan]
    ."""

    @functools.wraps(jitted)
    def call(*args):
        with checks_as_nan():
            return jitted(*args)

    def lower(*args):
        with checks_as_nan():
            return jitted.lower(*args)

    call.lower = lower
    return call
