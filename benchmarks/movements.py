"""Benchmark: ``fitting.fit_movements`` + ``fitting.predict_movements`` on a 5-joint MJCF arm from
a cold start, their cost per subject as the batch of subjects grows, and the MJCF chain's
kinematics against a closed form of the same arm.

**Data** (synthetic, seeded, generated before any timing and passed to the timed processes as a
pickle): the arm ``pmpjax/data/examples/arm5.xml`` with site ``hand`` (``pj.MjcfChain``), subjects
made as ``pmpjax/data/examples/reaching/make_example.py`` makes its two: continuous trials at
100 Hz, 0.5 s at rest at home ``(0.35, 0, −0.15)`` m in the subject's equilibrium posture, then
out-and-back reaches to targets 0.10–0.15 m from home (x ≥ 0.28 m, ≤ 0.52 m from the shoulder),
each lasting 1.00–1.40 s and starting where the last one ended, every reach one ``pj.simulate`` of
the λ0-PMP (``W = τ0 KJ``, ``ArimotoPlanner(k=None, tau=τ, tau0=τ0)``, RK4 at 0.5 ms; all
subjects of a reach in one batched call), 0.2° Gaussian noise per joint and sample. Each subject
has its own full, anisotropic ``KJ`` (trace 5, random eigenvectors, eigenvalues log-uniform with
cond ≤ 11), ``q_rest`` (±8° around (25, 12, 25, 68, 5)°), ``τ0`` ∈ [0.09, 0.13] s and
``τ`` ∈ [0.08, 0.11] s.

1. **Cold fit + predict** (``cold``): 4 subjects × 20 training reaches (two trials of 10) and a
   held-out trial of 10 reaches per subject. A fresh Python process (JAX's persistent compilation
   cache off: ``JAX_ENABLE_COMPILATION_CACHE=false``, no ``JAX_COMPILATION_CACHE_DIR`` or
   ``PMPJAX_CACHE_DIR``) imports pmpjax, builds the chain and the ``JointRecording`` objects,
   then calls ``fitting.fit_movements(chain, train)`` with its defaults and
   ``fitting.predict_movements(fit, held_out)``. Wall times with ``time.perf_counter``; compile
   time is the union of the tracing, lowering and XLA compile time spans JAX reports through
   ``jax.monitoring`` during each call; the stages (``_stage1``, ``_stage2``, and
   ``_identifiability`` when run) are timed by wrappers around fitting's private stage functions
   in that process only (blocking on their results). The process's whole wall time (interpreter
   start to exit, seen by the parent) is reported too.
2. **Batch scaling** (``scaling``): S = 4, 16, 64 subjects (the first S of one set of 64) with
   one trial of 6 reaches each (``fit_movements`` pads every subject to 8), ``fit_movements``
   defaults except that the step count is held at its start, one per sample (two in the
   figures below; the library's ``MAX_STEPS_PER_SAMPLE`` set to its start in the worker;
   ``--scaling-defaults`` lifts it):
   ``fit_movements`` otherwise repeats stage 2 for the whole batch, with a new compile, while any
   one subject's integration error exceeds 0.01°, and then S no longer measures the batch. Each S
   runs in its own fresh process as above. Up to ``--second-call-max`` subjects (4) the fit is
   called a second time with the same recordings (compiled: the run alone); above it, run time =
   the first call's wall time less its compile spans. Per subject: run time / S, the first call /
   S (compilation included), and run time per stage-2 Levenberg–Marquardt iteration summed over
   the subjects (how hard each subject was to fit taken out).
3. **Kinematics** (``kinematics``, in this process): ``pj.MjcfChain(arm5.xml, "hand")`` (site
   kinematics unrolled with the model's constants and evaluated from the site towards the world on
   vectors, each hinge about a coordinate axis a plane rotation, ``pmpjax._chains.serial``) against a
   hand-written ``pj.Chain`` subclass with the same arm's forward kinematics and Jacobian in
   closed form (each sine and cosine once through pmpjax's ``sincos``, as the library's
   closed-form chains; written here from the XML's axes and offsets, checked against MjcfChain
   to 1e-12), and for reference a chain whose ``fk_jac_soa`` runs the MJX-style kinematics
   (``pmpjax._chains.mjcf.site_jacobians``: per-body frames as stacked 3×3 products, vmapped, its
   derivative a closed-form ``custom_jvp``). Workloads: ``chain.fk_jac_soa`` on 10 000 postures
   drawn in the joint ranges, alone and with its derivative along each joint (``jax.linearize``
   and a ``vmap`` over the 5 unit tangents, as RODAS4 forms its Jacobian), jitted with the chain as
   an argument; ``pj.simulate`` of 24 and of 256 reaches with ``solver="rodas4"`` in the fit's
   configuration then (normalised time, 50 samples, 2 steps per sample; the first cold subject's
   parameters, reaches of 1.2 s, targets 0.10–0.15 m from home); and ``jax.jacfwd`` of that
   simulation of 24 reaches with respect to 22 parameters (q_rest, a symmetric change of KJ, log τ,
   log τ0: stage 2's work per iteration on one subject of 20 reaches). Compile = ``jax.jit(f).lower``
   + ``.compile()``; run = the fastest of repeated calls of the compiled function
   (``block_until_ready``; 3 calls a round for the kernels, 10 for simulate at 24 reaches, 1 at
   256, 2 for jacfwd), the three chains interleaved round by round (7 rounds) so that they see the
   same load, and the median over the rounds of each round's fastest call; the outputs of the three
   chains are compared. Ratios: each chain / closed form, compile and run apart.

``os.getloadavg()`` is recorded before and after each part: the machine is shared, and times
taken under load are upper bounds. ``--quick``: tiny sizes (2 subjects × 4 reaches with 2 held
out, then S = 2 in the same process; ``max_steps=(5, 3)``; the two ``fk_jac_soa`` workloads on
1 000 postures), writes ``results/quick/movements.json`` (or ``$PMPJAX_BENCH_RESULTS``); it
takes 2 min at load 3–4, 3 min at 4–6, nearly all of it the fit's compilation (stage 2: 60–75
s). Usage: ``python benchmarks/movements.py [--quick] [--parts cold scaling kinematics] [--sizes
4 16 64] [--scaling-reaches 6] [--scaling-defaults] [--second-call-max 4]``; ``--tables FILE``
reprints a results file's tables. Writes ``results/movements.json``. The full run takes ≈ 35 min at load
2–5, 19 of them the S = 64 row (its run is linear in S, below).

Latest figures: 2026-12-06 03:15–03:49 UTC, 2-core AMD EPYC (KVM), no GPU, jax/jaxlib 0.10.2,
MuJoCo 4.0.1, float64; 33.5 min in all, load average 2.2 at the start and 4.1
at the end (other work shared the machine; per part below).

Cold fit + predict, 4 subjects × 20 reaches, 10 held out each (2026-12-06 18:04 UTC, this part
alone with ``--parts cold``; load 0.5 → 1.4; RODAS4 from one step per sample)::

    | | wall [s] | compile [s] | run [s] |
    |---|---:|---:|---:|
    | process (interpreter start to exit) | 73.5 | | |
    | imports (jax, pmpjax, fitting) | 0.7 | | |
    | chain + recordings | 0.8 | | |
    | · stage1 (call 1) | 7.1 | 7.0 | 0.1 |
    | · stage2 (call 2) | 45.0 | 31.9 | 13.1 |
    | fit_movements | 53.8 | 40.0 | 13.8 |
    | predict_movements | 17.1 | 16.8 | 0.2 |
    | **fit + predict** | **70.8** | 56.8 | 14.0 |

    71 s against the 300 s target (met); 80 % of it compilation. Every subject converged at one
    step per sample (stage-2 iterations 21–33; stage 1 61–100, three at the cap), integration
    error 0.0018–0.0061° (against twice the steps; the tolerance is 0.01°); 40 of 40 held-out
    reaches found, median held-out RMSE 0.22° against the pseudo-inverse's 3.5°; fitted τ 0.3–7 %
    above the truth, τ0 1–6 % below. The code before, at two steps per sample, in the same
    conditions right after (load 1.1 → 1.6): fit + predict 79.3 s, stage 2 24.5 s run (stage-2
    iterations 31 against 33 on one subject, the others the same; integration error
    0.0002–0.0005°; τ's relative error within 0.0003 and the held-out RMSE within 0.0001° of
    now); ``predict_movements`` now compiles 4 s longer (it simulates again at two steps the
    reaches whose embedded error estimate is above ``simulate``'s tolerance). Earlier run of the
    full benchmark (03:15, load 1.9 → 2.8, two steps per sample): 137 s.

Batch scaling, 6 reaches per subject, steps held at 2 (03:15–03:49, before one step per sample
became the default)::

    | S | 1st call [s] | compile [s] | run [s] | run/subject [s] | 1st call/subject [s] | iter. | run/iter. [s] | load |
    |---:|---:|---:|---:|---:|---:|---:|---:|---|
    | 4 | 126.8 | 62.0 | 73.7 (2nd call) | 18.43 | 31.70 | 51.0 | 0.361 | 2.8→3.3 |
    | 16 | 188.9 | 66.2 | 122.7 | 7.67 | 11.81 | 33.1 | 0.232 | 3.3→4.4 |
    | 64 | 1133.2 | 67.8 | 1065.4 | 16.65 | 17.71 | 41.2 | 0.404 | 4.4→5.1 |

    (run: the 2nd call at S = 4, where the 1st call less its compile spans was 64.8 s; above it
    the 1st call less its compile spans; iter.: stage-2 iterations per subject, mean. Every
    subject converged; largest integration error 0.0015°, 0.77°, 0.94°.)

    Compilation (62–68 s whatever S) is amortised: per subject with it, 31.7 s at S = 4, 11.8 s
    at 16, 17.7 s at 64 (1.8× less at 64 than at 4). The run is not: ``fit_movements`` maps its
    subjects one after another inside one compiled call (``lax.map``, each subject a batch of 8
    reaches), so its run time is the sum of the subjects' fits and the run per subject does not
    fall with S (18.4, 7.7, 16.7 s; per stage-2 iteration 0.36, 0.23, 0.40 s). The rows differ by
    which subjects they hold (S = 4: P01 and P03 take 66 and 69 stage-2 iterations) and by the
    load (S = 64 ran at 4.4–5.1). Stage 2 is over 99 % of the run; stage 1 takes 0.1–1.4 s even
    though it stops at its 100-iteration cap on 46 of the 64 subjects. Two of the 64 (P16, P45)
    fit τ to ≈ 0 (−99.98 %, −100 %) with an integration error of 0.77° and 0.94° at 2 steps per
    sample, and report converged; with the library's doubling, P16 fitted alone (the same data)
    goes through stage 2 at 2, 4, 8, 16 and 32 steps per sample, each a new compile, takes 441 s
    and stops at the iteration cap with τ = 7e-8 s and 0.35° — in a batch, every subject would
    repeat those rounds.

Kinematics (2026-12-06 07:50 UTC, the same machine, this part alone with ``--parts kinematics``; load
4.01 → 5.72; JVPs: the derivative along each joint; simulate: RODAS4; jacfwd: 22 parameters;
compile: lower + XLA; ratios: the chain / closed form)::

    | workload | chain | compile [s] | run [ms] | median [ms] | compile ratio | run ratio | median ratio |
    |---|---|---:|---:|---:|---:|---:|---:|
    | fk_jac_soa, 10⁴ postures | closed form | 0.02 + 0.27 | 0.35 | 0.85 |  |  |  |
    | fk_jac_soa, 10⁴ postures | MjcfChain | 0.02 + 0.22 | 0.51 | 0.66 | 0.81 | 1.46 | 0.78 |
    | fk_jac_soa, 10⁴ postures | MJX-style | 0.03 + 0.50 | 3.26 | 3.36 | 1.82 | 9.29 | 3.96 |
    | fk_jac_soa + JVPs, 10⁴ postures | closed form | 0.07 + 0.63 | 1.64 | 1.79 |  |  |  |
    | fk_jac_soa + JVPs, 10⁴ postures | MjcfChain | 0.06 + 0.58 | 1.87 | 1.92 | 0.91 | 1.14 | 1.07 |
    | fk_jac_soa + JVPs, 10⁴ postures | MJX-style | 0.17 + 0.65 | 11.85 | 12.18 | 1.18 | 7.21 | 6.81 |
    | simulate, 24 reaches | closed form | 1.22 + 6.09 | 13.70 | 14.71 |  |  |  |
    | simulate, 24 reaches | MjcfChain | 1.06 + 6.41 | 13.74 | 15.83 | 1.02 | 1.00 | 1.08 |
    | simulate, 24 reaches | MJX-style | 1.34 + 9.30 | 26.77 | 30.17 | 1.45 | 1.95 | 2.05 |
    | simulate, 256 reaches | closed form | 1.16 + 6.68 | 283.29 | 283.90 |  |  |  |
    | simulate, 256 reaches | MjcfChain | 1.09 + 6.59 | 282.29 | 283.72 | 0.98 | 1.00 | 1.00 |
    | simulate, 256 reaches | MJX-style | 1.24 + 8.96 | 340.07 | 342.30 | 1.30 | 1.20 | 1.21 |
    | jacfwd of simulate, 24 reaches | closed form | 4.67 + 31.32 | 385.20 | 395.33 |  |  |  |
    | jacfwd of simulate, 24 reaches | MjcfChain | 5.46 + 72.42 | 378.50 | 383.98 | 2.16 | 0.98 | 0.97 |
    | jacfwd of simulate, 24 reaches | MJX-style | 6.77 + 50.49 | 629.06 | 644.32 | 1.59 | 1.63 | 1.63 |

    x and J agree with the closed form to 1.1e-16 (MjcfChain) and 2.8e-16 (MJX-style), the simulated
    trajectories to ≤ 8.9e-16 rad and their Jacobians to 2.7e-16; all 256 reaches SUCCESSFUL.
    MjcfChain costs what the closed form costs: in ``pj.simulate`` with RODAS4 1.00× at 24 reaches
    (median over the rounds 1.08×) and 1.00× at 256, the forward-mode Jacobian of the simulation
    (stage 2's work per iteration) 0.98×, the kernel with its derivative along each joint 1.14×
    (median 1.07×); compilation 0.8–1.0× the closed form's (2.2× for jacfwd in this run, 1.02× in
    a second run). The kernel alone reads 1.46× here from one fast round of the closed form (0.35
    ms; its other rounds 0.44–1.28 ms, MjcfChain's 0.51–0.89 ms); its median is 0.78×. A second
    run (07:39 UTC, load 5.6 → 4.7) gave 0.96, 0.90, 0.98, 0.72 and 0.98 (fastest calls) and
    0.90, 1.01, 0.96, 1.02 and 0.97 (medians) for the five workloads. The MJX-style chain stays
    1.6–2.0× at 24 reaches and in jacfwd.
"""

