"""Issue 9 item 6: public entry points work inside a caller's jit, vmap and grad (and their
compositions) with arrays captured from outside, and give the eager call's values.

Each case is ``(f, x)`` with ``f`` a function of one array built from public calls that closes
over JAX arrays; the eager value is the reference for the transformed ones (the transformations
must not change the computation), and gradients are also checked against central differences.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _reference import central_diff

import fitting
import pmpjax as pj

KJ = jnp.asarray(np.diag([0.5, 1.5, 2.0]))
Q_REST = jnp.asarray(np.deg2rad([5.0, 0.0, 0.0]))
WRIST = pj.Wrist()
MODEL = pj.Lambda0PMP(WRIST, KJ=KJ, q_rest=Q_REST, W=pj.damping_from_stiffness(KJ, 0.08))
PLANNER = pj.ArimotoPlanner(k=22.5, tau=0.08)
Q0 = jnp.asarray(np.deg2rad([5.0, 3.0, -2.0]))
J0 = jnp.asarray(np.array([[0.1, -0.9, 0.3], [0.2, 0.1, -1.0]]))
PATH = jnp.asarray(np.stack([np.linspace(0, 1, 21), 0.1 * np.sin(np.linspace(0, np.pi, 21))], -1))


def simulate_final(xt):
    return pj.simulate(MODEL, PLANNER, Q0, xt, duration=0.1, dt=4e-3).q[-1]


def simulate_sequence_path(xt):
    targets = jnp.stack([xt, -xt])
    return pj.simulate_sequence(MODEL, PLANNER, Q0, targets, duration=0.06, dt=4e-3,
                                saveat=pj.SaveAt(every=5)).x.reshape(-1)


def equilibrium(xt):
    return pj.equilibrium_posture(WRIST, KJ, Q_REST, xt).q


CASES = {
    "simulate": (simulate_final, np.array([0.1, 0.05])),
    "simulate_sequence": (simulate_sequence_path, np.array([0.08, -0.04])),
    "equilibrium_posture": (equilibrium, np.array([0.12, -0.07])),
    "weighted_pinv": (lambda w: pj.weighted_pinv(J0, w=w).reshape(-1), np.array([1.0, 0.5, 0.3])),
    "nullspace_projector": (lambda w: pj.nullspace_projector(J0, w=w).reshape(-1), np.array([1.0, 0.5, 0.3])),
    "task_damping": (lambda w: pj.task_damping(J0, w=w).reshape(-1), np.array([1.0, 0.5, 0.3])),
    "lambda0": (lambda t: pj.lambda0(J0, KJ, t), np.array([0.1, -0.2, 0.3])),
    "quat_from_joint_angles": (pj.quat_from_joint_angles, np.array([0.2, -0.1, 0.3])),
    "rotvec_from_joint_angles": (pj.rotvec_from_joint_angles, np.array([0.2, -0.1, 0.3])),
    "joint_angles_from_quat": (lambda q: pj.joint_angles_from_quat(pj.quat_from_joint_angles(q)),
                               np.array([0.2, -0.1, 0.3])),
    "curvature_areas": (lambda y: jnp.stack(pj.curvature_areas(PATH.at[:, 1].add(y[0] * PATH[:, 0]), PATH[0],
                                                               PATH[-1])), np.array([0.05])),
    "predicted_torsion": (lambda xt: fitting.predicted_torsion(WRIST, KJ, Q_REST, xt[None]), np.array([0.1, 0.2])),
}


@pytest.mark.parametrize("name", list(CASES))
def test_jit_vmap_grad_with_closed_over_arrays_equal_eager(name):
    f, x = CASES[name]
    x = jnp.asarray(x)
    eager = np.asarray(f(x))
    np.testing.assert_allclose(np.asarray(jax.jit(f)(x)), eager, rtol=1e-12, atol=1e-14)
    xs = jnp.stack([x, x * 0.9])
    batched = np.asarray(jax.jit(jax.vmap(f))(xs))
    np.testing.assert_allclose(batched[0], eager, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(batched[1], np.asarray(f(xs[1])), rtol=1e-12, atol=1e-14)
    loss = lambda x: jnp.sum(jnp.sin(f(x)))  # noqa: E731
    g = np.asarray(jax.grad(loss)(x))
    np.testing.assert_allclose(np.asarray(jax.jit(jax.grad(loss))(x)), g, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(np.asarray(jax.vmap(jax.grad(loss))(xs))[0], g, rtol=1e-10, atol=1e-12)
    fd = central_diff(lambda v: np.asarray(loss(jnp.asarray(v))), np.asarray(x))
    np.testing.assert_allclose(g, fd, rtol=1e-5, atol=1e-7)
