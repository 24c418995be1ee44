"""Independent NumPy implementations (no pmpjax code) used as references by the tests, and
:func:`compiled_names` (the XLA compilations of a block)."""

import contextlib
import logging
import re

import jax
import numpy as np


@contextlib.contextmanager
def compiled_names():
    """Yields the list of the names (``jit(f)``) of the XLA programs compiled inside the block."""
    names = []

    class _Handler(logging.Handler):
        def emit(self, record):
            m = re.match(r"Finished XLA compilation of (\S+)", record.getMessage())
            if m:
                names.append(m.group(1))

    logger, handler = logging.getLogger("jax"), _Handler()
    logger.addHandler(handler)
    try:
        with jax.log_compiles(True):
            yield names
    finally:
        logger.removeHandler(handler)


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


def minjerk_gain(t, T, cap):
    """Time-base generator (Python floats): ``γ = ξ̇/(1 − ξ)`` of ``ξ(s) = 10 s³ − 15 s⁴ + 6 s⁵``,
    ``s = t/T``, capped at ``cap``, and ``cap`` from ``t = T`` on. Computed as
    ``30 s² / (T (1 − s)(6 s² + 3 s + 1))`` (``1 − ξ = (1 − s)³ (6 s² + 3 s + 1)``): exact up to the
    cap, where ``1 − ξ`` would cancel."""
    s = max(t / T, 0.0)
    if s >= 1.0:
        return cap
    return min(30.0 * s * s / (T * (1.0 - s) * (6.0 * s * s + 3.0 * s + 1.0)), cap)


