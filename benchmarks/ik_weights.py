"""Benchmark: IK-weight identification (Algorithm 1) for many subjects in one call.

Workload: 1 000 synthetic subjects × 500 samples, n = 5, m = 3 (the Fig 1 data),
a fixed number of iterations (``tol = step_tol = 0``). Baseline, run in the same process: a
faithful per-subject NumPy/SciPy implementation of Algorithm 1 as the paper's MATLAB does it —
a Python loop over samples (weighted pseudo-inverse with ``np.linalg.inv``, error, ``ū``, ``v̄``)
and one bounded QP per iteration on ``Ψ̃``, ``Ω̃`` (``scipy.optimize.lsq_linear``, bounds
[w_min, 1]) — on the first 10 subjects. Also: batch-size scaling and the real-data estimate
(HuG-MP, 4 subjects × 6 tasks, point estimate and a bootstrap).

Run: ``python benchmarks/ik_weights.py [--quick]`` (about 2 min on 2 cores; ``--quick``: 200
subjects, 20 iterations); writes ``benchmarks/results/ik_weights.json`` (date, machine, versions,
load average, parameters, the rows, batch scaling and the real-data figures) after each stage (so a
partial run leaves its figures). The script sets
``XLA_FLAGS=--xla_force_host_platform_device_count=<cores>`` before importing jax and times
``estimate_ik_weights`` with ``devices=[one device]`` and with the items split over all devices
(the default), plus a subprocess pinned to one core (``os.sched_setaffinity``) for the rate of one
core alone: the baseline is a single-threaded Python loop, while even one XLA:CPU device spreads
each large fused loop over its intra-op thread pool (CPU time ≈ 1.9× wall time).

Latest figures (2026-12-06 07:16–07:18 UTC, ``results/ik_weights.json``; 2-core AMD EPYC (Zen 4)
KVM, no GPU, float64, JAX 0.10.2; default size, 1 000 subjects, 112 s). The machine was shared
with other developers' test runs (load average 8.1 at the start, 8.3 at the end, on 2 cores), so
the times are upper bounds; ratios are taken within the run:

| implementation                                             | subjects/s | compile+1st run [s] |
|------------------------------------------------------------|-----------:|--------------------:|
| NumPy/SciPy per-sample loop + QP (10 subj., 1 core)        |      0.971 |                     |
| JAX estimate_ik_weights, 1 device pinned to 1 core         |       1600 |                     |
| JAX estimate_ik_weights, 1 device                          |       1809 |                 9.0 |
| JAX estimate_ik_weights, 2 devices (items split)           |       1700 |                 6.4 |

Speed-up against the baseline: 1862× (best, 1 device), 1 core alone 1647×; weights agree with the
baseline to 1.5e-13, 1 vs 2 devices exactly. Batch scaling (subjects/s, default devices): B = 1:
522, 10: 831, 100: 1225, 1000: 1305. Real data (HuG-MP, 4 subjects × 6 tasks): point estimate
with 2 bootstrap replicates (100 samples/motion, at most 200 steps) 16.5 s, bootstrap (20
replicates, 25 samples/motion) 17.2 s; none of the point estimate's replicates ends with status
SUCCESSFUL within the 200 steps (``real_data_converged_fraction`` 0.0). Target (≥ 1 000× the
baseline): met, also by one core alone. The single-threaded baseline's rate moves with the load
more than the batched call: only same-run ratios count.

Where the time goes (per call of 0.22–0.29 s at B = 1 000, 1 device, on an idle machine, each part
measured back to back in one process):

- The Algorithm-1 kernel, 0.19–0.23 s (≈ 16 ns per sample-iteration per core: two 3 × 3 weighted
  pseudo-inverse solves, the error and 51 running sums, ≈ 300 flops). Each iteration is one fused
  pass over the samples: the 3 × 3 solve is the adjugate (one division; XLA:CPU ends a fused loop at
  each LDLᵀ division with several users), and the previous iteration's ``v̄`` is recomputed from its
  weights instead of carried (writing it out would split the pass).
- The reductions over samples are compiled with reassociation allowed (``xla_cpu_enable_fast_math``
  with NaN/inf/division/function semantics kept), so XLA:CPU vectorises them (3.8× on the kernel).
  Weights move by rounding only: against the strict-order kernel 2e-13 for 99 % of the 1 000
  subjects, 2e-11 for the worst-conditioned one, whose float64 NumPy baseline is itself 6e-9 from
  an extended-precision (long double) run of the algorithm.
- Input screening (NaN/inf, rank of J) in one jitted pass, 0.03 s; inputs passed to XLA without a
  copy when aligned; the component-leading layout made per chunk in cache; the rest < 0.01 s.
- Splitting items over 2 devices (``shard_map``, no communication) gives 0.86–1.27× over 1 device:
  one device already uses both cores for the big fused loops (pinned to one core: 0.5–0.65× of
  1 device). Chunks of 50 items are best (10/20/100/200/1 000 measured); 512-bit vectors give
  nothing.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

if __name__ == "__main__" and "--single-core" in sys.argv:
    os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})  # every XLA thread on one core
# one XLA:CPU device per core (set before jax is imported)
os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "")
                           + f" --xla_force_host_platform_device_count={os.cpu_count()}").strip()

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import _baselines as bl  # noqa: E402
import numpy as np  # noqa: E402
import scipy.optimize  # noqa: E402

import fitting  # noqa: E402


def baseline_subject(Qd, Xd, Js, gamma, iters, w_min=1e-3):
    """Algorithm 1, one subject, per-sample loop and a QP per iteration (NumPy/SciPy)."""
    K, n = Qd.shape
    w = np.ones(n)
    V = np.zeros((K, n))
    for _ in range(iters):
        Winv = np.diag(1.0 / w)
        e = 0.0
        U = np.zeros((K, n))
        Vn = np.zeros((K, n))
        for k in range(K):
            J = Js[k]
            B = np.linalg.inv(J @ Winv @ J.T)
            Jp = Winv @ J.T @ B
            qbar = Jp @ Xd[k] + V[k]
            e += np.linalg.norm(Qd[k] - qbar)
            U[k] = J.T @ B @ Xd[k]
            Vn[k] = gamma * (np.eye(n) - Jp @ J) @ Qd[k]
        V = Vn
        psi = (Qd - V).T @ Qd
        omega = U.T @ Qd
        Pt = np.concatenate([np.diag(psi[:, j]) for j in range(n)])
        Ot = np.concatenate([omega[:, j] for j in range(n)])
        w = scipy.optimize.lsq_linear(Pt, Ot, bounds=(w_min, 1.0)).x
        w = w / w.max()
    return w


def time_min(f, repeats):
    best = np.inf
    for _ in range(repeats):
        t = time.perf_counter()
        jax.block_until_ready(f())
        best = min(best, time.perf_counter() - t)
    return best


def workload(quick):
    n_subj, K, iters, gamma = (200 if quick else 1000), 500, (20 if quick else 50), 0.6
    q, x, J = (np.asarray(a) for a in fitting.ik_fig1_data(jax.random.PRNGKey(0), n_reps=n_subj, K=K))
    return n_subj, K, iters, gamma, q, x, J


def jax_rate(q, x, J, gamma, iters, devices, B=None, repeats=3):
    """(compile + first run [s], best time [s], weights) of one estimate_ik_weights call on B items."""
    B = len(q) if B is None else B
    run = lambda: fitting.estimate_ik_weights(  # noqa: E731
        q[:B], x[:B], J[:B], gamma=gamma, tol=0.0, step_tol=0.0, max_steps=iters, devices=devices).w
    t = time.perf_counter()
    w = np.asarray(run())
    first = time.perf_counter() - t
    return first, time_min(run, repeats), w


def single_core_worker(quick):
    """Run in a subprocess pinned to one core: the 1-device rate without XLA's intra-op threads."""
    n_subj, K, iters, gamma, q, x, J = workload(quick)
    first, t, w = jax_rate(q, x, J, gamma, iters, jax.devices()[:1])
    print(json.dumps({"seconds": t, "subjects_per_s": n_subj / t, "w0": w[0].tolist()}))


