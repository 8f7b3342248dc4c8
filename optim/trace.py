"""A measured trace: one signal of a mechanism sampled against time or crank angle, read from a
CSV file, and the same signal computed from the model at the same instants.

**The file.** A header row, then one row per sample (lines starting with ``#`` are
comments). One column locates the sample:

- ``time_s``: time, s, on the simulation's clock: the driven body is at its initial angle
  (``driver.initial_angle``) at t = 0 and every period after; ``t`` (the time column of
  ``jaxcrank simulate``'s ``trajectory.csv``) is read the same way;
- ``crank_angle_deg`` (or ``<driven body>_angle_deg``): the driven body's angle, deg, as the
  simulator measures it. An angle that grows past 360 deg counts revolutions (which a
  period-k orbit needs to tell its revolutions apart); angles wrapped into [0, 360) put every
  sample into one revolution.

With both, the time is used. One more column holds the signal: any column name of
``trajectory.csv`` (``slider_ax``, ``force_C_normal``, ...) with or without its unit appended
(``slider_ax_m_s2``, ``force_C_normal_N``, ``rod_omega_rad_s``: the unit with ``/`` and blanks
as ``_`` and ``^`` dropped), or a signal of [`jaxcrank.physics.signals.signals`][]
(``slider_x_deviation_m``, ``contact_force_B_N``, ``transmission_angle_error_deg``, ...).
[`signal_columns`][optim.trace.signal_columns] lists a mechanism's. Other columns are allowed
when the signal is named.

**Phase.** Each sample's crank angle, taken modulo 360 deg, is the instant of the model's
revolution it is compared with: ``phase_times`` turns it into the time after the driven
body passed its initial angle (exactly, for a constant speed; by bisection of the driver's
angle for a speed profile).
"""

from __future__ import annotations

import csv
import dataclasses
import difflib
import math
from pathlib import Path

import jax
import numpy as np

from jaxcrank.analysis.outputs import columns, frame_columns
from jaxcrank.physics import model
from jaxcrank.physics.drivers import ConstantSpeed
from jaxcrank.physics.params import ParameterError
from jaxcrank.physics.signals import signal_meanings, signals

TIME_COLUMNS = ("time_s", "t")
ANGLE_COLUMN = "crank_angle_deg"
#: the units signal names end in, longest first
_SIGNAL_UNITS = ("rad_s2", "m_s2", "rad_s", "m_s", "N_m", "deg", "m", "N")


def unit_suffix(unit: str) -> str:
    """A unit written for a column name: ``m/s^2`` -> ``m_s2``, ``N m`` -> ``N_m``."""
    return unit.replace("^", "").replace("/", "_").replace(" ", "_")


def signal_columns(mech) -> dict[str, str]:
    """Signal name -> unit (as written in names, ``m_s2``) of every signal a trace of ``mech``
    may hold: each ``trajectory.csv`` column but time, bare and with its unit appended, and
    every signal of [`jaxcrank.physics.signals.signal_meanings`][] (its unit is its name's
    suffix)."""
    out = {}
    for name, unit in columns(mech).items():
        if name != "t":
            out[name] = out[f"{name}_{unit_suffix(unit)}"] = unit_suffix(unit)
    for name in signal_meanings(mech):
        out.setdefault(name, next((u for u in _SIGNAL_UNITS if name.endswith(f"_{u}")), ""))
    return out


def check_signal(mech, name: str) -> str:
    """``name`` when ``mech`` has that signal ([`signal_columns`][optim.trace.signal_columns]).

    Raises:
        ParameterError: an unknown signal; the message names it and the valid names."""
    valid = signal_columns(mech)
    if name not in valid:
        close = difflib.get_close_matches(name, list(valid), n=6, cutoff=0.5)
        raise ParameterError(
            f"signal column {name!r} is not a signal of this mechanism"
            + (f"; close: {', '.join(close)}" if close else "")
            + f"; valid: the signals {', '.join(signal_meanings(mech))}, or any trajectory.csv column with or "
            f"without its unit ({len(valid)} names: optim.trace.signal_columns)"
        )
    return name


def model_signal(mech, frames: model.Frame, name: str) -> jax.Array:
    """The signal ``name`` of ``mech`` at the instants of ``frames`` (a
    [`Frame`][jaxcrank.physics.frame.Frame] of arrays), SI, angles in degrees; traceable."""
    sig = signals(mech, frames)
    if name in sig:
        return sig[name]
    cols = frame_columns(mech, frames)
    if name in cols:
        return cols[name]
    for base, unit in columns(mech).items():
        if name == f"{base}_{unit_suffix(unit)}":
            return cols[base]
    raise ParameterError(f"signal column {name!r} is not a signal of this mechanism (optim.trace.signal_columns)")


@dataclasses.dataclass(frozen=True, eq=False)
class Trace:
    """A measured trace (module docstring).

    Attributes:
        signal: the signal's column name (units in the name, or those of trajectory.csv).
        values: the measured signal, its unit, shape (n,).
        time_s: the sample times, s, shape (n,), or None (angles given).
        angle_deg: the driven body's angle at each sample, deg, shape (n,), or None (times given).
        source: where it came from (a path), for reports.
    """

    signal: str
    values: np.ndarray
    time_s: np.ndarray | None = None
    angle_deg: np.ndarray | None = None
    source: str = ""

    def __post_init__(self):
        values = np.asarray(self.values, dtype=float)
        if values.ndim != 1 or values.size < 2:
            raise ParameterError(f"trace {self.signal!r}: {values.size} samples; a trace needs at least 2")
        located = [(k, getattr(self, k)) for k in ("time_s", "angle_deg") if getattr(self, k) is not None]
        if not located:
            raise ParameterError(f"trace {self.signal!r}: no time_s or crank_angle_deg column locates the samples")
        for key, col in located:
            col = np.asarray(col, dtype=float)
            if col.shape != values.shape or not np.all(np.isfinite(col)):
                raise ParameterError(f"trace column {key}: {col.shape[0]} values, all finite, one per sample needed")
            object.__setattr__(self, key, col)
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            raise ParameterError(f"trace column {self.signal!r}: sample {int(bad[0])} is {values[bad[0]]}, not finite")
        object.__setattr__(self, "values", values)

    @property
    def n(self) -> int:
        return int(self.values.size)


