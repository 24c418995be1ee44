"""The L-stable solver (``simulate(..., solver="rodas4")``) on stiff λ0-PMP movements.

References, independent of pmpjax: SciPy ``solve_ivp`` (Radau, rtol 1e-10) of NumPy right-hand
sides written from design §3.1 and Eqs 7–10 (tests/_reference.py), NumPy's LAPACK solve, and
central differences. Stiff means Eq 10's gain with anisotropic ``KJ`` (cond up to 1e4), where
RK4 at the same step is refused (or diverges); the solver must stay within 0.01° of Radau at
≤ 5 steps per sample.

Compile budget: one arm batch (Arimoto, two stiffnesses), one arm time-base-generator movement,
one wrist batch at two step sizes, one gradient problem.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _reference import arimoto, arm4_fk, arm4_jac, central_diff, minjerk_gain, pmp_field, pmp_qdot, wrist_jac
from scipy.integrate import solve_ivp

import pmpjax as pj
from pmpjax._base.linalg import lu_factor_lists, lu_solve_lists

SAMPLES = 50
TS = tuple(np.linspace(0.0, 1.0, SAMPLES))
RADAU = dict(method="Radau", rtol=1e-10, atol=1e-12)


def spd_with_cond(rng, n, cond, trace=4.0):
    """A random SPD matrix with the given condition number and trace."""
    Q, _ = np.linalg.qr(rng.normal(size=(n, n)))
    ev = np.geomspace(1.0, cond, n)
    return Q @ np.diag(trace * ev / ev.sum()) @ Q.T


def eq10_gain(J0, W, tau0):
    """``k = b_max / τ0`` with ``b_max`` the largest eigenvalue of ``B(q0) = (J W⁻¹ Jᵀ)⁻¹``."""
    return 1.0 / (np.linalg.eigvalsh(J0 @ np.linalg.inv(W) @ J0.T)[0] * tau0)


def arm_radau(q0, x_d, KJ, q_rest, W, force, T=1.0):
    fk_jac = lambda q: (arm4_fk(q), arm4_jac(q))  # noqa: E731

    def rhs(t, q):
        x, J = fk_jac(q)
        return pmp_field(q, force(t, x, J), fk_jac, KJ, q_rest, W, "lambda0")

    sol = solve_ivp(rhs, (0.0, T), q0, t_eval=np.asarray(TS) * T, **RADAU)
    assert sol.success
    return sol.y.T


ARM_Q0 = np.deg2rad([-20.0, -30.0, 0.0, 80.0])
ARM_TARGET = arm4_fk(np.deg2rad([-40.0, -60.0, -20.0, 50.0]))
ARM_REST = np.deg2rad([-30.0, -40.0, -10.0, 60.0])


@pytest.fixture(scope="module")
def arm_case():
    """Two stiff arm movements (cond KJ = 1e3, 1e4), W = τ0 KJ, Arimoto with Eq 10's gain."""
    rng = np.random.default_rng(1)
    KJ = np.stack([spd_with_cond(rng, 4, c) for c in (1e3, 1e4)])
    tau0 = tau = 0.2
    W = tau0 * KJ
    refs = []
    for K, Wi in zip(KJ, W):
        k = eq10_gain(arm4_jac(ARM_Q0), Wi, tau0)
        g = arimoto(k, tau)
        refs.append(arm_radau(ARM_Q0, ARM_TARGET, K, ARM_REST, Wi, lambda t, x, J, g=g: g(t) * (ARM_TARGET - x)))
    model = pj.Lambda0PMP(pj.ShoulderElbowArm(), KJ=KJ, q_rest=ARM_REST, W=W)
    planner = pj.ArimotoPlanner(k=None, tau=tau, tau0=tau0)
    return model, planner, np.stack(refs)


