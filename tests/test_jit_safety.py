"""Public entry points work inside a caller's jit, vmap and grad (and their
compositions) with arrays captured from outside, and give the eager call's values.

Each case is ``(f, x)`` with ``f`` a function of one array built from public calls that closes
over JAX arrays. One composed transformation, ``jit(vmap(value_and_grad))``, is compared with the
eager values at both batch rows (the transformations must not change the computation), and its
gradients with central differences of the eager function. (The composition traces through every
single transformation; the library branches only on "is a tracer", so eager ``grad`` takes the same
path as ``jit(grad)``, and compiling each transformation separately proved nothing more.)

``simulate`` is ``simulate_sequence`` with one movement, so only the sequence is checked here;
``tests/test_simulate.py`` checks ``jit(grad(simulate))`` against central differences and
``vmap(simulate)`` against single runs.
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


def simulate_sequence_path(xt):
    targets = jnp.stack([xt, -xt])
    return pj.simulate_sequence(MODEL, PLANNER, Q0, targets, duration=0.06, dt=4e-3,
                                saveat=pj.SaveAt(every=5)).x.reshape(-1)


def equilibrium(xt):
    return pj.equilibrium_posture(WRIST, KJ, Q_REST, xt).q


CASES = {
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
    xs = jnp.stack([jnp.asarray(x), 0.9 * jnp.asarray(x)])
    eager = [np.asarray(f(x)) for x in xs]

    def loss(x):
        y = f(x)
        return jnp.sum(jnp.sin(y)), y

    (_, batched), grads = jax.jit(jax.vmap(jax.value_and_grad(loss, has_aux=True)))(xs)
    for i in range(2):
        np.testing.assert_allclose(np.asarray(batched[i]), eager[i], rtol=1e-12, atol=1e-14)
        fd = central_diff(lambda v: np.asarray(loss(jnp.asarray(v))[0]), np.asarray(xs[i]))
        np.testing.assert_allclose(np.asarray(grads[i]), fd, rtol=1e-5, atol=1e-7)
