"""IK-weight identification (Khoramshahi et al. 2022): Algorithm 1, its stopping statuses, the
examples of Figs 1 and 3, batching and masks, the gradient-based variant, analysis (β, bootstrap,
Hotelling) and the cross-model check.

References: an independent NumPy/SciPy Algorithm 1 (``tests/_reference.algorithm1``: per-iteration
``scipy.optimize.lsq_linear`` box QP) on data generated with ``np.linalg`` (``_reference``), the
paper's printed numbers (Figs 1 and 3, Eqs 13–14, β of Experiment 1), SciPy t-tests and direct
NumPy formulas (Hotelling), central differences (gradients), binomial bounds (bootstrap coverage).
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.optimize
import scipy.stats
from _reference import algorithm1, arm4_fk, arm4_jac, central_diff, ik_fig1_numpy, ik_fig3_numpy, weighted_pinv

import fitting
import pmpjax as pj
from fitting._ik.datasets import W_NATURAL, W_VISCOUS
from fitting._ik.examples import FIG1_W

W_STAR = np.array(FIG1_W)
S = pj.Status


@pytest.fixture(scope="module")
def fig1():
    """The paper's Fig 1 setting (100 repetitions, K = 500), generated with NumPy."""
    return ik_fig1_numpy(np.random.default_rng(1), n_reps=100)


@pytest.fixture(scope="module")
def fig1_result(fig1):
    # the default max_steps (200): the README's call of test_readme_case_... shares this compile
    return fitting.estimate_ik_weights(*fig1, gamma=0.6)


def _batch4(*arrays):
    return [np.broadcast_to(a, (4,) + a.shape) for a in arrays]


# ---------------------------------------------------------------------------------------------
# Algorithm 1 against the independent reference


def test_algorithm1_equals_reference_on_fig1(fig1, fig1_result):
    """Weights after the last update and the whole error history == the NumPy/SciPy Algorithm 1
    (lsq_linear box QP each iteration) run for the same number of updates."""
    q, x, J = fig1
    for i in (0, 1):
        it = int(fig1_result.iterations[i])
        ws, errs, _ = algorithm1(q[i], x[i], J[i], 0.6, it)
        np.testing.assert_allclose(fig1_result.w[i], ws[-1], atol=1e-12, rtol=0)
        np.testing.assert_allclose(fig1_result.error_history[i, :it], errs, rtol=1e-12, atol=0)
        assert np.all(np.isnan(fig1_result.error_history[i, it:]))


def test_algorithm1_equals_reference_on_random_data():
    """Random J, q̇, ẋ (ẋ ≠ J q̇, no IK model at all), per-item γ, a γ schedule, a fixed joint and a
    large w_min so that the lower bound of the box QP is active."""
    rng = np.random.default_rng(5)
    B, K, n, m = 3, 40, 4, 2
    q = rng.standard_normal((B, K, n)) * rng.uniform(0.2, 3.0, n)
    x = rng.standard_normal((B, K, m))
    J = rng.standard_normal((B, K, m, n))
    gam = np.array([0.0, 0.5, 0.9])
    for rate, fixed, w_min in ((None, (), 0.3), (0.3, (2,), 0.05)):
        res = fitting.estimate_ik_weights(q, x, J, gamma=gam, gamma_rate=rate, fixed=fixed or None, w_min=w_min,
                                          tol=0.0, step_tol=0.0, max_steps=12)
        assert np.all(res.iterations == 12) and np.all(res.status == S.MAX_STEPS)
        raws = []
        for b in range(B):
            ws, errs, raw = algorithm1(q[b], x[b], J[b], gam[b], 12, w_min=w_min, gamma_rate=rate or 0.0, fixed=fixed)
            np.testing.assert_allclose(res.w[b], ws[-1], atol=1e-11, rtol=0)
            np.testing.assert_allclose(res.error_history[b], errs, rtol=1e-11, atol=0)
            raws.append(raw)
        if w_min == 0.3:
            assert np.any(np.concatenate(raws) == 0.3)  # the lower bound of the QP is active


def test_fig3_data_equals_numpy_generator():
    for kw in ({}, dict(k_null=0.3, k_task=2.0, w_true=(1.0, 0.05))):
        got = fitting.ik_fig3_data(**kw)
        ref = ik_fig3_numpy(**{("w" if k == "w_true" else k): v for k, v in kw.items()})
        for a, b in zip(got, ref):
            np.testing.assert_allclose(a, b, rtol=0, atol=1e-14)


def test_fig1_data_follows_eq15():
    """σ = 0: q̇ = J#_{W*} ẋ (NumPy formula); σ > 0: J q̇ = ẋ and the null-space part is linear in σ.
    (The default sizes, 100 × 500: the README's call in test_readme_case_... shares the compile.)"""
    key = jax.random.PRNGKey(3)
    q0, x0, J0 = (np.asarray(a) for a in fitting.ik_fig1_data(key, sigma=0.0))
    np.testing.assert_allclose(q0, np.einsum("rkij,rkj->rki", weighted_pinv(J0, W_STAR), x0), atol=1e-12)
    q1, x1, J1 = (np.asarray(a) for a in fitting.ik_fig1_data(key, sigma=0.2))
    q2 = np.asarray(fitting.ik_fig1_data(key, sigma=0.4)[0])
    assert np.array_equal(x1, x0) and np.array_equal(J1, J0)
    np.testing.assert_allclose(np.einsum("rkij,rkj->rki", J1, q1), x1, atol=1e-12)
    np.testing.assert_allclose(q2 - q0, 2 * (q1 - q0), atol=1e-12)
    assert np.linalg.norm(q1 - q0) > 0.1 * np.linalg.norm(q0)


# ---------------------------------------------------------------------------------------------
# the paper's examples


