"""``jaxcrank life [--mechanism NAME | --config FILE | --design RESULT_JSON] [--set KEY=VALUE ...]
--cycles N --out DIR``: the life of a mechanism whose joints wear ([`jaxcrank.analysis.life.life`][]):
``life.csv``, ``profiles.csv``, ``summary.json``, ``worn.toml`` and figures, checkpointed after every step."""

from __future__ import annotations

import argparse
import csv
import json
import math
import time
from pathlib import Path

from ..physics.params import ParameterError
from . import config

#: angles of profiles.csv, per surface
PROFILE_ANGLES = 360


def add_arguments(p):
    """Add ``life``'s options to its parser ``p``."""
    p.description = (
        'Wear the mechanism\'s worn joints (law = "worn", or those named by --wear) over --cycles crank '
        "revolutions by cycle averaging: the steady state at the current profiles, the wear per cycle from "
        "Archard's law, a step of many cycles with error control, repeat. Writes life.csv (one row per step), "
        "profiles.csv (the worn profiles), summary.json (the life to --limit of --metric), worn.toml (the worn "
        "mechanism, for --config of the other commands) and figures/ into --out; a killed run carries on with --resume."
    )
    config.add_mechanism_arguments(p, "wear")
    p.add_argument("--cycles", type=float, required=True, help="crank revolutions to run (e.g. 1e7)")
    p.add_argument("--out", type=Path, default=Path("runs/life"), help="run directory (default: runs/life)")
    p.add_argument(
        "--wear",
        metavar="JOINTS",
        help="make these dry clearance joints wear, comma-separated (e.g. B,C), with the default Archard law "
        "(jaxcrank.physics.wear.Archard; change it with --set joints.<j>.wear.hole_coefficient=...)",
    )
    p.add_argument("--metric", help="the metric whose limit ends the life (a column of life.csv)")
    p.add_argument("--limit", type=float, help="the metric's limit (in the metric's unit)")
    p.add_argument("--rtol", type=float, default=0.01, help="step error relative to the deepest wear (0.01)")
    p.add_argument(
        "--average-revolutions", type=int, default=10, help="not periodic: revolutions the wear is averaged over (10)"
    )
    p.add_argument("--samples-per-revolution", type=int, default=720, help="samples per revolution of an orbit (720)")
    p.add_argument("--resume", action="store_true", help="carry on a killed run from its checkpoint in --out")
    p.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    p.add_argument("--quiet", action="store_true", help="no progress on standard error")
    return p


def _with_wear(mech, joints: str | None):
    from ..numerics.wear_run import with_wear

    return with_wear(mech, [s.strip() for s in (joints or "").split(",") if s.strip()], where="--wear")


def _write_csv(path: Path, rows: list[dict]) -> None:
    keys: list[str] = []
    for r in rows:
        keys += [k for k in r if k not in keys]
    with path.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)


def profile_rows(cycles, profiles) -> list[dict]:
    """profiles.csv's rows: per point, joint and surface, the depth (m) at every degree of
    the surface's own frame."""
    import jax.numpy as jnp
    import numpy as np

    from ..physics.wear import profile_on_grid

    deg = np.arange(PROFILE_ANGLES) * 360.0 / PROFILE_ANGLES
    angles = jnp.asarray(np.radians(deg))
    out = []
    for n, prof in zip(cycles, profiles):
        for j, pair in prof.items():
            for surface, coeffs in zip(("hole", "pin"), pair):
                depth = np.asarray(profile_on_grid(jnp.asarray(coeffs), angles))
                out += [
                    {"cycles": float(n), "joint": j, "surface": surface, "angle_deg": float(a), "depth_m": float(d)}
                    for a, d in zip(deg, depth)
                ]
    return out


def _plain_profiles(profiles) -> dict:
    """A point's profiles, ``joint -> [hole, pin]``, as lists of numbers (m)."""
    return {j: [[float(x) for x in h], [float(x) for x in p]] for j, (h, p) in profiles.items()}


