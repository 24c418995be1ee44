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


# --- central differences: the one helper of the suite -------------------------------------------

SQRT_EPS = float(np.sqrt(np.finfo(float).eps))


def central_diff(f, x, directions=None, *, scale=None):
    """Central differences of ``f`` (array-valued, NumPy or JAX) at ``x`` along ``directions``
    (default: the unit vectors of ``x``'s entries, shaped like ``x``), step ``sqrt(eps)·scale``
    with ``scale = max(1, max|x|)`` unless given. Returns (k, *f(x).shape) as float64 NumPy."""
    x = np.asarray(x, dtype=float)
    if directions is None:
        directions = np.eye(x.size).reshape((x.size,) + x.shape)
    h = SQRT_EPS * (max(1.0, float(np.max(np.abs(x)))) if scale is None else float(scale))
    return np.stack(
        [(np.asarray(f(x + h * d), dtype=float) - np.asarray(f(x - h * d), dtype=float)) / (2 * h) for d in directions]
    )


def symmetric_directions(n):
    """Unit perturbations of a symmetric n×n matrix (E_ij + E_ji for i <= j), (n(n+1)/2, n, n)."""
    out = []
    for i in range(n):
        for j in range(i, n):
            E = np.zeros((n, n))
            E[i, j] = E[j, i] = 1.0
            out.append(E)
    return np.stack(out)


# --- planar n-link arm ------------------------------------------------------------------------


def planar_fk(q, lengths):
    phi = np.cumsum(q)
    L = np.asarray(lengths)
    return np.array([np.sum(L * np.cos(phi)), np.sum(L * np.sin(phi))])


def planar_jac(q, lengths):
    """Column j: every link from j outward rotates about joint j."""
    phi = np.cumsum(q)
    L = np.asarray(lengths)
    return np.stack([[-np.sum((L * np.sin(phi))[j:]), np.sum((L * np.cos(phi))[j:])] for j in range(len(q))], -1)


# --- PMP fields (design §3.1) for any chain ------------------------------------------------------


def pmp_field(q, F, fk_jac, KJ, q_rest, W, kind):
    """Joint velocity of PMP1 / PMP2 / λ0-PMP under task force ``F`` (Figure 1B), plain NumPy:
    ``A = W⁻¹``; PMP1 ``A Jᵀ F``; PMP2 ``A (Jᵀ F − τ_el)``; λ0 ``A (Jᵀ (F + λ0) − τ_el)`` with
    ``λ0 = (J A Jᵀ)⁻¹ J A τ_el`` (Eq 4)."""
    _, J = fk_jac(q)
    A = np.linalg.inv(W)
    if kind == "pmp1":
        return A @ J.T @ F
    tau = KJ @ (q - q_rest)
    if kind == "pmp2":
        return A @ (J.T @ F - tau)
    lam0 = np.linalg.solve(J @ A @ J.T, J @ A @ tau)
    return A @ (J.T @ (F + lam0) - tau)


def slsqp_equilibrium(fk, jac, KJ, q_rest, x, q0=None):
    """``argmin ½ (q − q_rest)ᵀ KJ (q − q_rest)`` s.t. ``fk(q) = x`` by SciPy SLSQP (``ftol`` 1e-15;
    in the rare case it cycles at that tolerance, again at 1e-14)."""
    from scipy.optimize import minimize

    for ftol in (1e-15, 1e-14):
        r = minimize(
            lambda q: 0.5 * (q - q_rest) @ KJ @ (q - q_rest), q_rest if q0 is None else q0,
            jac=lambda q: KJ @ (q - q_rest), method="SLSQP", options={"ftol": ftol, "maxiter": 500},
            constraints=[{"type": "eq", "fun": lambda q: fk(q) - x, "jac": jac}],
        )
        if r.success:
            return r.x
    raise AssertionError(r.message)