def test_fig1_setting_recovers_true_weights(fig1_result):
    """Fig 1: every weight converges to w* (the mean over 100 repetitions within 10 % of w*;
    Algorithm 1's fixed point is biased by ≈ 0.02 at γ = 0.6, σ = 0.2) and the error decreases
    from the W = I evaluation. The runs end at the fixed point of the update (SUCCESSFUL), not at
    the paper's e ≤ ε: the error of Eq 17 stays near 0.1 with this null-space motion (the paper
    reports 0.07) even at the true weights; the few runs the 200 updates do not finish report
    MAX_STEPS. Converged weights lie within 0.2 of w* (5 standard deviations of the fixed point
    over repetitions, 0.04 at w = 0.8; the least-squares weights of the LM variant are closer)."""
    w = np.asarray(fig1_result.w)
    assert w.shape == (100, 5)
    np.testing.assert_allclose(w.mean(0), W_STAR, rtol=0.1)
    assert np.all(np.diff(w.mean(0)) < 0)
    assert np.allclose(w.max(-1), 1.0)
    hist = np.asarray(fig1_result.error_history)
    assert np.all(hist[:, 0] > np.nanmin(hist, axis=1))
    st = np.asarray(fig1_result.status)
    ok = np.asarray(fig1_result.converged)
    assert np.array_equal(ok, st == S.SUCCESSFUL) and ok.mean() >= 0.95
    assert np.all(np.isin(st, [S.SUCCESSFUL, S.MAX_STEPS]))
    assert np.all(np.abs(w[ok] - W_STAR) <= 0.2)
    assert np.all(np.asarray(fig1_result.ls_gap)[ok] <= 0.15)
    assert 0.05 < float(np.mean(fig1_result.error)) < 0.15


def test_fig3_gamma_sweep_against_reference_and_paper():
    """Fig 3 (null-space gain 0.3, task gain 2): γ = 0 converges to the wrong (0, 1), γ ≥ 0.6 to
    w* = (1, 0.01), closer the higher γ; iterates == the reference for γ = 0 and 0.6."""
    q, x, J = ik_fig3_numpy(k_null=0.3, k_task=2.0)
    gam = np.array([0.0, 0.6, 0.8, 0.9])
    res = fitting.estimate_ik_weights(*_batch4(q, x, J), gamma=gam, tol=0.0, step_tol=1e-9, max_steps=3000)
    w = np.asarray(res.w)
    assert np.all(res.status == S.STALLED)
    assert w[0, 1] == 1.0 and w[0, 0] < 0.05
    assert np.all(w[1:, 0] == 1.0) and w[1, 1] < 0.03 and np.all(np.abs(w[2:, 1] - 0.01) < 0.004)
    assert abs(w[3, 1] - 0.01) < abs(w[2, 1] - 0.01) < abs(w[1, 1] - 0.01)
    for k in (0, 1):
        it = int(res.iterations[k])
        ws, errs, _ = algorithm1(q, x, J, gam[k], it)
        np.testing.assert_allclose(w[k], ws[-1], atol=1e-12, rtol=0)
        np.testing.assert_allclose(res.error_history[k, :it], errs, rtol=1e-10, atol=1e-15)


def test_status_is_honest_about_how_a_run_ended():
    """``converged`` only for a fixed point that is an answer of the model. Fig 3 data at γ = 0.9
    stop at a fixed point w2 ≈ 0.058 (truth 0.01) that is 0.56 (in log w) from the
    least-squares weights of the same error: STALLED, not converged. The paper's schedule
    γ ← γ + 0.6 (1 − γ) stops the updates after 8 with w2 ≈ 0.47: SCHEDULE_END, not converged, also
    on data without null-space motion (w2 ≈ 0.61 there). Data without null-space motion at a
    constant γ = 0.6: the fixed point is the truth, SUCCESSFUL with w2 within 10⁻³ relative of
    0.01. Overflowing data: NONFINITE; no stopping rule within max_steps: MAX_STEPS."""
    a, b = ik_fig3_numpy(), ik_fig3_numpy(k_null=0.0)
    q = np.stack([a[0], b[0], 1e160 * a[0], a[0]])
    x = np.stack([a[1], b[1], 1e160 * a[1], a[1]])
    J = np.broadcast_to(a[2], (4,) + a[2].shape)
    res = fitting.estimate_ik_weights(q, x, J, gamma=np.array([0.9, 0.6, 0.6, 0.9]), max_steps=3000)
    assert list(np.asarray(res.status)) == [S.STALLED, S.SUCCESSFUL, S.NONFINITE, S.STALLED]
    assert list(np.asarray(res.converged)) == [False, True, False, False]
    assert abs(float(res.w[0, 1]) - 0.058) < 0.001 and abs(float(res.w[1, 1]) / 0.01 - 1) < 1e-3
    assert float(res.ls_gap[0]) > 0.5 and float(res.ls_gap[1]) < 1e-3
    sch = fitting.estimate_ik_weights(q, x, J, gamma=0.6, gamma_rate=0.6, max_steps=3000)
    assert list(np.asarray(sch.status)) == [S.SCHEDULE_END, S.SCHEDULE_END, S.NONFINITE, S.SCHEDULE_END]
    assert int(sch.iterations[0]) == 8 and abs(float(sch.w[0, 1]) - 0.469) < 0.001
    assert abs(float(sch.w[1, 1]) - 0.61) < 0.01
    assert np.isclose(float(sch.gamma[0]), 1 - 0.4 * 0.4**8)
    short = fitting.estimate_ik_weights(q, x, J, gamma=0.9, tol=0.0, step_tol=0.0, max_steps=3000)
    assert int(short.status[0]) == S.MAX_STEPS and int(short.iterations[0]) == 3000


# ---------------------------------------------------------------------------------------------
# converged means converged and correct (NumPy/SciPy references)


def _ls_residual(theta, q, x, J, gamma, free):
    """Eq 16 with the weights' own null-space estimate, ``(1 − γ) q̇ − J#(ẋ − γ J q̇)`` (K·n,),
    for ``log w`` of the free joints ``theta`` (the others at 1), in NumPy."""
    w = np.ones(q.shape[-1])
    w[free] = np.exp(theta)
    Jp = weighted_pinv(J, w)
    return ((1 - gamma) * q - np.einsum("kij,kj->ki", Jp, x - gamma * np.einsum("kij,kj->ki", J, q))).ravel()


def _gauss_newton_gap(w, q, x, J, gamma, free):
    """``max |Δ log w|`` of one Gauss–Newton step from ``w`` on the ratios of the free weights:
    derivatives by central differences, the minimum-norm least-squares step (orthogonal to the
    common scale)."""
    theta = np.log(np.asarray(w)[free])
    f = lambda t: _ls_residual(t, q, x, J, gamma, free)  # noqa: E731
    D = central_diff(f, theta, scale=1.0).T
    P = np.eye(len(theta)) - 1.0 / len(theta)
    return np.abs(np.linalg.lstsq(D @ P, -f(theta), rcond=None)[0]).max()