def test_rodas4_matches_radau_on_stiff_arm_movements(arm_case):
    model, planner, ref = arm_case
    kw = dict(duration=1.0, dt=1.0 / ((SAMPLES - 1) * 5), saveat=pj.SaveAt(ts=TS))
    tr = pj.simulate(model, planner, ARM_Q0, ARM_TARGET, solver="rodas4", **kw)
    assert np.all(np.asarray(tr.status) == 0)
    err = np.rad2deg(np.abs(np.asarray(tr.q) - ref)).max(axis=(1, 2))
    assert np.all(err <= 0.01), err
    # the same step is far outside RK4's stability region: refused, with the way out named
    with pytest.raises(ValueError, match="too large for RK4.*rodas4"):
        pj.simulate(model, planner, ARM_Q0, ARM_TARGET, solver="rk4", **kw)


def test_rodas4_matches_radau_with_the_time_base_generator():
    # Stiff at the end: γ = ξ̇/(1 − ξ) grows without bound as the hand arrives, up to its cap
    # (2000 /s here: RK4 needs dt < 1.25 ms); cond KJ = 1e4, W = τ0 KJ.
    rng = np.random.default_rng(2)
    KJ = spd_with_cond(rng, 4, 1e4)
    W = 0.2 * KJ
    T, cap = 1.0, 2000.0

    def force(t, x, J):  # F = γ B (x_d − x), so that ẋ = γ (x_d − x)
        B = np.linalg.inv(J @ np.linalg.inv(W) @ J.T)
        return minjerk_gain(t, T, cap) * B @ (ARM_TARGET - x)

    ref = arm_radau(ARM_Q0, ARM_TARGET, KJ, ARM_REST, W, force)
    model = pj.Lambda0PMP(pj.ShoulderElbowArm(), KJ=KJ, q_rest=ARM_REST, W=W)
    planner = pj.MinimumJerkPlanner(duration=T, gain_cap=cap)
    kw = dict(duration=T, dt=T / ((SAMPLES - 1) * 5), saveat=pj.SaveAt(ts=TS))
    tr = pj.simulate(model, planner, ARM_Q0, ARM_TARGET, solver="rodas4", **kw)
    assert int(tr.status) == 0
    assert np.rad2deg(np.abs(np.asarray(tr.q) - ref)).max() <= 0.01
    with pytest.raises(ValueError, match="too large for RK4"):
        pj.simulate(model, planner, ARM_Q0, ARM_TARGET, solver="rk4", **kw)


def test_rodas4_on_stiff_wrist_movements_is_fourth_order():
    # Wrist (Eq 6), Figure 3's duration, Eq 10's gain at cond KJ = 1e4, and the Figure 3 model:
    # within 0.01° of Radau at 5 steps per sample; halving the step divides the error by ~2⁴.
    rng = np.random.default_rng(3)
    KJ = np.stack([spd_with_cond(rng, 3, 1e4), np.diag([0.5, 1.5, 2.0])])
    q_rest = np.deg2rad([5.0, 0.0, 0.0])
    T, tau0 = 0.4, 0.08
    q0, x_d = np.zeros(3), np.array([0.15, 0.2])
    ts = np.asarray(TS) * T
    refs = []
    for K in KJ:
        W = tau0 * K
        g = arimoto(eq10_gain(wrist_jac(q0), W, tau0), tau0)
        sol = solve_ivp(lambda t, q, K=K, W=W, g=g: pmp_qdot(q, t, x_d, K, q_rest, W, g), (0.0, T), q0,
                        t_eval=ts, **RADAU)
        refs.append(sol.y.T)
    refs = np.stack(refs)
    model = pj.Lambda0PMP(pj.Wrist(), KJ=KJ, q_rest=q_rest, W=tau0 * KJ)
    planner = pj.ArimotoPlanner(k=None, tau=tau0, tau0=tau0)
    errs = []
    for steps in (2, 4):
        tr = pj.simulate(model, planner, q0, x_d, duration=T, dt=T / ((SAMPLES - 1) * steps),
                         saveat=pj.SaveAt(ts=tuple(ts)), solver="rodas4")
        errs.append(np.rad2deg(np.abs(np.asarray(tr.q) - refs)).max(axis=(1, 2)))
    assert np.all(errs[1] <= 0.01), errs
    assert 10 < errs[0][1] / errs[1][1] < 25  # the smooth Figure 3 movement: fourth order (16)


