"""Gradients through ``mjx.step`` on the springy arm (Williamson 1996) against central differences
of plain C MuJoCo ``mj_step`` loops (``tests/_springy.py``).

One compile (value and gradient of 0.2 s of open-loop rollout, 1 arm × 100 steps), in a file of
its own so that ``--dist loadfile`` runs it beside ``test_springy_rollouts.py``'s forward rollout.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _springy import c_replay, central_diff

import pmpjax as pj


def test_rollout_gradient_matches_c_mujoco_central_differences(free_arm, P):
    """jax.grad through 0.2 s of mjx.step (lax.scan) w.r.t. blend weights α, stiffness K,
    damping B and the initial posture q0, vs central differences of the same loss on C MuJoCo."""
    T = 100
    alpha0 = np.array([0.4, 0.3, 0.2, 0.1])
    q_ref = P[2]
    q00 = free_arm.q_rest + np.array([0.05, 0.0, -0.05, 0.1, 0.0, 0.05])

    def loss(alpha, K, B, q0):
        q_set = jnp.broadcast_to(jnp.asarray(alpha) @ P, (T, 6))
        tr = pj.rollout(free_arm, q_set, K=K, B=B, q0=q0)
        return jnp.sum((tr.q - q_ref[None]) ** 2) * free_arm.dt + jnp.sum((tr.q_final - q_ref) ** 2)

    def loss_c(alpha, K, B, q0):
        qs, _, _, qT = c_replay(free_arm, np.tile(alpha @ P, (T, 1)), q0=q0, K=K, B=B)
        return np.sum((qs - q_ref) ** 2) * free_arm.dt + np.sum((qT - q_ref) ** 2)

    x0 = (alpha0, free_arm.K, free_arm.B, q00)
    # Compiled as users are advised to compile gradients through rollouts (about a quarter faster).
    val, grads = pj.fast_compile_jit(jax.value_and_grad(loss, argnums=(0, 1, 2, 3)))(*x0)
    assert float(val) == pytest.approx(loss_c(*x0), rel=1e-12)
    for i, g in enumerate(grads):
        f = lambda x, i=i: loss_c(*(x if j == i else a for j, a in enumerate(x0)))  # noqa: E731
        fd = central_diff(f, x0[i])
        # Step sqrt(eps)·max(|x|, 1): the quotient carries ~eps·|loss|/h ≈ 1e-8 of round-off.
        assert np.allclose(np.asarray(g), fd, rtol=2e-6, atol=1e-7), i
