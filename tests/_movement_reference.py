"""An independent generator of continuous multi-reach joint-angle recordings (NumPy, SciPy and
C MuJoCo only: no pmpjax simulation or kinematics), for tests of readers and fits.

The λ0-PMP field is :func:`tests._reference.pmp_field` (design §3.1); the Arimoto gain is Eq 8
with Eq 10's ``k = 1/(λ_min(J W⁻¹ Jᵀ) τ0)`` set at each reach's start posture; ``W = τ0 KJ``
(Eq 7). Each reach is integrated by SciPy's LSODA (``rtol`` 1e-10, ``atol`` 1e-12: stiff or not, it
switches itself; on the 4-joint arm's trials Radau at 1e-9 agrees to 4e-10 rad and takes five
times as long) and sampled
from its dense output on one clock.
"""

from __future__ import annotations

import numpy as np
from _reference import arimoto, minjerk_gain, planar_fk, planar_jac, pmp_field
from scipy.integrate import solve_ivp

RTOL, ATOL = 1e-10, 1e-12


def planar_fk_jac(q, lengths):
    """``(x (2,), J (2, n))`` of a planar arm with link ``lengths`` (closed form)."""
    return planar_fk(q, lengths), planar_jac(q, lengths)


def mjcf_fk_jac(model, data, site_id, q):
    """``(x (3,), J (3, nv))``: site ``site_id``'s position and translational Jacobian at
    ``qpos = q`` by C MuJoCo (``mj_kinematics``, ``mj_comPos``, ``mj_jacSite``); ``data`` is
    overwritten. Hinge/slide models (``nq == nv``)."""
    import mujoco

    data.qpos[:] = q
    mujoco.mj_kinematics(model, data)
    mujoco.mj_comPos(model, data)
    jacp = np.zeros((3, model.nv))
    mujoco.mj_jacSite(model, data, jacp, None, site_id)
    return data.site_xpos[site_id].copy(), jacp


def mjcf_fk_jac_fn(xml_path, site="hand"):
    """``fk_jac(q) -> (x, J)`` for the site named ``site`` of the MJCF file ``xml_path`` (C MuJoCo),
    and the model."""
    import mujoco

    model = mujoco.MjModel.from_xml_path(str(xml_path))
    data = mujoco.MjData(model)
    sid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, site)
    if sid < 0:
        raise ValueError(f"no site {site!r} in {xml_path}")
    return (lambda q: mjcf_fk_jac(model, data, sid, np.asarray(q, dtype=float))), model


def random_spd(rng, n, cond, trace):
    """A full, anisotropic SPD matrix (n, n): eigenvalues log-spaced over ``cond`` (largest /
    smallest), eigenvectors a random orthogonal matrix, scaled to ``trace``."""
    Q, R = np.linalg.qr(rng.standard_normal((n, n)))
    Q = Q * np.sign(np.diag(R))
    ev = np.geomspace(1.0, float(cond), n)
    K = (Q * ev) @ Q.T
    K = 0.5 * (K + K.T)
    return K * (float(trace) / np.trace(K))


def eq10_gain(fk_jac, q, W, tau0):
    """Eq 10: ``k = b_max / τ0 = 1 / (λ_min(J W⁻¹ Jᵀ) τ0)`` at posture ``q``."""
    _, J = fk_jac(q)
    M = J @ np.linalg.solve(W, J.T)
    return 1.0 / (np.linalg.eigvalsh(0.5 * (M + M.T))[0] * tau0)


def null_space(J, tol=1e-12):
    """Orthonormal basis (n, n − rank) of the null space of ``J`` (SVD)."""
    _, s, Vt = np.linalg.svd(J)
    rank = int(np.sum(s > tol * max(s[0], 1.0)))
    return Vt[rank:].T