# --- central differences: the suite's one finite-difference routine -------------------------------

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
    in the rare case it cycles at that tolerance, again from where it stopped at 1e-14, then 1e-13)."""
    from scipy.optimize import minimize

    start = q_rest if q0 is None else q0
    for ftol in (1e-15, 1e-14, 1e-13):
        r = minimize(
            lambda q: 0.5 * (q - q_rest) @ KJ @ (q - q_rest), start,
            jac=lambda q: KJ @ (q - q_rest), method="SLSQP", options={"ftol": ftol, "maxiter": 500},
            constraints=[{"type": "eq", "fun": lambda q: fk(q) - x, "jac": jac}],
        )
        if r.success:
            return r.x
        if np.all(np.isfinite(r.x)):
            start = r.x
    raise AssertionError(r.message)


def _rot_batch(axis, t):
    c, s, o, z = np.cos(t), np.sin(t), np.ones_like(t), np.zeros_like(t)
    rows = {0: [[o, z, z], [z, c, -s], [z, s, c]], 1: [[c, z, s], [z, o, z], [-s, z, c]],
            2: [[c, -s, z], [s, c, z], [z, z, o]]}[axis]
    return np.moveaxis(np.array(rows), (0, 1), (-2, -1))


def wrist_fk_jac_batch(Q):
    """:func:`wrist_fk` and :func:`wrist_jac` (d = 1) of postures (N, 3) at once: (N, 2), (N, 2, 3)."""
    A = _rot_batch(0, -Q[:, 0])
    AB = A @ _rot_batch(2, Q[:, 1])
    u = (AB @ _rot_batch(1, Q[:, 2]))[..., 0]
    w = np.stack([np.broadcast_to([-1.0, 0.0, 0.0], u.shape), A[..., 2], AB[..., 1]], 1)  # (N, 3 joints, 3)
    return u @ P_SCREEN.T, np.einsum("ki,nji->nkj", P_SCREEN, np.cross(w, u[:, None]))


def wrist_equilibria(KJ, q_rest, x, *, iterations=8):
    """``argmin ½ (q − q_rest)ᵀ KJ (q − q_rest)`` s.t. ``wrist_fk(q) = x`` for targets ``x`` (N, 2)
    at once: Newton on the Lagrange conditions ``KJ (q − q_rest) = Jᵀ λ``, ``fk(q) = x`` from
    ``q_rest`` (the constraint's curvature by central differences of the Jacobian). Returns
    postures (N, 3); asserts that the conditions hold to 1e-12."""
    x = np.atleast_2d(x)
    N, h = len(x), 1e-6
    q, lam = np.broadcast_to(q_rest, (N, 3)).astype(float), np.zeros((N, 2))

    def conditions(q, lam):
        p, J = wrist_fk_jac_batch(q)
        return np.concatenate([(q - q_rest) @ KJ.T - np.einsum("nki,nk->ni", J, lam), p - x], -1), J

    for _ in range(iterations):
        r, J = conditions(q, lam)
        dJ = np.stack([(wrist_fk_jac_batch(q + h * e)[1] - wrist_fk_jac_batch(q - h * e)[1]) / (2 * h)
                       for e in np.eye(3)], -1)  # (N, 2, 3 [J's column], 3 [joint])
        M = np.zeros((N, 5, 5))
        M[:, :3, :3] = KJ - np.einsum("nkij,nk->nij", dJ, lam)
        M[:, :3, 3:], M[:, 3:, :3] = -np.swapaxes(J, 1, 2), J
        step = np.linalg.solve(M, -r[..., None])[..., 0]
        q, lam = q + step[:, :3], lam + step[:, 3:]
    r, _ = conditions(q, lam)
    assert np.abs(r).max() < 1e-12, np.abs(r).max()
    return q


# ---------------------------------------------------------------------------------------------
# IK weights (Khoramshahi et al. 2022), written from the paper with np.linalg and SciPy only


def weighted_pinv(J, w):
    """``J#_W = W⁻¹ Jᵀ (J W⁻¹ Jᵀ)⁻¹`` (..., n, m) for ``J`` (..., m, n), diagonal weights ``w`` (n,)."""
    JA = J / np.asarray(w)[..., None, :]  # J W⁻¹
    return np.swapaxes(JA, -1, -2) @ np.linalg.inv(JA @ np.swapaxes(J, -1, -2))


def ik_fig1_numpy(rng, *, n_reps=100, K=500, w=(1.0, 0.8, 0.6, 0.4, 0.2), m=3, sigma=0.2):
    """Fig 1 data (Section 4.1): J, ẋ ~ N(0, 1), ṽ ~ N(0, σ²), q̇ = J#_W ẋ + (I − J#_W J) ṽ (Eq 15)."""
    n = len(w)
    J = rng.standard_normal((n_reps, K, m, n))
    xdot = rng.standard_normal((n_reps, K, m))
    v = sigma * rng.standard_normal((n_reps, K, n))
    Jp = weighted_pinv(J, w)
    qdot = np.einsum("rkij,rkj->rki", Jp, xdot) + v - np.einsum("rkij,rkj->rki", Jp @ J, v)
    return qdot, xdot, J


def ik_fig3_numpy(*, w=(1.0, 0.01), k_task=1.0, k_null=1.0, dt=0.1, duration=6.0, q0=(0.5, 0.5)):
    """Fig 3: two prismatic joints, x = q1 + q2, goal 1 → 1.5 (t = 2 s) → 0.5 (t = 3 s), explicit
    Euler of q̇ = J#_W k_task (x_g − x) + (I − J#_W J)(−k_null q1, 0)."""
    J = np.array([[1.0, 1.0]])
    Jp = weighted_pinv(J, w)
    N = np.eye(2) - Jp @ J
    q = np.array(q0, dtype=float)
    out = []
    for k in range(int(round(duration / dt))):
        t = k * dt
        goal = 1.0 if t < 2.0 else 1.5 if t < 3.0 else 0.5
        qd = Jp @ [k_task * (goal - q.sum())] + N @ [-k_null * q[0], 0.0]
        out.append(qd)
        q = q + dt * qd
    qdot = np.array(out)
    return qdot, qdot @ J.T, np.broadcast_to(J, (len(out), 1, 2)).copy()


def algorithm1(qdot, xdot, J, gamma, iters, *, w_min=1e-3, gamma_rate=0.0, fixed=()):
    """Algorithm 1 for one subject, ``iters`` updates. ``qdot`` (K, n), ``xdot`` (K, m), ``J`` (K, m, n).

    Lines 1–21 of the paper: evaluation with the previous null-space estimate V̄, ū = Jᵀ B ẋ,
    v̄ = γ (I − J# J) q̇, Ψ = (Q̇ − V̄) Q̇ᵀ, Ω = Ū Q̇ᵀ, the QP of Eq 24 on Ψ̃ (n², n), Ω̃ (n²,) solved
    by ``scipy.optimize.lsq_linear`` with bounds [w_min, 1], fixed joints set back to 1, w / max w.
    Returns the weights after each update (iters, n), the errors e (iters,) and the QP solutions
    before normalisation (iters, n).
    """
    import scipy.optimize

    K, n = qdot.shape
    w, V, g = np.ones(n), np.zeros((K, n)), float(gamma)
    free = np.array([i not in fixed for i in range(n)])
    ws, errs, raw = [], [], []
    for _ in range(iters):
        Winv = np.diag(1.0 / w)
        B = np.linalg.inv(J @ Winv @ np.swapaxes(J, 1, 2))  # (K, m, m)
        Jp = Winv @ np.swapaxes(J, 1, 2) @ B  # (K, n, m)
        qbar = np.einsum("kij,kj->ki", Jp, xdot) + V
        errs.append(np.mean(np.linalg.norm(qdot - qbar, axis=1)))
        U = np.einsum("kji,kjl,kl->ki", J, B, xdot)  # ū = Jᵀ B ẋ
        V = g * (qdot - np.einsum("kij,kj->ki", Jp @ J, qdot))
        Psi = (qdot - V).T @ qdot
        Omega = U.T @ qdot
        Psi_t = np.concatenate([np.diag(Psi[:, j]) for j in range(n)])
        Omega_t = np.concatenate([Omega[:, j] for j in range(n)])
        w = scipy.optimize.lsq_linear(Psi_t, Omega_t, bounds=(w_min, 1.0), method="bvls", tol=1e-15).x
        raw.append(w.copy())
        w[~free] = 1.0
        w[free] = w[free] / w[free].max()
        ws.append(w.copy())
        g = g + gamma_rate * (1.0 - g)
    return np.array(ws), np.array(errs), np.array(raw)


def arm4_fk(q, L1=0.30, L2=0.33):
    """HuG-MP README: p(q) = Rx(q1) Ry(q2) Rz(−q3) ([0, 0, −L1] + Ry(−q4) [0, 0, −L2])."""
    q = np.asarray(q)
    return rx(q[0]) @ ry(q[1]) @ rz(-q[2]) @ (np.array([0, 0, -L1]) + ry(-q[3]) @ np.array([0, 0, -L2]))


def arm4_jac(q, L1=0.30, L2=0.33):
    """Jacobian of :func:`arm4_fk` by complex steps (exact to rounding)."""
    h = 1e-30
    return np.stack([arm4_fk(np.asarray(q, complex) + 1j * h * e, L1, L2).imag / h for e in np.eye(4)], axis=1)


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
