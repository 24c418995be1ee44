"""Benchmark: first-call (compile) and second-call (run) time of every public entry point that
compiles, at the sizes of the main job's ``--quick`` parts.

Each case runs in a fresh subprocess with JAX's persistent compilation cache off, calls the entry
point twice on the same inputs and reports ``first − second`` as compile time (tracing, lowering,
XLA compilation and one-off host work) and ``second`` as run time, against a budget of 3 s per
first call (the last column).

Usage: ``python benchmarks/compile_times.py [--only CASE ...] [--quick]`` (``--quick`` runs two
cheap cases and writes nothing); writes ``benchmarks/results/compile_times.json`` (date, machine,
versions, load average, the cases and the table as data).

Latest figures (2026-12-06 07:09–07:12 UTC, ``results/compile_times.json``; 2-core AMD EPYC (Zen 4)
KVM, no GPU, Python 3.11, JAX 0.10.2, float64; default cases, about 3 min). The machine is shared
with other developers' test runs: the load average rose from 2.6 at the start to 8.5 at the end
(above 4 from ``fit_donders`` on), so every time here is an upper bound and the later rows more so::

    case                     compile [s]   run [s]  within 3 s
    simulate                        1.85     0.005  yes
    simulate_final                  1.58     0.005  yes
    grad_simulate                  10.17     0.054  no
    equilibrium_posture             1.44     0.001  yes
    figure3_data                    2.39     0.012  yes
    fit_donders                     7.46     1.209  no
    estimate_ik_weights             5.10     0.229  no
    estimate_ik_weights_lm          4.65     2.213  no
    pointing_pipeline               3.87     9.043  no
    fit_time_constants             31.53     0.112  no
    arm_equilibrium                 5.71     0.009  no
    rollout_mjx                     9.12     0.034  no
    rollout_mujoco                  0.01     0.012  yes

Five cases meet the 3 s budget: ``simulate`` (both save modes), ``equilibrium_posture``,
``figure3_data`` and the C MuJoCo rollout. The fits and the gradient do not: ``fit_time_constants``
(31.5 s, under a load of 8) and ``grad_simulate`` (10.2 s) compile longest. ``pointing_pipeline``'s
second call took 9.0 s at a load of 6.7, so its split into compile and run is uncertain in this run.

What the compile time is: XLA's CPU compilation of graphs that hold the RK4 step (the chain, the
redundancy solve and the planner), forward-mode Jacobians of whole simulations (the fits) or MJX
kinematics inside Newton's loop; run times are milliseconds to seconds. Each entry point's docstring states its cost. What users can do: the
persistent compilation cache (the command line turns it on; a second run of the main job compiles
nothing), and keeping shapes fixed (batch sizes are bucketed to powers of two, so similar sizes
share a compile).

How the library keeps compiles down, each measured in paired fresh processes:

- ``pmpjax.fast_compile_jit`` (pmpjax/_base/compile.py) compiles the top-level calls of the fits,
  equilibria, MJX rollouts, sweeps and the RK4 stability check with XLA:CPU's legacy loop emitters
  instead of its MLIR fusion emitters: compile / run [s] equilibrium_posture 3.14 / 0.004 → 2.42 /
  0.002, fit_donders 17.4 / 2.0 → 12.7 / 2.0, estimate_ik_weights_lm 5.1 / 2.8 → 3.9 / 1.2,
  fit_time_constants 14.5 / 1.3 → 13.7 / 0.6, rollout_mjx 14.1 / 0.12 → 10.7 / 0.03; the main job
  (``reproduce --quick --no-cache``) 183 → 144 s wall. Not for Algorithm 1 of the IK weights (38 %
  slower runs) nor for ``simulate``'s kernel at large batches (30 % slower at B = 10 000).
- ``simulate`` below 1 025 movements runs its RK4 stages in a loop with the legacy emitters (XLA
  compile of the kernel 2.9–3.7 s unrolled, 1.7–1.9 s so; runs at B = 1 000 0.20–0.22 → 0.24–0.27
  s), so larger batches keep the unrolled kernel; derivatives through ``simulate`` take the JVP of
  the stage-loop variant, and the fits' Jacobians are traced once at the product batch of the
  tangents and items (``pmpjax.internal.forward_jacobians``): ``fit_time_constants`` tracing 9.8 →
  6.5 CPU s, XLA compile 27.2 → 21.5 CPU s, same optimum to 1e-15.
- Rejected: ``--xla_backend_optimization_level=0`` (compile 16.5 s instead of 21.5 s but runs 5–15×
  slower), ``=1``, ``--xla_llvm_disable_expensive_passes``, ``--xla_cpu_max_isa=AVX2``,
  ``--xla_cpu_use_thunk_runtime=false``, ``--xla_cpu_parallel_codegen_split_count=1`` (no gain).
"""