from __future__ import annotations

import time

_T_START = time.perf_counter()

import argparse  # noqa: E402
import json  # noqa: E402
import os  # noqa: E402
import pickle  # noqa: E402
import platform  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _baselines as bl  # noqa: E402

import fitting  # noqa: E402
import pmpjax as pj  # noqa: E402
from fitting.internal import movement_fit_module as F  # noqa: E402
from pmpjax.internal import pytree_dataclass, sincos, site_jacobians, static_field  # noqa: E402

_T_IMPORTED = time.perf_counter()

HERE = Path(__file__).resolve().parent
ARM = Path(pj.__file__).parent / "data" / "examples" / "arm5.xml"
SITE = "hand"
FS = 100.0  # [Hz]
DT = 5e-4  # [s] RK4 step of the data
NOISE_DEG = 0.2
LEAD = 0.5  # [s] at rest before the first target
HOLD = (1.0, 1.4)  # [s] reach durations
X_HOME = (0.35, 0.0, -0.15)  # [m]
REACH = (0.10, 0.15)  # [m] target distance from home
Q_REST_DEG = (25.0, 12.0, 25.0, 68.0, 5.0)
SEED = 2033
BUDGET_S = 300.0  # the cold fit + predict target on two cores
#: arm5.xml's joint ranges [deg] (postures for the kinematics timing)
RANGES_DEG = ((-60, 180), (-30, 150), (-90, 90), (0, 150), (-70, 80))


