"""Benchmark: sweep throughput (designs per second) against a plain Python loop.

    python bench/bench_sweep.py [--designs 16] [--batch-sizes 1,2,4,8,16] [--devices 1,2]
                                [--workers 2] [--revolutions 4] [--loop-designs N]
                                [--out bench/results/sweep.json]

The workload is a Monte Carlo of the paper design (clearances at B and C within
+-0.05 mm, uniform), each part simulated as ``jaxcrank sweep`` does
(:class:`jaxcrank.runs.sweep.Settings`: ``--revolutions`` crank revolutions, by default
the paper run of 0.4 s, tsit5 at rtol = atol = 1e-6, 0.1 deg output samples).
Measured in one run, on this machine's CPU:

- ``loop``: a Python loop over the designs, each one call of the same jitted
  single-design function (:func:`jaxcrank.runs.sweep.simulate_design`), the baseline;
- ``batch``: :func:`jaxcrank.runs.sweep.run` with ``chunk`` = each batch size on one
  device (chunk 1: each design solved alone; larger: one ``vmap`` per chunk);
- ``devices``: the largest batch size on 1, 2, ... host devices (each count in a
  fresh process with ``--xla_force_host_platform_device_count``; the sweep shards
  every chunk over all devices);
- ``workers``: ``sweep.run(..., chunk=1, workers=N)``: N local processes.

Each entry has the wall time of all designs end to end (the first call: start-up
and compilation included) and after compilation (a second call; with workers, whose
processes end with each call, the time after every worker has finished one design),
with designs per second for both. Writes one JSON file; nothing is asserted. Runs on
whatever JAX's default backend is: on a GPU
machine, e.g. ``--designs 2048 --batch-sizes 2048 --devices 1 --loop-designs 1``
(a batch needs thousands of designs there, and a single solve is ~20x slower than
on a CPU, so the loop baseline gets one design).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

from _common import machine, timed  # bench/ is on sys.path; imports JAX lazily


def _setup():
    import jax

    jax.config.update("jax_enable_x64", True)
    import jaxcrank as jc
    from jaxcrank import sweep

    return jax, jc, sweep


def _designs(n):
    _setup()
    from jaxcrank import sampling

    tol = {"clearance_B": sampling.Tolerance(5e-4, 5e-5), "clearance_C": sampling.Tolerance(5e-4, 5e-5)}
    return sampling.monte_carlo(tol, n, seed=0)


def _settings(revolutions):
    _, _, sweep = _setup()
    # metrics after the first revolution (or the first quarter of a shorter run)
    return sweep.Settings(revolutions=revolutions, metrics_from_revolution=min(1.0, revolutions / 4))


def loop(n, revolutions):
    jax, jc, sweep = _setup()
    names, xs = _designs(n)
    settings = _settings(revolutions)
    base = jc.paper()
    one = jax.jit(lambda x: sweep.simulate_design(base, names, x, settings))
    _, first = timed(lambda: [jax.block_until_ready(one(x)) for x in xs])
    _, wall = timed(lambda: [jax.block_until_ready(one(x)) for x in xs])
    return _entry("loop", 1, 1, 1, n, first, wall)


def _entry(mode, batch, devices, workers, n, end_to_end, wall=None, failed=0):
    return {
        "mode": mode,
        "batch": batch,
        "devices": devices,
        "workers": workers,
        "designs": n,
        "end_to_end_s": end_to_end,
        "end_to_end_designs_per_s": n / end_to_end,
        "compile_s": None if wall is None else max(end_to_end - wall, 0.0),
        "wall_s": wall,
        "designs_per_s": None if wall is None else n / wall,
        "failed": failed,
    }


def batched(n, batch, revolutions, workers=1):
    jax, jc, sweep = _setup()
    names, xs = _designs(n)
    settings = _settings(revolutions)
    base = jc.paper()
    chunk = max(batch, jax.device_count())
    if workers > 1:
        return _workers(jc.paper(), names, xs, settings, workers)
    run = lambda: sweep.run(base, names, xs, settings, chunk=chunk, progress=False, engine="xla")  # noqa: E731
    table, first = timed(run)
    wall = timed(run)[1]
    failed = int(sum(s != "ok" for s in table["status"]))
    return _entry("batch", chunk, jax.device_count(), 1, n, first, wall, failed)


def _workers(base, names, xs, settings, workers):
    """``sweep.run(..., chunk=1, workers=N)``'s pool, each design's completion
    timestamped: after compilation = the designs finished after every worker's first
    one, over the time they took (worker start-up and compilation excluded)."""
    _, _, sweep = _setup()
    stamps = []
    chunks = [([i], xs[i : i + 1]) for i in range(len(xs))]
    start = time.perf_counter()
    sweep.run_in_workers(base, names, settings, chunks, workers, lambda idx, result: stamps.append(time.perf_counter()))
    n = len(xs)
    warm = stamps[workers - 1]
    wall = (stamps[-1] - warm) * n / (n - workers)
    entry = _entry("workers", 1, 1, workers, n, stamps[-1] - start, wall)
    entry["note"] = (
        "wall_s: time from the moment every worker had finished one design (compiled) to the "
        "last design, scaled to all designs"
    )
    return entry


def _child(args):
    """Run one measurement in a fresh process (device count is fixed at JAX start-up)."""
    cmd = [
        sys.executable,
        __file__,
        "--child",
        args["mode"],
        "--designs",
        str(args["designs"]),
        "--batch-sizes",
        str(args["batch"]),
        "--revolutions",
        str(args["revolutions"]),
        "--workers",
        str(args.get("workers", 1)),
    ]
    env = dict(os.environ)
    flags = env.get("XLA_FLAGS", "")
    env["XLA_FLAGS"] = f"{flags} --xla_force_host_platform_device_count={args['devices']}".strip()
    out = subprocess.run(cmd, env=env, capture_output=True, text=True)
    if out.returncode:
        raise RuntimeError(f"{' '.join(cmd)} failed:\n{out.stderr[-3000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--designs", type=int, default=16, help="designs per measurement (default 16)")
    p.add_argument("--batch-sizes", default="1,2,4,8,16", help="comma-separated vmap chunk sizes")
    p.add_argument("--devices", default="1,2", help="comma-separated host device counts")
    p.add_argument("--workers", default="2", help="comma-separated local worker-process counts (chunk 1)")
    p.add_argument("--revolutions", type=float, default=4.0, help="crank revolutions per design (default 4)")
    p.add_argument("--loop-designs", type=int, help="designs in the Python-loop baseline (default: --designs)")
    p.add_argument("--out", type=Path, default=Path("bench/results/sweep.json"))
    p.add_argument("--child", choices=["loop", "batch"], help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.child:
        res = (
            loop(a.designs, a.revolutions)
            if a.child == "loop"
            else batched(a.designs, int(a.batch_sizes), a.revolutions, int(a.workers))
        )
        print(json.dumps(res))
        return 0

    batches = [int(b) for b in a.batch_sizes.split(",")]
    devices = [int(d) for d in a.devices.split(",")]
    common = {"designs": a.designs, "revolutions": a.revolutions}

    def show(label, r):
        after = "" if r["designs_per_s"] is None else f"{r['designs_per_s']:.3f} designs/s after compile, "
        print(f"{label}: {after}{r['end_to_end_designs_per_s']:.3f} end to end", flush=True)

    runs = [_child({"mode": "loop", "batch": 1, "devices": 1, **common, "designs": a.loop_designs or a.designs})]
    show("loop", runs[-1])
    for b in batches:
        runs.append(_child({"mode": "batch", "batch": b, "devices": 1, **common}))
        show(f"chunk {b}, 1 device", runs[-1])
    for d in devices:
        if d == 1:
            continue
        runs.append(_child({"mode": "batch", "batch": max(batches), "devices": d, **common}))
        show(f"chunk {max(batches)}, {d} devices", runs[-1])
    for w in [int(w) for w in a.workers.split(",") if w.strip()]:
        runs.append(_child({"mode": "batch", "batch": 1, "devices": 1, "workers": w, **common}))
        show(f"chunk 1, {w} workers", runs[-1])
    base = runs[0]
    for r in runs:
        r["end_to_end_vs_loop"] = r["end_to_end_designs_per_s"] / base["end_to_end_designs_per_s"]
        if r["designs_per_s"] is not None:
            r["after_compile_vs_loop"] = r["designs_per_s"] / base["designs_per_s"]

    report = {
        "machine": machine(),
        "workload": "Monte Carlo of the paper design, clearances B and C 0.5 +- 0.05 mm (uniform); "
        f"{a.revolutions:g} revolutions at 600 rpm, tsit5, rtol = atol = 1e-6",
        "target_designs_per_s": 5.0,
        "runs": runs,
        "best_end_to_end": max(runs, key=lambda r: r["end_to_end_designs_per_s"]),
    }
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps(report, indent=2))
    best = report["best_end_to_end"]
    print(
        f"wrote {a.out}; best end to end {best['end_to_end_designs_per_s']:.3f} designs/s "
        f"(chunk {best['batch']}, {best['devices']} devices, {best['workers']} workers)"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