def _checkpoint(out: Path, run, rows, section_state=None) -> None:
    """Write the run so far (its profiles already plain lists) to ``out/checkpoint.json``, atomically."""
    data = {
        "section_state": None if section_state is None else [float(v) for v in section_state],
        "cycles": [float(c) for c in run.cycles],
        "profiles": run.profiles,
        "schedule": [float(s) for s in run.schedule],
        "rejected": int(run.rejected),
        "rows": rows,
    }
    tmp = out / "checkpoint.json.tmp"
    tmp.write_text(json.dumps(data))
    tmp.replace(out / "checkpoint.json")


def life_columns(mech) -> list[str]:
    """The numeric columns of a life run's ``life.csv`` ([`jaxcrank.analysis.life.Life.row`][]): each worn
    joint's wear, then the steady state's metrics, units in the names."""
    from ..numerics import tracking
    from ..numerics import wear_run as nw
    from ..physics import signals

    rate = "hole_wear_m3_per_cycle"
    per_joint = ("hole_max_depth_m", "pin_max_depth_m", "hole_volume_m3", "pin_volume_m3", "clearance_m", rate)
    wear = [f"{j}_{c}" for j in nw.worn_joints(mech) for c in (*per_joint, f"{rate}_ci95_low", f"{rate}_ci95_high")]
    metrics = list(signals.metric_definitions(mech)) + [tracking.whole_run_name(n) for n in signals.force_metrics(mech)]
    return ["cycles", *wear, *metrics]


