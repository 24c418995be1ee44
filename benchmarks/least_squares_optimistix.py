"""Benchmark: the hand-written LM (``fitting.least_squares``) vs ``optimistix.least_squares``
(Levenberg–Marquardt) on the Donders NIO fit, and implicit gradients of the fitted optimum.

Problem: the residual of ``fitting.fit_donders`` (torsion of implicit λ0-PMP equilibria, 8
parameters) for S synthetic subjects (Table 1–2 subjects, 500 postures, 0.5° noise), 2 starts each,
all vmapped in one jit (as ``fit_donders`` does per chunk). Both solvers get the same residual, the
same starts and at most 100 steps; compile time apart (``.lower().compile()``), run time the minimum
of repeats with ``block_until_ready``. Then the gradient of a fitted parameter with respect to the
observed postures of one subject: optimistix by its ``ImplicitAdjoint`` (reverse mode); the
hand-written LM's ``while_loop`` has no reverse mode, so its only route is forward mode through the
iterations (``jax.jacfwd``, one pass per observed posture coordinate: not attempted at 1 500 inputs).

Usage: ``python benchmarks/least_squares_optimistix.py [--subjects 16] [--repeats 2]`` (about 3 min
on 2 cores); writes ``benchmarks/results/least_squares_optimistix.json`` (date, machine, versions,
load average, parameters, both solvers' figures and the table).

Latest figures (2026-12-06 07:23–07:25 UTC, ``results/least_squares_optimistix.json``; 2-core AMD
EPYC (Zen 4) KVM, no GPU, JAX 0.10.2, optimistix 0.1.0, equinox 0.13.8, float64; default size, 16
subjects, 167 s). The machine was shared with other developers' test runs (load average 8.6 at the
start, 8.2 at the end, on 2 cores), so the times are upper bounds; the ratios are taken within the
run::

    | solver | compile [s] | run [s] | ms/subject | median steps | converged |
    |---|---:|---:|---:|---:|---:|
    | fitting.least_squares | 16.5 | 3.09 | 193.3 | 18.5 | 1.000 |
    | optimistix LM | 36.3 | 11.48 | 717.8 | 44.0 | 1.000 |

    best-start cost, max relative difference: 1.83e-15
    optimistix d q_rest[PS] / d postures (1500 inputs, reverse mode): compile 33.6 s, run 0.187 s;
        directional -3.265424e-04 vs central difference -3.265781e-04

Decision (written in ``fitting/_optimise/least_squares.py``): keep the hand-written LM (2.2× faster
to compile, 3.7× faster to run, the same optima); optimistix's implicit gradients work but no fit
needs them.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import optimistix as optx  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _baselines as bl  # noqa: E402

import pmpjax as pj  # noqa: E402
from fitting import least_squares  # noqa: E402
from fitting.internal import nio_residual, nio_starts  # noqa: E402

N_POST, N_STARTS, MAX_STEPS = 500, 2, 100


def data(S):
    names, K, q = pj.paper_subjects()
    idx = np.arange(S) % 6
    rec = pj.synthetic_recordings(K[idx], q[idx], N_POST, noise_deg=0.5, seed=3)
    x, qo = rec.pointing, rec.joint_angles
    th0 = nio_starts(qo.mean(1), 5, 3, N_STARTS, 0)
    return jnp.asarray(th0), jnp.asarray(x), jnp.asarray(qo), jnp.ones(x.shape[:2])


RESID = nio_residual(pj.Wrist(), 5, 4.0, "torsion", 1e-10)


@jax.jit
def ours(th0, x, q, w):
    def one(t, x, q, w):
        r = least_squares(RESID, t, (x, q, w), max_steps=MAX_STEPS)
        return r.x, r.cost, r.steps, r.converged

    return jax.vmap(lambda ts, x, q, w: jax.vmap(lambda t: one(t, x, q, w))(ts))(th0, x, q, w)


SOLVER = optx.LevenbergMarquardt(rtol=1e-12, atol=1e-12)


def optx_one(t, x, q, w):
    sol = optx.least_squares(lambda y, a: RESID(y, a), SOLVER, t, args=(x, q, w), max_steps=MAX_STEPS,
                             throw=False)
    r = RESID(sol.value, (x, q, w))
    return sol.value, 0.5 * jnp.sum(r**2), sol.stats["num_steps"], sol.result == optx.RESULTS.successful


@jax.jit
def theirs(th0, x, q, w):
    return jax.vmap(lambda ts, x, q, w: jax.vmap(lambda t: optx_one(t, x, q, w))(ts))(th0, x, q, w)


def timed(f, args, repeats):
    t = time.perf_counter()
    c = f.lower(*args).compile()
    tc = time.perf_counter() - t
    out, best = None, np.inf
    for _ in range(repeats):
        t = time.perf_counter()
        out = jax.block_until_ready(c(*args))
        best = min(best, time.perf_counter() - t)
    return tc, best, out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--subjects", type=int, default=16)
    ap.add_argument("--repeats", type=int, default=2)
    a = ap.parse_args()
    args = data(a.subjects)
    res = bl.header({"subjects": a.subjects, "postures": N_POST, "starts": N_STARTS, "max_steps": MAX_STEPS,
                     "repeats": a.repeats, "noise_deg": 0.5}, "optimistix", "equinox")
    print(f"load average at start: {os.getloadavg()}")
    lines = ["| solver | compile [s] | run [s] | ms/subject | median steps | converged |",
             "|---|---:|---:|---:|---:|---:|"]
    for name, f in (("fitting.least_squares", ours), ("optimistix LM", theirs)):
        tc, tr, (x, cost, steps, conv) = timed(f, args, a.repeats)
        best = np.argmin(np.where(np.isfinite(np.asarray(cost)), np.asarray(cost), np.inf), axis=1)
        cbest = np.take_along_axis(np.asarray(cost), best[:, None], 1)[:, 0]
        res[name] = dict(compile_s=tc, run_s=tr, ms_per_subject=1e3 * tr / a.subjects,
                         median_steps=float(np.median(steps)), converged=float(np.mean(conv)),
                         best_cost=cbest.tolist())
        lines.append(f"| {name} | {tc:.1f} | {tr:.2f} | {1e3 * tr / a.subjects:.1f} | {np.median(steps):.1f} | "
                     f"{np.mean(conv):.3f} |")
        print(f"{name:22s} compile {tc:6.1f} s  run {tr:6.2f} s  {1e3 * tr / a.subjects:7.1f} ms/subject  "
              f"median steps {np.median(steps):5.1f}  converged {np.mean(conv):.3f}")
    c0, c1 = (np.asarray(res[k]["best_cost"]) for k in ("fitting.least_squares", "optimistix LM"))
    res["max_rel_cost_difference"] = float(np.max(np.abs(c0 - c1) / c0))
    print(f"best-start cost, max relative difference: {res['max_rel_cost_difference']:.2e}")

    # implicit gradient of a fitted optimum w.r.t. the observed postures (one subject, one start)
    th0, x, q, w = (v[0] for v in args)

    def fitted_q_rest_ps(qobs):
        return optx_one(th0[0], x, qobs, w)[0][5]

    g_fn = jax.jit(jax.grad(fitted_q_rest_ps))
    t = time.perf_counter()
    g_c = g_fn.lower(q).compile()
    tc = time.perf_counter() - t
    t = time.perf_counter()
    g = jax.block_until_ready(g_c(q))
    tr = time.perf_counter() - t
    # central-difference check along one random direction
    d = np.random.default_rng(0).normal(size=q.shape) * 1e-3
    h = 1e-4
    fd = (fitted_q_rest_ps(q + h * d) - fitted_q_rest_ps(q - h * d)) / (2 * h)
    res["optimistix_implicit_grad"] = dict(compile_s=tc, run_s=tr, directional=float(jnp.sum(g * d)),
                                           central_difference=float(fd))
    print(f"optimistix d q_rest[PS] / d postures (1500 inputs, reverse mode): compile {tc:.1f} s, run {tr:.3f} s; "
          f"directional {float(jnp.sum(g * d)):.6e} vs central difference {float(fd):.6e}")
    res["load_end"] = bl.load_average()
    gi = res["optimistix_implicit_grad"]
    lines += ["", f"Best-start cost, max relative difference: {res['max_rel_cost_difference']:.2e}. optimistix "
                  f"d q_rest[PS] / d postures ({3 * N_POST} inputs, reverse mode): compile {gi['compile_s']:.1f} s, "
                  f"run {gi['run_s']:.3f} s; directional {gi['directional']:.6e} vs central difference "
                  f"{gi['central_difference']:.6e}. Load average {res['load_start'][0]:.1f} → "
                  f"{res['load_end'][0]:.1f}."]
    res["tables"] = ["\n".join(lines)]
    print("\n" + res["tables"][0])
    print(f"load average at end: {os.getloadavg()}; wrote {bl.write_results('least_squares_optimistix', res)}")


if __name__ == "__main__":
    main()
