"""Independent references for the springy-arm tests (test_primitives*.py, test_springy_*.py):
plain C MuJoCo ``mj_step`` loops (spring torque in ``qfrc_applied``), settled C rollouts for
statics, central differences, the paper's minimum-jerk velocity formula. (The arm fixtures are
module-scoped, in conftest.py.)"""

import _reference
import mujoco
import numpy as np


def central_diff(f, x0):
    """Central differences of scalar ``f`` at ``x0``, shaped like ``x0`` (the suite's one finite-difference
    routine, ``_reference.central_diff``)."""
    x0 = np.asarray(x0, float)
    return _reference.central_diff(f, x0).reshape(x0.shape)


def c_replay(arm, q_set, *, q0, qdot0=None, probe=None, force=None, K=None, B=None):
    """Plain C MuJoCo: the spring law written into qfrc_applied, one mj_step per set-point."""
    m = arm.mj_model
    K = arm.K if K is None else np.asarray(K)
    B = arm.B if B is None else np.asarray(B)
    d = mujoco.MjData(m)
    d.qpos[:] = q0
    if qdot0 is not None:
        d.qvel[:] = qdot0
    qs, hands, xmats = [], [], []
    for k in range(len(q_set)):
        qs.append(d.qpos.copy())
        d.qfrc_applied[:] = -K * (d.qpos - q_set[k]) - B * d.qvel
        if probe is not None:
            d.mocap_pos[0] = probe[k]
        if force is not None:
            d.xfrc_applied[arm.layout.hand_body, :3] = force[k]
        mujoco.mj_step(m, d)
        hands.append(d.site_xpos[arm.layout.hand_site].copy())
        xmats.append(d.xmat[arm.layout.hand_body].reshape(3, 3).copy())
    return np.array(qs), np.array(hands), np.array(xmats), d.qpos.copy()


def c_settle(arm, q_set, K, *, seconds=4.0):
    """Statics from dynamics: hold each set-point ``q_set`` (N, n) with stiffness ``K`` ((N,) n)
    and strong damping in C MuJoCo until the arm stops. Returns postures (N, n), hand (N, 3) and
    the largest final speed (a settledness check)."""
    m = arm.mj_model
    q_set = np.atleast_2d(q_set)
    K = np.broadcast_to(K, q_set.shape)
    M = arm.inertia_diag
    qs, hands, speed = [], [], 0.0
    for qs_i, K_i in zip(q_set, K):
        B = np.minimum(2.0 * np.sqrt(K_i * M), 0.4 * M / m.opt.timestep)  # ~critical, explicit-stable
        d = mujoco.MjData(m)
        d.qpos[:] = qs_i
        for _ in range(int(seconds / m.opt.timestep)):
            d.qfrc_applied[:] = -K_i * (d.qpos - qs_i) - B * d.qvel
            mujoco.mj_step(m, d)
        mujoco.mj_kinematics(m, d)
        qs.append(d.qpos.copy())
        hands.append(d.site_xpos[arm.layout.hand_site].copy())
        speed = max(speed, float(np.abs(d.qvel).max()))
    return np.array(qs), np.array(hands), speed


def _paper_velocity(t, delta, t0, d):
    s = (t - t0) / d
    return np.where((s > 0) & (s < 1), delta / d * (30 * s**4 - 60 * s**3 + 30 * s**2), 0.0)