def read_trace(path, signal: str | None = None) -> Trace:
    """Read a trace CSV (module docstring). ``signal``: the signal's column (default: the one
    column besides time and angle).

    Raises:
        ParameterError: no time_s / crank_angle_deg column, no such signal column (or several
            candidates and none named), a value that is not a number, or fewer than 2 samples;
            the message names the file and column."""
    path = Path(path)
    with open(path, newline="") as fh:
        rows = [r for r in csv.reader(line for line in fh if line.strip() and not line.lstrip().startswith("#"))]
    if not rows:
        raise ParameterError(f"{path}: empty; a trace needs a header row (time_s or crank_angle_deg, a signal)")
    header = [h.strip() for h in rows[0]]
    time = next((c for c in TIME_COLUMNS if c in header), None)
    angle = ANGLE_COLUMN if ANGLE_COLUMN in header else next((c for c in header if c.endswith("_angle_deg")), None)
    if time is None and angle is None:
        raise ParameterError(f"{path}: no time_s or crank_angle_deg column (columns: {', '.join(header)})")
    if signal is None:
        rest = [c for c in header if c not in (time, angle)]
        if len(rest) != 1:
            raise ParameterError(f"{path}: name the signal column ([data] signal): candidates {', '.join(rest)}")
        signal = rest[0]
    if signal not in header:
        raise ParameterError(f"{path}: no signal column {signal!r} (columns: {', '.join(header)})")
    table = {}
    for key in (time, angle, signal):
        if key is None:
            continue
        j, values = header.index(key), []
        for i, row in enumerate(rows[1:], start=2):
            try:
                values.append(float(row[j]))
            except (ValueError, IndexError):
                cell = row[j] if j < len(row) else "(missing)"
                raise ParameterError(f"{path}: line {i}, column {key}: {cell!r} is not a number") from None
        table[key] = np.asarray(values)
    try:
        return Trace(
            signal,
            table[signal],
            time_s=table.get(time) if time else None,
            angle_deg=None if time else table[angle],
            source=str(path),
        )
    except ParameterError as err:
        raise ParameterError(f"{path}: {err}") from None


def write_trace(path, trace: Trace) -> None:
    """Write ``trace`` as a CSV that [`read_trace`][optim.trace.read_trace] reads back (10
    significant digits; the time column when the trace has times, else the angle)."""
    key, where = ("time_s", trace.time_s) if trace.time_s is not None else (ANGLE_COLUMN, trace.angle_deg)
    with open(path, "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow([key, trace.signal])
        writer.writerows([f"{a:.17g}", f"{v:.10g}"] for a, v in zip(where, trace.values))


def _driver(mech):
    return model.compile_model(mech).linkage.driver


def _times_of_angles(mech, relative: np.ndarray) -> np.ndarray:
    """Times in [0, T) at which the driven body has turned ``relative`` rad (in [0, 2 pi))
    from its initial angle: closed form at a constant speed, else bisection of its angle."""
    driver, period = _driver(mech), float(mech.period)
    if isinstance(driver, ConstantSpeed):
        return np.minimum(relative / abs(float(driver.speed)), np.nextafter(period, 0.0))
    angle = jax.jit(jax.vmap(driver.angle))
    lo, hi = np.zeros_like(relative), np.full_like(relative, period)
    start = float(driver.initial_angle)
    for _ in range(64):
        mid = 0.5 * (lo + hi)
        below = np.asarray(angle(mid)) - start < relative
        lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
    return 0.5 * (lo + hi)


def phase_times(mech, trace: Trace) -> tuple[np.ndarray, np.ndarray]:
    """Each sample's instant within its revolution, s in [0, T), and its revolution number
    (0, 1, ... from the trace's first revolution; T: ``mech.period``, the driver's period).

    Raises:
        ParameterError: a driver that is not periodic (a torque)."""
    driver = _driver(mech)
    if not hasattr(driver, "speed"):
        kind = type(driver).__name__
        raise ParameterError(f"a trace is aligned by the driver's period; this driver ({kind}) has none")
    period = float(mech.period)
    if trace.time_s is not None:
        turns = np.floor(trace.time_s / period)
        return trace.time_s - turns * period, (turns - turns.min()).astype(int)
    relative = (np.radians(trace.angle_deg) - float(driver.initial_angle)) * math.copysign(1.0, float(driver.speed))
    turns = np.floor(relative / (2.0 * math.pi))
    return _times_of_angles(mech, relative - 2.0 * math.pi * turns), (turns - turns.min()).astype(int)


def trace_angles_deg(mech, trace: Trace) -> np.ndarray:
    """The driven body's angle at each sample, deg (as given, or from the times), for plots."""
    if trace.angle_deg is not None:
        return trace.angle_deg
    return np.degrees(np.asarray(jax.vmap(_driver(mech).angle)(trace.time_s)))
