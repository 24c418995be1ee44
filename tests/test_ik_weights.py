"""IK-weight identification (Khoramshahi et al. 2022): Algorithm 1, its QP, the examples of
Figs 1 and 3, batching and masks, the gradient-based variant, analysis and the cross-model check.
References: scipy.optimize.lsq_linear (QP), closed forms from the paper (Eqs 13–14), SciPy
t-tests / direct NumPy formulas (Hotelling), central differences (gradients), autodiff (Jacobian).
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.optimize
import scipy.stats

import fitting
import pmpjax as pj
from fitting._ik.examples import FIG1_W, fig1_data, fig3_data
from fitting._ik.weights import box_qp_update, qp_matrices

W_STAR = np.array(FIG1_W)


@pytest.fixture(scope="module")
def fig1():
    q, x, J = fig1_data(jax.random.PRNGKey(1), n_reps=100)
    return np.asarray(q), np.asarray(x), np.asarray(J)


@pytest.fixture(scope="module")
def fig1_result(fig1):
    return fitting.estimate_ik_weights(*fig1, gamma=0.6, max_iter=150)


# ---------------------------------------------------------------------------------------------
# the update step


def test_closed_form_update_equals_qp_solver(rng):
    """Eq 24 with bounds [w_min, 1] (Ψ̃, Ω̃ of lines 16–17) solved by SciPy == closed form."""
    for _ in range(20):
        n = int(rng.integers(2, 7))
        Qd = rng.standard_normal((n, 40))
        V = 0.3 * rng.standard_normal((n, 40))
        U = rng.standard_normal((n, 40)) * rng.uniform(0.1, 2.0, (n, 1))
        psi, omega = (Qd - V) @ Qd.T, U @ Qd.T
        Pt, Ot, H, F = (np.asarray(a) for a in qp_matrices(psi, omega))
        assert np.allclose(H, np.diag(np.diag(H)))  # the Hessian is diagonal
        assert np.allclose(F, -(Ot @ Pt))
        ref = scipy.optimize.lsq_linear(Pt, Ot, bounds=(1e-3, 1.0), tol=1e-14).x
        got = np.asarray(box_qp_update(psi, omega, w_min=1e-3))
        assert np.allclose(got, ref, atol=1e-8), (got, ref)


# ---------------------------------------------------------------------------------------------
# the paper's examples


def test_fig1_setting_recovers_true_weights(fig1_result):
    w = np.asarray(fig1_result.w)
    assert w.shape == (100, 5)
    assert np.all(np.abs(w.mean(0) - W_STAR) < 0.03), w.mean(0)
    assert np.allclose(w.max(-1), 1.0)
    hist = np.asarray(fig1_result.error_history)
    # the first evaluation is W = I with no null-space estimate; the error decreases from there
    assert np.all(hist[:, 0] > np.nanmin(hist, axis=1))


def test_fig3_wrong_fixed_point_at_gamma0_right_at_high_gamma():
    q, x, J = fig3_data(k_null=0.3, k_task=2.0)
    gam = np.array([0.0, 0.6, 0.8, 0.9])
    b = lambda a: np.broadcast_to(a, (4,) + a.shape)  # noqa: E731
    res = fitting.estimate_ik_weights(b(q), b(x), b(J), gamma=gam, tol=0.0, step_tol=1e-9, max_iter=3000)
    w = np.asarray(res.w)
    assert np.isclose(w[0, 1], 1.0) and w[0, 0] < 0.05  # γ = 0: "task done by joint 1", w ≈ (0, 1)
    for k in (1, 2, 3):
        assert np.isclose(w[k, 0], 1.0) and w[k, 1] < 0.03, (gam[k], w[k])  # w* = (1, 0.01)
    # the paper's schedule γ_{t+1} = γ_t + c (1 − γ_t) runs γ towards 1
    sch = fitting.estimate_ik_weights(b(q), b(x), b(J), gamma=0.6, gamma_rate=0.6, max_iter=3000)
    it = int(sch.iterations[0])
    assert np.isclose(float(sch.gamma[0]), 1 - 0.4 * 0.4**it)
    assert np.isclose(np.asarray(sch.w)[0, 0], 1.0)


# ---------------------------------------------------------------------------------------------
# batching, masks, failures


def test_batched_equals_per_subject(fig1, fig1_result):
    q, x, J = fig1
    for i in (0, 37):
        one = fitting.estimate_ik_weights(q[i], x[i], J[i], gamma=0.6, max_iter=150)
        assert np.allclose(one.w, fig1_result.w[i], atol=1e-12, rtol=0)
        assert int(one.iterations) == int(fig1_result.iterations[i])


def test_inside_a_callers_jit_equals_eager(fig1, fig1_result):
    """Traced inputs take the strict-summation kernel (compiler options apply to top-level calls
    only); same weights as the eager (reassociated-sum) call to rounding."""
    q, x, J = fig1
    f = jax.jit(lambda q, x, J: fitting.estimate_ik_weights(q, x, J, gamma=0.6, max_iter=150))
    res = f(q[:4], x[:4], J[:4])
    np.testing.assert_allclose(res.w, fig1_result.w[:4], atol=1e-10, rtol=0)
    assert np.array_equal(res.iterations, fig1_result.iterations[:4])


def test_mask_equals_truncation(fig1):
    q, x, J = (a[0].copy() for a in fig1)
    mask = np.arange(500) < 300
    q[300:] = np.nan  # padding is never looked at
    J[300:] = 0.0
    a = fitting.estimate_ik_weights(q, x, J, gamma=0.6, mask=mask, max_iter=150)
    b = fitting.estimate_ik_weights(q[:300], x[:300], J[:300], gamma=0.6, max_iter=150)
    assert np.allclose(a.w, b.w, atol=1e-12, rtol=0)
    assert np.allclose(a.error_history, b.error_history, atol=1e-12, rtol=0, equal_nan=True)


def test_failing_subject_is_flagged_others_go_on(fig1, fig1_result):
    q, x, J = (a.copy() for a in fig1)
    q[5, 10, 2] = np.nan
    J[9, 3] = 0.0  # rank-deficient Jacobian
    with pytest.raises(ValueError, match="qdot"):
        fitting.estimate_ik_weights(q, x, J, gamma=0.6, max_iter=150)
    res = fitting.estimate_ik_weights(q, x, J, gamma=0.6, max_iter=150, on_invalid="flag")
    st = np.asarray(res.status)
    assert st[5] == 2 and st[9] == 2 and np.sum(st != 0) == 2
    assert np.all(np.isnan(res.w[5])) and not res.converged[9]
    ok = np.setdiff1d(np.arange(100), [5, 9])
    assert np.allclose(res.w[ok], fig1_result.w[ok], atol=1e-12, rtol=0)


def test_bad_input_raises_clear_errors(fig1):
    q, x, J = (a[0] for a in fig1)
    est = fitting.estimate_ik_weights
    with pytest.raises(ValueError, match="J"):
        est(q, x, J[:, :, :4])  # n mismatch
    with pytest.raises(ValueError, match="J"):
        est(q, x[:, :2], J)  # m mismatch
    with pytest.raises(ValueError, match="sample axes"):
        est(q[:400], x, J)  # K mismatch
    with pytest.raises(ValueError, match="gamma"):
        est(q, x, J, gamma=1.2)
    with pytest.raises(ValueError, match="gamma"):
        est(q, x, J, gamma=-0.1)
    with pytest.raises(ValueError, match="gamma_rate"):
        est(q, x, J, gamma_rate=2.0)
    xb = x.copy()
    xb[3] = np.nan
    with pytest.raises(ValueError, match="xdot"):
        est(q, xb, J)
    Jr = J.copy()
    Jr[7] = np.outer(Jr[7, :, 0], np.ones(5))  # rank 1
    with pytest.raises(ValueError, match="rank-deficient"):
        est(q, x, Jr)
    with pytest.raises(ValueError, match="mask"):
        est(q, x, J, mask=np.ones(10, bool))
    with pytest.raises(ValueError, match="redundant"):
        est(q[:, :3], x, J[:, :, :3])
    with pytest.raises(ValueError, match="fixed"):
        est(q, x, J, fixed=(0, 1, 2, 3, 4))


# ---------------------------------------------------------------------------------------------
# the gradient-based variant


def test_model_error_gradient_matches_central_differences(fig1):
    q, x, J = (a[0, :50] for a in fig1)
    f = jax.jit(lambda w: fitting.ik_model_error(w, q, x, J, 0.6))
    w0 = np.array([0.9, 0.7, 0.5, 0.45, 0.3])
    g = np.asarray(jax.grad(f)(jnp.asarray(w0)))
    h = 1e-6
    fd = np.array([(f(w0 + h * e) - f(w0 - h * e)) / (2 * h) for e in np.eye(5)])
    assert np.allclose(g, fd, rtol=1e-6, atol=1e-9)
    # scale invariance of Eq 4: the error does not change along w
    assert abs(float(g @ w0)) < 1e-10


def test_gradient_variant_agrees_with_algorithm1(fig1, fig1_result):
    q, x, J = (a[:4] for a in fig1)
    lm = fitting.estimate_ik_weights_lm(q, x, J, gamma=0.6)
    assert bool(np.all(lm.converged))
    assert np.all(np.abs(np.asarray(lm.w) - W_STAR) < 0.06)
    assert np.allclose(lm.w, fig1_result.w[:4], atol=0.06)
    # it minimises the modelling error: no worse than Algorithm 1's weights
    e_lm = fitting.ik_model_error(lm.w, q, x, J, 0.6)
    e_a1 = fitting.ik_model_error(fig1_result.w[:4], q, x, J, 0.6)
    assert np.all(np.asarray(e_lm) <= np.asarray(e_a1) + 1e-9)


# ---------------------------------------------------------------------------------------------
# analysis


def test_decomposition_reproduces_eqs_13_14():
    q = np.array([[0.0, 1.0]])
    J = np.array([[[1.0, 1.0]]])
    x = np.array([[1.0]])
    task, null = fitting.ik_decomposition(q, x, J, np.array([1.0, 1.0]))
    assert np.allclose(task, [[0.5, 0.5]]) and np.allclose(null, [[-0.5, 0.5]])
    task, null = fitting.ik_decomposition(q, x, J, np.array([1.0, 1 / 9]))
    assert np.allclose(task, [[0.1, 0.9]]) and np.allclose(null, [[-0.1, 0.1]])


def test_contribution_coefficients_eq26():
    w = np.array([[1.0, 0.148, 0.062, 1.0], [0.5, 0.25, 1.0, 1.0]])
    beta = np.asarray(fitting.contribution_coefficients(w))
    ref = (1 / w) / (1 / w).sum(-1, keepdims=True)
    assert np.allclose(beta, ref) and np.allclose(beta.sum(-1), 1.0)
    assert np.allclose(beta[0], [0.04, 0.27, 0.65, 0.04], atol=0.01)  # paper, Natural condition
    g = jax.grad(lambda v: fitting.contribution_coefficients(v)[2])(jnp.asarray(w[1]))
    h = 1e-6
    fd = [(float(fitting.contribution_coefficients(w[1] + h * e)[2])
           - float(fitting.contribution_coefficients(w[1] - h * e)[2])) / (2 * h) for e in np.eye(4)]
    assert np.allclose(g, fd, rtol=1e-6, atol=1e-10)


def test_overspecified_joint_of_the_4dof_arm(rng):
    arm = pj.Arm4()
    q = rng.uniform([-1.2, -1.2, -0.8, 0.3], [-0.1, 0.0, 0.4, 2.0], (50, 4))
    assert list(fitting.overspecified_joints(arm.jacobian(q))) == [False, False, False, True]
    planar = pj.PlanarArm([0.3, 0.3, 0.2])
    qp = rng.uniform(0.3, 1.5, (50, 3))
    assert not fitting.overspecified_joints(planar.jacobian(qp)).any()


def test_hotelling_against_scipy(rng):
    a = rng.standard_normal((17, 2)) + [0.3, 0.0]
    b = a + 0.5 * rng.standard_normal((17, 2)) + [0.2, -0.1]
    res = fitting.hotelling_t2(a, b, paired=True)
    d = a - b
    S = np.cov(d, rowvar=False)
    t2 = 17 * d.mean(0) @ np.linalg.solve(S, d.mean(0))
    F = (17 - 2) / (2 * 16) * t2
    assert np.isclose(float(res.t2), t2) and np.isclose(float(res.f), F)
    assert np.isclose(float(res.p), scipy.stats.f.sf(F, 2, 15), rtol=1e-8)
    assert (int(res.df1), int(res.df2)) == (2, 15)
    # two independent samples
    c = rng.standard_normal((12, 3))
    e = rng.standard_normal((15, 3)) + 0.4
    ind = fitting.hotelling_t2(c, e, paired=False)
    Sp = ((c - c.mean(0)).T @ (c - c.mean(0)) + (e - e.mean(0)).T @ (e - e.mean(0))) / 25
    dm = c.mean(0) - e.mean(0)
    t2i = 12 * 15 / 27 * dm @ np.linalg.solve(Sp, dm)
    Fi = 23 / (3 * 25) * t2i
    assert np.isclose(float(ind.t2), t2i) and np.isclose(float(ind.p), scipy.stats.f.sf(Fi, 3, 23))
    # one variable: T² = t² and the same p as SciPy's t-tests
    r1 = fitting.hotelling_t2(a[:, :1], b[:, :1], paired=True)
    t = scipy.stats.ttest_rel(a[:, 0], b[:, 0])
    assert np.isclose(float(r1.t2), t.statistic**2) and np.isclose(float(r1.p), t.pvalue)
    r2 = fitting.hotelling_t2(c[:, :1], e[:, :1], paired=False)
    t = scipy.stats.ttest_ind(c[:, 0], e[:, 0])
    assert np.isclose(float(r2.t2), t.statistic**2) and np.isclose(float(r2.p), t.pvalue)


def test_arm4_jacobian_against_autodiff_and_differences(rng):
    arm = pj.Arm4(L1=0.31, L2=0.35)
    q = rng.uniform(-1.0, 1.0, (6, 4))
    J = np.asarray(arm.jacobian(q))
    assert np.allclose(J, jax.jit(jax.vmap(jax.jacfwd(arm.fk)))(jnp.asarray(q)), atol=1e-13)
    h = 1e-6
    fd = np.stack([(arm.fk(q + h * e) - arm.fk(q - h * e)) / (2 * h) for e in np.eye(4)], -1)
    assert np.allclose(J, fd, atol=1e-8)
    # README: q2 = −90° puts the straight arm forward (+x) at L1 + L2
    assert np.allclose(arm.fk(jnp.array([0.0, -np.pi / 2, 0.0, 0.0])), [0.66, 0.0, 0.0], atol=1e-12)
    # lengths are differentiable leaves
    gL = jax.grad(lambda L: pj.Arm4(L1=L, L2=0.35).fk(jnp.asarray(q[0]))[2])(0.31)
    fdL = (pj.Arm4(L1=0.31 + h, L2=0.35).fk(q[0])[2] - pj.Arm4(L1=0.31 - h, L2=0.35).fk(q[0])[2]) / (2 * h)
    assert np.isclose(gL, fdL, atol=1e-8)


# ---------------------------------------------------------------------------------------------
# cross-model check


def test_lambda0_pmp_movements_give_back_W():
    """λ0-PMP: q̇ = J#_W ẋ − N_W W⁻¹ KJ (q − q_rest) (design §3.1). Its task part is exactly the
    weighted pseudo-inverse of Eq 15, its null part the elastic pull to the rest posture. That
    pull is correlated with the movement, and Algorithm 1 explains part of it by tilting W (with
    KJ = 0.02 I, ‖q̇_null‖ ≈ 5 % of ‖q̇‖ gives w off by ≈ 13 %), so we use movements from many
    start postures with a weak elastic term (KJ = 0.004 I: ‖q̇_null‖ ≈ 1 %), the regime in which
    the paper's model (task part + small null-space part) holds, and require W within 5 %.
    """
    arm = pj.PlanarArm([0.35, 0.3, 0.25])
    w_true = np.array([1.0, 0.5, 0.2])
    KJ = 0.004 * np.eye(3)
    rng = np.random.default_rng(3)
    q0 = np.array([0.4, 1.0, 0.9]) + 0.25 * rng.standard_normal((12, 3))
    x0 = np.asarray(arm.fk(q0))
    ang = rng.uniform(0, 2 * np.pi, 12)
    target = x0 + 0.12 * np.stack([np.cos(ang), np.sin(ang)], -1)
    model = pj.Lambda0PMP(arm, KJ=KJ, q_rest=np.array([0.4, 1.0, 0.9]), W=np.diag(w_true))
    traj = pj.simulate(model, pj.ConstantPlanner(3.0), q0, target, duration=0.6, dt=5e-3,
                       saveat=pj.SaveAt(every=4))
    assert np.all(np.asarray(traj.status) == 0)
    J = arm.jacobian(traj.q)
    K = traj.q.shape[0] * traj.q.shape[1]
    res = fitting.estimate_ik_weights(np.asarray(traj.qdot).reshape(K, 3),
                                      np.asarray(traj.xdot).reshape(K, 2),
                                      np.asarray(J).reshape(K, 2, 3), gamma=0.6, tol=0.0,
                                      step_tol=1e-10, max_iter=3000)
    assert bool(res.converged)
    w = np.asarray(res.w)
    assert np.all(np.abs(w / w.max() - w_true) <= 0.05 * w_true), w


# ---------------------------------------------------------------------------------------------
# the list-level kernels of the fused Algorithm-1 loop, and items split over devices


def test_list_level_solve_and_pinv_against_numpy(rng):
    """``spd_solve_lists`` (closed forms for m <= 3, LDLᵀ above) and ``pinv_diag_lists`` ==
    ``numpy.linalg.solve`` and the NumPy formula ``W⁻¹ Jᵀ (J W⁻¹ Jᵀ)⁻¹ b``."""
    from pmpjax._base.linalg import spd_solve_lists
    from pmpjax._pmp.redundancy import pinv_diag_lists

    for m in (1, 2, 3, 4):
        A = rng.standard_normal((6, m, m + 2))
        M = A @ np.swapaxes(A, -1, -2) + 0.1 * np.eye(m)  # (6, m, m) SPD
        b1, b2 = rng.standard_normal((2, 6, m))
        Ml = [[jnp.asarray(M[:, r, c]) for c in range(m)] for r in range(m)]
        got = spd_solve_lists(Ml, list(jnp.asarray(b1.T)), list(jnp.asarray(b2.T)))
        for b, y in zip((b1, b2), got):
            assert np.allclose(np.stack(y, -1), np.linalg.solve(M, b[..., None])[..., 0], rtol=1e-10, atol=1e-12)
    n, m = 5, 3
    J = rng.standard_normal((6, m, n))
    w = rng.uniform(0.05, 1.0, (6, n))
    b = rng.standard_normal((6, m))
    Jl = [[jnp.asarray(J[:, r, i]) for i in range(n)] for r in range(m)]
    (got,) = pinv_diag_lists(Jl, list(jnp.asarray(1.0 / w.T)), list(jnp.asarray(b.T)))
    JA = J / w[:, None, :]
    ref = np.einsum("kir,kr->ki", np.swapaxes(JA, -1, -2) @ np.linalg.inv(JA @ np.swapaxes(J, -1, -2)), b)
    assert np.allclose(np.stack(got, -1), ref, rtol=1e-10, atol=1e-12)


_TWO_DEVICES = r"""
import json, jax, numpy as np
jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_rank_promotion", "raise")
import fitting
from fitting._ik.examples import fig1_data
q, x, J = (np.array(a) for a in fig1_data(jax.random.PRNGKey(2), n_reps=7, K=120))
q[3, 5, 1] = np.nan  # a flagged item
mask = np.ones((7, 120), bool); mask[5, 80:] = False  # a ragged item
run = lambda devs: fitting.estimate_ik_weights(q, x, J, gamma=0.6, mask=mask, max_iter=60,
                                              on_invalid="flag", devices=devs)