# ruff: noqa: E501  (the pasted result tables above)
from __future__ import annotations

import argparse
import os
import subprocess
import sys

BUDGET_S = 3.0

# Each case: (what it runs, setup code, call expression). Setup runs once; the call twice.
CASES: dict[str, tuple[str, str, str]] = {
    "simulate": (
        "pj.simulate, Figure 3 wrist, 8 targets, 0.4 s at dt = 1 ms, every step saved",
        "m = pj.Lambda0PMP(pj.Wrist(1.0), KJ=np.diag([.5, 1.5, 2.]), q_rest=np.deg2rad([5., 0, 0]), W=0.08 * np.diag([.5, 1.5, 2.]))\n"
        "tg = np.stack(list(pj.center_out_targets().values()))",
        "pj.simulate(m, pj.ArimotoPlanner(k=22.5, tau=0.08), np.deg2rad([5., 0, 0]), tg, duration=0.4).q.block_until_ready()",
    ),
    "simulate_final": (
        "pj.simulate, same problem, SaveAt(final=True)",
        "m = pj.Lambda0PMP(pj.Wrist(1.0), KJ=np.diag([.5, 1.5, 2.]), q_rest=np.deg2rad([5., 0, 0]), W=0.08 * np.diag([.5, 1.5, 2.]))\n"
        "tg = np.stack(list(pj.center_out_targets().values()))",
        "pj.simulate(m, pj.ArimotoPlanner(k=22.5, tau=0.08), np.deg2rad([5., 0, 0]), tg, duration=0.4, saveat=pj.SaveAt(final=True)).q.block_until_ready()",
    ),
    "grad_simulate": (
        "jax.grad of a path loss through pj.simulate w.r.t. KJ (Figure 3 problem, 8 targets)",
        "tg = np.stack(list(pj.center_out_targets().values()))\n"
        "def loss(KJ):\n"
        "    m = pj.Lambda0PMP(pj.Wrist(1.0), KJ=KJ, q_rest=np.deg2rad([5., 0, 0]), W=0.08 * KJ)\n"
        "    return jnp.sum(pj.simulate(m, pj.ArimotoPlanner(k=22.5, tau=0.08), np.deg2rad([5., 0, 0]), tg, duration=0.4, saveat=pj.SaveAt(every=20)).x ** 2)\n"
        "g = jax.jit(jax.grad(loss))",
        "g(jnp.diag(jnp.array([.5, 1.5, 2.]))).block_until_ready()",
    ),
    "equilibrium_posture": (
        "pj.equilibrium_posture, wrist, 64 targets",
        "tg = 0.2 * np.random.default_rng(0).uniform(-1, 1, (64, 2))",
        "pj.equilibrium_posture(pj.Wrist(1.0), np.diag([.5, 1.5, 2.]), np.deg2rad([5., 0, 0]), tg).q.block_until_ready()",
    ),
    "figure3_data": ("pj.figure3_data (main job part figure3)", "", "pj.figure3_data()"),
    "fit_donders": (
        "fitting.fit_donders, 6 Table subjects x 500 postures, NIO (main job part donders_nio)",
        "names, KJ, qr = pj.paper_subjects()\n"
        "rec = pj.synthetic_recordings(KJ, qr, 500, noise_deg=0.5, seed=0, names=names)",
        "fitting.fit_donders(pj.Wrist(), rec.pointing, rec.joint_angles, mask=rec.mask, n_starts=2)",
    ),
    "estimate_ik_weights": (
        "fitting.estimate_ik_weights, the IK paper's Figure 1 data, 100 repetitions",
        "q, x, J = fitting.ik_fig1_data(jax.random.PRNGKey(0), n_reps=100)",
        "fitting.estimate_ik_weights(q, x, J, gamma=0.6).w.block_until_ready()",
    ),
    "estimate_ik_weights_lm": (
        "fitting.estimate_ik_weights_lm, same data",
        "q, x, J = fitting.ik_fig1_data(jax.random.PRNGKey(0), n_reps=100)",
        "fitting.estimate_ik_weights_lm(q, x, J, gamma=0.6).w.block_until_ready()",
    ),
    "pointing_pipeline": (
        "fitting.analyze_pointing + predict_pointing, 2 subjects x 3 trials (main job --quick)",
        "exp = pj.synthetic_pointing_experiment(subjects=('subj1', 'subj4'), n_trials=3, target_spread=0.0, n_donders=64, seed=0)\n"
        "KJ, qr = exp.truth['KJ'], exp.truth['q_rest']",
        "fitting.predict_pointing(fitting.analyze_pointing(exp.recording), KJ, qr)",
    ),
    "fit_time_constants": (
        "fitting.fit_time_constants, 2 subjects x 3 trials (main job --quick)",
        "exp = pj.synthetic_pointing_experiment(subjects=('subj1', 'subj4'), n_trials=3, target_spread=0.0, n_donders=64, seed=0)\n"
        "an = fitting.analyze_pointing(exp.recording); KJ, qr = exp.truth['KJ'], exp.truth['q_rest']",
        "fitting.fit_time_constants(an, KJ, qr)",
    ),
    "arm_equilibrium": (
        "pj.arm_equilibrium, springy arm, 8 blends (MJX kinematics, Newton)",
        "arm = pj.load_arm(contacts=False); P = pj.default_primitives()\n"
        "a = np.random.default_rng(0).dirichlet(np.ones(4), 8)",
        "pj.arm_equilibrium(arm, pj.blend(a, P)).q.block_until_ready()",
    ),
    "rollout_mjx": (
        "pj.rollout backend='mjx', springy arm, 4 set-point runs x 200 steps",
        "arm = pj.load_arm(contacts=False); qs = np.broadcast_to(pj.default_primitives()[:, None], (4, 200, 6))",
        "pj.rollout(arm, qs, backend='mjx').q.block_until_ready()",
    ),
    "rollout_mujoco": (
        "pj.rollout backend='mujoco' (C MuJoCo, no compile), same runs",
        "arm = pj.load_arm(contacts=False); qs = np.broadcast_to(pj.default_primitives()[:, None], (4, 200, 6))",
        "pj.rollout(arm, qs, backend='mujoco').q",
    ),
}

