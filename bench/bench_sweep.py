"""Benchmark: sweep throughput (designs per second) against a plain Python loop.

    python bench/bench_sweep.py [--designs 16] [--batch-sizes 1,2,4,8,16] [--devices 1,2]
                                [--revolutions 4] [--loop-designs N] [--out bench/results/sweep.json]

The workload is a Monte Carlo of the paper design (clearances at B and C within
+-0.05 mm, uniform), each part simulated as ``jaxcrank sweep`` does
(:class:`jaxcrank.sweep.Settings`: ``--revolutions`` crank revolutions, by default
the paper run of 0.4 s, tsit5 at rtol = atol = 1e-6, 0.1 deg output samples).
Measured in one run, on this machine's CPU:

- ``loop``: a Python loop over the designs, each one call of the same jitted
  single-design function (:func:`jaxcrank.sweep.simulate_design`), the baseline;
- ``batch``: :func:`jaxcrank.sweep.run` with ``chunk`` = each batch size on one
  device (one ``vmap`` per chunk);
- ``devices``: the largest batch size on 1, 2, ... host devices (each count in a
  fresh process with ``--xla_force_host_platform_device_count``; the sweep shards
  every chunk over all devices).

Each entry has the compile time (first chunk, minus a chunk's run time), the wall
time of all designs after compilation and designs per second. Writes one JSON
file; nothing is asserted. Runs on whatever JAX's default backend is: on a GPU
machine, e.g. ``--designs 2048 --batch-sizes 2048 --devices 1 --loop-designs 1``
(a batch needs thousands of designs there, and a single solve is ~20x slower than
on a CPU, so the loop baseline gets one design).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path


def _setup():
    import jax

    jax.config.update("jax_enable_x64", True)
    import jaxcrank as jc
    from jaxcrank import sweep

    return jax, jc, sweep


def _designs(n):
    _, _, sweep = _setup()
    tol = {"clearance_B": sweep.Tolerance(5e-4, 5e-5), "clearance_C": sweep.Tolerance(5e-4, 5e-5)}
    return sweep.monte_carlo(tol, n, seed=0)


def _settings(revolutions):
    _, _, sweep = _setup()
    # metrics after the first revolution (or the first quarter of a shorter run)
    return sweep.Settings(revolutions=revolutions, metrics_from_revolution=min(1.0, revolutions / 4))


def _timed(fn):
    tic = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - tic


def loop(n, revolutions):
    jax, jc, sweep = _setup()
    names, xs = _designs(n)
    settings = _settings(revolutions)
    base = jc.paper()
    one = jax.jit(lambda x: sweep.simulate_design(base, names, x, settings))
    _, first = _timed(lambda: jax.block_until_ready(one(xs[0])))
    _, wall = _timed(lambda: [jax.block_until_ready(one(x)) for x in xs])
    per = wall / n
    return {"mode": "loop", "batch": 1, "devices": 1, "designs": n, "compile_s": max(first - per, 0.0),
            "wall_s": wall, "designs_per_s": n / wall}


def batched(n, batch, revolutions):
    jax, jc, sweep = _setup()
    names, xs = _designs(n)
    settings = _settings(revolutions)
    base = jc.paper()
    chunk = max(batch, jax.device_count())
    # first chunk: compilation + one chunk; then every design with the compiled code
    table, first = _timed(lambda: sweep.run(base, names, xs[:chunk], settings, chunk=chunk, progress=False))
    table, wall = _timed(lambda: sweep.run(base, names, xs, settings, chunk=chunk, progress=False))
    per_chunk = wall * chunk / n
    return {"mode": "batch", "batch": chunk, "devices": jax.device_count(), "designs": n,
            "compile_s": max(first - per_chunk, 0.0), "wall_s": wall, "designs_per_s": n / wall,
            "failed": int(sum(s != "ok" for s in table["status"]))}


def _child(args):
    """Run one measurement in a fresh process (device count is fixed at JAX start-up)."""
    cmd = [sys.executable, __file__, "--child", args["mode"], "--designs", str(args["designs"]),
           "--batch-sizes", str(args["batch"]), "--revolutions", str(args["revolutions"])]
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
    p.add_argument("--revolutions", type=float, default=4.0, help="crank revolutions per design (default 4)")
    p.add_argument("--loop-designs", type=int, help="designs in the Python-loop baseline (default: --designs)")
    p.add_argument("--out", type=Path, default=Path("bench/results/sweep.json"))
    p.add_argument("--child", choices=["loop", "batch"], help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.child:
        res = loop(a.designs, a.revolutions) if a.child == "loop" else batched(a.designs, int(a.batch_sizes),
                                                                                 a.revolutions)
        print(json.dumps(res))
        return 0

    batches = [int(b) for b in a.batch_sizes.split(",")]
    devices = [int(d) for d in a.devices.split(",")]
    common = {"designs": a.designs, "revolutions": a.revolutions}
    runs = [_child({"mode": "loop", "batch": 1, "devices": 1, **common,
                    "designs": a.loop_designs or a.designs})]
    print(f"loop: {runs[-1]['designs_per_s']:.3f} designs/s", flush=True)
    for b in batches:
        runs.append(_child({"mode": "batch", "batch": b, "devices": 1, **common}))
        print(f"batch {b}, 1 device: {runs[-1]['designs_per_s']:.3f} designs/s", flush=True)
    for d in devices:
        if d == 1:
            continue
        runs.append(_child({"mode": "batch", "batch": max(batches), "devices": d, **common}))
        print(f"batch {max(batches)}, {d} devices: {runs[-1]['designs_per_s']:.3f} designs/s", flush=True)
    base = runs[0]["designs_per_s"]
    for r in runs:
        r["speedup_vs_loop"] = r["designs_per_s"] / base
    import jax

    report = {"machine": {"platform": platform.platform(), "cpu_count": os.cpu_count(),
                          "python": platform.python_version(), "jax": jax.__version__,
                          "device": f"{jax.default_backend()}: {jax.devices()[0].device_kind}"},
              "workload": "Monte Carlo of the paper design, clearances B and C 0.5 +- 0.05 mm (uniform); "
                          f"{a.revolutions:g} revolutions at 600 rpm, tsit5, rtol = atol = 1e-6",
              "target_designs_per_s": 5.0, "runs": runs,
              "best": max(runs, key=lambda r: r["designs_per_s"])}
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps(report, indent=2))
    print(f"wrote {a.out}; best {report['best']['designs_per_s']:.3f} designs/s "
          f"(batch {report['best']['batch']}, {report['best']['devices']} devices)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
