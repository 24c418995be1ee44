"""Benchmark: a 1 000 000-movement curvature sweep with ``fitting.sweep``.

Kernel (``fitting._sweep.examples.curvature_row``): one parameter row = the 8 outbound λ0-PMP
center-out movements of the wrist (Figure 3 set-up, 0.4 s, RK4 at dt = 5 ms as in the main job's
curvature map, every step saved; at 10 ms ``simulate``'s error estimate flags about a third of the
movements ``INACCURATE``, and 20 ms is unstable) for one stiffness anisotropy × rest posture,
reduced to ``A_net``, ``A_sum`` per target (``pmpjax.curvature_measures``) and a status: 125 000
rows = 10⁶ movements by default, chunks of 2 000 rows.

Measured, each configuration in a fresh process so that peak memory (``ru_maxrss``) is its own:

- the bare kernel: ``jit(vmap(fn))`` (or its ``shard_map`` over 2 devices) called on the same
  chunks in a plain loop, ``block_until_ready``, compiled beforehand (``lower().compile()``);
- ``fitting.sweep`` with and without the on-disk store, 1 and 2 local devices (2 devices:
  ``XLA_FLAGS=--xla_force_host_platform_device_count=2``), after a warm-up sweep that compiles;
- ``fitting.sweep(client=...)`` on a local Dask cluster of 2 worker processes (1 thread each);
- peak memory of the stored sweep at a tenth of the size and at the full size (flat: only the
  outputs grow);
- ``--stores``: the shard-format measurement behind the module docstring of ``fitting/_sweep.py``
  (NPZ vs Parquet vs Zarr; needs pyarrow and zarr importable, which pmpjax does not install).

Usage: ``python benchmarks/sweep.py [--movements 1000000] [--repeats 1] [--quick] [--stores]``
(``--quick``: 16 000 movements, one chunk); ``--overhead --movements 100000 --repeats 2``: only bare
kernel vs sweep, 1 and 2 devices, interleaved, min of repeats (prints, writes nothing). Writes
``benchmarks/results/sweep.json`` (date, machine, versions including dask and distributed, load
average, parameters, each configuration's figures and the table).

Latest figures (2026-12-06 08:05–08:06 UTC, ``results/sweep.json``; 2-core AMD EPYC (Zen 4) KVM, no
GPU, JAX 0.10.2, float64), run at a smaller size than the default 10⁶ movements:
``--movements 160000`` (10 chunks, 102 s). The machine was shared with other developers' test runs
(load average 6.7 at the start, 7.8 at the end, on 2 cores), so the times are upper bounds, and
each configuration ran once, so the ratios carry that load's noise (ratios below 1 are noise)::

    | 160000 movements (20000 rows, chunks of 2000 rows) | wall [s] | movements/s | vs bare kernel |
    |---|---:|---:|---:|
    | bare kernel, 1 device | 8.8 | 18,098 | 1.000 |
    | sweep, 1 device, in memory | 6.9 | 23,183 | 0.781 |
    | sweep, 1 device, NPZ store | 7.6 | 21,140 | 0.856 |
    | bare kernel, 2 devices (shard_map) | 5.2 | 30,617 | 1.000 |
    | sweep, 2 devices, in memory | 5.6 | 28,579 | 1.071 |
    | sweep, 2 devices, NPZ store | 4.6 | 34,477 | 0.888 |
    | sweep, Dask 2 workers x 1 thread, NPZ store (vs 1 device) | 4.4 | 36,057 | 0.502 |

    compile (bare, 1 device) 0.0 s; warm-up sweep (compiles) 6.4 s (1 device), 4.7 s (2 devices), 13.4 s (Dask, + cluster start 1.1 s)
    resume-verify of the complete store: 0.22 s (1 device run)
    peak RSS: 16000 movements 398 MB (outputs 0.4 MB); 160000 movements 446 MB (outputs 3.8 MB); after the warm-up 389 / 389 MB
    failed rows: 0; mean |A_net| 0.0405; load average 6.7 → 7.8

Reading: at this size and load the engine and the NPZ store cost nothing measurable against the
bare kernel (0.78–1.07, single runs); 2 devices ran the bare kernel 1.7× faster than 1 device, and
the Dask cluster (2 worker processes, 1 thread each) matched the 2-device sweep. Peak memory grows
only by the outputs. The engine's own work per chunk is a ``device_put`` of the parameters, a
``device_get`` of the outputs and one fsync'd write, overlapped with the chunks in flight (two
dispatched ahead).

Two other runs at this size on this machine (load 5–7) stopped making progress and were ended: a
chunk's execution never completed, with every XLA:CPU thread idle and the caller waiting in
``device_get`` (once in the local engine with 1 device, after the warm-up; once in a Dask worker,
which runs one chunk at a time). Three runs of ``fitting.sweep`` on 5 and 10 chunks outside the
benchmark completed. Cause: both XLA:CPU intra-op pool threads blocked in jaxlib 0.10's batched
LAPACK kernel (``lapack_dsyevd_ffi`` → ``ParallelBatchMap`` → ``BlockingCounter::Wait``: above
~1 500 3×3 matrices it schedules the batch's pieces on that pool and waits), one per ``eigvalsh``
of ``simulate``'s traced check of ``W`` and ``KJ``; with every pool thread waiting nothing runs the
pieces. The check is now LAPACK-free and ``fitting.sweep`` reports a chunk that stalls
(``fitting/_sweep/engines.py``) instead of waiting forever.
"""

