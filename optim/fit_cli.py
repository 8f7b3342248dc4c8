"""``jaxcrank fit --config FIT.toml --data TRACE.csv [--out DIR] [--quiet] [--resume]``: calibrate a
mechanism's parameters against a measured trace ([`optim.fit.fit`][]).

The config file (TOML; SI units):

```toml
mechanism = "paper"            # a preset's name, or a [mechanism] table as config.toml writes it,
                               # or [mechanism] file = "my_linkage.toml" (beside this file)

[parameters.clearance_B]       # any name jaxcrank.set_parameter accepts
start = 2.1e-4
lower = 1e-4
upper = 6e-4

[data]
signal = "slider_ax_m_s2"      # the trace's signal column (default: its one column besides time/angle)
noise = 40.0                   # the noise scale, the signal's unit (default: the measured RMS)

[fit]                          # all optional
max_iterations = 30
ftol = 1e-6
xtol = 1e-8
gtol = 1e-10
max_relative_halfwidth = 0.5   # a wider 95 % interval marks a parameter as not identifiable
window_revolutions = 20        # not periodic: revolutions from rest before the compared window

[steady]                       # optional: jaxcrank.SteadyOptions fields, and rtol, atol, max_steps
settle_revolutions = 20
```

``--out DIR`` gets ``fit.json`` ([`FitResult.summary`][optim.fit.FitResult.summary], with the
config and the trace's path), ``fit.csv`` (the start, then one row per iteration: misfit,
trial misfit, accepted, damping, step, CPU seconds, the trial's regime, and the iterate's
parameters, units in the names) and ``fit.png`` (measured, start and fitted trace against the
crank angle, and the residuals). After every accepted iteration ``checkpoint.json`` holds the
iterate: a killed fit run again with ``--resume`` starts from it.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import tomllib
from pathlib import Path

from jaxcrank.numerics.shooting import SteadyOptions
from jaxcrank.physics.params import ParameterError
from jaxcrank.runs.sweep_table import atomic_write

from .calibrate import FIT_STEADY, FitParameter
from .least_squares import LMSettings

SECTIONS = ("mechanism", "parameters", "data", "fit", "steady")
FIT_KEYS = ("max_relative_halfwidth", "window_revolutions")
STEADY_SOLVE_KEYS = ("solver", "rtol", "atol", "dt0", "max_steps")


def add_arguments(p):
    """Add ``fit``'s options to its argparse parser ``p``."""
    p.description = (
        "Fit mechanism parameters (clearances, restitution, friction, ...) to a measured trace by least squares "
        "on the steady periodic orbit, with the exact Jacobian; writes fit.json, fit.csv and fit.png into --out."
    )
    p.add_argument("--config", type=Path, required=True, help="fit config TOML ([mechanism], [parameters], ...)")
    p.add_argument("--data", type=Path, required=True, help="the measured trace: CSV with time_s or crank_angle_deg")
    p.add_argument("--out", type=Path, default=Path("runs/fit"), help="output directory (default runs/fit)")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.add_argument(
        "--resume", action="store_true", help="start from the last iterate of a killed fit in --out (checkpoint.json)"
    )
    return p


def _mechanism(value, folder: Path):
    """The base mechanism of the config's ``mechanism`` key: a preset's name, or a table (its
    own ``mechanism`` key may name a preset, whose values the table's others change; or
    ``preset = NAME`` or ``file = "linkage.toml"``, relative to ``folder``, as in a design
    problem file, with the table's other keys as changes)."""
    from jaxcrank.physics.presets import PRESETS, preset
    from jaxcrank.runs import codec, config

    if isinstance(value, dict) and ("file" in value or "preset" in value):
        from .spec import mechanism_section

        return mechanism_section(value, folder)
    if isinstance(value, dict) and value.get("mechanism") in PRESETS and value["mechanism"] not in codec.KINDS:
        rest = {k: v for k, v in value.items() if k != "mechanism"}
        base = preset(value["mechanism"])
        return config.from_dict(rest, base=base) if rest else base
    from jaxcrank.runs.spec import spec_mechanism

    return spec_mechanism(value)


def _numbers(table: dict, section: str, valid) -> dict:
    bad = sorted(set(table) - set(valid))
    if bad:
        raise ParameterError(f"unknown [{section}] keys {bad}; valid: {', '.join(valid)}")
    return dict(table)