def _ls_weights(q, x, J, gamma, free, w_min=1e-3):
    """The least-squares weights of the same error by SciPy (trust region, ``w ≥ w_min``),
    normalised to ``max w = 1``: the first free weight is held at 1, the others fitted."""
    free = np.flatnonzero(free)
    res = scipy.optimize.least_squares(
        lambda t: _ls_residual(np.r_[0.0, t], q, x, J, gamma, free), np.zeros(len(free) - 1),
        bounds=(np.log(w_min), -np.log(w_min)), xtol=1e-14, ftol=1e-14, gtol=1e-14)
    w = np.ones(q.shape[-1])
    w[free] = np.exp(np.r_[0.0, res.x])
    w[free] /= w[free].max()
    return np.maximum(w, w_min)


def test_readme_case_converges_to_the_fixed_point_and_the_truth():
    """The README's call (Fig 1 data from ``ik_fig1_data``, PRNGKey(0), defaults): at least 98
    of the 100 items converge; their weights are within 0.2 of w* (5 standard deviations of the
    fixed point over repetitions; 0.124 here), within tol (10⁻³, relative) of the fixed point of the NumPy/SciPy
    Algorithm 1 run until its steps vanish, and their ``ls_gap`` equals a NumPy Gauss–Newton step
    (central differences) and is at most ``ls_tol`` = 0.15, the SciPy least-squares weights being
    as close. Velocities in other units (× 10⁻³) give the same weights and statuses (the paper's
    e ≤ ε, in the units of q̇, declared every item converged after one update there)."""
    q, x, J = (np.asarray(a) for a in fitting.ik_fig1_data(jax.random.PRNGKey(0), n_reps=100))
    res = fitting.estimate_ik_weights(q, x, J, gamma=0.6)
    st, w = np.asarray(res.status), np.asarray(res.w)
    ok = st == S.SUCCESSFUL
    assert ok.sum() >= 98 and np.all(st[~ok] == S.MAX_STEPS)
    assert np.all(np.abs(w[ok] - W_STAR) <= 0.2)
    assert np.all(np.asarray(res.ls_gap)[ok] <= 0.15)
    free = np.ones(5, bool)
    for i in np.flatnonzero(ok)[:3]:
        ws, _, _ = algorithm1(q[i], x[i], J[i], 0.6, 600)
        assert np.abs(np.log(ws[-1] / ws[-2])).max() < 1e-12  # the reference is at its fixed point
        assert np.abs(np.log(w[i] / ws[-1])).max() <= 1e-3
        gap = _gauss_newton_gap(w[i], q[i], x[i], J[i], 0.6, free)
        np.testing.assert_allclose(float(res.ls_gap[i]), gap, rtol=1e-5)
        assert np.abs(np.log(w[i] / _ls_weights(q[i], x[i], J[i], 0.6, free))).max() <= 0.15
    small = fitting.estimate_ik_weights(1e-3 * q, 1e-3 * x, J, gamma=0.6)
    assert np.array_equal(np.asarray(small.status), st)
    np.testing.assert_allclose(small.w, w, rtol=1e-9)


def test_fixed_points_far_from_the_least_squares_weights_are_not_successful():
    """Fig 3 data (two prismatic joints, 60 samples) with a null-space pull correlated with the
    task: at γ = 0.9 (pull gain 1) Algorithm 1's fixed point w2 = 0.058 is far (> 2 ls_tol in
    log w) from the SciPy least-squares weights of the same error (w2 at the floor; truth 0.01),
    and at γ = 0 (pull gain 0.3) joint 1's weight falls to 0.04 (truth 1), far from them too: both
    STALLED, with ``ls_gap`` equal to the NumPy Gauss–Newton step. The gradient variant reports the
    floor it hits (w2 → 0) as STALLED, not SUCCESSFUL."""
    a, b = ik_fig3_numpy(), ik_fig3_numpy(k_null=0.3, k_task=2.0)
    # (the two items twice: the batch of four of the tests above, whose compiled run this shares)
    q, x = np.stack([a[0], b[0]] * 2), np.stack([a[1], b[1]] * 2)
    J = np.broadcast_to(a[2], (4,) + a[2].shape)
    gam = np.array([0.9, 0.0] * 2)
    res = fitting.estimate_ik_weights(q, x, J, gamma=gam, max_steps=3000)
    w = np.asarray(res.w)
    assert list(np.asarray(res.status)) == [S.STALLED, S.STALLED] * 2
    assert abs(w[0, 1] - 0.058) < 0.001 and w[1, 0] < 0.05
    free = np.ones(2, bool)
    for i in range(2):
        assert np.abs(np.log(w[i] / _ls_weights(q[i], x[i], J[i], gam[i], free))).max() > 0.3
        gap = _gauss_newton_gap(w[i], q[i], x[i], J[i], gam[i], free)
        assert gap > 0.3
        np.testing.assert_allclose(float(res.ls_gap[i]), gap, rtol=1e-5)
    lm = fitting.estimate_ik_weights_lm(q[:1], x[:1], J[:1], gamma=0.9)
    assert int(lm.status[0]) == S.STALLED and float(lm.w[0, 1]) == 1e-3


def test_hugmp_fits_that_disagree_with_least_squares_are_not_successful():
    """The bundled HuG-MP recordings (subjects 1–2, six tasks each, motions pooled, 20 samples per
    motion, the over-specified elbow fixed, γ = 0.6, defaults): on every subject × task Algorithm
    1's weights differ from SciPy's least-squares weights of the same modelling error by a factor
    of 4 or more (≥ 1.4 in log w): the recordings hold large null-space motion that the IK model
    does not describe (the two estimators of the same model disagree). None of these fits is
    SUCCESSFUL: each is STALLED (a fixed point ``ls_gap`` > ``ls_tol`` from those weights, or a
    crawl) or MAX_STEPS."""
    arm = pj.ShoulderElbowArm()
    items = []
    for subject in (1, 2):
        a = pj.hugmp_arrays(pj.load_hugmp(subject), arm, samples=20)
        items += [tuple(a[k][task][a["mask"][task]] for k in ("qdot", "xdot", "J")) for task in range(6)]
    K = max(len(i[0]) for i in items)
    mask = np.stack([np.arange(K) < len(i[0]) for i in items])
    q, x = (np.stack([np.pad(i[c], ((0, K - len(i[c])), (0, 0))) for i in items]) for c in (0, 1))
    J = np.stack([np.concatenate([i[2], np.broadcast_to(np.eye(3, 4), (K - len(i[2]), 3, 4))]) for i in items])
    fixed = np.asarray(fitting.overspecified_joints(J, mask=mask))
    assert list(fixed) == [False, False, False, True]
    res = fitting.estimate_ik_weights(q, x, J, gamma=0.6, mask=mask, fixed=fixed)
    st, w = np.asarray(res.status), np.asarray(res.w)
    far = np.array([np.abs(np.log(w[b] / _ls_weights(*items[b], 0.6, ~fixed))).max() for b in range(len(items))])
    assert np.all(far > 1.4)
    assert np.all(np.isin(st, [S.STALLED, S.MAX_STEPS]))
    assert np.all(np.asarray(res.ls_gap)[st == S.STALLED] > 0.15)