# ruff: noqa: E501  (the pasted result table above)
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

CHUNK = 2_000  # rows (16 000 movements) per compiled call
DT = 0.005  # s: 80 RK4 steps per 0.4 s movement, the main job's step (at 10 ms simulate's error
# estimate flags about a third of the movements INACCURATE; 20 ms is unstable for anisotropic KJ)


def _params(rows: int):
    import numpy as np

    import fitting

    n_rest = 250
    n_aniso = max(1, rows // n_rest)
    p = fitting.grid(anisotropy=np.linspace(0.5, 3.0, n_aniso), rest_ps_deg=np.linspace(-20.0, 20.0, n_rest))
    return {k: v[:rows] for k, v in p.items()}


def _kernel():
    import functools

    from fitting.internal import curvature_row

    return functools.partial(curvature_row, dt=DT)


def _maxrss_mb() -> float:
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def child(cfg: dict) -> dict:
    """One configuration in this (fresh) process; returns timings and peak memory."""
    import jax

    jax.config.update("jax_enable_x64", True)
    import tempfile

    import numpy as np

    import fitting

    fn = _kernel()
    rows = cfg["rows"]
    params = _params(rows)
    res: dict = {"rows": rows, "movements": 8 * rows, "devices": len(jax.local_devices())}
    warm = {k: v[:CHUNK] + 1e-3 for k, v in _params(CHUNK).items()}  # another sweep, same compiled kernel
    t0 = time.perf_counter()
    fitting.sweep(fn, warm, chunk_size=CHUNK, progress=False)
    res["compile_and_warmup_s"] = time.perf_counter() - t0
    rss0 = _maxrss_mb()
    with tempfile.TemporaryDirectory() as tmp:
        if cfg.get("store", True):
            t0 = time.perf_counter()
            out = fitting.sweep(fn, params, chunk_size=CHUNK, out=os.path.join(tmp, "s"), progress=False)
            res["sweep_store_s"] = time.perf_counter() - t0
            res["maxrss_mb"] = _maxrss_mb()
            res["maxrss_before_mb"] = rss0
            res["output_mb"] = sum(a.nbytes for a in jax.tree_util.tree_leaves(out.outputs)) / 1e6
            res["failed"] = out.n_failed
            res["a_net_mean_abs"] = float(np.nanmean(np.abs(out.outputs["A_net"])))
            t0 = time.perf_counter()
            again = fitting.sweep(fn, params, chunk_size=CHUNK, out=os.path.join(tmp, "s"), progress=False)
            res["resume_verify_s"] = time.perf_counter() - t0
            assert again.chunks_computed == 0
    if cfg.get("memory_only"):
        return res
    # the bare kernel on the same chunks: the sweep's own compiled kernel (no store, no bookkeeping)
    from fitting.internal import LocalEngine

    kernel_key = next(reversed(LocalEngine._kernels))[0]  # the sweep's compiled kernel and its placement
    engine = LocalEngine(fn, jax.local_devices(), CHUNK, kernel_key)
    n_chunks = -(-rows // CHUNK)
    chunks = []
    for k in range(n_chunks):
        sl = slice(k * CHUNK, min((k + 1) * CHUNK, rows))
        pad = CHUNK - (sl.stop - sl.start)
        chunks.append({n: np.concatenate([a[sl], np.repeat(a[sl.stop - 1:sl.stop], pad)]) for n, a in params.items()})
    t0 = time.perf_counter()
    compiled = engine.kernel.lower(jax.device_put(chunks[0], engine.sharding)).compile()
    res["bare_compile_s"] = time.perf_counter() - t0

    def bare():
        outs = [compiled(jax.device_put(c, engine.sharding)) for c in chunks]
        jax.block_until_ready(outs)
        return np.concatenate([np.asarray(o["A_net"]) for o in outs])[:rows]

    # interleaved repeats (min of each): the machine is shared, its load drifts during a run
    res["bare_kernel_s"] = res["sweep_nostore_s"] = np.inf
    for _ in range(cfg.get("repeats", 1)):
        t0 = time.perf_counter()
        a_bare = bare()
        res["bare_kernel_s"] = min(res["bare_kernel_s"], time.perf_counter() - t0)
        t0 = time.perf_counter()
        mem = fitting.sweep(fn, params, chunk_size=CHUNK, progress=False)
        res["sweep_nostore_s"] = min(res["sweep_nostore_s"], time.perf_counter() - t0)
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            fitting.sweep(fn, params, chunk_size=CHUNK, out=os.path.join(tmp, "s"), progress=False)
            res["sweep_store_s"] = min(res["sweep_store_s"], time.perf_counter() - t0)
    np.testing.assert_array_equal(a_bare, mem.outputs["A_net"])
    return res


def run_child(cfg: dict, devices: int = 1) -> dict:
    env = {**os.environ, "XLA_FLAGS": f"--xla_force_host_platform_device_count={devices}"}
    r = subprocess.run([sys.executable, os.path.abspath(__file__), "--child", json.dumps(cfg)], env=env,
                       capture_output=True, text=True)
    if r.returncode:
        raise RuntimeError(r.stderr[-4000:])
    return json.loads(r.stdout.strip().splitlines()[-1])


def run_dask(rows: int) -> dict:
    import jax

    jax.config.update("jax_enable_x64", True)
    import tempfile

    from distributed import Client, LocalCluster

    import fitting

    fn = _kernel()
    params = _params(rows)
    res = {"rows": rows, "movements": 8 * rows}
    t0 = time.perf_counter()
    with LocalCluster(n_workers=2, processes=True, threads_per_worker=1, host="127.0.0.1",
                      dashboard_address=None) as cluster, Client(cluster) as client:
        res["cluster_start_s"] = time.perf_counter() - t0
        warm = {k: v[: 2 * CHUNK] + 1e-3 for k, v in _params(2 * CHUNK).items()}  # 2 chunks: both workers compile
        t0 = time.perf_counter()
        fitting.sweep(fn, warm, chunk_size=CHUNK, client=client, progress=False)
        res["compile_and_warmup_s"] = time.perf_counter() - t0
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            fitting.sweep(fn, params, chunk_size=CHUNK, client=client, out=os.path.join(tmp, "s"), progress=False)
            res["sweep_store_s"] = time.perf_counter() - t0
    return res


def store_formats():
    """The NPZ / Parquet / Zarr shard measurement of fitting/_sweep.py's docstring."""
    import hashlib
    import io
    import shutil
    import tempfile

    import numpy as np

    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
        import zarr
    except ImportError:
        print("--stores needs pyarrow and zarr importable (not pmpjax dependencies); skipped")
        return []
    from pathlib import Path

    from fitting.internal import atomic_write

    ch = 10_000
    rows_out = []

    def digest(b):
        return hashlib.blake2b(b, digest_size=16).hexdigest()

    for n in (100_000, 1_000_000):
        rng = np.random.default_rng(0)
        outs = [{"A_net": rng.normal(size=(ch, 8)), "A_sum": rng.normal(size=(ch, 8)),
                 "status": np.zeros((ch, 8), np.int32)} for _ in range(n // ch)]
        for fmt in ("npz", "parquet", "zarr"):
            d = Path(tempfile.mkdtemp())
            t0 = time.perf_counter()
            sums = []
            if fmt == "npz":
                for k, o in enumerate(outs):
                    b = io.BytesIO()
                    np.savez(b, **o)
                    atomic_write(d / f"{k:06d}-{digest(b.getvalue())}.npz", b.getvalue())
            elif fmt == "parquet":
                for k, o in enumerate(outs):
                    t = pa.table({c: pa.FixedSizeListArray.from_arrays(pa.array(a.reshape(-1)), 8)
                                  for c, a in o.items()})
                    b = pa.BufferOutputStream()
                    pq.write_table(t, b, compression="none")
                    data = b.getvalue().to_pybytes()
                    atomic_write(d / f"{k:06d}-{digest(data)}.parquet", data)
            else:
                g = zarr.open_group(str(d), mode="w")
                for c, dt in (("A_net", "f8"), ("A_sum", "f8"), ("status", "i4")):
                    g.create_array(c, shape=(n, 8), chunks=(ch, 8), dtype=dt, compressors=None)
                for k, o in enumerate(outs):
                    for c, a in o.items():
                        g[c][k * ch:(k + 1) * ch] = a
                    sums.append({c: digest(a.tobytes()) for c, a in o.items()})
            tw = time.perf_counter() - t0

            def verify(load):
                for p in sorted(d.iterdir()):
                    data = p.read_bytes()
                    assert digest(data) == p.name.split("-")[1].split(".")[0]
                    if load:
                        if fmt == "npz":
                            with np.load(io.BytesIO(data)) as z:
                                [z[f] for f in z.files]
                        else:
                            pq.read_table(pa.BufferReader(data))

            def zarr_verify():
                g = zarr.open_group(str(d), mode="r")
                arrs = {c: g[c][:] for c in ("A_net", "A_sum", "status")}
                for k, s in enumerate(sums):
                    for c in arrs:
                        assert digest(np.ascontiguousarray(arrs[c][k * ch:(k + 1) * ch]).tobytes()) == s[c]

            t0 = time.perf_counter()
            zarr_verify() if fmt == "zarr" else verify(True)
            tr = time.perf_counter() - t0
            t0 = time.perf_counter()
            zarr_verify() if fmt == "zarr" else verify(False)
            tv = time.perf_counter() - t0
            rows_out.append({"rows": n, "format": fmt, "write_s": tw, "read_verify_s": tr, "resume_verify_s": tv})
            print(f"| {n} | {fmt} | {tw:.2f} | {tr:.2f} | {tv:.2f} |", flush=True)
            shutil.rmtree(d)
    return rows_out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--movements", type=int, default=1_000_000)
    ap.add_argument("--quick", action="store_true", help="16 000 movements (smoke run)")
    ap.add_argument("--stores", action="store_true", help="also the NPZ/Parquet/Zarr shard measurement")
    ap.add_argument("--repeats", type=int, default=1, help="interleaved repeats of bare / sweep runs (min)")
    ap.add_argument("--overhead", action="store_true",
                    help="only the overhead measurement: 1 and 2 devices, --repeats interleaved runs")
    ap.add_argument("--child", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        print(json.dumps(child(json.loads(args.child))))
        return
    import _baselines as bl

    movements = 16_000 if args.quick else args.movements
    rows = movements // 8
    results = bl.header({"movements": movements, "rows": rows, "chunk_rows": CHUNK, "dt_s": DT,
                         "repeats": args.repeats, "quick": args.quick, "overhead_only": args.overhead,
                         "stores": args.stores}, "dask", "distributed")
    load0 = results["load_start"]
    print(f"{bl.machine()}; load average {load0[0]:.1f}; {movements} movements = {rows} rows, chunks of {CHUNK}",
          flush=True)
    if args.overhead:
        for d in (1, 2):
            r = run_child({"rows": rows, "repeats": args.repeats}, devices=d)
            print(f"{d} device(s), {movements} movements, min of {args.repeats}: bare {r['bare_kernel_s']:.2f} s, "
                  f"sweep in memory {r['sweep_nostore_s']:.2f} s ({r['sweep_nostore_s'] / r['bare_kernel_s']:.3f}), "
                  f"sweep + store {r['sweep_store_s']:.2f} s ({r['sweep_store_s'] / r['bare_kernel_s']:.3f}); "
                  f"load {os.getloadavg()[0]:.1f}", flush=True)
        return
    small = max(CHUNK, rows // 10)
    results["memory_small"] = run_child({"rows": small, "memory_only": True})
    print("memory, 1/10 size:", results["memory_small"], flush=True)
    results["one_device"] = run_child({"rows": rows, "repeats": args.repeats})
    print("1 device:", results["one_device"], flush=True)
    results["two_devices"] = run_child({"rows": rows, "repeats": args.repeats}, devices=2)
    print("2 devices:", results["two_devices"], flush=True)
    results["dask"] = run_dask(rows)
    print("dask:", results["dask"], flush=True)
    if args.stores:
        results["stores"] = store_formats()
    results["load_end"] = bl.load_average()

    one, two, dk, sm = results["one_device"], results["two_devices"], results["dask"], results["memory_small"]
    rate = lambda s: movements / s  # noqa: E731
    lines = [f"| {movements} movements ({rows} rows, chunks of {CHUNK} rows) | wall [s] | movements/s | "
             "vs bare kernel |", "|---|---:|---:|---:|"]
    table_rows = []
    for name, r, key, bare in (
        ("bare kernel, 1 device", one, "bare_kernel_s", one["bare_kernel_s"]),
        ("sweep, 1 device, in memory", one, "sweep_nostore_s", one["bare_kernel_s"]),
        ("sweep, 1 device, NPZ store", one, "sweep_store_s", one["bare_kernel_s"]),
        ("bare kernel, 2 devices (shard_map)", two, "bare_kernel_s", two["bare_kernel_s"]),
        ("sweep, 2 devices, in memory", two, "sweep_nostore_s", two["bare_kernel_s"]),
        ("sweep, 2 devices, NPZ store", two, "sweep_store_s", two["bare_kernel_s"]),
        ("sweep, Dask 2 workers x 1 thread, NPZ store (vs 1 device)", dk, "sweep_store_s", one["bare_kernel_s"]),
    ):
        table_rows.append({"configuration": name, "wall_s": r[key], "movements_per_s": rate(r[key]),
                           "vs_bare_kernel": r[key] / bare})
        lines.append(f"| {name} | {r[key]:.1f} | {rate(r[key]):,.0f} | {r[key] / bare:.3f} |")
    lines += ["",
              f"compile (bare, 1 device) {one['bare_compile_s']:.1f} s; warm-up sweep (compiles) "
              f"{one['compile_and_warmup_s']:.1f} s (1 device), {two['compile_and_warmup_s']:.1f} s (2 devices), "
              f"{dk['compile_and_warmup_s']:.1f} s (Dask, + cluster start {dk['cluster_start_s']:.1f} s)",
              f"resume-verify of the complete store: {one['resume_verify_s']:.2f} s (1 device run)",
              f"peak RSS: {sm['movements']} movements {sm['maxrss_mb']:.0f} MB (outputs {sm['output_mb']:.1f} MB); "
              f"{one['movements']} movements {one['maxrss_mb']:.0f} MB (outputs {one['output_mb']:.1f} MB); "
              f"after the warm-up {sm['maxrss_before_mb']:.0f} / {one['maxrss_before_mb']:.0f} MB",
              f"failed rows: {one['failed']}; mean |A_net| {one['a_net_mean_abs']:.4f}; "
              f"load average {load0[0]:.1f} → {results['load_end'][0]:.1f}"]
    results["table"] = table_rows
    results["tables"] = ["\n".join(lines)]
    print("\n" + results["tables"][0])
    print("results ->", bl.write_results("sweep", results))


if __name__ == "__main__":
    main()
