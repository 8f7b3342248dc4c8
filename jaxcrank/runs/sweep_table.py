"""A sweep's files: the table (CSV, one row per design, appended one whole batch at a
time) and atomic writes, and the checks that a table on disk belongs to this sweep."""

from __future__ import annotations

import csv
import io
import json
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from jaxtyping import Shaped

from ..errors import CorruptFileError
from ..physics.parameters import parameter_unit
from .sweep_design import STATUSES, metric_names


def parameter_columns(mech, names: Sequence[str]) -> list[str]:
    """The column of each parameter of ``names`` in a table over designs of ``mech``:
    ``<name>_<unit>`` ([`jaxcrank.physics.parameters.parameter_unit`][]).

    Raises:
        ParameterError: for a name ``mech`` does not have.
    """
    return [f"{n}_{parameter_unit(mech, n)}" for n in names]


def columns(mech, names: Sequence[str]) -> list[str]:
    """Column names of a sweep table over ``names`` of ``mech``: ``index``, one
    ``<name>_<unit>`` per parameter, ``status``, ``message``, the mechanism's headline
    metrics ([`metric_names`][jaxcrank.runs.sweep_design.metric_names]), ``steps``."""
    metrics = list(metric_names(mech))
    return ["index"] + parameter_columns(mech, names) + ["status", "message"] + metrics + ["steps"]


def metric_columns(table) -> list[str]:
    """The metric columns of a sweep table (the columns between ``message`` and ``steps``),
    in table order."""
    keys = list(table)
    if "message" not in keys:
        return []
    return [k for k in keys[keys.index("message") + 1 :] if k != "steps"]


#: the text columns of a sweep table (every other column holds numbers)
TEXT_COLUMNS = ("status", "message")


def read_table(path, text: Sequence[str] = TEXT_COLUMNS) -> dict[str, Shaped[np.ndarray, " rows"]]:
    """A sweep table (CSV) as columns: numbers as float arrays (empty cells NaN),
    the ``text`` columns (``status`` and ``message``; a regime table adds ``regime``) as
    string arrays; rows sorted by ``index``.

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
            if key in text:
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
    return table_from_rows(rows, text)


def table_from_rows(rows: list[dict[str, str]], text: Sequence[str] = TEXT_COLUMNS) -> dict[str, np.ndarray]:
    """Rows of CSV cells (strings) as columns sorted by ``index`` (see
    [`read_table`][jaxcrank.runs.sweep_table.read_table] )."""
    if not rows:
        return {}
    rows = sorted(rows, key=lambda r: int(r["index"]))
    out = {}
    for key in rows[0]:
        vals = [r[key] for r in rows]
        if key in text:
            out[key] = np.array(vals, dtype=object)
        else:
            out[key] = np.array([float(v) if v != "" else np.nan for v in vals])
    out["index"] = out["index"].astype(int)
    return out


def csv_text(rows) -> str:
    buf = io.StringIO()
    csv.writer(buf).writerows(rows)
    return buf.getvalue()


def append(path: Path, text: str) -> None:
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


def atomic_write(path: Path, write) -> None:
    """Write a file through a temporary file and a rename: readers see the old file or
    the whole new one, never a part."""
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as f:
        write(f)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


def resumable_rows(path: Path, cols, names, designs, text: Sequence[str] = TEXT_COLUMNS) -> set[int]:
    """Indices of the designs already in the table at ``path``, after checking that the
    table belongs to this sweep: its header, indices and parameter values (exact).
    ``text``: the table's text columns (as [`read_table`][jaxcrank.runs.sweep_table.read_table])."""
    table = read_table(path, text)
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


#: what a run was made of (its base mechanism and settings, as text), beside its table
IDENTITY_FILE = "run.json"


def open_table(
    out,
    resume: bool,
    designs: np.ndarray,
    cols,
    names,
    text: Sequence[str] = TEXT_COLUMNS,
    writer: bool = True,
    identity: dict | None = None,
) -> tuple[Path | None, set[int]]:
    """Open the table of a run over ``designs`` in the directory ``out``: ``table.csv``'s
    path (None without ``out``) and the indices of the designs already in it.

    A new run writes ``designs.npy``, ``identity`` (what else its rows depend on: the base
    mechanism and the settings, as text) to `IDENTITY_FILE` and the table's header;
    ``resume`` continues an existing one after checking that it is over the same designs
    (exactly), of the same identity and that its table is this run's
    ([`resumable_rows`][jaxcrank.runs.sweep_table.resumable_rows]). Only a ``writer``
    (process 0 of a distributed job) writes.

    Raises:
        ParameterError: ``out`` holds a table but ``resume`` is not set, or a run over other
            designs, or of another base mechanism or settings (naming which).
        CorruptFileError: ``designs.npy``, `IDENTITY_FILE` or the table cannot be read.
    """
    from ..physics.params import ParameterError

    if out is None:
        return None, set()
    out = Path(out)
    path = out / "table.csv"
    if path.exists() and not resume:
        raise ParameterError(
            f"{out} already holds a table (table.csv): pass resume=True (--resume) to continue it "
            "or choose another output directory"
        )
    done: set[int] = set()
    if resume and (out / "designs.npy").exists():
        try:
            old = np.load(out / "designs.npy")
        except (ValueError, OSError, EOFError) as err:
            raise CorruptFileError(
                f"{out / 'designs.npy'}: cannot be read ({err}); the run cannot be resumed "
                "(move the directory away to start over)"
            ) from None
        if old.shape != designs.shape or not np.array_equal(old, designs):
            raise ParameterError(f"{out} holds a run over other designs: resume needs the same spec")
    if resume and identity is not None and (out / IDENTITY_FILE).exists():
        _check_identity(out / IDENTITY_FILE, identity)
    if resume and path.exists():
        done = resumable_rows(path, cols, names, designs, text)
    if writer:
        out.mkdir(parents=True, exist_ok=True)
        atomic_write(out / "designs.npy", lambda f: np.save(f, designs))
        if identity is not None:
            atomic_write(out / IDENTITY_FILE, lambda f: f.write(json.dumps(identity, indent=1).encode()))
        if not path.exists():
            atomic_write(path, lambda f: f.write(csv_text([cols]).encode()))
    return path, done


def run_identity(base, settings: dict) -> dict | None:
    """What a run's rows depend on besides its designs: the base mechanism (as its file holds it)
    and ``settings`` (plain values), for [`open_table`][jaxcrank.runs.sweep_table.open_table];
    None for a mechanism that cannot be written out (its resume is then not checked for it)."""
    from ..physics.params import ParameterError
    from .codec import to_dict

    try:
        identity = {"mechanism": to_dict(base), "settings": settings}
        return json.loads(json.dumps(identity))
    except (ParameterError, TypeError, ValueError):
        return None


def _check_identity(path: Path, identity: dict) -> None:
    """Raise a ParameterError naming what differs between the run recorded in ``path`` and ``identity``."""
    from ..physics.params import ParameterError

    try:
        recorded = json.loads(path.read_text())
    except (ValueError, OSError) as err:
        raise CorruptFileError(f"{path}: cannot be read ({err}); move the directory away to start over") from None
    differ = [key for key in identity if recorded.get(key) != identity[key]]
    if differ:
        raise ParameterError(
            f"{path.parent} holds a run of another {' and '.join(differ)} ({path.name} records them): resuming "
            "would mix its rows with this run's; give the run's own mechanism and settings, or choose another --out"
        )