def run(args) -> int:
    """Run ``jaxcrank life`` from parsed arguments; returns the exit status."""
    import jax.numpy as jnp

    from ..analysis import life as lf
    from ..numerics import wear_run as nw

    # --wear first, so that --set can reach the new worn joints' wear law
    base = argparse.Namespace(**{**vars(args), "overrides": [], "rpm": None})
    mech = _with_wear(config.mechanism_from_arguments(base), args.wear)
    overrides = list(args.overrides)
    if args.rpm is not None:
        overrides.append(f"driver.speed={2.0 * math.pi * args.rpm / 60.0!r}")
    mech = config.apply_overrides(mech, overrides)
    if not nw.worn_joints(mech):
        raise ParameterError(
            "the mechanism has no worn joint: name clearance joints with --wear (e.g. --wear B,C), give them "
            'law = "worn" in a --config file, or use --mechanism paper-wear'
        )
    if (args.metric is None) != (args.limit is None):
        raise ParameterError("--metric and --limit go together")
    if args.metric is not None and args.metric not in life_columns(mech):  # before hours of life, not after
        raise ParameterError(f"--metric {args.metric!r} is not a column of life.csv: {', '.join(life_columns(mech))}")
    if not (args.cycles > 0 and math.isfinite(args.cycles)):
        raise ParameterError(f"--cycles = {args.cycles!r} must be a positive number")
    out: Path = args.out
    config.check_resume(out, args.resume)
    out.mkdir(parents=True, exist_ok=True)
    config.save(mech, out / "config.toml")
    options = lf.LifeOptions(
        rtol=args.rtol,
        average_revolutions=args.average_revolutions,
        steady=lf.LIFE_OPTIONS.steady.replace(samples_per_revolution=args.samples_per_revolution),
    )
    say = (lambda text: None) if args.quiet else (lambda text: print(f"life: {text}", flush=True))
    start = time.perf_counter()
    done_rows: list[dict] = []
    resume = None
    ck = out / "checkpoint.json"
    if args.resume and ck.exists():
        data = json.loads(ck.read_text())
        last = {j: (jnp.asarray(h), jnp.asarray(p)) for j, (h, p) in data["profiles"][-1].items()}
        here = nw.with_profiles(mech, last)
        say(f"resuming at {data['cycles'][-1]:.4g} cycles ({len(data['cycles'])} points done)")
        warm = None if data.get("section_state") is None else jnp.asarray(data["section_state"])
        point = lf.wear_per_cycle(here, options, warm_start=warm)  # from the last orbit's section state
        resume = lf.Life(mech, [data["cycles"][-1]], [last], [point], [], list(data["schedule"][-1:]), 0, options)
        done_rows = data["rows"][:-1]
        prior = (
            [float(c) for c in data["cycles"][:-1]],
            data["profiles"][:-1],
            data["schedule"],
            data["rejected"],
        )
    else:
        prior = ([], [], [], 0)

    fresh: list[dict] = []  # this process's rows: each point's row is made once

    def on_point(r):
        fresh.extend(r.row(i) for i in range(len(fresh), len(r.cycles)))
        rows = done_rows + fresh
        cycles = prior[0] + list(r.cycles)
        profiles = prior[1] + [_plain_profiles(pr) for pr in r.profiles]
        schedule = prior[2] + list(r.schedule[1:] if resume is not None else r.schedule)
        full = lf.Life(mech, cycles, profiles, [], [], schedule, prior[3] + r.rejected, options)
        _checkpoint(out, full, rows, r.points[-1].steady.section_state)
        row = rows[-1]
        depths = ", ".join(f"{j} hole {1e6 * row[f'{j}_hole_max_depth_m']:.3g} um" for j in nw.worn_joints(mech))
        say(f"{row['cycles']:.4g} cycles: {row['regime']}, deepest wear {depths}")

    run_ = lf.life(mech, args.cycles, options, on_point=on_point, resume=resume)
    first = run_.points[0]
    data = json.loads(ck.read_text())
    rows, cycles = data["rows"], data["cycles"]
    profiles = [{j: (jnp.asarray(h), jnp.asarray(p)) for j, (h, p) in pr.items()} for pr in data["profiles"]]
    _write_csv(out / "life.csv", rows)
    _write_csv(out / "profiles.csv", profile_rows(cycles, profiles))
    config.save(nw.with_profiles(mech, profiles[-1]), out / "worn.toml")  # the mechanism as the run left it
    summary = {
        "mechanism": getattr(mech, "name", type(mech).__name__),
        "cycles": args.cycles,
        "points": len(cycles),
        "rejected_steps": data["rejected"],
        "regimes": sorted({r["regime"] for r in rows}),
        "worn_joints": {j: _wear_parameters(mech.joints[j]) for j in nw.worn_joints(mech)},
        "final": {k: v for k, v in rows[-1].items()},
        "wall_s": round(time.perf_counter() - start, 1),
    }
    if args.metric is not None:
        if args.metric not in rows[0]:
            raise ParameterError(f"--metric {args.metric!r} is not a column of life.csv: {', '.join(rows[0])}")
        values = [r[args.metric] for r in rows]
        life_cycles = float(lf.cycles_to_limit(cycles, values, args.limit))
        summary["life"] = {
            "metric": args.metric,
            "limit": args.limit,
            "cycles_to_limit": life_cycles if math.isfinite(life_cycles) else None,
            "reached": math.isfinite(life_cycles),
        }
        say(
            f"life to {args.metric} = {args.limit:g}: "
            + (f"{life_cycles:.4g} cycles" if math.isfinite(life_cycles) else f"not reached in {args.cycles:g} cycles")
        )
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    if not args.no_figures:
        from . import plots_life

        plots_life.write_figures(out, mech, rows, cycles, profiles, first if resume is None else None)
    say(f"wrote {out}")
    return 0


def _wear_parameters(law) -> dict:
    w = law.wear
    return {
        "hole_coefficient": float(w.hole_coefficient),
        "pin_coefficient": float(w.pin_coefficient),
        "hole_hardness_Pa": float(w.hole_hardness),
        "pin_hardness_Pa": float(w.pin_hardness),
        "length_m": float(w.length),
        "modes": int(law.modes),
        "clearance_m": float(law.clearance),
    }