def _grad_problem():
    chain = pj.Wrist()
    q0 = np.zeros(3)
    targets = np.array([[0.15, 0.2], [-0.2, 0.05]])
    K0 = np.array([[1.2, 0.3, 0.0], [0.3, 0.4, 0.1], [0.0, 0.1, 2.4]])
    q_rest = np.deg2rad([5.0, -3.0, 2.0])

    def loss(v):
        """A scalar of the trajectories: v = (3 KJ diagonal scalings, log τ0)."""
        KJ = K0 * jnp.exp(v[:3])[:, None] * jnp.exp(v[:3])[None, :]
        tau0 = jnp.exp(v[3])
        model = pj.Lambda0PMP(chain, KJ=KJ, q_rest=q_rest, W=tau0 * KJ)
        planner = pj.ArimotoPlanner(k=None, tau=0.08, tau0=tau0)
        tr = pj.simulate(model, planner, q0, targets, duration=0.4, dt=0.01, saveat=pj.SaveAt(every=5),
                         solver="rodas4")
        return jnp.sum(jnp.sin(3.0 * tr.q)) + jnp.sum(tr.x**2)

    return loss, np.array([0.1, -0.2, 0.05, np.log(0.08)])


def test_rodas4_gradients_match_central_differences():
    loss, v = _grad_problem()
    # one compile for values and reverse-mode gradient: the differences use the value half
    vg = pj.fast_compile_jit(jax.value_and_grad(loss))
    fd = central_diff(lambda u: vg(jnp.asarray(u))[0], v)
    g_rev = np.asarray(vg(jnp.asarray(v))[1])
    g_fwd = np.asarray(pj.fast_compile_jit(jax.jacfwd(loss))(jnp.asarray(v)))
    scale = np.abs(fd).max()
    assert np.allclose(g_rev, fd, atol=1e-6 * scale), (g_rev, fd)
    assert np.allclose(g_fwd, g_rev, atol=1e-12 * scale)


def test_rodas4_batch_equals_single_calls(arm_case):
    model, planner, _ = arm_case
    kw = dict(duration=1.0, dt=1.0 / ((SAMPLES - 1) * 5), saveat=pj.SaveAt(ts=TS), solver="rodas4")
    batch = pj.simulate(model, planner, ARM_Q0, ARM_TARGET, **kw)
    for i in range(2):
        one = pj.simulate(pj.Lambda0PMP(model.chain, KJ=model.KJ[i], q_rest=model.q_rest, W=model.W[i]),
                          planner, ARM_Q0, ARM_TARGET, **kw)
        np.testing.assert_allclose(np.asarray(one.q), np.asarray(batch.q)[i], rtol=0, atol=1e-12)


@pytest.mark.bad_input("pj.simulate", "pj.simulate_sequence")
def test_unknown_solver_is_refused_by_name():
    model = pj.Lambda0PMP(pj.Wrist(), KJ=np.eye(3), q_rest=np.zeros(3), W=0.1 * np.eye(3))
    for bad in ("radau", None, 4):
        with pytest.raises(ValueError, match="`solver`"):
            pj.simulate(model, pj.ConstantPlanner(5.0), np.zeros(3), np.array([0.1, 0.0]), duration=0.1,
                        solver=bad)


def test_pivoted_lu_matches_lapack(rng):
    # the per-trajectory linear solves of every RODAS4 step: leading pivots of zero need pivoting
    for m in (2, 3, 4, 5):
        A = rng.normal(size=(m, m, 9))
        A[0, 0, :4] = 0.0
        b = rng.normal(size=(m, 9))
        lu = lu_factor_lists([[jnp.asarray(A[i, j]) for j in range(m)] for i in range(m)])
        x = np.stack(lu_solve_lists(lu, [jnp.asarray(b[i]) for i in range(m)]))
        ref = np.stack([np.linalg.solve(A[..., k], b[:, k]) for k in range(9)], -1)
        np.testing.assert_allclose(x, ref, rtol=1e-10, atol=1e-12)