def continuous_recording(fk_jac, KJ, q_rest, tau0, tau, q_start, targets, hold, *, fs=100.0, noise_deg=0.0,
                         seed=0, t0=0.0, lead=0.0, W=None, minjerk=None):
    """One continuous λ0-PMP trial of reaches to ``targets`` (M, m), sampled at ``fs`` [Hz].

    The hand rests at ``q_start`` (n,) [rad] from ``t0`` (with no target: the λ0-PMP field with
    ``F = 0`` for ``lead`` seconds, a null-space drift unless ``q_start`` is an equilibrium); target
    k appears at ``t_k = t0 + lead + Σ_{j<k} hold_j`` (``hold`` [s] a scalar or one per target).
    At each switch the Arimoto time restarts at 0 (``t − t_k``), Eq 10's ``k`` is recomputed at
    the current posture, and integration continues from the current state. ``W = τ0 KJ`` (Eq 7)
    unless given. ``minjerk = (T, cap)`` [s, 1/s] replaces Arimoto's gain by the minimum-jerk
    time-base generator ``F = γ(t − t_k) (J W⁻¹ Jᵀ)⁻¹ (x_d − x)`` with ``γ`` of
    :func:`_reference.minjerk_gain` (``tau`` unused; ``gains`` then holds ``cap``).
    Samples at ``t0 + i/fs`` up to the end of the last reach (included when it lies
    on the clock); Gaussian noise of ``noise_deg`` [deg] (seeded) is added to the joints.

    Returns ``(t (T,), q (T, n) [rad, noisy], info)``; ``info``: ``q`` (T, n) noise-free, ``x``
    (T, m) noise-free hand positions, ``t_switch`` (M,) the ``t_k``, ``t_end`` the end of the last
    reach, ``targets`` (M, m), ``gains`` (M,) Eq 10's ``k`` of each reach, ``q_final`` (M, n) each
    reach's posture at its end (integrated, not sampled), ``x_final`` (M, m), ``W``.
    """
    KJ, q_rest = np.asarray(KJ, float), np.asarray(q_rest, float)
    q_start, targets = np.asarray(q_start, float), np.atleast_2d(np.asarray(targets, float))
    M = targets.shape[0]
    hold = np.broadcast_to(np.asarray(hold, float), (M,))
    if np.any(hold <= 0) or lead < 0:
        raise ValueError("`hold` must be positive and `lead` non-negative")
    W = float(tau0) * KJ if W is None else np.asarray(W, float)
    ends = t0 + lead + np.cumsum(hold)
    t_switch, t_end = np.concatenate([[t0 + lead], ends[:-1]]), float(ends[-1])
    n_samples = int(np.floor((t_end - t0) * fs * (1 + 1e-12))) + 1
    t = t0 + np.arange(n_samples) / fs
    q_clean = np.full((n_samples, q_start.size), np.nan)

    def integrate(q0, span, field):
        sol = solve_ivp(field, span, q0, method="LSODA", rtol=RTOL, atol=ATOL, dense_output=True)
        if not sol.success:
            raise RuntimeError(f"solve_ivp failed on {span}: {sol.message}")
        return sol

    def fill(sol, a, b, last):  # samples in [a, b); the last reach takes every sample from a on
        sel = (t >= a) if last else (t >= a) & (t < b)
        if sel.any():
            q_clean[sel] = sol.sol(t[sel]).T

    q = q_start.copy()
    if lead > 0:
        m = targets.shape[1]
        sol = integrate(q, (t0, t0 + lead), lambda s, y: pmp_field(y, np.zeros(m), fk_jac, KJ, q_rest, W, "lambda0"))
        fill(sol, t0, t0 + lead, False)
        q = sol.y[:, -1].copy()
    gains, q_final = np.empty(M), np.empty((M, q.size))
    for k in range(M):
        a, b = t_switch[k], ends[k]
        target = targets[k]
        if minjerk is None:
            gains[k] = eq10_gain(fk_jac, q, W, tau0)
            K = arimoto(gains[k], tau)

            def field(s, y, a=a, K=K, target=target):
                F = K(s - a) * (target - fk_jac(y)[0])
                return pmp_field(y, F, fk_jac, KJ, q_rest, W, "lambda0")
        else:
            gains[k] = minjerk[1]

            def field(s, y, a=a, target=target):
                x, J = fk_jac(y)
                F = minjerk_gain(s - a, *minjerk) * np.linalg.solve(J @ np.linalg.solve(W, J.T), target - x)
                return pmp_field(y, F, fk_jac, KJ, q_rest, W, "lambda0")

        sol = integrate(q, (a, b), field)
        fill(sol, a, b, k == M - 1)
        q = sol.y[:, -1].copy()
        q_final[k] = q
    if np.isnan(q_clean).any():
        raise RuntimeError("a sample time was not covered by any reach")
    rng = np.random.default_rng(seed)
    q_noisy = q_clean + np.deg2rad(noise_deg) * rng.standard_normal(q_clean.shape) if noise_deg else q_clean.copy()
    info = {
        "q": q_clean, "x": np.stack([fk_jac(v)[0] for v in q_clean]), "t_switch": t_switch, "t_end": t_end,
        "targets": targets, "gains": gains, "q_final": q_final,
        "x_final": np.stack([fk_jac(v)[0] for v in q_final]), "W": W,
    }
    return t, q_noisy, info


#: The 3-joint planar arm of the planar tests: link lengths [m], rest posture [rad], home [m].
PLANAR_LENGTHS = np.array([0.30, 0.25, 0.15])
PLANAR_Q_REST = np.deg2rad([40.0, 60.0, 30.0])
PLANAR_HOME = np.array([0.25, 0.30])


def planar_trial(KJ, q_home, seed, *, tau0, tau=None, minjerk=None, n_out=4):
    """One continuous trial on the planar arm: out and back from home to ``n_out`` targets 0.12 m
    away in seeded random directions, each held 1.0–1.3 s, after 0.5 s at rest, at 100 Hz with 0.2°
    noise (:func:`continuous_recording`'s ``tau``/``minjerk`` choose the planner). Returns
    ``(t, q, info)``."""
    rng = np.random.default_rng(seed)
    ang = rng.uniform(0, 2 * np.pi, n_out)
    out = PLANAR_HOME + 0.12 * np.stack([np.cos(ang), np.sin(ang)], 1)
    targets = np.stack([out, np.broadcast_to(PLANAR_HOME, out.shape)], 1).reshape(-1, 2)
    hold = rng.uniform(1.0, 1.3, size=len(targets))
    return continuous_recording(lambda v: planar_fk_jac(v, PLANAR_LENGTHS), KJ, PLANAR_Q_REST, tau0, tau, q_home,
                                targets, hold, fs=100.0, noise_deg=0.2, seed=seed, lead=0.5, minjerk=minjerk)


def planar_arm_fk(q):
    """The planar arm's hand position (2,) at ``q`` (3,) [rad] (closed form)."""
    return planar_fk_jac(q, PLANAR_LENGTHS)[0]


def planar_arm_jac(q):
    """The planar arm's Jacobian (2, 3) at ``q`` (3,) [rad] (closed form)."""
    return planar_fk_jac(q, PLANAR_LENGTHS)[1]
