"""Batched MJX rollouts of the springy Cog-like arm vs the plain C ``mujoco.mj_step`` loop.

Each rollout is 2 s (1000 steps of 2 ms) of the 6-DoF arm (contacts disabled, as for fits and
gradients) with the spring law ``τ = −K (θ − θ_set) − B θ̇`` written into ``qfrc_applied`` every
step; set-points differ per arm. MJX: ``pmpjax._springy_arm.arm._rollout_batch`` (``lax.scan`` over
``mjx.step``, ``vmap`` over arms), compile time measured separately with ``.lower().compile()``,
run time = min over repeats with ``block_until_ready``. Baseline, same process and model: the C
loop in Python (set ``qfrc_applied``, ``mj_step``), one arm, then B arms one after another.

Run: ``python benchmarks/primitives_mjx.py [--quick]``; writes benchmarks/results/primitives_mjx.json.

Latest figures (2026-11-22, 2-core CPU, no GPU, other jobs running — load average ≈ 8, so
absolute times are inflated; ratios are taken in the same run):

    batch | MJX compile [s] | MJX run [s] | MJX steps/s | C loop [s] | C steps/s | MJX/C speed
    ------+-----------------+-------------+-------------+------------+-----------+------------
        1 |           105.5 |       0.323 |       3 095 |      0.041 |    24 544 |       0.13
       64 |           129.3 |       7.292 |       8 776 |      0.791 |    80 941 |       0.11
     1024 |            48.0 |     160.159 |       6 394 |     10.045 |   101 946 |       0.06

(C loop for B = 1024 timed on 64 arms and scaled linearly.) On this CPU MJX loses everywhere:
the C loop, even driven from Python one step at a time, is 8–16× faster per step. MJX's step for
this 6-DoF arm is dominated by per-op overhead of many tiny kernels (kinematics scans, the
constraint/sensor pipeline); batching helps only up to ~64 arms (3.1k → 8.8k steps/s) and then
memory traffic of the (B, ·) state dominates. Compilation (48–130 s under load; ~3× less on an
idle machine) costs more than 100 000 C steps. What MJX buys is jit/vmap/grad composition: exact
reverse-mode gradients through rollouts (``tests/test_primitives.py``) and one code path for
batches — not speed on a 2-core CPU; use C MuJoCo for plain forward simulation there.
"""

from __future__ import annotations

import argparse
import json
import os
import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from pmpjax import _arm  # noqa: E402
from pmpjax._springy_arm.primitives import default_primitives  # noqa: E402

STEPS = 1000  # 2 s at dt = 2 ms


def mjx_case(arm, B, repeats):
    rng = np.random.default_rng(0)
    P = np.asarray(default_primitives())
    alpha = rng.dirichlet(np.ones(4), size=B)
    q_set = jnp.asarray(np.broadcast_to((alpha @ P)[:, None, :], (B, STEPS, 6)))
    K = jnp.broadcast_to(jnp.asarray(arm.K), (B, 6))
    Bd = jnp.broadcast_to(jnp.asarray(arm.B), (B, 6))
    q0 = jnp.broadcast_to(jnp.asarray(arm.q_rest), (B, 6))
    z = jnp.zeros((B, 6))
    probe = jnp.broadcast_to(jnp.asarray(_arm.PROBE_PARK), (B, STEPS, 3))
    force = jnp.zeros((B, STEPS, 3))
    ctrl = _arm.Scripted()
    c0 = jax.vmap(ctrl.init)(q0)
    args = (arm.mjx_model, arm.layout, ctrl, K, Bd, q0, z, q0, c0, (q_set, probe, force))
    t0 = time.perf_counter()
    compiled = _arm._rollout_batch.lower(*args).compile()
    compile_s = time.perf_counter() - t0
    dyn = args[:1] + args[2:]
    jax.block_until_ready(compiled(*dyn))
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(compiled(*dyn))
        best = min(best, time.perf_counter() - t0)
    return compile_s, best, np.asarray(q_set[:, 0])


def c_case(arm, q_sets, repeats):
    m = arm.mj_model
    d = mujoco.MjData(m)
    K, Bd = arm.K, arm.B
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        for q_set in q_sets:
            mujoco.mj_resetData(m, d)
            d.qpos[:] = arm.q_rest
            for _ in range(STEPS):
                d.qfrc_applied[:] = -K * (d.qpos - q_set) - Bd * d.qvel
                mujoco.mj_step(m, d)
        best = min(best, time.perf_counter() - t0)
    return best


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="batch sizes 1 and 64 only")
    ap.add_argument("--repeats", type=int, default=3)
    a = ap.parse_args()
    arm = _arm.load_arm(contacts=False)
    sizes = (1, 64) if a.quick else (1, 64, 1024)
    rows = []
    c1 = None
    for B in sizes:
        comp, run, q_sets = mjx_case(arm, B, a.repeats)
        # C baseline: B arms sequentially (for B = 1024 time 64 arms and scale, it is linear).
        nc = min(B, 64)
        c_run = c_case(arm, q_sets[:nc], 1 if nc > 1 else a.repeats) * B / nc
        if B == 1:
            c1 = c_run
        row = dict(
            batch=B,
            steps=B * STEPS,
            mjx_compile_s=comp,
            mjx_run_s=run,
            mjx_steps_per_s=B * STEPS / run,
            c_run_s=c_run,
            c_steps_per_s=B * STEPS / c_run,
            mjx_over_c_speed=c_run / run,
        )
        rows.append(row)
        print(
            f"B={B:5d}  MJX compile {comp:6.1f} s  run {run:8.3f} s  "
            f"{row['mjx_steps_per_s']:10.0f} steps/s | C loop {c_run:8.3f} s  "
            f"{row['c_steps_per_s']:10.0f} steps/s | MJX/C speed {row['mjx_over_c_speed']:.2f}"
        )
    out = dict(
        date="2026-11-22",
        machine="2-core CPU, no GPU (shared, loaded)",
        steps_per_rollout=STEPS,
        dt=arm.dt,
        c_one_arm_s=c1,
        rows=rows,
    )
    os.makedirs(os.path.join(os.path.dirname(__file__), "results"), exist_ok=True)
    with open(os.path.join(os.path.dirname(__file__), "results", "primitives_mjx.json"), "w") as f:
        json.dump(out, f, indent=2)


if __name__ == "__main__":
    main()
