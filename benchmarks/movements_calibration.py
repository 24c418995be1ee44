"""Calibration: the standard errors of ``fitting.fit_movements`` and ``fitting.fit_reaching``
against the Monte Carlo spread of their estimates.

**Method (``movements``).** One subject's recordings, made by the independent reference of the tests
(``tests/_movement_reference.py``: SciPy Radau of the NumPy λ0-PMP in the run below, LSODA since,
which agrees to 4e-10 rad; closed-form kinematics, Eq 10's gain at each reach's start): a 3-joint
``pj.PlanarArm`` (links 0.30, 0.25, 0.15 m), a full, anisotropic ``KJ`` (cond 5, trace 3),
``q_rest`` (40, 60, 30)°, ``τ0`` 0.12 s, ``τ`` 0.10 s, two continuous trials of 8 reaches (out and
back to 4 targets 0.12 m from home, 1.0–1.3 s each, 0.5 s at rest first), sampled at 100 Hz. The
noise-free trials are made once; each of ``R`` replicates adds its own 0.2° Gaussian noise per joint
and sample and is fitted as a subject of one ``fit_movements`` call (defaults). Per parameter: the
standard deviation of the converged replicates' estimates (the truth of the spread), the median
reported standard error, their ratio, the RMS of the z-scores ``(estimate − mean of estimates) /
stderr`` and the coverage of the 95 % intervals ``estimate ± 1.96 stderr`` of the mean of estimates.
With R replicates the spread itself is uncertain by about ``1/√(2(R−1))`` (13 % at R = 32, 10 % at
48).

**Method (``reaching``).** ``fit_reaching``'s per-subject fit (its kernel ``_fit_motions``, the
default Arimoto model with fitted time constants) on 16 motions of the HuG-MP arm between postures
in the HuG-MP ranges, made by the tests' LSODA reference (``tests/test_reaching.py``: ``KJ`` of
cond 10, ``τ/T`` 0.12, ``τ0/T`` 0.10, recordings 1.5 T long); each replicate adds 0.2° noise to
every sample (the start posture and the final posture, whose hand position is the target,
included), all replicates fitted as subjects of one call.

Usage: ``python benchmarks/movements_calibration.py [--parts movements reaching] [--replicates 48]
[--reaching-replicates 24]``; writes ``results/movements_calibration.json`` (a part not run keeps
its previous entry).

Latest figures (``movements``): 2026-12-06 08:34 UTC, 2-core AMD EPYC (KVM), no GPU, jax 0.10.2,
float64; R = 48, every replicate converged; the fit of the 48 took 193 s with compilation under a load average of
17–18 (other work shared the machine)::

    | parameter | mean | sd (Monte Carlo) | stderr (median) | stderr / sd | RMS z | 95 % coverage |
    |---|---:|---:|---:|---:|---:|---:|
    | S_K[q1,q1] | 0.024253 | 0.00878 | 0.00921 | 1.05 | 0.94 | 0.94 |
    | S_K[q2,q2] | 0.082897 | 0.00763 | 0.0086 | 1.13 | 0.95 | 0.92 |
    | S_K[q1,q2] | 0.13404 | 0.00842 | 0.0102 | 1.21 | 0.99 | 0.94 |
    | S_K[q1,q3] | 0.070849 | 0.00725 | 0.00787 | 1.09 | 0.91 | 0.94 |
    | S_K[q2,q3] | 0.78465 | 0.00494 | 0.00532 | 1.08 | 0.81 | 0.96 |
    | q_rest[q1] | 0.70179 | 0.0289 | 0.0356 | 1.23 | 0.81 | 0.98 |
    | q_rest[q2] | 1.0477 | 0.016 | 0.0174 | 1.09 | 0.87 | 0.94 |
    | q_rest[q3] | 0.5224 | 0.0091 | 0.0109 | 1.20 | 0.87 | 0.94 |
    | log(tau/s) | -2.2981 | 0.0383 | 0.0352 | 0.92 | 1.11 | 0.92 |
    | log(tau0/s) | -2.1268 | 0.0243 | 0.0255 | 1.05 | 1.03 | 0.96 |
    | delay [s] | -0.23674 | 0.00189 | 0.00223 | 1.18 | 0.92 | 0.98 |

The reported errors (the delete-one-reach jackknife) are 0.92–1.23 times the Monte Carlo spread
(within its ±10 % uncertainty, the jackknife's usual slight excess), the z-scores' RMS 0.81–1.11,
and the 95 % intervals cover 92–98 %. The estimates are unbiased: mean τ 0.1005 s, τ0 0.1192 s
(truth 0.10, 0.12).

Latest figures (``reaching``): 2026-12-06 09:04 UTC, the same machine; R = 16, every replicate converged; the
fit of the 16 took 138 s with compilation under a load average of 5–4 (1-minute; 12–11 over 15 minutes)::

    | parameter | mean | sd (Monte Carlo) | stderr (median) | stderr / sd | RMS z | 95 % coverage |
    |---|---:|---:|---:|---:|---:|---:|
    | S_K[q1,q1] | 0.35246 | 0.0143 | 0.0173 | 1.20 | 0.79 | 0.94 |
    | S_K[q2,q2] | -0.19402 | 0.0123 | 0.0122 | 0.99 | 0.92 | 1.00 |
    | S_K[q3,q3] | 0.24735 | 0.0209 | 0.0208 | 1.00 | 0.98 | 1.00 |
    | S_K[q1,q2] | 0.37487 | 0.00846 | 0.00643 | 0.76 | 1.10 | 0.94 |
    | S_K[q1,q3] | 0.82623 | 0.0168 | 0.0188 | 1.12 | 0.81 | 1.00 |
    | S_K[q1,q4] | -0.16658 | 0.00847 | 0.00964 | 1.14 | 1.08 | 0.94 |
    | S_K[q2,q3] | -0.36376 | 0.00549 | 0.00938 | 1.71 | 0.62 | 1.00 |
    | S_K[q2,q4] | 0.52827 | 0.00516 | 0.00668 | 1.29 | 0.77 | 0.94 |
    | S_K[q3,q4] | -0.032099 | 0.00844 | 0.0109 | 1.29 | 0.81 | 1.00 |
    | q_rest[q1] | -0.49556 | 0.0313 | 0.034 | 1.09 | 0.86 | 1.00 |
    | q_rest[q2] | -0.6827 | 0.0621 | 0.0677 | 1.09 | 0.87 | 1.00 |
    | q_rest[q3] | -0.097115 | 0.0346 | 0.0375 | 1.09 | 0.87 | 0.94 |
    | log(tau/T) | -2.1156 | 0.0061 | 0.00972 | 1.59 | 0.62 | 1.00 |
    | log(tau0/T) | -2.3089 | 0.00684 | 0.00862 | 1.26 | 0.81 | 0.94 |

The jackknife errors are 0.76–1.71 times the spread (±18 % at R = 16), 1.0–1.3 for most
parameters: conservative where 16 motions leave a deleted motion much leverage; the 95 % intervals
cover 94–100 %. The Gauss–Newton errors, measured the same way, were 0.26–0.76 times it.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "tests"))
import _baselines as bl  # noqa: E402
from _movement_reference import continuous_recording, planar_fk_jac, random_spd  # noqa: E402
from _reference import slsqp_equilibrium  # noqa: E402

import fitting  # noqa: E402
import pmpjax as pj  # noqa: E402

LENGTHS = np.array([0.30, 0.25, 0.15])
TAU0, TAU = 0.12, 0.10
Q_REST = np.deg2rad([40.0, 60.0, 30.0])
HOME = np.array([0.25, 0.30])
NOISE_DEG = 0.2


def clean_trials():
    fk_jac = lambda q: planar_fk_jac(q, LENGTHS)  # noqa: E731
    KJ = random_spd(np.random.default_rng(11), 3, cond=5.0, trace=3.0)
    q_home = slsqp_equilibrium(lambda q: fk_jac(q)[0], lambda q: fk_jac(q)[1], KJ, Q_REST, HOME,
                               q0=np.deg2rad([30.0, 80.0, 40.0]))
    out = []
    for seed in (1, 2):
        rng = np.random.default_rng(seed)
        ang = rng.uniform(0, 2 * np.pi, 4)
        far = HOME + 0.12 * np.stack([np.cos(ang), np.sin(ang)], 1)
        targets = np.stack([far, np.broadcast_to(HOME, far.shape)], 1).reshape(-1, 2)
        hold = rng.uniform(1.0, 1.3, size=len(targets))
        t, q, _ = continuous_recording(fk_jac, KJ, Q_REST, TAU0, TAU, q_home, targets, hold, fs=100.0,
                                       noise_deg=0.0, seed=seed, lead=0.5)
        out.append((t, q))
    return out


def calibration(names, params, stderr):
    """Rows and a Markdown table: per parameter the Monte Carlo spread against the reported errors."""
    rows = []
    for i, name in enumerate(names):
        sd = float(params[:, i].std(ddof=1))
        z = (params[:, i] - params[:, i].mean()) / stderr[:, i]
        rows.append({"parameter": name, "mean": float(params[:, i].mean()), "sd": sd,
                     "stderr_median": float(np.median(stderr[:, i])), "ratio": float(np.median(stderr[:, i]) / sd),
                     "rms_z": float(np.sqrt(np.mean(z**2))), "coverage_95": float(np.mean(np.abs(z) < 1.96))})
    lines = ["| parameter | mean | sd (Monte Carlo) | stderr (median) | stderr / sd | RMS z | 95 % coverage |",
             "|---|---:|---:|---:|---:|---:|---:|"]
    lines += [f"| {r['parameter']} | {r['mean']:.5g} | {r['sd']:.3g} | {r['stderr_median']:.3g} | {r['ratio']:.2f} | "
              f"{r['rms_z']:.2f} | {r['coverage_95']:.2f} |" for r in rows]
    return rows, "\n".join(lines)


def movements_part(R):
    trials = clean_trials()
    recs = []
    for r in range(R):
        g = np.random.default_rng(1000 + r)
        for k, (t, q) in enumerate(trials):
            noisy = q + np.deg2rad(NOISE_DEG) * g.standard_normal(q.shape)
            recs.append(pj.JointRecording(f"R{r:02d}", f"R{r:02d}_trial{k + 1}", t, noisy, ("q1", "q2", "q3")))
    t0 = time.perf_counter()
    fit = fitting.fit_movements(pj.PlanarArm(LENGTHS), recs)
    wall = time.perf_counter() - t0
    ok = fit.converged
    rows, table = calibration(fit.param_names, fit.params[ok], fit.stderr[ok])
    print(f"fit_movements: {int(ok.sum())} of {R} replicates converged; fit {wall:.1f} s (compilation included)")
    print(table)
    return dict(replicates=R, converged=int(ok.sum()), wall_s=wall, rows=rows, table=table,
                truth={"tau": TAU, "tau0": TAU0}, tau_mean=float(fit.tau[ok].mean()),
                tau0_mean=float(fit.tau0[ok].mean()))


def reaching_part(R, n_motions=16):
    """``fit_reaching``'s fit of one subject's motions (its per-subject kernel, ``_fit_motions``)
    on 16 motions of the HuG-MP arm made by the tests' independent LSODA reference."""
    import test_reaching as ref

    from fitting.internal import (
        REACHING_SAMPLES,
        ReachingConfig,
        ReachingMotions,
        fit_reaching_motions,
        reaching_param_names,
    )

    KJ, q_rest = ref._kj_with_cond(10.0), np.deg2rad([-30.0, -35.0, -5.0, 60.0])
    rng = np.random.default_rng(7)
    lo, hi = np.deg2rad([-60, -70, -30, 40]), np.deg2rad([-10, -5, 10, 100])
    q0s, targets = rng.uniform(lo, hi, (n_motions, 4)), ref.arm_fk_batch(rng.uniform(lo, hi, (n_motions, 4)))
    T = rng.uniform(0.8, 1.2, n_motions)
    clean = np.stack([ref.lambda0_movement(q0, xd, KJ, q_rest, 0.12 * t, 0.10 * t, 1.5 * t)
                      for q0, xd, t in zip(q0s, targets, T)])
    motions = []
    for r in range(R):
        q = clean + np.deg2rad(NOISE_DEG) * np.random.default_rng(500 + r).standard_normal(clean.shape)
        x = ref.arm_fk_batch(q.reshape(-1, 4)).reshape(n_motions, REACHING_SAMPLES, 3)
        one = np.ones(n_motions, int)
        motions.append(ReachingMotions(f"R{r:02d}", one, one, np.arange(1, n_motions + 1), q, x, T, 1.5 * T))
    cfg = ReachingConfig("lambda0", "tau0_KJ", "fitted", 5)
    t0 = time.perf_counter()
    out = fit_reaching_motions(motions, cfg)
    wall = time.perf_counter() - t0
    ok = np.asarray(out["converged"])
    names = reaching_param_names(cfg)
    rows, table = calibration(names, np.asarray(out["x"])[ok], np.asarray(out["se"])[ok])
    print(f"fit_reaching: {int(ok.sum())} of {R} replicates converged; fit {wall:.1f} s (compilation included)")
    print(table)
    return dict(replicates=R, converged=int(ok.sum()), wall_s=wall, rows=rows, table=table, motions=n_motions)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--replicates", type=int, default=48)  # (≈ 3 min on two cores)
    ap.add_argument("--reaching-replicates", type=int, default=24)
    ap.add_argument("--parts", nargs="+", default=["movements", "reaching"], choices=["movements", "reaching"])
    args = ap.parse_args(argv)
    res = bl.header({"replicates": args.replicates, "reaching_replicates": args.reaching_replicates,
                     "noise_deg": NOISE_DEG, "parts": args.parts})
    prev = {}
    path = Path(os.environ.get("PMPJAX_BENCH_RESULTS") or HERE / "results") / "movements_calibration.json"
    if path.exists():
        prev = json.loads(path.read_text())
    run = {"movements": lambda: movements_part(args.replicates),
           "reaching": lambda: reaching_part(args.reaching_replicates)}
    for part in ("movements", "reaching"):
        if part in args.parts:
            start = {"date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "load_start": bl.load_average()}
            res[part] = {**start, **run[part](), "load_end": bl.load_average()}
        elif part in prev:
            res[part] = prev[part]
    res["load_end"] = bl.load_average()
    print("wrote", bl.write_results("movements_calibration", res))


if __name__ == "__main__":
    os.environ.setdefault("MPLBACKEND", "Agg")
    main()