def build(cfg: dict, folder: Path | str = ".") -> dict:
    """The fit a config dict describes (module docstring; ``folder``: where a ``[mechanism]``
    ``file`` is looked for, the config file's): ``mechanism``, ``parameters``
    ([`FitParameter`][optim.calibrate.FitParameter]s), ``signal``, ``noise``, ``settings``
    ([`LMSettings`][optim.least_squares.LMSettings]), ``options`` (SteadyOptions) and the
    ``[fit]`` extras.

    Raises:
        ParameterError: an unknown section or key, a parameter without start, lower and upper,
            or a value out of range (the message names it)."""
    bad = sorted(set(cfg) - set(SECTIONS))
    if bad:
        raise ParameterError(f"unknown fit config keys {bad}; valid: {', '.join(SECTIONS)}")
    mech = _mechanism(cfg.get("mechanism"), Path(folder))
    table = cfg.get("parameters") or {}
    if not isinstance(table, dict) or not table:
        raise ParameterError(
            "[parameters]: name at least one parameter, e.g. [parameters.clearance_B] start, lower, upper"
        )
    params = []
    for name, spec in _flatten(table).items():
        missing = [k for k in ("start", "lower", "upper") if k not in spec]
        if missing or set(spec) - {"start", "lower", "upper"}:
            raise ParameterError(
                f"[parameters.{name}] needs exactly start, lower and upper (SI); missing {missing}, "
                f"unknown {sorted(set(spec) - {'start', 'lower', 'upper'})}"
            )
        params.append(FitParameter(name, *(_float(f"{name}.{k}", spec[k]) for k in ("start", "lower", "upper"))))
    data = _numbers(cfg.get("data", {}), "data", ("signal", "noise"))
    section = _numbers(cfg.get("fit", {}), "fit", tuple(f.name for f in dataclasses.fields(LMSettings)) + FIT_KEYS)
    extras = {k: section.pop(k) for k in FIT_KEYS if k in section}
    valid = tuple(f.name for f in dataclasses.fields(SteadyOptions) if f.name != "solve") + STEADY_SOLVE_KEYS
    steady = _numbers(cfg.get("steady", {}), "steady", valid)
    try:
        options = FIT_STEADY.replace(**steady)
    except TypeError as err:
        raise ParameterError(f"[steady]: {err}") from None
    return {
        "mechanism": mech,
        "parameters": params,
        "signal": data.get("signal"),
        "noise": None if data.get("noise") is None else _float("data.noise", data["noise"]),
        "settings": LMSettings(**section),
        "options": options,
        **extras,
    }


def _float(name, value) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ParameterError(f"{name} = {value!r} must be a number")
    return float(value)


def _flatten(table: dict, prefix: str = "") -> dict:
    """``[parameters.contact.restitution]`` reads as a nested table: its dotted name back."""
    out = {}
    for key, value in table.items():
        name = f"{prefix}{key}"
        if not isinstance(value, dict):
            raise ParameterError(f"[parameters] {name} = {value!r}: give a table with start, lower and upper")
        if {"start", "lower", "upper"} & set(value):
            out[name] = value
        else:
            out.update(_flatten(value, f"{name}."))
    return out