def load():
    return round(os.getloadavg()[0], 2)


def log(msg):
    print(f"[{time.strftime('%H:%M:%S')} load {load():.1f}] {msg}", flush=True)


# --- synthetic subjects ----------------------------------------------------------------------


def draw_subject(rng):
    """A subject's truth: KJ (5, 5) SPD, trace 5; q_rest (5,) [rad]; τ, τ0 [s]."""
    lam = np.exp(rng.uniform(-1.2, 1.2, 5))
    Q, _ = np.linalg.qr(rng.standard_normal((5, 5)))
    KJ = (Q * (5.0 * lam / lam.sum())) @ Q.T
    return dict(KJ=0.5 * (KJ + KJ.T), q_rest=np.deg2rad(np.asarray(Q_REST_DEG) + rng.uniform(-8.0, 8.0, 5)),
                tau0=float(rng.uniform(0.09, 0.13)), tau=float(rng.uniform(0.08, 0.11)))


def targets_and_holds(rng, n_reaches):
    """``n_reaches`` targets (out, home, out, ...) and durations on the sampling clock (as
    make_example.py)."""
    home = np.asarray(X_HOME)
    out = []
    while len(out) < -(-n_reaches // 2):
        u = rng.standard_normal(3)
        u /= np.linalg.norm(u)
        x = home + rng.uniform(*REACH) * u
        if x[0] >= 0.28 and np.linalg.norm(x) <= 0.52:
            out.append(x)
    targets = np.stack([p for x in out for p in (x, home)])[:n_reaches]
    holds = rng.integers(round(HOLD[0] * FS), round(HOLD[1] * FS) + 1, size=n_reaches) / FS
    return targets, holds


def make_subjects(chain, S: int, trials: list[int], tag: int) -> dict:
    """``S`` subjects (truth drawn from seed ``[SEED, s]``), each with one continuous trial per
    entry of ``trials`` (its reach count; seeds ``[SEED, tag, s, trial]``). Every reach is one
    ``pj.simulate`` of all S subjects at once."""
    truth = [draw_subject(np.random.default_rng([SEED, s])) for s in range(S)]
    KJ = np.stack([t["KJ"] for t in truth])
    q_rest = np.stack([t["q_rest"] for t in truth])
    tau = np.array([t["tau"] for t in truth])
    tau0 = np.array([t["tau0"] for t in truth])
    eq = pj.equilibrium_posture(chain, KJ, q_rest, np.broadcast_to(np.asarray(X_HOME), (S, 3)))
    if not np.all(np.asarray(eq.converged)):
        raise RuntimeError("no equilibrium posture at home for some subject")
    q_home = np.asarray(eq.q)
    model = pj.Lambda0PMP(chain, KJ=KJ, q_rest=q_rest, W=pj.damping_from_stiffness(KJ, tau0))
    planner = pj.ArimotoPlanner(k=None, tau=tau, tau0=tau0)
    every = round(1.0 / (FS * DT))
    recs = [[] for _ in range(S)]
    for trial, n_reaches in enumerate(trials, 1):
        rngs = [np.random.default_rng([SEED, tag, s, trial]) for s in range(S)]
        plan = [targets_and_holds(r, n_reaches) for r in rngs]
        parts = [[np.tile(q_home[s], (round(LEAD * FS), 1))] for s in range(S)]
        q = q_home.copy()
        for k in range(n_reaches):
            target = np.stack([p[0][k] for p in plan])
            tr = pj.simulate(model, planner, q, target, duration=HOLD[1], dt=DT, saveat=pj.SaveAt(every=every))
            if not np.all(np.asarray(tr.ok)):
                raise RuntimeError(f"simulation failed (trial {trial}, reach {k + 1})")
            qs = np.asarray(tr.q)
            for s in range(S):
                m = round(plan[s][1][k] * FS)
                parts[s].append(qs[s, :m])
                q[s] = qs[s, m]
        for s in range(S):
            qq = np.concatenate(parts[s] + [q[s][None]])
            qq = qq + np.deg2rad(NOISE_DEG) * rngs[s].standard_normal(qq.shape)
            recs[s].append((f"P{s + 1:02d}_trial{trial}", np.arange(qq.shape[0]) / FS, qq))
    return dict(joint_names=chain.joint_names, truth=truth, q_home=q_home, recordings=recs, trials=list(trials))


def recordings(data, subjects, trials) -> list:
    """``pj.JointRecording`` objects of ``subjects`` (indices) and ``trials`` (1-based)."""
    return [pj.JointRecording(f"P{s + 1:02d}", name, t, q, data["joint_names"])
            for s in subjects for k, (name, t, q) in enumerate(data["recordings"][s], 1) if k in trials]


# --- the timed worker processes ----------------------------------------------------------------


def instrument_stages() -> list:
    """Time fitting's private stage functions (wall, blocking on the result, and the compile
    spans inside) by wrapping them in this process; returns the list the calls are appended to."""

    calls = []
    for name in ("_stage1", "_identifiability", "_stage2"):
        orig = getattr(F, name)

        def wrapped(*a, _orig=orig, _name=name, **k):
            t_wall, p0 = time.time(), time.perf_counter()
            out = jax.block_until_ready(_orig(*a, **k))
            calls.append(dict(stage=_name.lstrip("_"), wall_s=time.perf_counter() - p0,
                              compile_s=bl.compile_seconds(t_wall)))
            return out

        setattr(F, name, wrapped)
    return calls


def timed(fn, *a, **k):
    t_wall, p0 = time.time(), time.perf_counter()
    with bl.CpuClock() as clk:
        out = fn(*a, **k)
    return out, dict(wall_s=time.perf_counter() - p0, compile_s=bl.compile_seconds(t_wall), cores=clk.cores)


def fit_facts(fit, data, subjects) -> dict:
    truth = [data["truth"][s] for s in subjects]
    return dict(
        converged=[bool(v) for v in fit.converged], status=fit.messages, n_reaches=fit.n_reaches.tolist(),
        lm_steps=fit.lm_steps.tolist(), steps_per_sample=fit.steps_per_sample, solver=fit.solver,
        integration_error_deg=fit.integration_error_deg.tolist(), train_rmse_deg=fit.rmse_deg.tolist(),
        tau_rel_err=[float(fit.tau[a] / t["tau"] - 1) for a, t in enumerate(truth)],
        tau0_rel_err=[float(fit.tau0[a] / t["tau0"] - 1) for a, t in enumerate(truth)],
        unidentified=[list(map(list, u)) for u in fit.unidentified])


def job_cold(path) -> dict:
    p0 = time.perf_counter()
    with open(path, "rb") as f:
        data = pickle.load(f)
    chain = pj.MjcfChain(ARM, SITE)
    S, ntr = len(data["truth"]), len(data["trials"]) - 1
    train = recordings(data, range(S), range(1, ntr + 1))
    test = recordings(data, range(S), [ntr + 1])
    setup = time.perf_counter() - p0
    stages = instrument_stages()
    fit, t_fit = timed(fitting.fit_movements, chain, train, **_fit_options())
    pred, t_pred = timed(fitting.predict_movements, fit, test)
    summ = pred.summary()[-1]
    return dict(
        import_s=_T_IMPORTED - _T_START, setup_s=setup, fit=t_fit, predict=t_pred, stages=list(stages),
        fit_predict_s=t_fit["wall_s"] + t_pred["wall_s"], subjects=S,
        train_reaches_per_subject=sum(data["trials"][:-1]), held_out_reaches_per_subject=data["trials"][-1],
        **fit_facts(fit, data, range(S)),
        held_out=dict(found=len(pred), of=data["trials"][-1] * S, median_rmse_deg=summ["model_median_rmse [deg]"],
                      pinv_median_rmse_deg=summ["pinv_minjerk_median_rmse [deg]"],
                      median_final_deg=summ["model_median_final [deg]"]))


def job_scaling(path, S: int, calls: int, hold_steps: bool) -> dict:

    if hold_steps:  # no doubling of the step count: every S does the same work per subject
        F.MAX_STEPS_PER_SAMPLE = F.STEPS_PER_SAMPLE
    with open(path, "rb") as f:
        data = pickle.load(f)
    chain = pj.MjcfChain(ARM, SITE)
    train = recordings(data, range(S), [1])
    stages = instrument_stages()
    fit, first = timed(fitting.fit_movements, chain, train, **_fit_options())
    first["stages"], stages[:] = list(stages), []
    out = dict(S=S, reaches_per_subject=data["trials"][0], first=first, steps_held=hold_steps,
               **fit_facts(fit, data, range(S)))
    if calls > 1:
        fit2, second = timed(fitting.fit_movements, chain, train, **_fit_options())
        second["stages"] = list(stages)
        out.update(second=second, same_result=bool(np.array_equal(fit.params, fit2.params, equal_nan=True)))
    return out


_OPTIONS: dict = {}


def _fit_options() -> dict:
    return dict(_OPTIONS)


def worker(args) -> dict:
    """Run ``args.jobs`` ("cold", "scaling:S") in this process."""
    bl.watch_compiles()
    if args.max_steps:
        _OPTIONS["max_steps"] = tuple(args.max_steps)
    out = dict(compile_cache=bool(jax.config.jax_enable_compilation_cache), scaling=[])
    for job in args.jobs:
        if job == "cold":
            out["cold"] = job_cold(args.data_cold)
        else:
            _, S, calls = job.split(":")
            out["scaling"].append(job_scaling(args.data_scaling, int(S), int(calls), not args.scaling_defaults))
    return out


def cold_env() -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("JAX_COMPILATION_CACHE_DIR", "PMPJAX_CACHE_DIR")}
    env["JAX_ENABLE_COMPILATION_CACHE"] = "false"
    return env


