"""The optimiser's checkpoint: ``checkpoint.npz`` (iterate, optimiser state, history)
and ``history.csv``, replaced atomically (temporary file and rename) after every
iteration. A truncated or corrupted checkpoint raises
[`jaxcrank.CorruptFileError`][jaxcrank.errors.CorruptFileError] naming the file; it is never silently replaced by a
fresh start."""

from __future__ import annotations

import csv
import json
import zipfile
import zlib
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from jaxcrank.errors import CorruptFileError


def flatten(state):
    """The optimiser state's leaves as named numpy arrays."""
    leaves = jax.tree.leaves(state)
    return {f"leaf{i}": np.asarray(x) for i, x in enumerate(leaves)}


def unflatten(template, arrays):
    """The optimiser state shaped like ``template`` from [`flatten`][optim.checkpoint.flatten]'s arrays."""
    leaves, treedef = jax.tree.flatten(template)
    return jax.tree.unflatten(
        treedef, [jnp.asarray(arrays[f"leaf{i}"], dtype=np.asarray(x).dtype) for i, x in enumerate(leaves)]
    )


def history_columns(problem):
    """The columns of ``history.csv`` and of the history records (units in the names)."""
    return (
        ["iteration", "objective_deg", "objective_without_cost_deg", "cost_deg"]
        + [f"grad_{n}_deg_per_SI" for n in problem.names]
        + [f"{n}_SI" for n in problem.names]
        + ["projected_gradient", "step", "halvings", "evaluations", "regime", "leading_multiplier", "seconds"]
    )


def write_history(path: Path, problem, history):
    cols = history_columns(problem)
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=cols)
        w.writeheader()
        for h in history:
            w.writerow({c: h.get(c) for c in cols})  # a history from before a column: empty there


def save(out: Path, problem, settings, u, state, history, f0, quiet, converged, stop_reason=None):
    """One atomic file holds everything a resume needs; history.csv is a copy for people.
    ``converged``: the convergence test met (or None); ``stop_reason``: why a run that did not
    converge stopped for good (or None), so that a resume does not repeat it."""
    out.mkdir(parents=True, exist_ok=True)
    meta = {
        "names": list(problem.names),
        "method": settings.optimizer.label,
        "f0": f0,
        "quiet": quiet,
        "converged": converged,
        "stop_reason": stop_reason,
        "history": history,
    }
    arrays = {
        "u": np.asarray(u),
        "meta": np.asarray(json.dumps(meta)),
        **{f"state_{k}": v for k, v in flatten(state).items()},
    }
    tmp = out / "checkpoint.tmp.npz"
    np.savez(tmp, **arrays)
    tmp.replace(out / "checkpoint.npz")
    tmp = out / "history.tmp.csv"
    write_history(tmp, problem, history)
    tmp.replace(out / "history.csv")


_META_KEYS = {"names", "method", "f0", "quiet", "converged", "history"}


def load(out: Path):
    """(u, optimiser-state leaves, meta dict) from ``out/checkpoint.npz``.

    Raises:
        FileNotFoundError: there is no checkpoint.
        CorruptFileError: the file is truncated, corrupted or lacks an entry a
            resume needs; the message names the file.
    """
    path = Path(out) / "checkpoint.npz"
    if not path.exists():
        raise FileNotFoundError(f"no checkpoint at {path}")
    try:
        with np.load(path) as arrays:
            meta = json.loads(str(arrays["meta"]))
            leaves = {k[6:]: np.asarray(arrays[k]) for k in arrays.files if k.startswith("state_")}
            u = np.asarray(arrays["u"])
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile, zlib.error) as err:
        raise CorruptFileError(
            f"{path}: cannot be read ({type(err).__name__}: {err}); the run cannot be "
            "resumed from it (move it away to start over)"
        ) from None
    missing = _META_KEYS - set(meta) if isinstance(meta, dict) else _META_KEYS
    if missing or not isinstance(meta.get("history"), list) or len(meta["history"]) == 0:
        raise CorruptFileError(
            f"{path}: its metadata lacks {sorted(missing) or 'history'}; the checkpoint is corrupted"
        )
    if u.shape != (len(meta["names"]),) or not np.all(np.isfinite(u)):
        raise CorruptFileError(f"{path}: the design u = {u} does not fit {meta['names']}; the checkpoint is corrupted")
    return jnp.asarray(u), leaves, meta
