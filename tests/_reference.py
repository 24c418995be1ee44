"""Independent NumPy implementations (no pmpjax code) used as references by the tests."""

import numpy as np


def rx(t):
    c, s = np.cos(t), np.sin(t)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def ry(t):
    c, s = np.cos(t), np.sin(t)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def rz(t):
    c, s = np.cos(t), np.sin(t)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


P_SCREEN = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, 1.0]])


def wrist_fk(q, d=1.0):
    """Eq 6 by explicit matrix products."""
    R = rx(-q[0]) @ rz(q[1]) @ ry(q[2])
    return d * P_SCREEN @ R[:, 0]


def wrist_jac(q, d=1.0):
    """Geometric Jacobian: column i = P (ω_i × u) with spatial joint axes ω_i."""
    u = (rx(-q[0]) @ rz(q[1]) @ ry(q[2]))[:, 0]
    w1 = -np.array([1.0, 0, 0])
    w2 = rx(-q[0]) @ np.array([0, 0, 1.0])
    w3 = rx(-q[0]) @ rz(q[1]) @ np.array([0, 1.0, 0])
    return d * P_SCREEN @ np.stack([np.cross(w, u) for w in (w1, w2, w3)], axis=1)


def pmp_qdot(q, t, target, KJ, q_rest, W, gain, kind="lambda0", d=1.0):
    """PMP1 / PMP2 / λ0-PMP joint velocity (design §3.1) in plain NumPy."""
    x, J = wrist_fk(q, d), wrist_jac(q, d)
    A = np.linalg.inv(W)
    F = gain(t) * (target - x)
    if kind == "pmp1":
        return A @ J.T @ F
    tau = KJ @ (q - q_rest)
    if kind == "pmp2":
        return A @ (J.T @ F - tau)
    B = np.linalg.inv(J @ A @ J.T)
    lam0 = B @ J @ A @ tau
    return A @ (J.T @ (F + lam0) - tau)


def arimoto(k, tau):
    return lambda t: k * (1 - np.exp(-t / tau) - (t / tau) * np.exp(-t / tau))