def run_worker(jobs: list[str], data: dict, max_steps, scaling_defaults: bool = False) -> dict:
    """Run ``jobs`` in a fresh process of this script (no compilation cache); returns its JSON
    with ``process_wall_s``, the process's whole wall time."""
    with tempfile.NamedTemporaryFile(suffix=".json", delete=False) as f:
        out = f.name
    cmd = [sys.executable, os.path.abspath(__file__), "--worker", *jobs, "--out", out]
    cmd += [a for k in ("cold", "scaling") if k in data for a in (f"--data-{k}", data[k])]
    if max_steps:
        cmd += ["--max-steps", *map(str, max_steps)]
    if scaling_defaults:
        cmd += ["--scaling-defaults"]
    l0, p0 = load(), time.perf_counter()
    proc = subprocess.run(cmd, env=cold_env(), cwd=HERE.parent)
    wall = time.perf_counter() - p0
    if proc.returncode != 0:
        raise RuntimeError(f"worker {jobs} failed with exit code {proc.returncode}")
    with open(out) as f:
        res = json.load(f)
    os.unlink(out)
    res.update(process_wall_s=wall, load_start=l0, load_end=load())
    return res


# --- parts 1 and 2 -----------------------------------------------------------------------------


def fits(args, tmp) -> tuple:
    """The cold fit + predict and the batch-scaling rows: (cold result or None, scaling rows)."""
    chain = pj.MjcfChain(ARM, SITE)
    data = {}
    if "cold" in args.parts:
        S, trials = (2, [4, 2]) if args.quick else (4, [10, 10, 10])
        log(f"cold: generating {S} subjects, trials of {trials} reaches (the last held out) ...")
        data["cold"] = os.path.join(tmp, "cold.pkl")
        with open(data["cold"], "wb") as f:
            pickle.dump(make_subjects(chain, S, trials, tag=1), f)
    sizes = [2] if args.quick else args.sizes
    if "scaling" in args.parts:
        nr = 4 if args.quick else args.scaling_reaches
        log(f"scaling: generating {max(sizes)} subjects × {nr} reaches ...")
        data["scaling"] = os.path.join(tmp, "scaling.pkl")
        with open(data["scaling"], "wb") as f:
            pickle.dump(make_subjects(chain, max(sizes), [nr], tag=2), f)
    cold, rows = None, []
    if args.quick:  # one process for everything (the scaling fit then reuses the cold fit's compile)
        jobs = (["cold"] if "cold" in data else []) + ([f"scaling:{S}:2" for S in sizes] if "scaling" in data else [])
        log(f"quick: {jobs} in one fresh process ...")
        res = run_worker(jobs, data, args.max_steps, args.scaling_defaults)
        cold = res.get("cold")
        if cold:
            cold.update(process_wall_s=res["process_wall_s"], load_start=res["load_start"], load_end=res["load_end"])
        for r in res["scaling"]:
            r.update(load_start=res["load_start"], load_end=res["load_end"])
        return cold, res["scaling"]
    if "cold" in data:
        log("cold: fit_movements + predict_movements in a fresh process ...")
        res = run_worker(["cold"], data, args.max_steps)
        cold = res["cold"]
        cold.update(process_wall_s=res["process_wall_s"], load_start=res["load_start"], load_end=res["load_end"],
                    compile_cache=res["compile_cache"])
        log(f"  fit {cold['fit']['wall_s']:.0f} s (compile {cold['fit']['compile_s']:.0f} s), predict "
            f"{cold['predict']['wall_s']:.1f} s (compile {cold['predict']['compile_s']:.1f} s), process "
            f"{cold['process_wall_s']:.0f} s; converged {cold['converged']}")
    if "scaling" in data:
        for S in sizes:
            calls = 2 if S <= args.second_call_max else 1
            log(f"scaling: S = {S} in a fresh process ({calls} fit call{'s' * (calls > 1)}) ...")
            res = run_worker([f"scaling:{S}:{calls}"], data, args.max_steps, args.scaling_defaults)
            r = res["scaling"][0]
            r.update(process_wall_s=res["process_wall_s"], load_start=res["load_start"], load_end=res["load_end"],
                     compile_cache=res["compile_cache"])
            log(f"  first call {r['first']['wall_s']:.0f} s (compile {r['first']['compile_s']:.0f} s)"
                + (f", second {r['second']['wall_s']:.0f} s" if "second" in r else "")
                + f": run {run_seconds(r) / S:.2f} s per subject")
            rows.append(r)
    return cold, rows


