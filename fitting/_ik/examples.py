"""The illustrative examples of Khoramshahi et al. (2022), Section 4.1 (Figs 1–3).

- Fig 1/2: i.i.d. random data, ``n = 5``, ``m = 3``, ``K = 500``, ``w* = (1, .8, .6, .4, .2)``,
  null-space velocities of scale σ = 0.2, repeated (100 times in the paper).
- Fig 3: two prismatic joints, a 1-D task (``x = q1 + q2``, ``J = [1, 1]``), ``w* = (1, 0.01)``,
  a null-space motion pulling joint 1 to zero, targets 1 → 1.5 (t = 2 s) → 0.5 (t = 3 s),
  6 s at dt = 0.1 s (K = 60), start ``q = (0.5, 0.5)``.

The paper generates "Q̇ and J_k from N(0, 1)" and "V from N(0, σ)"; velocities must satisfy the
IK model of Eq 15, so here ``ẋ_k ~ N(0, I)``, ``J_k ~ N(0, 1)``, ``ṽ_k ~ N(0, σ² I)`` and
``q̇_k = J#_{W*} ẋ_k + N_{W*} ṽ_k`` (the null-space part must satisfy ``J v = 0``, Eq 15).
"""

from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from pmpjax._base.linalg import from_soa, mv, to_soa
from pmpjax._pmp.redundancy import pinv_apply_diag_soa

FIG1_W = (1.0, 0.8, 0.6, 0.4, 0.2)


def fig1_data(key, *, n_reps: int = 100, K: int = 500, w_true=FIG1_W, m: int = 3, sigma: float = 0.2):
    """Random data of Fig 1: returns ``qdot`` (R, K, n), ``xdot`` (R, K, m), ``J`` (R, K, m, n)."""
    return _fig1_data(key, jnp.asarray(w_true, dtype=float), jnp.asarray(sigma, dtype=float),
                      n_reps=int(n_reps), K=int(K), m=int(m))


@partial(jax.jit, static_argnames=("n_reps", "K", "m"))
def _fig1_data(key, w_true, sigma, *, n_reps, K, m):
    n = w_true.shape[0]
    # one draw, split into J, ẋ and ṽ (three separate draws take seconds to compile)
    z = jax.random.normal(key, (n_reps, K, m * n + m + n))
    J = z[..., : m * n].reshape(n_reps, K, m, n)
    xdot = z[..., m * n : m * n + m]
    v = sigma * z[..., m * n + m :]
    # q̇ = J#_W ẋ + N_W ṽ = ṽ + J#_W (ẋ − J ṽ), through the one pseudo-inverse kernel
    Jc, vc = to_soa(J, 2), to_soa(v)
    a = jnp.broadcast_to((1.0 / w_true).reshape((n, 1, 1)), (n, n_reps, K))
    qdot = vc + pinv_apply_diag_soa(Jc, a, to_soa(xdot) - mv(Jc, vc))[0]
    return from_soa(qdot), xdot, J


def fig3_data(*, w_true=(1.0, 0.01), k_task: float = 1.0, k_null: float = 1.0, dt: float = 0.1,
              duration: float = 6.0, q0=(0.5, 0.5)):
    """Two prismatic joints, 1-D task (Fig 3). Returns ``qdot`` (K, 2), ``xdot`` (K, 1), ``J`` (K, 1, 2).

    ``q̇ = J#_{W*} k_task (x_g(t) − x) + N_{W*} (−k_null q1, 0)``, explicit Euler at ``dt``;
    the goal switches 1 → 1.5 at t = 2 s → 0.5 at t = 3 s. (The paper's null-space term is
    printed garbled; this is the reading "pull joint 1 to zero".)
    """
    w = np.asarray(w_true, dtype=float)
    J = np.array([[1.0, 1.0]])
    Jp = (J / w).T / ((J / w) @ J.T)[0, 0]
    N = np.eye(2) - Jp @ J
    q = np.asarray(q0, dtype=float)
    qd, xd, Js = [], [], []
    K = int(round(duration / dt))
    for k in range(K):
        t = k * dt
        xg = 1.0 if t < 2.0 else (1.5 if t < 3.0 else 0.5)
        v = np.array([-k_null * q[0], 0.0])
        qdot = Jp[:, 0] * k_task * (xg - q.sum()) + N @ v
        qd.append(qdot)
        xd.append(J @ qdot)
        Js.append(J)
        q = q + dt * qdot
    return np.array(qd), np.array(xd), np.array(Js)


def fig2_gammas():
    """The γ values swept in Fig 2 / Fig 3."""
    return (0.0, 0.2, 0.4, 0.6, 0.8, 0.9)


ik_fig1_data = fig1_data
ik_fig3_data = fig3_data