def write_history(path: Path, result) -> None:
    """``fit.csv``: the start, then one row per iteration (module docstring)."""
    names = [p.name for p in result.parameters]
    cols = [f"{n}_{u}" if u != "1" else n for n, u in zip(names, result.units)]
    head = ["iteration", "misfit", "trial_misfit", "accepted", "damping", "step", "cpu_s", "regime"]
    with open(path, "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(head + ["period_revolutions"] + cols)
        s = result.start
        writer.writerow([0, s.misfit, s.misfit, True, "", "", "", s.regime, s.period_revolutions] + [*s.x])
        for row in result.history:
            writer.writerow([row.get(k, "") for k in head + ["period_revolutions"]] + [row[n] for n in names])


def plot_fit(result, path: Path) -> None:
    """``fit.png``: measured, start and fitted trace against the crank angle, and the residuals."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    order = np.argsort(result.angle_deg, kind="stable")
    a = result.angle_deg[order]
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(8, 6), sharex=True, height_ratios=(3, 1))
    top.plot(a, result.measured[order], ".", ms=3, color="0.35", label="measured")
    top.plot(a, result.start.model[order], "--", lw=1, color="tab:orange", label="start")
    top.plot(a, result.final.model[order], "-", lw=1.2, color="tab:blue", label="fitted")
    top.set_ylabel(result.signal)
    top.legend(loc="best", fontsize=8)
    top.set_title(f"{result.final.source} ({result.final.regime}); misfit {result.final.misfit:.4g}", fontsize=9)
    bottom.plot(a, (result.final.model - result.measured)[order], ".", ms=2, color="tab:blue")
    bottom.axhline(0.0, color="0.5", lw=0.8)
    bottom.set_ylabel("fitted - measured")
    bottom.set_xlabel("crank angle, deg")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def resume_parameters(params: list, checkpoint: Path, resume: bool) -> tuple[list, dict | None]:
    """The parameters to start from: ``params``, or with ``resume`` their values at the last
    accepted iterate in ``checkpoint`` (bounds kept), and what was resumed (None: a fresh fit).

    Raises:
        ParameterError: a checkpoint present without ``resume`` (the folder holds a fit), or with
            ``resume`` one that is unreadable or names other parameters."""
    if not resume:
        if checkpoint.exists():
            raise ParameterError(
                f"{checkpoint.parent} already holds a fit (checkpoint.json): pass --resume or another --out"
            )
        return params, None
    if not checkpoint.exists():
        return params, None
    try:
        saved = json.loads(checkpoint.read_text())
        design = saved["design"]
    except (json.JSONDecodeError, KeyError) as err:
        raise ParameterError(f"{checkpoint}: not a fit checkpoint ({err}); remove it to start afresh") from None
    if set(design) != {p.name for p in params}:
        raise ParameterError(f"{checkpoint} fits {sorted(design)}, the config {sorted(p.name for p in params)}")
    moved = [dataclasses.replace(p, start=float(min(max(design[p.name], p.lower), p.upper))) for p in params]
    return moved, {"iteration": saved["iteration"], "misfit": saved["misfit"], "design": design}


def run(args) -> int:
    """Run ``jaxcrank fit`` (module docstring)."""
    from . import fit as fit_module
    from .trace import read_trace

    try:
        cfg = tomllib.loads(Path(args.config).read_text())
    except tomllib.TOMLDecodeError as err:
        raise ParameterError(f"{args.config}: malformed TOML: {err}") from None
    try:
        spec = build(cfg, Path(args.config).parent)
    except ParameterError as err:
        raise ParameterError(f"{args.config}: {err}") from None
    trace = read_trace(args.data, spec["signal"])
    out = Path(args.out)
    checkpoint = out / "checkpoint.json"
    params, resumed = resume_parameters(spec["parameters"], checkpoint, args.resume)
    out.mkdir(parents=True, exist_ok=True)

    def save(row):
        if row["accepted"]:
            text = json.dumps({**row, "config": cfg, "trace": str(args.data)}, indent=2)
            atomic_write(checkpoint, lambda f: f.write(text.encode()))

    result = fit_module.fit(
        spec["mechanism"],
        params,
        trace,
        noise=spec["noise"],
        options=spec["options"],
        settings=spec["settings"],
        window_revolutions=spec.get("window_revolutions"),
        max_relative_halfwidth=spec.get("max_relative_halfwidth", 0.5),
        progress=not args.quiet,
        on_iteration=save,
    )
    summary = {"trace": str(args.data), **result.summary(), "config": cfg, "resumed_from": resumed}
    (out / "fit.json").write_text(json.dumps(summary, indent=2))
    write_history(out / "fit.csv", result)
    plot_fit(result, out / "fit.png")
    lines = []
    for p, v, ok in zip(result.parameters, result.fitted, result.intervals.identifiable):
        lo, hi = summary["parameters"][p.name]["ci95"]
        band = f"[{lo:.6g}, {hi:.6g}]" if lo is not None else "(no interval)"
        lines.append(f"  {p.name} = {v:.6g} {band}{'' if ok else ' NOT IDENTIFIABLE'}")
    print(
        f"wrote {out}/ (fit.json, fit.csv, fit.png): {result.final.regime}, misfit "
        f"{result.start.misfit:.6g} -> {result.final.misfit:.6g} ({result.stop_reason})"
    )
    print("\n".join(lines))
    return 0
