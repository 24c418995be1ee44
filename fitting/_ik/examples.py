"""The illustrative examples of Khoramshahi et al. (2022), Section 4.1 (Figs 1–3).

- Fig 1/2: i.i.d. random data, ``n = 5``, ``m = 3``, ``K = 500``, ``w* = (1, .8, .6, .4, .2)``,
  null-space velocities of scale σ = 0.2, repeated (100 times in the paper).
- Fig 3: two prismatic joints, a 1-D task (``x = q1 + q2``, ``J = [1, 1]``), ``w* = (1, 0.01)``,
  a null-space motion pulling joint 1 to zero, targets 1 → 1.5 (t = 2 s) → 0.5 (t = 3 s),
  6 s at dt = 0.1 s (K = 60), start ``q = (0.5, 0.5)``.

The paper generates "Q̇ and J_k from N(0, 1)" and "V from N(0, σ)"; velocities must satisfy the
IK model of Eq 15, so here ``ẋ_k ~ N(0, I)``, ``J_k ~ N(0, 1)``, ``ṽ_k ~ N(0, σ² I)`` and
``q̇_k = J#_{W*} ẋ_k + N_{W*} ṽ_k`` (the null-space part must satisfy ``J v = 0``, Eq 15). Both
generators go through the one weighted pseudo-inverse (``pmpjax.weighted_pinv``); the tests make
their own data with NumPy.
"""

from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

import pmpjax as pj
from pmpjax.internal import as_prng_key, check_positive_int, fast_compile_jit, renamed_keywords

FIG1_W = (1.0, 0.8, 0.6, 0.4, 0.2)


def _weights(w_true, n_min=2):
    w = np.asarray(w_true, dtype=float)
    if w.ndim != 1 or w.size < n_min or not np.all(np.isfinite(w)) or np.any(w <= 0):
        raise ValueError(f"`w_true` must be {n_min} or more positive finite weights, got {w_true!r}")
    return w


@renamed_keywords(key="seed")
def ik_fig1_data(seed=0, *, n_reps: int = 100, K: int = 500, w_true=FIG1_W, m: int = 3, sigma: float = 0.2):
    """Random data of Khoramshahi et al. (2022), Figure 1: a redundant chain whose joint velocities
    follow the weighted pseudo-inverse ``W* = diag(w_true)`` plus null-space motion.

    **Arguments:**

    - ``seed``: an integer or a JAX PRNG key (an integer gives ``jax.random.PRNGKey(seed)``).
    - ``n_reps``: R repetitions.
    - ``K``: samples per repetition.
    - ``w_true``: (n,) the true weights.
    - ``m``: task dimensions, ``m < n``.
    - ``sigma``: the null-space scale, ≥ 0.

    **Returns:**

    ``(qdot, xdot, J)``: (R, K, n) joint velocities, (R, K, m) task velocities, (R, K, m, n) Jacobians.

    **Raises:**

    - ``ValueError`` naming the argument for fewer than 2 or non-positive weights, non-positive sizes,
      ``m >= n``, a negative ``sigma`` or a bad ``seed``.
    """
    w = _weights(w_true)
    n_reps, K, m = (check_positive_int(name, v) for name, v in (("n_reps", n_reps), ("K", K), ("m", m)))
    if not m < w.size:
        raise ValueError(f"`m` must be smaller than n = {w.size} (a redundant chain), got {m}")
    if not (np.isfinite(float(sigma)) and float(sigma) >= 0):
        raise ValueError(f"`sigma` must be a finite number >= 0, got {sigma}")
    key = as_prng_key("seed", seed)
    return _fig1_data(key, jnp.asarray(w), jnp.asarray(float(sigma)), n_reps=n_reps, K=K, m=m)


@partial(fast_compile_jit, static_argnames=("n_reps", "K", "m"))
def _fig1_data(key, w_true, sigma, *, n_reps, K, m):
    n = w_true.shape[0]
    # one draw, split into J, ẋ and ṽ (three separate draws take seconds to compile)
    z = jax.random.normal(key, (n_reps, K, m * n + m + n))
    J = z[..., : m * n].reshape(n_reps, K, m, n)
    xdot = z[..., m * n : m * n + m]
    v = sigma * z[..., m * n + m :]
    # q̇ = J#_W ẋ + N_W ṽ = ṽ + J#_W (ẋ − J ṽ)
    Jp = pj.weighted_pinv(J, w=jnp.broadcast_to(w_true, (n_reps, K, n)))
    qdot = v + jnp.einsum("rkij,rkj->rki", Jp, xdot - jnp.einsum("rkij,rkj->rki", J, v))
    return qdot, xdot, J


def ik_fig3_data(*, w_true=(1.0, 0.01), k_task: float = 1.0, k_null: float = 1.0, dt: float = 0.1,
                 duration: float = 6.0, q0=(0.5, 0.5)):
    """Khoramshahi et al. (2022), Figure 3: two prismatic joints, a 1-D task.

    ``q̇ = J#_{W*} k_task (x_g(t) − x) + N_{W*} (−k_null q1, 0)``, explicit Euler at ``dt`` for
    ``duration`` from ``q0``; the goal switches 1 → 1.5 at t = 2 s → 0.5 at t = 3 s. (The paper's
    null-space term is printed garbled; this is the reading "pull joint 1 to zero".)

    **Arguments:**

    - ``w_true``: the 2 true weights.
    - ``k_task``: gain of the task term [1/s], ≥ 0.
    - ``k_null``: gain of the null-space pull [1/s], ≥ 0.
    - ``dt``: the Euler step [s].
    - ``duration``: the run's length [s].
    - ``q0``: the 2 start positions.

    **Returns:**

    ``(qdot, xdot, J)``: (K, 2), (K, 1), (K, 1, 2).

    **Raises:**

    - ``ValueError`` naming the argument for bad weights, negative gains, non-positive times or a bad
      ``q0``.
    """
    w = _weights(w_true)
    if w.size != 2:
        raise ValueError(f"`w_true` must hold the 2 weights of the two joints, got {w_true!r}")
    for name, v in (("k_task", k_task), ("k_null", k_null)):
        if not (np.isfinite(float(v)) and float(v) >= 0):
            raise ValueError(f"`{name}` must be a finite gain >= 0, got {v}")
    for name, v in (("dt", dt), ("duration", duration)):
        if not (np.isfinite(float(v)) and float(v) > 0):
            raise ValueError(f"`{name}` must be a positive time [s], got {v}")
    q = np.asarray(q0, dtype=float)
    if q.shape != (2,) or not np.all(np.isfinite(q)):
        raise ValueError(f"`q0` must be 2 finite joint positions, got {q0!r}")
    K = int(round(duration / dt))
    if K < 1:
        raise ValueError(f"`duration` ({duration}) must hold at least one step `dt` ({dt})")
    J = np.array([[1.0, 1.0]])
    Jp = np.asarray(pj.weighted_pinv(J, w=w))  # (2, 1), constant: the chain is prismatic
    N = np.asarray(pj.nullspace_projector(J, w=w))
    qd = np.empty((K, 2))
    for k in range(K):
        t = k * dt
        xg = 1.0 if t < 2.0 else (1.5 if t < 3.0 else 0.5)
        qd[k] = Jp[:, 0] * k_task * (xg - q.sum()) + N @ np.array([-k_null * q[0], 0.0])
        q = q + dt * qd[k]
    return qd, qd @ J.T, np.broadcast_to(J, (K, 1, 2)).copy()