def test_unidentifiable_and_inconsistent_items_are_not_successful():
    """A joint that never moves and has no Jacobian column, one sample of a 5-joint chain with a
    3-D task (2 equations for 4 weight ratios): TOO_FEW_DATA for both estimators. Task velocities
    unrelated to J q̇ (no IK model holds): Algorithm 1 never reports SUCCESSFUL. The item beside
    them (Fig 1 data) converges."""
    q, x, J = (a[:2].copy() for a in ik_fig1_numpy(np.random.default_rng(3), n_reps=2))
    J[1, :, :, 4] = 0.0
    q[1] = np.einsum("kij,kj->ki", weighted_pinv(J[1, :, :, :4], W_STAR[:4]), x[1]) @ np.eye(4, 5)
    res = fitting.estimate_ik_weights(q, x, J, gamma=0.6, max_steps=3000)
    assert list(np.asarray(res.status)) == [S.SUCCESSFUL, S.TOO_FEW_DATA]
    assert np.isinf(float(res.ls_gap[1]))
    lm = fitting.estimate_ik_weights_lm(q, x, J, gamma=0.6)
    assert list(np.asarray(lm.status)) == [S.SUCCESSFUL, S.TOO_FEW_DATA]
    one = fitting.estimate_ik_weights(q[0, :1], x[0, :1], J[0, :1], gamma=0.6, max_steps=3000)
    assert int(one.status) == S.TOO_FEW_DATA
    assert int(fitting.estimate_ik_weights_lm(q[0, :1], x[0, :1], J[0, :1], gamma=0.6).status) == S.TOO_FEW_DATA
    rng = np.random.default_rng(5)
    qr = rng.standard_normal((3, 40, 4)) * rng.uniform(0.2, 3.0, 4)
    xr, Jr = rng.standard_normal((3, 40, 2)), rng.standard_normal((3, 40, 2, 4))
    bad = fitting.estimate_ik_weights(qr, xr, Jr, gamma=np.array([0.0, 0.5, 0.9]), max_steps=1000)
    assert not np.any(bad.converged)


# ---------------------------------------------------------------------------------------------
# batching, masks, failures


def test_batched_equals_per_subject(fig1, fig1_result):
    q, x, J = fig1
    for i in (0, 37):
        one = fitting.estimate_ik_weights(q[i], x[i], J[i], gamma=0.6)
        assert np.allclose(one.w, fig1_result.w[i], atol=1e-12, rtol=0)
        assert int(one.iterations) == int(fig1_result.iterations[i]) and int(one.status) == int(fig1_result.status[i])


def test_inside_a_callers_jit_equals_eager(fig1, fig1_result):
    """Traced inputs take the strict-summation kernel (compiler options apply to top-level calls
    only); same weights as the eager (reassociated-sum) call to rounding."""
    q, x, J = fig1
    f = jax.jit(lambda q, x, J: fitting.estimate_ik_weights(q, x, J, gamma=0.6))
    res = f(q[:4], x[:4], J[:4])
    np.testing.assert_allclose(res.w, fig1_result.w[:4], atol=1e-10, rtol=0)
    assert np.array_equal(res.iterations, fig1_result.iterations[:4])


def test_mask_equals_truncation(fig1):
    q, x, J = (a[0].copy() for a in fig1)
    mask = np.arange(500) < 300
    q[300:] = np.nan  # padding is never looked at
    J[300:] = 0.0
    a = fitting.estimate_ik_weights(q, x, J, gamma=0.6, mask=mask)
    b = fitting.estimate_ik_weights(q[:300], x[:300], J[:300], gamma=0.6)
    assert np.allclose(a.w, b.w, atol=1e-12, rtol=0)
    assert np.allclose(a.error_history, b.error_history, atol=1e-12, rtol=0, equal_nan=True)


def test_failing_subject_is_flagged_others_go_on(fig1, fig1_result):
    q, x, J = (a.copy() for a in fig1)
    q[5, 10, 2] = np.nan
    J[9, 3] = 0.0  # rank-deficient Jacobian
    with pytest.raises(ValueError, match="qdot"):
        fitting.estimate_ik_weights(q, x, J, gamma=0.6)
    res = fitting.estimate_ik_weights(q, x, J, gamma=0.6, on_invalid="flag")
    st = np.asarray(res.status)
    assert st[5] == S.INVALID_INPUT and st[9] == S.INVALID_INPUT
    ok = np.setdiff1d(np.arange(100), [5, 9])
    assert np.array_equal(st[ok], np.asarray(fig1_result.status)[ok])
    assert np.all(np.isnan(res.w[5])) and not res.converged[9]
    assert np.allclose(res.w[ok], fig1_result.w[ok], atol=1e-12, rtol=0)