# --- part 3: kinematics ------------------------------------------------------------------------


class ClosedFormArm5(pj.Chain):
    """arm5.xml's hand site in closed form: ``x = Ry(−q0) Rx(−q1) Rz(q2) ([0, 0, −L1] + Ry(−q3)
    ([0, 0, −L2] + Rx(q4) [0, 0, −L3]))`` (axes of the XML's joints: −y, −x, +z on the upper arm,
    −y at the elbow, +x at the wrist; offsets 0.30, 0.27, 0.08 m), expanded from the right with
    each sine and cosine once; the Jacobian's columns by differentiating each factor."""

    n, m = 5, 3
    lengths = (0.30, 0.27, 0.08)

    def fk_jac_soa(self, qc):
        L1, L2, L3 = self.lengths
        s, c = sincos(qc)
        s0, s1, s2, s3, s4 = (s[i] for i in range(5))
        c0, c1, c2, c3, c4 = (c[i] for i in range(5))
        w1, w2 = L3 * s4, -L2 - L3 * c4  # forearm + hand in the forearm frame (after the wrist)
        u0, u1, u2 = -s3 * w2, w1, c3 * w2 - L1  # the site in the upper-arm frame
        r0, r1 = c2 * u0 - s2 * u1, s2 * u0 + c2 * u1  # Rz(q2) u (r2 = u2)
        t1, t2 = c1 * r1 + s1 * u2, c1 * u2 - s1 * r1  # Rx(−q1) r (t0 = r0)
        x0, x2 = c0 * r0 - s0 * t2, s0 * r0 + c0 * t2  # Ry(−q0) t (x1 = t1)

        def abc(v0, v1, v2):  # Ry(−q0) Rx(−q1) Rz(q2) v
            a0, a1 = c2 * v0 - s2 * v1, s2 * v0 + c2 * v1
            b1, b2 = c1 * a1 + s1 * v2, c1 * v2 - s1 * a1
            return c0 * a0 - s0 * b2, b1, s0 * a0 + c0 * b2

        zero = jnp.zeros_like(s0)
        col0 = (-x2, zero, x0)  # −e_y × x
        col1 = (s0 * t1, t2, -c0 * t1)  # Ry(−q0) (−e_x × t)
        col2 = (s0 * s1 * r0 - c0 * r1, c1 * r0, -s0 * r1 - c0 * s1 * r0)  # Ry(−q0) Rx(−q1) (e_z × r)
        col3 = abc(-c3 * w2, zero, -s3 * w2)  # ∂u/∂q3
        col4 = abc(-s3 * L3 * s4, L3 * c4, c3 * L3 * s4)  # ∂u/∂q4 = Ry(−q3) (0, L3 c4, L3 s4)
        cols = (col0, col1, col2, col3, col4)
        J = jnp.stack([jnp.stack([col[i] for col in cols]) for i in range(3)])
        return jnp.stack([x0, t1, x2]), J