def main(quick=False):
    n_subj, K, iters, gamma, q, x, J = workload(quick)
    devs = jax.devices()
    res = bl.header({"subjects": n_subj, "samples": K, "n": 5, "m": 3, "iterations": iters, "gamma": gamma,
                     "baseline_subjects": 10, "devices": len(devs), "quick": quick})

    def save(**items):  # results are written as they come
        res.update(items)
        bl.write_results("ik_weights", json.loads(json.dumps(res, default=float)))

    c1, t1, w1 = jax_rate(q, x, J, gamma, iters, devs[:1])
    save(jax_1device_seconds=t1, jax_1device_subjects_per_s=n_subj / t1, jax_1device_compile_plus_first_run_s=c1)
    cN, tN, wN = jax_rate(q, x, J, gamma, iters, devs)
    save(jax_ndevice_seconds=tN, jax_ndevice_subjects_per_s=n_subj / tN, jax_ndevice_compile_plus_first_run_s=cN,
         max_abs_weight_difference_1_vs_n_devices=float(np.abs(w1 - wN).max()))
    worker = subprocess.run([sys.executable, __file__, "--single-core"] + (["--quick"] if quick else []),
                            capture_output=True, text=True, check=True)
    single = json.loads(worker.stdout.strip().splitlines()[-1])
    save(jax_1core_seconds=single["seconds"], jax_1core_subjects_per_s=single["subjects_per_s"])

    n_base = 10
    t = time.perf_counter()
    w_base = np.stack([baseline_subject(q[i], x[i], J[i], gamma, iters) for i in range(n_base)])
    t_base = (time.perf_counter() - t) / n_base
    agree = float(np.abs(w_base - w1[:n_base]).max())
    best = max(n_subj / t1, n_subj / tN)
    save(baseline_seconds_per_subject=t_base, baseline_subjects_per_s=1 / t_base,
         speedup=best * t_base, speedup_1device=(n_subj / t1) * t_base,
         speedup_1core=single["subjects_per_s"] * t_base, max_abs_weight_difference_vs_baseline=agree)
    rows = [("NumPy/SciPy per-sample loop + QP (10 subj., 1 core)", 1 / t_base, ""),
            ("JAX estimate_ik_weights, 1 device pinned to 1 core", single["subjects_per_s"], ""),
            ("JAX estimate_ik_weights, 1 device", n_subj / t1, f"{c1:.1f}"),
            (f"JAX estimate_ik_weights, {len(devs)} devices (items split)", n_subj / tN, f"{cN:.1f}")]
    lines = ["| implementation | subjects/s | compile+1st run [s] |", "|---|---:|---:|"]
    lines += [f"| {name} | {rate:.4g} | {comp} |" for name, rate, comp in rows]
    save(rows=[{"implementation": name, "subjects_per_s": rate,
                "compile_plus_first_run_s": float(comp) if comp else None} for name, rate, comp in rows],
         tables=["\n".join(lines)])
    print("\n".join(lines))
    print(f"speed-up vs baseline: {res['speedup']:.0f}x (best), 1 device {res['speedup_1device']:.0f}x, "
          f"1 core {res['speedup_1core']:.0f}x; weights agree with the baseline to {agree:.1e}, "
          f"1 vs {len(devs)} devices to {res['max_abs_weight_difference_1_vs_n_devices']:.1e}", flush=True)

    scaling = {}
    for B in (1, 10, 100, n_subj):
        scaling[B] = B / jax_rate(q, x, J, gamma, iters, None, B)[1]
        save(batch_scaling_subjects_per_s=scaling)
    print("batch scaling (subjects/s, default devices): "
          + ", ".join(f"B={b}: {v:.3g}" for b, v in scaling.items()), flush=True)

    t = time.perf_counter()
    real = fitting.hugmp_ik_weights(n_boot=2, samples=100, max_steps=200)
    t_real_point = time.perf_counter() - t
    save(real_data_point_estimate_s=t_real_point, real_data_w_S01=np.asarray(real["w"][0]).tolist(),
         real_data_converged_fraction=float(np.mean(real["converged"])))
    t = time.perf_counter()
    real_b = fitting.hugmp_ik_weights(n_boot=20, samples=25, max_steps=200)
    t_real_boot = time.perf_counter() - t
    save(real_data_bootstrap20_s=t_real_boot,
         real_data_ci_halfwidth_median=float(np.nanmedian(real_b["hi"] - real_b["lo"])),
         load_end=bl.load_average())
    print(f"real data (4 subjects x 6 tasks): point estimate {t_real_point:.1f} s, "
          f"bootstrap (20 replicates, 25 samples/motion) {t_real_boot:.1f} s")
    print(f"load average (1 min) {res['load_start'][0]:.1f} at start, {res['load_end'][0]:.1f} at end")
    return res


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--single-core", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    single_core_worker(args.quick) if args.single_core else main(args.quick)