@pytest.mark.bad_input("fitting.estimate_ik_weights", "fitting.ik_model_error", "fitting.estimate_ik_weights_lm")
def test_bad_input_raises_clear_errors(fig1):
    q, x, J = (a[0, :60] for a in fig1)
    for est in (fitting.estimate_ik_weights, fitting.estimate_ik_weights_lm):
        with pytest.raises(ValueError, match="J"):
            est(q, x, J[:, :, :4])  # n mismatch
        with pytest.raises(ValueError, match="J"):
            est(q, x[:, :2], J)  # m mismatch
        with pytest.raises(ValueError, match="sample axes"):
            est(q[:40], x, J)  # K mismatch
        with pytest.raises(ValueError, match="gamma"):
            est(q, x, J, gamma=1.2)
        with pytest.raises(ValueError, match="gamma"):
            est(q, x, J, gamma=-0.1)
        with pytest.raises(ValueError, match="gamma"):
            est(np.stack([q, q]), np.stack([x, x]), np.stack([J, J]), gamma=np.ones(3) * 0.5)
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
        with pytest.raises(TypeError, match="mask"):
            est(q, x, J, mask=np.ones(60))
        with pytest.raises(ValueError, match="redundant"):
            est(q[:, :3], x, J[:, :, :3])
        with pytest.raises(ValueError, match="fixed"):
            est(q, x, J, fixed=(0, 1, 2, 3, 4))
        with pytest.raises(ValueError, match="fixed"):
            est(q, x, J, fixed=(7,))
        with pytest.raises(ValueError, match="w_min"):
            est(q, x, J, w_min=0.0)
    est = fitting.estimate_ik_weights
    with pytest.raises(ValueError, match="gamma_rate"):
        est(q, x, J, gamma_rate=2.0)
    for name in ("tol", "step_tol", "rank_tol", "ls_tol"):
        with pytest.raises(ValueError, match=name):
            est(q, x, J, **{name: -1.0})
    with pytest.raises(ValueError, match="max_steps"):
        est(q, x, J, max_steps=0)
    with pytest.warns(DeprecationWarning, match="max_iter"), pytest.raises(ValueError, match="max_steps"):
        est(q, x, J, max_iter=0)  # the old name, passed on under the new one
    with pytest.raises(TypeError, match="max_iter.*max_steps"):
        est(q, x, J, max_iter=5, max_steps=5)
    with pytest.raises(ValueError, match="w_max"):
        est(q, x, J, w_max=0.5)
    with pytest.raises(ValueError, match="on_invalid"):
        est(q, x, J, on_invalid="ignore")
    with pytest.raises(TypeError, match="devices"):
        est(q, x, J, devices="cpu")
    with pytest.raises(ValueError, match="max_steps"):
        fitting.estimate_ik_weights_lm(q, x, J, max_steps=0)
    err = fitting.ik_model_error
    with pytest.raises(ValueError, match="`w`"):
        err(np.ones(4), q, x, J)
    with pytest.raises(ValueError, match="`w`"):
        err(np.array([1.0, 0.5, 0.0, 0.2, 0.1]), q, x, J)
    with pytest.raises(ValueError, match="`w`"):
        err(np.ones((3, 5)), q, x, J)
    with pytest.raises(ValueError, match="gamma"):
        err(np.ones(5), q, x, J, gamma=2.0)


# ---------------------------------------------------------------------------------------------
# the gradient-based variant


@pytest.fixture(scope="module")
def lm_data(fig1):
    return tuple(a[:4] for a in fig1)


@pytest.fixture(scope="module")
def lm_result(lm_data):
    return fitting.estimate_ik_weights_lm(*lm_data, gamma=0.6)


def test_lm_minimises_the_error_and_agrees_with_algorithm1(lm_data, lm_result, fig1_result):
    """LM weights (Fig 1 data): converged, within 12 % of w* (4 standard deviations of the
    estimate at K = 500) and of Algorithm 1's, and no worse in mean squared modelling error (Eq 16,
    NumPy) than Algorithm 1's weights (LM minimises it)."""
    q, x, J = lm_data
    assert bool(np.all(lm_result.converged)) and np.all(lm_result.status == S.SUCCESSFUL)
    w_a1 = np.asarray(fig1_result.w[:4])
    np.testing.assert_allclose(lm_result.w, np.broadcast_to(W_STAR, (4, 5)), rtol=0.12)
    np.testing.assert_allclose(lm_result.w, w_a1, rtol=0.12)
    for i in range(4):
        b = x[i] - 0.6 * np.einsum("kij,kj->ki", J[i], q[i])
        e2 = [np.mean(np.sum((0.4 * q[i] - np.einsum("kij,kj->ki", weighted_pinv(J[i], w), b)) ** 2, axis=1))
              for w in (np.asarray(lm_result.w[i]), w_a1[i])]
        assert e2[0] <= e2[1] * (1 + 1e-12)


def test_lm_batch_equals_singles(lm_data, lm_result):
    q, x, J = lm_data
    for i in (0, 3):
        one = fitting.estimate_ik_weights_lm(q[i], x[i], J[i], gamma=0.6)
        np.testing.assert_allclose(one.w, lm_result.w[i], atol=1e-10, rtol=0)
        assert int(one.status) == int(lm_result.status[i])


def test_lm_gradient_matches_central_differences(lm_data):
    """d w / d data through the implicit function theorem vs central differences (step
    sqrt(eps)·scale) of the refitted weights, along a random direction of q̇ and of J."""
    q, x, J = (a[0] for a in lm_data)  # the shape of the singles above: one compiled fit
    rng = np.random.default_rng(2)
    c = rng.standard_normal(5)
    Dq, DJ = rng.standard_normal(q.shape), rng.standard_normal(J.shape)

    def loss(s, t):
        r = fitting.estimate_ik_weights_lm(q + s * Dq, x, J + t * DJ, gamma=0.6)
        return jnp.sum(r.w @ c)

    # one compilation: the differences use the value half of the same compiled value_and_grad
    vg = pj.fast_compile_jit(jax.value_and_grad(loss, argnums=(0, 1)))
    f = lambda s, t: vg(jnp.asarray(s, float), jnp.asarray(t, float))[0]  # noqa: E731
    g = np.array(vg(jnp.asarray(0.0, float), jnp.asarray(0.0, float))[1])  # strong float64, as in f
    assert np.all(np.abs(g) > 1e-2)
    # step sqrt(eps)·scale: the refitted optimum is exact to ≈ 1e-12, so the differences carry
    # ≈ 1e-12 / h ≈ 1e-4 of noise; a larger step (truncation error O(h²) ≈ 1e-10) checks to 1e-5
    for h, rtol in ((np.sqrt(np.finfo(float).eps) * np.abs(q).mean(), 1e-3), (1e-5, 1e-5)):
        fd = ((f(h, 0.0) - f(-h, 0.0)) / (2 * h), (f(0.0, h) - f(0.0, -h)) / (2 * h))
        np.testing.assert_allclose(g, np.array(fd), rtol=rtol)


def test_model_error_gradient_matches_central_differences(fig1):
    q, x, J = (a[0, :50] for a in fig1)
    f = jax.jit(lambda w: fitting.ik_model_error(w, q, x, J, 0.6))
    w0 = np.array([0.9, 0.7, 0.5, 0.45, 0.3])
    g = np.asarray(jax.grad(f)(jnp.asarray(w0)))
    h = np.sqrt(np.finfo(float).eps) * 0.5
    fd = np.array([(f(w0 + h * e) - f(w0 - h * e)) / (2 * h) for e in np.eye(5)])
    assert np.allclose(g, fd, rtol=1e-5, atol=1e-8)
    # scale invariance of Eq 4: the error does not change along w
    assert abs(float(g @ w0)) < 1e-10
    # against a direct NumPy evaluation of Eq 16
    Jp = weighted_pinv(J, w0)
    e = (1 - 0.6) * q - np.einsum("kij,kj->ki", Jp, x - 0.6 * np.einsum("kij,kj->ki", J, q))
    assert np.isclose(float(f(w0)), np.linalg.norm(e, axis=1).mean(), rtol=1e-12)