@pytree_dataclass
class MjxPathChain(pj.Chain):
    """An MJCF site through the MJX-style kinematics (``pmpjax._chains.mjcf.site_jacobians``:
    every body's frame as stacked 3×3 products, vmapped over postures; the model a pytree leaf)."""

    mjx_model: Any
    site_id: int = static_field(default=0)
    n: int = static_field(default=0)
    m: int = static_field(default=3)

    def fk_jac_soa(self, qc):
        batch = qc.shape[1:]
        x, J = site_jacobians(self.mjx_model, self.site_id, qc.reshape(self.n, -1).T)
        return x.T.reshape((3,) + batch), J.transpose(1, 2, 0).reshape((3, self.n) + batch)


def compile_apart(f, *a):
    p0 = time.perf_counter()
    lowered = jax.jit(f).lower(*a)
    p1 = time.perf_counter()
    compiled = lowered.compile()
    p2 = time.perf_counter()
    return compiled, p1 - p0, p2 - p1


def part_kinematics(args) -> dict:
    N, B, Bj = (1000, 16, 16) if args.quick else (10_000, 256, 24)
    rounds = 3 if args.quick else 7
    mj = pj.MjcfChain(ARM, SITE)
    chains = {"closed form": ClosedFormArm5(), "MjcfChain": mj,
              "MJX-style": MjxPathChain(mjx_model=mj.mjx_model, site_id=mj.site_id, n=mj.n)}
    lo, hi = np.deg2rad(np.array(RANGES_DEG, float)).T
    qc = jnp.asarray(np.random.default_rng(SEED).uniform(lo, hi, (N, 5)).T)  # (n, N)
    out = dict(date=time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), machine=bl.machine(), postures=N,
               reaches=B, jacobian_reaches=Bj, rounds=rounds, load_start=load())

    # agreement first (x and J at every posture)
    fk = jax.jit(lambda c, q: c.fk_jac_soa(q))
    ref = [np.asarray(v) for v in fk(chains["closed form"], qc)]
    agree = {}
    for name in ("MjcfChain", "MJX-style"):
        agree[name] = max(float(np.max(np.abs(np.asarray(g) - r))) for g, r in zip(fk(chains[name], qc), ref))
    log(f"kinematics: max |x, J| difference from the closed form: {agree}")
    assert agree["MjcfChain"] < 1e-12, agree
    out["fk_jac_max_abs_diff"] = agree

    # the fit's simulation: the first cold subject on normalised time, reaches of 1.2 s
    t = draw_subject(np.random.default_rng([SEED, 0]))
    T, samples, steps = 1.2, 50, 2
    KJ0 = jnp.asarray(t["KJ"])
    eq = pj.equilibrium_posture(mj, t["KJ"], t["q_rest"], np.asarray(X_HOME))
    targets, _ = targets_and_holds(np.random.default_rng([SEED, 3]), 2 * B)
    targets = jnp.asarray(targets[0::2][:B])
    q0 = jnp.broadcast_to(jnp.asarray(eq.q), (B, 5))
    ts = tuple(float(v) for v in np.linspace(0.0, 1.0, samples))
    iu = np.triu_indices(5)
    # 22 parameters, as the fit's: q_rest (5), a symmetric change of KJ (15), log τ, log τ0
    theta = jnp.concatenate([jnp.asarray(t["q_rest"]), jnp.zeros(15), jnp.log(jnp.array([t["tau"], t["tau0"]]))])

    def sim(chain, theta, q0, tg):
        dK = jnp.zeros((5, 5)).at[iu].set(theta[5:20])
        KJ = KJ0 + 0.5 * (dK + dK.T)
        tau, tau0 = jnp.exp(theta[20]) / T, jnp.exp(theta[21]) / T
        model = pj.Lambda0PMP(chain, KJ=KJ, q_rest=theta[:5], W=tau0 * KJ)
        planner = pj.ArimotoPlanner(k=None, tau=tau, tau0=tau0)
        tr = pj.simulate(model, planner, q0, tg, duration=1.0, dt=1.0 / ((samples - 1) * steps),
                         saveat=pj.SaveAt(ts=ts), solver="rodas4")
        return tr.q, tr.status

    def jac(chain, theta, q0, tg):
        return jax.jacfwd(lambda th: sim(chain, th, q0, tg)[0])(theta)

    def fk_lin(chain, q):  # x, J and their derivatives along each joint (RODAS4's Jacobian columns)
        out, lin = jax.linearize(chain.fk_jac_soa, q)
        return out, jax.vmap(lin)(jnp.broadcast_to(jnp.eye(5).reshape((5, 5, 1)), (5,) + q.shape))

    work = [("fk_jac_soa", f"{N} postures", lambda c, q: c.fk_jac_soa(q), (qc,), 3),
            ("fk_jac_soa + derivative along each joint", f"{N} postures", fk_lin, (qc,), 3)]
    if not args.quick:
        work += [("simulate rodas4", f"{Bj} reaches", sim, (theta, q0[:Bj], targets[:Bj]), 10),
                 ("simulate rodas4", f"{B} reaches", sim, (theta, q0, targets), 1),
                 ("jacfwd of simulate (22 parameters)", f"{Bj} reaches", jac, (theta, q0[:Bj], targets[:Bj]), 2)]
    res = {}
    for wname, size, f, a, reps in work:
        comp = {}
        for name, chain in chains.items():
            log(f"kinematics: compiling {wname} ({size}) with {name} ...")
            compiled, lo_s, co_s = compile_apart(f, chain, *a)
            comp[name] = dict(fn=compiled, lower_s=lo_s, compile_s=co_s)
        outs = {name: jax.block_until_ready(c["fn"](chains[name], *a)) for name, c in comp.items()}
        if not wname.startswith("fk_jac_soa"):
            r = np.asarray(outs["closed form"][0])
            for name in comp:
                if name != "closed form":
                    comp[name]["max_abs_diff"] = float(np.max(np.abs(np.asarray(outs[name][0]) - r)))
            if wname == "simulate rodas4":
                comp["closed form"]["successful"] = int(np.sum(np.asarray(outs["closed form"][1]) == 0))
        times = {name: [] for name in comp}
        for _ in range(rounds):  # interleaved: every chain sees the same load
            for name, c in comp.items():
                times[name].append(bl.best_of(lambda c=c, name=name: jax.block_until_ready(c["fn"](chains[name], *a)),
                                              reps))
        key = f"{wname}, {size}"
        res[key] = dict(size=size, chains={name: dict({k: v for k, v in c.items() if k != "fn"},
                                                        run_s=min(times[name]), runs_s=times[name])
                                             for name, c in comp.items()})
        base = res[key]["chains"]["closed form"]
        for name, r in res[key]["chains"].items():
            r["median_run_s"] = float(np.median(r["runs_s"]))
            if name != "closed form":
                r["compile_ratio"] = (r["lower_s"] + r["compile_s"]) / (base["lower_s"] + base["compile_s"])
                r["run_ratio"] = r["run_s"] / base["run_s"]
                r["median_run_ratio"] = r["median_run_s"] / float(np.median(base["runs_s"]))
        log(f"  {key}: run " + ", ".join(f"{n} {v['run_s'] * 1e3:.2f} ms" for n, v in res[key]["chains"].items()))
    out["workloads"] = res
    out["load_end"] = load()
    return out


