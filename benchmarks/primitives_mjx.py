"""Forward rollouts of the springy Cog-like arm: MJX vs C MuJoCo's batch rollout vs a C loop.

Each rollout is 2 s (1000 steps of 2 ms) of the 6-DoF arm (contacts disabled, as for fits and
gradients) with the spring law ``τ = −K (θ − θ_set) − B θ̇`` applied every step; set-points differ
per arm. Compared in the same process, on the same model and inputs (final postures checked equal):

- ``mjx``: ``pmpjax.rollout(..., backend="mjx")`` — ``lax.scan`` over ``mjx.step``, ``vmap`` over
  arms; compile time measured apart (``.lower().compile()`` of the batch kernel);
- ``c1`` / ``c2``: ``pmpjax.rollout(..., backend="mujoco", nthread=1 | 2)`` — MuJoCo's own
  multi-threaded ``mujoco.rollout`` with the springs as affine actuators (no compile);
- ``loop``: the baseline, a single-threaded Python loop of ``mj_step`` writing ``qfrc_applied``.

Run times are the minimum of repeats (``block_until_ready`` for MJX); the Python loop is timed on
at most 64 arms (once when there are 64) and scaled linearly to B. Run:
``python benchmarks/primitives_mjx.py [--quick] [--repeats 3]`` (about 2 min on 2 cores; ``--quick``:
B = 1 and 64); writes ``benchmarks/results/primitives_mjx.json`` (date, machine, versions, load
average, parameters, one row per batch size and the table).

Latest figures (2026-12-06 07:25–07:27 UTC, ``results/primitives_mjx.json``; 2-core AMD EPYC (Zen 4)
KVM, no GPU, JAX 0.10.2, MuJoCo 4.0.1, float64; default sizes B = 1, 64, 1 024, 111 s). The machine
was shared with other developers' test runs (load average 8.1 at the start, 8.0 at the end, on 2
cores), so the times are upper bounds, and MuJoCo's second thread found no idle core::

    | B | steps | Python mj_step loop [s] | C 1 thread [s] | × loop | C 2 threads [s] | × loop | MJX compile [s] | MJX run [s] | × loop | MJX speed / C 2 threads |
    |---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|
    | 1 | 1000 | 0.005 | 0.008 | 0.58 | 0.008 | 0.57 | 7.7 | 0.025 | 0.19 | 0.34 |
    | 64 | 64000 | 0.939 | 0.302 | 3.11 | 0.303 | 3.10 | 9.3 | 0.376 | 2.50 | 0.81 |
    | 1024 | 1024000 | 7.498 | 5.460 | 1.37 | 5.688 | 1.32 | 12.3 | 7.020 | 1.07 | 0.81 |

MJX runs the arms at 0.34–0.81× the steps per second of MuJoCo's batch rollout and compiles its
batch kernel in 8–12 s. The Python loop's 64-arm figure is a single timing under that load (its
per-step rate is a third of the one-arm rate), so its ratios carry the load's noise.

Reading: on this CPU MJX is never the fastest. From 64 arms on MuJoCo's batch rollout wins: it
removes the Python overhead of the loop (one ``mj_step`` call per step) and runs the arms on both
cores when they are idle; for one arm the plain loop is faster (5 ms against 8 ms: the batch call's
fixed cost). MJX's step for this small arm is dominated by the per-op overhead of many tiny kernels
and costs a compile. MJX is for what it alone gives: ``jax.grad``/``vmap``/``jit`` through
rollouts.
"""

# ruff: noqa: E501  (the pasted result table above)
from __future__ import annotations

import argparse
import time

import jax

jax.config.update("jax_enable_x64", True)

import _baselines as bl  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import mujoco  # noqa: E402
import numpy as np  # noqa: E402

import pmpjax as pj  # noqa: E402
from pmpjax.internal import PROBE_PARK, Scripted, rollout_batch  # noqa: E402

STEPS = 1000  # 2 s at dt = 2 ms


def set_points(B: int) -> np.ndarray:
    rng = np.random.default_rng(0)
    P = np.asarray(pj.default_primitives())
    return np.broadcast_to((rng.dirichlet(np.ones(4), size=B) @ P)[:, None, :], (B, STEPS, 6)).copy()


def best_of(fn, repeats):
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def mjx_case(arm, q_set, repeats):
    """Compile and run the MJX batch kernel behind ``rollout(..., backend="mjx")``."""
    B = q_set.shape[0]
    q_set = jnp.asarray(q_set)
    K = jnp.broadcast_to(jnp.asarray(arm.K), (B, 6))
    Bd = jnp.broadcast_to(jnp.asarray(arm.B), (B, 6))
    q0 = q_set[:, 0]
    z = jnp.zeros((B, 6))
    probe = jnp.broadcast_to(jnp.asarray(PROBE_PARK), (B, STEPS, 3))
    force = jnp.zeros((B, STEPS, 3))
    ctrl = Scripted()
    c0 = jax.vmap(ctrl.init)(q0)
    args = (arm.mjx_model, arm.layout, ctrl, K, Bd, q0, z, q0, c0, (q_set, probe, force))
    t0 = time.perf_counter()
    compiled = rollout_batch.lower(*args).compile()
    compile_s = time.perf_counter() - t0
    dyn = args[:1] + args[2:]
    jax.block_until_ready(compiled(*dyn))
    run, out = best_of(lambda: jax.block_until_ready(compiled(*dyn)), repeats)
    return compile_s, run, np.asarray(out[1])