# ---------------------------------------------------------------------------------------------
# analysis


@pytest.mark.bad_input("fitting.ik_decomposition", "fitting.contribution_coefficients",
                       "fitting.overspecified_joints", "fitting.hotelling_t2")
def test_analysis_bad_input():
    q, x, J = np.ones((5, 3)), np.ones((5, 2)), np.tile(np.eye(2, 3), (5, 1, 1))
    with pytest.raises(ValueError, match="`w`"):
        fitting.ik_decomposition(q, x, J, np.ones(2))
    with pytest.raises(ValueError, match="`w`"):
        fitting.ik_decomposition(q, x, J, np.array([1.0, -1.0, 1.0]))
    with pytest.raises(ValueError, match="`J`"):
        fitting.ik_decomposition(q, x, J[:, :, :2], np.ones(3))
    with pytest.raises(ValueError, match="share"):
        fitting.ik_decomposition(q[:4], x, J, np.ones(3))
    with pytest.raises(ValueError, match="`qdot`"):
        fitting.ik_decomposition(np.full((5, 3), np.nan), x, J, np.ones(3))
    with pytest.raises(ValueError, match="`w`"):
        fitting.contribution_coefficients(np.array([1.0, 0.0]))
    with pytest.raises(ValueError, match="`w`"):
        fitting.contribution_coefficients(np.array([1.0, np.nan]))
    with pytest.raises(ValueError, match="`J`"):
        fitting.overspecified_joints(np.ones(3))
    with pytest.raises(ValueError, match="mask"):
        fitting.overspecified_joints(J, mask=np.ones(4, bool))
    with pytest.raises(ValueError, match="mask"):
        fitting.overspecified_joints(J, mask=np.zeros(5, bool))
    with pytest.raises(ValueError, match="fraction"):
        fitting.overspecified_joints(J, fraction=0.0)
    a = np.random.default_rng(0).standard_normal((6, 2))
    with pytest.raises(ValueError, match="`b`"):
        fitting.hotelling_t2(a, np.ones((6, 3)))
    with pytest.raises(ValueError, match="paired"):
        fitting.hotelling_t2(a, a[:5])
    with pytest.raises(ValueError, match="more subjects"):
        fitting.hotelling_t2(a[:2], a[:2] + 1)
    with pytest.raises(ValueError, match="singular"):
        fitting.hotelling_t2(np.c_[a[:, 0], np.ones(6)], np.c_[a[:, 1], np.ones(6)])
    with pytest.raises(TypeError, match="paired"):
        fitting.hotelling_t2(a, a + 1, paired="yes")
    with pytest.raises(ValueError, match="`a`"):
        fitting.hotelling_t2(np.full((6, 2), np.inf), a)


def test_decomposition_reproduces_eqs_13_14():
    q = np.array([[0.0, 1.0]])
    J = np.array([[[1.0, 1.0]]])
    x = np.array([[1.0]])
    task, null = fitting.ik_decomposition(q, x, J, np.array([1.0, 1.0]))
    assert np.allclose(task, [[0.5, 0.5]]) and np.allclose(null, [[-0.5, 0.5]])
    task, null = fitting.ik_decomposition(q, x, J, np.array([1.0, 1 / 9]))
    assert np.allclose(task, [[0.1, 0.9]]) and np.allclose(null, [[-0.1, 0.1]])


def test_contribution_coefficients_eq26():
    """A closed form (w = (1, 1/2, 1/4) -> β = (1, 2, 4)/7), the sum, and a gradient."""
    beta = np.asarray(fitting.contribution_coefficients(np.array([[1.0, 0.5, 0.25], [2.0, 1.0, 0.5]])))
    np.testing.assert_allclose(beta, np.array([[1, 2, 4], [1, 2, 4]]) / 7, rtol=1e-14)
    w = np.array([0.5, 0.25, 1.0, 1.0])
    g = jax.grad(lambda v: fitting.contribution_coefficients(v)[2])(jnp.asarray(w))
    h = np.sqrt(np.finfo(float).eps)
    fd = [(float(fitting.contribution_coefficients(w + h * e)[2])
           - float(fitting.contribution_coefficients(w - h * e)[2])) / (2 * h) for e in np.eye(4)]
    assert np.allclose(g, fd, rtol=1e-6, atol=1e-9)


# Discussion of the paper, Experiment 1 (4-DoF shoulder–elbow chain, elbow over-specified)
BETA_PAPER = {"Natural": (0.04, 0.27, 0.65, 0.04), "Viscous": (0.09, 0.68, 0.14, 0.09)}


def test_beta_of_estimated_weights_matches_the_paper():
    """Reaching data generated with NumPy (the README's 4-DoF arm, complex-step Jacobians,
    q̇ = J#_W ẋ + a small null-space motion) with weights w ∝ 1/β from the paper's printed β;
    Algorithm 1 with the elbow fixed (the paper's convention) gives back weights whose β (Eq 26)
    equal the printed ones to their rounding (±0.005). The weights of the synthetic data set
    (``W_NATURAL``, ``W_VISCOUS``) are these 1/β to 1 %."""
    rng = np.random.default_rng(8)
    K = 300
    qs = rng.uniform([-1.0, -1.2, -0.6, 0.4], [-0.2, -0.2, 0.3, 1.8], (K, 4))
    J = np.stack([arm4_jac(q) for q in qs])
    assert np.allclose(J, pj.ShoulderElbowArm().jacobian(qs), atol=1e-12)  # the README chain is pj.ShoulderElbowArm
    np.testing.assert_allclose(arm4_fk(qs[0]), pj.ShoulderElbowArm().fk(qs[0]), atol=1e-15)
    xd = 0.3 * rng.standard_normal((K, 3))
    v = 0.003 * rng.standard_normal((K, 4))
    qd, xds = [], []
    for cond, beta in BETA_PAPER.items():
        w = 1.0 / np.array(beta)
        w[:3] /= w[:3].max()
        w[3] = 1.0
        Jp = weighted_pinv(J, w)
        qd.append(np.einsum("kij,kj->ki", Jp, xd) + v - np.einsum("kij,kj->ki", Jp @ J, v))
        xds.append(np.einsum("kij,kj->ki", J, qd[-1]))
        np.testing.assert_allclose({"Natural": W_NATURAL, "Viscous": W_VISCOUS}[cond], w, rtol=0.01)
    # the 4-DoF arm's single redundant degree of freedom makes Algorithm 1 slow: ≈ 3 500 updates
    res = fitting.estimate_ik_weights(np.stack(qd), np.stack(xds), np.stack([J, J]), gamma=0.0, fixed=[3],
                                      step_tol=1e-9, max_steps=6000)
    assert np.all(res.status == S.SUCCESSFUL)
    beta = np.asarray(fitting.contribution_coefficients(res.w))
    np.testing.assert_allclose(beta, np.array(list(BETA_PAPER.values())), atol=0.005)