# --- tables ------------------------------------------------------------------------------------


def table_cold(c) -> str:
    st = c["stages"]
    lines = ["| | wall [s] | compile [s] | run [s] |", "|---|---:|---:|---:|",
             f"| process (interpreter start to exit) | {c['process_wall_s']:.1f} | | |",
             f"| imports (jax, pmpjax, fitting) | {c['import_s']:.1f} | | |",
             f"| chain + recordings | {c['setup_s']:.1f} | | |"]
    for k, s in enumerate(st):
        lines.append(f"| · {s['stage']} (call {k + 1}) | {s['wall_s']:.1f} | {s['compile_s']:.1f} | "
                     f"{s['wall_s'] - s['compile_s']:.1f} |")
    for name in ("fit", "predict"):
        v = c[name]
        lines.append(f"| {name}_movements | {v['wall_s']:.1f} | {v['compile_s']:.1f} | "
                     f"{v['wall_s'] - v['compile_s']:.1f} |")
    comp = c["fit"]["compile_s"] + c["predict"]["compile_s"]
    lines.append(f"| **fit + predict** | **{c['fit_predict_s']:.1f}** | {comp:.1f} | {c['fit_predict_s'] - comp:.1f} |")
    return "\n".join(lines)


def run_seconds(r) -> float:
    """Run time of a scaling row: its second call, or (one call) the first call's wall time less
    its compile spans."""
    return r["second"]["wall_s"] if "second" in r else r["first"]["wall_s"] - r["first"]["compile_s"]


def per_iteration(r) -> float:
    """Run time per stage-2 Levenberg–Marquardt iteration (summed over the subjects) of a scaling
    row: the batch's cost with how hard each subject was to fit taken out."""
    return run_seconds(r) / max(1, sum(v[1] for v in r["lm_steps"]))


def table_scaling(rows) -> str:
    lines = ["| S | reaches/subject | 1st call [s] | compile [s] | 1st call − compile [s] | 2nd call [s] | "
             "run/subject [s] | 1st call/subject [s] | stage-2 LM iterations (mean) | run/iteration [s] | converged | "
             "integration error (max) [°] | load |",
             "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|---:|---|"]
    for r in rows:
        S, f = r["S"], r["first"]
        lm = np.mean([v[1] for v in r["lm_steps"]])
        second = f"{r['second']['wall_s']:.1f}" if "second" in r else "—"
        lines.append(f"| {S} | {r['reaches_per_subject']} | {f['wall_s']:.1f} | {f['compile_s']:.1f} | "
                     f"{f['wall_s'] - f['compile_s']:.1f} | {second} | {run_seconds(r) / S:.2f} | "
                     f"{f['wall_s'] / S:.2f} | {lm:.1f} | {per_iteration(r):.3f} | {sum(r['converged'])}/{S} | "
                     f"{max(r['integration_error_deg']):.2g} | "
                     f"{r['load_start']:.1f}→{r['load_end']:.1f} |")
    return "\n".join(lines)


#: shorter workload names for the table (the results file keeps the full ones)
_SHORT = {"fk_jac_soa + derivative along each joint": "fk_jac_soa + JVPs", "simulate rodas4": "simulate",
          "jacfwd of simulate (22 parameters)": "jacfwd of simulate", "10000 postures": "10⁴ postures"}


def table_kinematics(k) -> str:
    """compile: lower + XLA [s]; run: the fastest call [ms]; median: the median over the rounds of
    each round's fastest call [ms]; ratios: MjcfChain or MJX-style / closed form."""
    lines = ["| workload | chain | compile [s] | run [ms] | median [ms] | compile ratio | run ratio | median ratio |",
             "|---|---|---:|---:|---:|---:|---:|---:|"]
    for wname, res in k["workloads"].items():
        label = wname
        for a, b in _SHORT.items():
            label = label.replace(a, b)
        for name, r in res["chains"].items():
            med = float(np.median(r["runs_s"]))
            if name == "closed form":
                ratio = ("", "", "")
            else:
                base = float(np.median(res["chains"]["closed form"]["runs_s"]))
                ratio = (f"{r['compile_ratio']:.2f}", f"{r['run_ratio']:.2f}", f"{med / base:.2f}")
            lines.append(f"| {label} | {name} | {r['lower_s']:.2f} + {r['compile_s']:.2f} | "
                         f"{r['run_s'] * 1e3:.2f} | {med * 1e3:.2f} | {ratio[0]} | {ratio[1]} | {ratio[2]} |")
    return "\n".join(lines)