def loop_case(arm, q_set, repeats):
    """Baseline: one arm after another, ``mj_step`` in Python with the torque in ``qfrc_applied``."""
    m = arm.mj_model
    d = mujoco.MjData(m)
    K, Bd = arm.K, arm.B

    def run():
        out = []
        for qs in q_set:
            mujoco.mj_resetData(m, d)
            d.qpos[:] = qs[0]
            for k in range(STEPS):
                d.qfrc_applied[:] = -K * (d.qpos - qs[k]) - Bd * d.qvel
                mujoco.mj_step(m, d)
            out.append(d.qpos.copy())
        return np.array(out)

    return best_of(run, repeats)


def c_case(arm, q_set, nthread, repeats):
    return best_of(lambda: pj.rollout(arm, q_set, backend="mujoco", nthread=nthread).q_final, repeats)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="batch sizes 1 and 64 only")
    ap.add_argument("--repeats", type=int, default=3)
    a = ap.parse_args()
    sizes = (1, 64) if a.quick else (1, 64, 1024)
    out = bl.header({"sizes": list(sizes), "repeats": a.repeats, "steps_per_rollout": STEPS,
                     "loop_arms_timed": 64, "quick": a.quick})
    arm = pj.load_arm(contacts=False)
    out["parameters"]["dt_s"] = arm.dt
    rows = []
    for B in sizes:
        q_set = set_points(B)
        nl = min(B, 64)  # the Python loop is linear in B: time 64 arms and scale
        loop_s, q_loop = loop_case(arm, q_set[:nl], a.repeats if nl == 1 else 1)
        loop_s *= B / nl
        c1_s, q_c1 = c_case(arm, q_set, 1, a.repeats)
        c2_s, q_c2 = c_case(arm, q_set, 2, a.repeats)
        row = dict(batch=B, steps=B * STEPS, loop_s=loop_s, c1_s=c1_s, c2_s=c2_s)
        if B <= 64 or not a.quick:
            comp, run, q_mjx = mjx_case(arm, q_set, a.repeats)
            row.update(mjx_compile_s=comp, mjx_s=run)
            assert np.abs(q_mjx - q_c1).max() < 1e-10
        assert np.abs(q_c1[:nl] - q_loop).max() < 1e-10 and np.array_equal(q_c1, q_c2)
        for k in ("loop", "c1", "c2", "mjx"):
            if f"{k}_s" in row:
                row[f"{k}_steps_per_s"] = B * STEPS / row[f"{k}_s"]
                row[f"{k}_speedup_vs_loop"] = loop_s / row[f"{k}_s"]
        rows.append(row)
        mjx = (
            f" | MJX compile {row['mjx_compile_s']:6.1f} s run {row['mjx_s']:8.3f} s "
            f"{row['mjx_steps_per_s']:>10,.0f}/s ×{row['mjx_speedup_vs_loop']:.2f}"
            if "mjx_s" in row
            else ""
        )
        print(
            f"B={B:5d} | loop {loop_s:8.3f} s {row['loop_steps_per_s']:>10,.0f}/s"
            f" | C 1 thread {c1_s:8.3f} s {row['c1_steps_per_s']:>10,.0f}/s ×{row['c1_speedup_vs_loop']:.2f}"
            f" | C 2 threads {c2_s:8.3f} s {row['c2_steps_per_s']:>10,.0f}/s ×{row['c2_speedup_vs_loop']:.2f}" + mjx
        )
    lines = ["| B | steps | Python mj_step loop [s] | C 1 thread [s] | × loop | C 2 threads [s] | × loop | "
             "MJX compile [s] | MJX run [s] | × loop | MJX speed / C 2 threads |",
             "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        mjx = (f"{r['mjx_compile_s']:.1f} | {r['mjx_s']:.3f} | {r['mjx_speedup_vs_loop']:.2f} | "
               f"{r['c2_s'] / r['mjx_s']:.2f}" if "mjx_s" in r else " | | | ")
        lines.append(f"| {r['batch']} | {r['steps']} | {r['loop_s']:.3f} | {r['c1_s']:.3f} | "
                     f"{r['c1_speedup_vs_loop']:.2f} | {r['c2_s']:.3f} | {r['c2_speedup_vs_loop']:.2f} | {mjx} |")
    out.update(rows=rows, tables=["\n".join(lines)], load_end=bl.load_average())
    print("\n" + out["tables"][0])
    print(f"load average {out['load_start'][0]:.1f} -> {out['load_end'][0]:.1f}")
    print("results ->", bl.write_results("primitives_mjx", out))


if __name__ == "__main__":
    main()