CHILD = """
import time, numpy as np, jax, jax.numpy as jnp
jax.config.update("jax_enable_x64", True)
import pmpjax as pj, fitting
{setup}
t0 = time.perf_counter(); {call}; t1 = time.perf_counter(); {call}; t2 = time.perf_counter()
print("RESULT", t1 - t0, t2 - t1)
"""


def run_case(name: str) -> dict:
    what, setup, call = CASES[name]
    code = CHILD.format(setup=setup, call=call)
    env = {**os.environ, "JAX_ENABLE_COMPILATION_CACHE": "false", "MPLBACKEND": "Agg"}
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    line = next((ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT")), None)
    if proc.returncode or line is None:
        return {"case": name, "what": what, "error": (proc.stderr.strip().splitlines() or ["?"])[-1]}
    first, second = map(float, line.split()[1:])
    return {"case": name, "what": what, "first_s": first, "run_s": second, "compile_s": max(first - second, 0.0)}


def main(argv=None) -> int:
    import _baselines as bl

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", nargs="*")
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)
    names = args.only or (["equilibrium_posture", "rollout_mujoco"] if args.quick else list(CASES))
    out = bl.header({"budget_s": BUDGET_S, "cases": names, "compilation_cache": False})
    rows = []
    print(f"load average {os.getloadavg()[0]:.1f}", flush=True)
    print(f"{'case':24s} {'compile [s]':>11s} {'run [s]':>9s}  budget {BUDGET_S:g} s")
    lines = ["| case | compile [s] | run [s] | within 3 s |", "|---|---:|---:|---|"]
    for n in names:
        r = run_case(n)
        r["load"] = os.getloadavg()[0]
        rows.append(r)
        if "error" in r:
            print(f"{n:24s} ERROR {r['error']}", flush=True)
            lines.append(f"| {n} | error: {r['error']} | | |")
        else:
            ok = "yes" if r["compile_s"] <= BUDGET_S else "no"
            print(f"{n:24s} {r['compile_s']:11.2f} {r['run_s']:9.3f}  {ok}", flush=True)
            lines.append(f"| {n} | {r['compile_s']:.2f} | {r['run_s']:.3f} | {ok} |")
    out.update(rows=rows,
               ratios={f"budget/compile {r['case']}": BUDGET_S / max(r["compile_s"], 1e-3)
                       for r in rows if "compile_s" in r},
               targets={f"budget/compile {r['case']}": 1.0 for r in rows if "compile_s" in r},
               tables=["\n".join(lines)], load_end=bl.load_average())
    print("\n" + "\n".join(lines))
    print(f"load average {out['load_start'][0]:.1f} -> {out['load_end'][0]:.1f}")
    if not args.quick:
        print("wrote", bl.write_results("compile_times", out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