one, two = run(jax.devices()[:1]), run(None)
print(json.dumps({"devices": len(jax.devices()), "w1": np.asarray(one.w).tolist(),
                  "w2": np.asarray(two.w).tolist(), "it1": np.asarray(one.iterations).tolist(),
                  "it2": np.asarray(two.iterations).tolist(), "st1": np.asarray(one.status).tolist(),
                  "st2": np.asarray(two.status).tolist(), "out_devices": len(two.w.devices())}))
"""


def test_items_split_over_two_devices_equal_one_device():
    """``devices``: 7 items split over 2 CPU devices (padding, a flagged and a ragged item) give
    the single-device weights, iterations and statuses, gathered on one device."""
    import json
    import os
    import subprocess
    import sys

    env = dict(os.environ, XLA_FLAGS=(os.environ.get("XLA_FLAGS", "")
                                      + " --xla_force_host_platform_device_count=2").strip())
    proc = subprocess.run([sys.executable, "-c", _TWO_DEVICES], capture_output=True, text=True,
                          env=env, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    r = json.loads(proc.stdout.strip().splitlines()[-1])
    assert r["devices"] == 2 and r["out_devices"] == 1
    w1, w2 = np.array(r["w1"]), np.array(r["w2"])
    assert r["st1"] == r["st2"] and r["st1"][3] == 2 and sum(r["st1"]) == 2
    assert r["it1"] == r["it2"]
    assert np.allclose(w1, w2, atol=1e-12, rtol=0, equal_nan=True)