def test_overspecified_joint_of_the_4dof_arm(rng):
    arm = pj.ShoulderElbowArm()
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
    S_ = np.cov(d, rowvar=False)
    t2 = 17 * d.mean(0) @ np.linalg.solve(S_, d.mean(0))
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


# ---------------------------------------------------------------------------------------------
# bootstrap intervals


def _trial_data(rng, P, T, S_, w, sigma, sigma_trial):
    """Subjects × trials × samples of a 3-joint, 1-D task (random J, ẋ) with a null-space motion
    that has a per-trial component (so trials, not samples, are the independent units)."""
    n = len(w)
    J = rng.standard_normal((P, T, S_, 1, n))
    x = rng.standard_normal((P, T, S_, 1))
    v = sigma * rng.standard_normal((P, T, S_, n)) + sigma_trial * rng.standard_normal((P, T, 1, n))
    Jp = weighted_pinv(J, w)
    q = np.einsum("...ij,...j->...i", Jp, x) + v - np.einsum("...ij,...j->...i", Jp @ J, v)
    return q, x, J


@pytest.mark.parametrize("estimator, options", [
    # (Algorithm 1 to the fixed point: these data determine the weights to 0.3 %, the default tol is 0.1 %)
    ("algorithm1", dict(max_steps=300, tol=1e-5, step_tol=1e-9)),
    ("lm", {}),
])
def test_bootstrap_intervals_cover_the_truth(estimator, options):
    """150 synthetic subjects (20 trials of 3 samples, w* = (1, 0.5, 0.25)), 95 % intervals from
    100 replicates each, all in one call, with each estimator: the share of intervals holding w*
    is within the 99.9 % binomial bounds of 0.95 for each free joint (a 90 % or 68 % interval, or
    resampling samples instead of trials, falls outside)."""
    rng = np.random.default_rng(21)
    w = np.array([1.0, 0.5, 0.25])
    P = 150
    q, x, J = _trial_data(rng, P, 20, 3, w, 0.001, 0.003)
    res = fitting.bootstrap_ik_weights(q, x, J, n_boot=100, seed=jax.random.PRNGKey(4), gamma=0.6,
                                       estimator=estimator, **options)
    assert np.mean(np.asarray(res.converged)) > 0.85  # (measured: Algorithm 1 0.89)
    lo, hi = np.asarray(res.lo), np.asarray(res.hi)
    assert res.samples.shape == (100, P, 3) and res.status.shape == (100, P)
    assert np.all(lo <= res.w) and np.all(res.w <= hi)
    cover = ((lo <= w) & (w <= hi)).sum(0)[1:]
    lo_b, hi_b = scipy.stats.binom.interval(0.999, P, 0.95)
    assert np.all((lo_b <= cover) & (cover <= hi_b)), (cover, lo_b, hi_b)


@pytest.mark.parametrize("estimator", ["algorithm1", "lm"])
def test_bootstrap_in_chunks_gives_the_replicates_of_one_call(monkeypatch, estimator):
    """The replicates go to the estimator in chunks of about ``BOOTSTRAP_CHUNK_BYTES`` of data (the
    last one padded to the same shape): 9 replicates (the data and 8 draws) in chunks of 4 give the
    replicates, intervals and statuses of one call; an item without data is NaN / INVALID_INPUT."""
    from fitting._ik import analysis

    rng = np.random.default_rng(7)
    q, x, J = _trial_data(rng, 3, 6, 5, np.array([1.0, 0.5, 0.25]), 0.05, 0.05)
    mask = np.ones(q.shape[:-1], bool)
    mask[2] = False
    kw = dict(n_boot=8, seed=jax.random.PRNGKey(2), gamma=0.6, estimator=estimator, mask=mask)
    one = fitting.bootstrap_ik_weights(q, x, J, **kw)
    by_int = fitting.bootstrap_ik_weights(q, x, J, **{**kw, "seed": 2})  # an integer: PRNGKey of it
    np.testing.assert_array_equal(np.asarray(by_int.lo), np.asarray(one.lo))
    per_rep = 8 * 3 * 6 * 5 * (1 * 3 + 1 + 3 + 1)  # items × trials × samples × (J, ẋ, q̇, mask) in bytes
    monkeypatch.setattr(analysis, "BOOTSTRAP_CHUNK_BYTES", 4 * per_rep)
    seen = []
    inner = analysis.estimate_ik_weights if estimator == "algorithm1" else fitting.estimate_ik_weights_lm
    target = (analysis, "estimate_ik_weights") if estimator == "algorithm1" else (fitting._ik.weights,
                                                                                  "estimate_ik_weights_lm")
    monkeypatch.setattr(*target, lambda q, *a, **k: seen.append(np.shape(q)[0]) or inner(q, *a, **k))
    chunked = fitting.bootstrap_ik_weights(q, x, J, **kw)
    assert seen == [4, 4, 4]
    for f in ("w", "lo", "hi", "samples", "status", "w_status"):
        np.testing.assert_allclose(np.asarray(getattr(chunked, f)), np.asarray(getattr(one, f)), atol=1e-9, rtol=0)
    assert np.all(np.isnan(np.asarray(one.w)[2])) and int(one.w_status[2]) == S.INVALID_INPUT
    assert np.all(np.isfinite(np.asarray(one.w)[:2]))
    with pytest.raises(ValueError, match="`estimator` must be 'algorithm1' or 'lm'"):
        fitting.bootstrap_ik_weights(q, x, J, estimator="qp")


