"""Benchmark: the ensemble kernel against the XLA sweep on the paper Monte Carlo.

    python bench/bench_ensemble.py [--device cpu] [--designs 96] [--workers 2] [--threads 2]
    python bench/bench_ensemble.py --device gpu [--batch-sizes 1024,4096,16384] [--xla-batches 512,2048]

The workload is ``bench/bench_sweep.py``'s: a Monte Carlo of the paper design
(clearances at B and C 0.5 +- 0.05 mm, uniform), each design the paper run (4
revolutions, 0.4 s, tsit5 at rtol = atol = 1e-6, metrics after the first revolution),
the same designs for both engines, in one run on one machine.

- ``--device cpu``: the XLA engine as the CPU sweep runs it fastest (each design
  solved alone, ``--workers`` processes; after compilation: from the moment every
  worker has finished one design) and the kernel on ``--threads`` threads (compile time:
  code generation and the C compiler, with an empty kernel cache). Writes
  ``cpu_speedup_vs_xla`` (kernel over XLA designs/s after compilation) and the
  two-sample Kolmogorov-Smirnov test of every metric's distribution over the designs
  (the engines' single runs differ by impact chaos; their distributions must agree:
  p > 0.01).
- ``--device gpu``: the kernel compiled as CUDA (one design per GPU thread) at each
  batch size, end to end (host to host, compilation excluded and reported), and the
  XLA engine with one ``vmap`` batch at each of ``--xla-batches`` (0 skips it); writes
  ``gpu_designs_per_s`` (the best batch size) and the fraction of fp64 peak from an
  operation count of the generated code, and a plot of designs/s against batch size for
  both engines (``ensemble_gpu.png`` beside the JSON). Its entries are merged into the
  output file, so the CPU numbers stay.

Writes one JSON file (default ``bench/results/ensemble.json``); nothing is asserted.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import tempfile
import time
from pathlib import Path

from _common import machine  # bench/ is on sys.path; imports JAX lazily

RESULTS = Path(__file__).resolve().parent / "results"
WORKLOAD = (
    "Monte Carlo of the paper design, clearances B and C 0.5 +- 0.05 mm (uniform); "
    "{rev:g} revolutions at 600 rpm, tsit5, rtol = atol = 1e-6, metrics after revolution {start:g}"
)


def _setup(revolutions, n, seed=0):
    import jax

    jax.config.update("jax_enable_x64", True)
    import jaxcrank as jc
    from jaxcrank import sampling, sweep

    tol = {"clearance_B": sampling.Tolerance(5e-4, 5e-5), "clearance_C": sampling.Tolerance(5e-4, 5e-5)}
    names, xs = sampling.monte_carlo(tol, n, seed=seed)
    settings = sweep.Settings(revolutions=revolutions, metrics_from_revolution=min(1.0, revolutions / 4))
    return jc.paper(), names, xs, settings


def _entry(engine, device, batch, parallel, n, wall, compile_s, end_to_end=None, failed=0, **extra):
    return {
        "engine": engine,
        "device": device,
        "batch": batch,
        "parallel": parallel,
        "designs": n,
        "compile_s": compile_s,
        "wall_s": wall,
        "designs_per_s": n / wall,
        "end_to_end_s": end_to_end,
        "failed": failed,
        **extra,
    }


def xla_cpu(base, names, xs, settings, workers):
    """XLA in ``workers`` processes, each design alone; metrics per design for the KS test."""
    import numpy as np

    from jaxcrank import sweep

    stamps, results = [], {}

    def record(idx, result):
        stamps.append(time.perf_counter())
        results[idx[0]] = result

    chunks = [([i], xs[i : i + 1]) for i in range(len(xs))]
    start = time.perf_counter()
    sweep.run_in_workers(base, names, settings, chunks, workers, record)
    n = len(xs)
    warm = stamps[workers - 1]
    wall = (stamps[-1] - warm) * n / (n - workers)
    metrics = np.stack([results[i][0][0] for i in range(n)])
    status = np.array([int(results[i][1][0]) for i in range(n)])
    entry = _entry(
        "xla", "cpu", 1, f"{workers} processes", n, wall, stamps[workers - 1] - start, stamps[-1] - start,
        failed=int(np.sum(status != 0)),
        note="wall_s: from the moment every worker had finished one design (compiled) to the last, scaled to all",
    )  # fmt: skip
    return entry, metrics, status


def kernel_cpu(base, names, xs, settings, threads):
    """The kernel on ``threads`` threads; compile time with an empty kernel cache."""
    import numpy as np

    from jaxcrank.numerics.kernel import engine

    saved = os.environ.get("JAXCRANK_KERNEL_CACHE")
    with tempfile.TemporaryDirectory() as cache:
        os.environ["JAXCRANK_KERNEL_CACHE"] = cache
        engine.library.cache_clear()
        start = time.perf_counter()
        engine.solve(base, names, xs[:1], settings, threads=1)  # generate + compile + one design
        first = time.perf_counter() - start
        start = time.perf_counter()
        engine.solve(base, names, xs[:1], settings, threads=1)
        compile_s = first - (time.perf_counter() - start)
        start = time.perf_counter()
        out = engine.solve(base, names, xs, settings, threads=threads)
        wall = time.perf_counter() - start
    if saved is None:
        os.environ.pop("JAXCRANK_KERNEL_CACHE")
    else:
        os.environ["JAXCRANK_KERNEL_CACHE"] = saved
    steps = int(np.sum(out.steps + out.rejected))
    entry = _entry(
        "kernel", "cpu", len(xs), f"{threads} threads", len(xs), wall, compile_s, wall + compile_s,
        failed=int(np.sum(out.status != 0)), steps_per_design=steps / len(xs),
        us_per_step_per_thread=wall * threads / steps * 1e6,
    )  # fmt: skip
    return entry, out.metrics, out.status


def ks_tests(base, a, b, sa, sb):
    """Two-sample KS statistic and p-value of every metric of ``base`` (the sweep's columns)
    over the ok designs of each engine."""
    from scipy import stats

    from jaxcrank.runs.sweep import metric_names

    out = {}
    for j, key in enumerate(metric_names(base)):
        x, y = a[sa == 0, j], b[sb == 0, j]
        res = stats.ks_2samp(x, y)
        out[key] = {"statistic": float(res.statistic), "p_value": float(res.pvalue)}
    return out


def _operations(source_text: str, name: str) -> int:
    """Scalar operations of a generated function: its statements (one operation each),
    libm calls counted as 20 (a common cost of a double-precision sin, pow or atan2)."""
    body = source_text[source_text.index(f"KFN void KNAME({name})(") :]
    body = body[: body.index("\n}\n")]
    statements = len(re.findall(r"^\s*const (KD|KB|KL) v", body, re.M))
    calls = len(re.findall(r"\bKF[12]\((sin|cos|pow|atan2|exp|sqrt),", body)) + 2 * body.count("KSINCOS(")
    return statements + 19 * calls


def gpu(base, names, xs_all, settings, batch_sizes, xla_batches, peak_tflops):
    import numpy as np

    from jaxcrank import sweep
    from jaxcrank.numerics.kernel import gpu as kgpu
    from jaxcrank.numerics.kernel import source

    st = source.structure(base, names)
    text = source.kernel_source(st)
    compile_s = kgpu.compile_seconds(st)
    field, frame, interp = (_operations(text, f) for f in ("jk_field", "jk_frame", "jk_interp"))
    runs = []
    for b in batch_sizes:
        xs = xs_all[:b]
        start = time.perf_counter()
        out = kgpu.solve(base, names, xs, settings)
        wall = time.perf_counter() - start
        steps = np.sum(out.steps + out.rejected)
        samples = settings.n_samples * len(xs)
        ops = steps * (5 * field + frame + 60) + samples * (interp + frame)
        runs.append(
            _entry(
                "kernel",
                "gpu",
                b,
                f"{b} threads",
                b,
                wall,
                compile_s,
                wall + compile_s,
                failed=int(np.sum(out.status != 0)),
                operations=float(ops),
                fp64_fraction_of_peak=float(ops / wall / (peak_tflops * 1e12)),
            )  # fmt: skip
        )
    for xla_batch in [b for b in xla_batches if b > 0]:
        xs = xs_all[:xla_batch]
        run = lambda xs=xs, b=xla_batch: sweep.run(base, names, xs, settings, chunk=b, progress=False, engine="xla")  # noqa: E731
        start = time.perf_counter()
        run()
        first = time.perf_counter() - start
        start = time.perf_counter()
        table = run()
        wall = time.perf_counter() - start
        failed = int(sum(s != "ok" for s in table["status"]))
        runs.append(_entry("xla", "gpu", xla_batch, "vmap", xla_batch, wall, first - wall, first, failed=failed))
    return runs


def plot_gpu(runs, path):
    """Designs/s against batch size, one line per engine (log-log), saved to ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    for name in ("kernel", "xla"):
        pts = sorted((r["batch"], r["designs_per_s"]) for r in runs if r["engine"] == name)
        if pts:
            ax.loglog(*zip(*pts), "o-", label=f"{name} (after compilation)")
    ax.set_xlabel("batch size, designs")
    ax.set_ylabel("paper runs per second, 1/s")
    ax.set_title("ensemble throughput on the GPU")
    ax.grid(True, which="both", lw=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--device", choices=("cpu", "gpu"), default="cpu")
    p.add_argument("--designs", type=int, default=96, help="designs per engine on the CPU (default 96)")
    p.add_argument("--workers", type=int, default=2, help="XLA worker processes on the CPU (default 2)")
    p.add_argument("--threads", type=int, default=None, help="kernel threads (default: usable CPUs)")
    p.add_argument("--revolutions", type=float, default=4.0)
    p.add_argument("--batch-sizes", default="1024,4096,16384", help="GPU kernel batch sizes")
    p.add_argument("--xla-batches", default="512,2048", help="GPU XLA vmap batch sizes (0: skip)")
    p.add_argument("--peak-tflops", type=float, default=33.5, help="the GPU's fp64 peak, TFLOP/s (H100 SXM: 33.5)")
    p.add_argument("--out", type=Path, default=RESULTS / "ensemble.json")
    args = p.parse_args(argv)

    if args.device == "cpu":
        from jaxcrank.numerics.kernel import engine

        threads = args.threads or engine.default_threads()
        load_before = os.getloadavg()[0]
        base, names, xs, settings = _setup(args.revolutions, args.designs)
        k_entry, k_metrics, k_status = kernel_cpu(base, names, xs, settings, threads)
        print(json.dumps(k_entry), flush=True)
        x_entry, x_metrics, x_status = xla_cpu(base, names, xs, settings, args.workers)
        print(json.dumps(x_entry), flush=True)
        ks = ks_tests(base, k_metrics, x_metrics, k_status, x_status)
        result = {
            "machine": machine(),
            "workload": WORKLOAD.format(rev=args.revolutions, start=settings.metrics_from_revolution),
            "device": "cpu",
            "runs": [k_entry, x_entry],
            "cpu_speedup_vs_xla": k_entry["designs_per_s"] / x_entry["designs_per_s"],
            "ks_two_sample": ks,
            "ks_min_p_value": min(v["p_value"] for v in ks.values()),
            "load_average_1min": {"before": load_before, "after": os.getloadavg()[0]},
        }
        old = json.loads(args.out.read_text()) if args.out.exists() else {}
        for key in ("gpu_runs", "gpu_designs_per_s", "gpu_machine", "gpu_best_batch", "gpu_fp64_fraction_of_peak"):
            if key in old:
                result[key] = old[key]
    else:
        sizes = [int(s) for s in args.batch_sizes.split(",")]
        xla_sizes = [int(s) for s in args.xla_batches.split(",")]
        base, names, xs, settings = _setup(args.revolutions, max(sizes + xla_sizes))
        runs = gpu(base, names, xs, settings, sizes, xla_sizes, args.peak_tflops)
        plot_gpu(runs, args.out.with_name(args.out.stem + "_gpu.png"))
        kernel_runs = [r for r in runs if r["engine"] == "kernel"]
        best = max(kernel_runs, key=lambda r: r["designs_per_s"])
        result = json.loads(args.out.read_text()) if args.out.exists() else {}
        result.update(
            {
                "gpu_machine": machine(),
                "gpu_runs": runs,
                "gpu_designs_per_s": best["designs_per_s"],
                "gpu_best_batch": best["batch"],
                "gpu_fp64_fraction_of_peak": best["fp64_fraction_of_peak"],
            }
        )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps({k: v for k, v in result.items() if not isinstance(v, (dict, list))}, indent=2))


if __name__ == "__main__":
    main()