def test_rodas4_tableau_satisfies_the_rosenbrock_order_conditions():
    # The coefficients in rodas.f's form (a, c, m, d, alpha) converted back to Hairer & Wanner's
    # (alpha_ij, gamma_ij) (IV.7.25: C = diag(1/γ) − Γ⁻¹, A = αΓ⁻¹, m = bΓ⁻¹) and checked against the
    # eight order-4 conditions of Table IV.7.1, the embedded solution (the last stage's argument,
    # stiffly accurate) against the four of order 3, and alpha_i, d_i = gamma_i against the row sums.
    from pmpjax._pmp.integrate import RODAS4 as tab

    s, g = len(tab.alpha), tab.gamma
    A, C = np.zeros((s, s)), np.zeros((s, s))
    for i in range(s):
        A[i, : len(tab.a[i])], C[i, : len(tab.c[i])] = tab.a[i], tab.c[i]
    G = np.linalg.inv(np.eye(s) / g - C)
    al, b, bh = A @ G, np.asarray(tab.m) @ G, A[-1] @ G
    np.testing.assert_allclose(np.diag(G), g, rtol=0, atol=1e-14)
    np.testing.assert_allclose(al.sum(1), tab.alpha, rtol=0, atol=1e-13)
    np.testing.assert_allclose(G.sum(1), tab.d, rtol=0, atol=1e-13)
    beta = al + G - np.diag(np.diag(G))
    bp, a1 = beta.sum(1), al.sum(1)
    order4 = [b.sum(), b @ bp, b @ a1**2, b @ beta @ bp, b @ a1**3, b @ (a1 * (al @ bp)), b @ beta @ a1**2,
              b @ beta @ beta @ bp]
    rhs = [1, 0.5 - g, 1 / 3, 1 / 6 - g + g * g, 1 / 4, 1 / 8 - g / 3, 1 / 12 - g / 3,
           1 / 24 - g / 2 + 1.5 * g * g - g**3]
    np.testing.assert_allclose(order4, rhs, rtol=0, atol=1e-13)
    np.testing.assert_allclose([bh.sum(), bh @ bp, bh @ a1**2, bh @ beta @ bp], rhs[:4], rtol=0, atol=1e-13)
    # L-stable: R(∞) = 1 − bᵀ(α + Γ)⁻¹ 1 = 0 (stability function R(z) = 1 + z bᵀ(I − z(α + Γ))⁻¹ 1).
    assert abs(1.0 - b @ np.linalg.solve(al + G, np.ones(s))) < 1e-13


def test_rodas4_step_with_stages_in_a_loop_is_the_documented_stage_equation():
    # One step of a time-dependent linear field y' = A y + sin(3t) b (∂f/∂t ≠ 0, so every stage's
    # d_i h ∂f/∂t term counts) against NumPy: (I/(γh) − A) U_i = f(t + α_i h, y + Σ a_ij U_j)
    # + Σ (c_ij/h) U_j + d_i h ∂f/∂t, y_next = y + Σ m_i U_i; both kernels (stages unrolled or looped).
    from pmpjax._pmp.integrate import RODAS4 as tab
    from pmpjax._pmp.integrate import rosenbrock_step

    A = np.array([[-50.0, 1.0], [0.5, -0.3]])
    bv = np.array([1.0, -2.0])
    t, h, y = 0.3, 0.05, np.array([[0.4], [-0.1]])

    def f(t_, y_, _):
        return jnp.asarray(A) @ y_ + jnp.sin(3.0 * t_) * jnp.asarray(bv)[:, None]

    M = np.eye(2) / (tab.gamma * h) - A
    ft = 3.0 * np.cos(3.0 * t) * bv[:, None]
    U = []
    for i in range(len(tab.alpha)):
        yi = y + sum(a * u for a, u in zip(tab.a[i], U))
        rhs = A @ yi + np.sin(3.0 * (t + tab.alpha[i] * h)) * bv[:, None] + tab.d[i] * h * ft
        rhs = rhs + sum(c / h * u for c, u in zip(tab.c[i], U))
        U.append(np.linalg.solve(M, rhs))
    ref = y + sum(m * u for m, u in zip(tab.m, U))
    for loop in (False, True):
        out = jax.jit(lambda y_, lp=loop: rosenbrock_step(f, t, y_, h, None, stage_loop=lp))(jnp.asarray(y))
        np.testing.assert_allclose(np.asarray(out), ref, rtol=1e-12, atol=1e-15)
