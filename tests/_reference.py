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


def shoelace(poly):
    """Signed area of a closed polygon (N, 2) (counter-clockwise positive)."""
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)


def clip_half_plane(poly, normal):
    """Sutherland–Hodgman: the part of polygon ``poly`` with ``poly @ normal >= 0``."""
    out = []
    n = len(poly)
    for i in range(n):
        p, q = poly[i], poly[(i + 1) % n]
        dp, dq = p @ normal, q @ normal
        if dp >= 0:
            out.append(p)
        if (dp >= 0) != (dq >= 0):
            out.append(p + (q - p) * dp / (dp - dq))
    return np.array(out) if out else np.zeros((0, 2))


def polygon_areas(path, start, end):
    """Reference (A_R, A_L): the closed polygon start → path → end → start (back along the
    line), cut by the line and measured by the shoelace formula. A lobe on the left is traversed
    clockwise (forward along the path, back along the line), one on the right anticlockwise."""
    u = (end - start) / np.linalg.norm(end - start)
    left = np.array([-u[1], u[0]])
    poly = np.vstack([start, path, end]) - start
    a_left = -shoelace(clip_half_plane(poly, left))
    a_right = shoelace(clip_half_plane(poly, -left))
    return a_right, a_left