def versions() -> dict:
    import jaxlib
    import mujoco

    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                                cwd=HERE.parent).stdout.strip()
    except OSError:
        commit = None
    return dict(python=platform.python_version(), jax=jax.__version__, jaxlib=jaxlib.__version__,
                mujoco=mujoco.__version__, numpy=np.__version__, commit=commit)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="tiny sizes (under 2 min)")
    ap.add_argument("--parts", nargs="+", choices=("cold", "scaling", "kinematics"),
                    default=["cold", "scaling", "kinematics"])
    ap.add_argument("--sizes", type=int, nargs="+", default=[4, 16, 64], help="subjects per batch (scaling)")
    ap.add_argument("--scaling-reaches", type=int, default=6, help="reaches per subject (scaling)")
    ap.add_argument("--scaling-defaults", action="store_true",
                    help="scaling: let fit_movements double the step count (default: held at 2 per sample)")
    ap.add_argument("--second-call-max", type=int, default=4,
                    help="scaling: call the fit a second time (run alone) up to this many subjects")
    ap.add_argument("--max-steps", type=int, nargs=2, default=None, help="LM iterations (default: fit_movements')")
    ap.add_argument("--tables", metavar="JSON", help="print (and store) the tables of a results file, then exit")
    ap.add_argument("--worker", dest="jobs", nargs="+", help=argparse.SUPPRESS)
    ap.add_argument("--data-cold", help=argparse.SUPPRESS)
    ap.add_argument("--data-scaling", help=argparse.SUPPRESS)
    ap.add_argument("--out", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.jobs:
        res = worker(args)
        with open(args.out, "w") as f:
            json.dump(res, f)
        return 0
    if args.tables:
        with open(args.tables) as f:
            res = json.load(f)
        summarise(res)
        with open(args.tables, "w") as f:
            json.dump(res, f, indent=1)
        return 0
    if args.quick and args.max_steps is None:
        args.max_steps = [5, 3]
    t0 = time.perf_counter()
    res = dict(date=time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), machine=bl.machine(), versions=versions(),
               cpu_count=os.cpu_count(), load_start=load(), quick=args.quick,
               options=dict(max_steps=args.max_steps or "fit_movements defaults",
                            second_call_max=args.second_call_max, scaling_defaults=args.scaling_defaults))
    with tempfile.TemporaryDirectory() as tmp:
        cold, rows = fits(args, tmp) if {"cold", "scaling"} & set(args.parts) else (None, [])
    if cold:
        res["cold"] = cold
    if rows:
        res["batch_scaling"] = rows
    if "kinematics" in args.parts:
        res["kinematics"] = part_kinematics(args)
    res.update(load_end=load(), seconds=time.perf_counter() - t0)
    summarise(res)
    name = "movements"
    if args.quick and not os.environ.get("PMPJAX_BENCH_RESULTS"):
        os.environ["PMPJAX_BENCH_RESULTS"] = str(HERE / "results" / "quick")
    print(f"results -> {bl.write_results(name, res)}")
    return 0


def summarise(res) -> None:
    """Add ``tables``, ``ratios``, ``targets`` and ``scaling`` (the cost-versus-batch rows of
    ``python -m benchmarks``) to ``res`` from its measurements, and print the tables."""
    ratios, targets, scaling, tables = {}, {}, [], []
    opts = res["options"]
    c = res.get("cold")
    if c:
        tables.append(f"Cold fit + predict ({c['subjects']} subjects × {c['train_reaches_per_subject']} reaches, "
                      f"{c['held_out_reaches_per_subject']} held out each; load {c['load_start']}→{c['load_end']}):"
                      "\n\n" + table_cold(c))
        ratios["cold: 300 s budget / (fit + predict, compilation included)"] = BUDGET_S / c["fit_predict_s"]
        targets["cold: 300 s budget / (fit + predict, compilation included)"] = 1.0
    rows = res.get("batch_scaling")
    if rows:
        how = ("--quick: in one process with the cold fit, whose compiled stages it reuses" if res["quick"]
               else f"each S a fresh process; a second call up to S = {opts['second_call_max']}")
        how += "; steps per sample " + ("doubled as fit_movements does" if opts["scaling_defaults"] else "held at 2")
        tables.append(f"Batch scaling ({how}):\n\n" + table_scaling(rows))
        for r in rows:
            scaling.append(dict(series="fit_movements per subject (run)", B=r["S"], seconds=run_seconds(r) / r["S"]))
            scaling.append(dict(series="fit_movements per subject (compile + run)", B=r["S"],
                                seconds=r["first"]["wall_s"] / r["S"]))
        if len(rows) > 1:
            a, b = rows[0], rows[-1]
            key = f"scaling: per-subject cost S={a['S']} / S={b['S']}"
            ratios[key + " (run)"] = (run_seconds(a) / a["S"]) / (run_seconds(b) / b["S"])
            ratios[key + " (run per stage-2 iteration)"] = per_iteration(a) / per_iteration(b)
            ratios[key + " (compile + run)"] = (a["first"]["wall_s"] / a["S"]) / (b["first"]["wall_s"] / b["S"])
            targets[key + " (compile + run)"] = 1.0
    k = res.get("kinematics")
    if k:
        when = f"{k['date']}, " if "date" in k else ""
        tables.append(f"Kinematics ({when}this process; load {k['load_start']}→{k['load_end']}):\n\n"
                      + table_kinematics(k))
        for wname, w in k["workloads"].items():
            for name, r in w["chains"].items():
                if name != "closed form":
                    ratios[f"kinematics {wname}: {name} / closed form run time"] = r["run_ratio"]
                    ratios[f"kinematics {wname}: {name} / closed form compile time"] = r["compile_ratio"]
    res.update(ratios=ratios, targets=targets, scaling=scaling, tables=tables)
    print("\n\n".join([""] + tables))
    print(f"\nload {res['load_start']} → {res['load_end']}; {res['machine']}; jax {res['versions']['jax']}; "
          f"{res['seconds']:.0f} s in all")


if __name__ == "__main__":
    sys.exit(main())