@pytest.mark.bad_input("fitting.bootstrap_ik_weights")
def test_bootstrap_batch_equals_singles_and_bad_input():
    """With one key per item, a batch gives what its items give alone; unusable items are NaN."""
    rng = np.random.default_rng(4)
    q, x, J = _trial_data(rng, 3, 6, 5, np.array([1.0, 0.5, 0.25]), 0.05, 0.05)
    mask = np.ones(q.shape[:-1], bool)
    mask[1, 4:] = False  # a subject with fewer trials
    keys = jax.random.split(jax.random.PRNGKey(0), 3)
    kw = dict(n_boot=8, gamma=0.6)  # (the options of the chunking test above: its compiles are shared)
    res = fitting.bootstrap_ik_weights(q, x, J, mask=mask, seed=keys, **kw)
    for i in (0, 1):
        one = fitting.bootstrap_ik_weights(q[i], x[i], J[i], mask=mask[i], seed=keys[i], **kw)
        for f in ("w", "lo", "hi"):
            np.testing.assert_allclose(getattr(one, f), getattr(res, f)[i], atol=1e-10, rtol=0)
        np.testing.assert_allclose(one.samples, res.samples[:, i], atol=1e-10, rtol=0)
    # The intervals are the (1 ± level)/2 percentiles of the replicates (the default level 0.95).
    for level, r in ((0.95, res), (0.8, fitting.bootstrap_ik_weights(q, x, J, mask=mask, seed=keys, level=0.8, **kw))):
        np.testing.assert_array_equal(np.asarray(r.samples), np.asarray(res.samples))
        lo, hi = np.percentile(np.asarray(res.samples), [50 * (1 - level), 50 * (1 + level)], axis=0)
        np.testing.assert_allclose(np.asarray(r.lo), lo, rtol=0, atol=1e-12)
        np.testing.assert_allclose(np.asarray(r.hi), hi, rtol=0, atol=1e-12)
    shared = fitting.bootstrap_ik_weights(q, x, J, mask=mask, seed=keys[0], **kw)
    assert not np.allclose(shared.samples[:, 0], shared.samples[:, 2])  # items draw differently
    bad = fitting.bootstrap_ik_weights(q, x, J, mask=np.zeros_like(mask), seed=keys, **kw)
    assert np.all(np.isnan(bad.w)) and np.all(bad.w_status == S.INVALID_INPUT)
    boot = fitting.bootstrap_ik_weights
    with pytest.raises(ValueError, match="level"):
        boot(q, x, J, level=1.5)
    with pytest.raises(ValueError, match="n_boot"):
        boot(q, x, J, n_boot=1)
    with pytest.raises(ValueError, match="mask"):
        boot(q, x, J, mask=mask[..., :3])
    with pytest.raises(ValueError, match="share"):
        boot(q, x[:, :5], J)
    with pytest.raises(TypeError, match="seed"):
        boot(q, x, J, seed=0.5)
    with pytest.warns(DeprecationWarning, match="key"), pytest.raises(TypeError, match="seed"):
        boot(q, x, J, key=0.5)  # the old keyword, passed on under the new one
    with pytest.raises(TypeError, match="on_invalid"):
        boot(q, x, J, on_invalid="raise")
    with pytest.raises(ValueError, match="gamma"):
        boot(q, x, J, gamma=3.0)


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
                                      step_tol=1e-10, max_steps=3000)
    assert int(res.status) == S.STALLED  # a fixed point of the update (e > 0 with a null part)
    w = np.asarray(res.w)
    assert np.all(np.abs(w / w.max() - w_true) <= 0.05 * w_true), w


def test_arm4_jacobian_against_autodiff_and_differences(rng):
    arm = pj.ShoulderElbowArm(L1=0.31, L2=0.35)
    q = rng.uniform(-1.0, 1.0, (6, 4))
    J = np.asarray(arm.jacobian(q))
    assert np.allclose(J, jax.jit(jax.vmap(jax.jacfwd(arm.fk)))(jnp.asarray(q)), atol=1e-13)
    h = 1e-6
    fd = np.stack([(arm.fk(q + h * e) - arm.fk(q - h * e)) / (2 * h) for e in np.eye(4)], -1)
    assert np.allclose(J, fd, atol=1e-8)
    # README: q2 = −90° puts the straight arm forward (+x) at L1 + L2
    assert np.allclose(arm.fk(jnp.array([0.0, -np.pi / 2, 0.0, 0.0])), [0.66, 0.0, 0.0], atol=1e-12)
    # lengths are differentiable leaves
    gL = jax.grad(lambda L: pj.ShoulderElbowArm(L1=L, L2=0.35).fk(jnp.asarray(q[0]))[2])(0.31)
    z = lambda L: pj.ShoulderElbowArm(L1=L, L2=0.35).fk(q[0])[2]  # noqa: E731
    fdL = (z(0.31 + h) - z(0.31 - h)) / (2 * h)
    assert np.isclose(gL, fdL, atol=1e-8)


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
    ref = np.stack([weighted_pinv(J[k], w[k]) @ b[k] for k in range(6)])
    assert np.allclose(np.stack(got, -1), ref, rtol=1e-10, atol=1e-12)


_TWO_DEVICES = r"""
import json, jax, numpy as np
jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_rank_promotion", "raise")
import fitting
from _reference import ik_fig1_numpy
q, x, J = ik_fig1_numpy(np.random.default_rng(2), n_reps=7, K=120)
q[3, 5, 1] = np.nan  # a flagged item
mask = np.ones((7, 120), bool); mask[5, 80:] = False  # a ragged item
run = lambda devs: fitting.estimate_ik_weights(q, x, J, gamma=0.6, mask=mask, max_steps=60,
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
    from pathlib import Path

    env = dict(os.environ, XLA_FLAGS=(os.environ.get("XLA_FLAGS", "")
                                      + " --xla_force_host_platform_device_count=2").strip())
    env["PYTHONPATH"] = os.pathsep.join([str(Path(__file__).parent), env.get("PYTHONPATH", "")])
    proc = subprocess.run([sys.executable, "-c", _TWO_DEVICES], capture_output=True, text=True,
                          env=env, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    r = json.loads(proc.stdout.strip().splitlines()[-1])
    assert r["devices"] == 2 and r["out_devices"] == 1
    w1, w2 = np.array(r["w1"]), np.array(r["w2"])
    assert r["st1"] == r["st2"] and r["st1"][3] == S.INVALID_INPUT
    assert sum(s == S.INVALID_INPUT for s in r["st1"]) == 1
    assert r["it1"] == r["it2"]
    assert np.allclose(w1, w2, atol=1e-12, rtol=0, equal_nan=True)
