import numpy as np
import pytest

import pmpjax as pj


def _spd(rng, n):
    a = rng.normal(size=(n, n))
    return a @ a.T + n * np.eye(n)


def test_weighted_pinv_is_minimum_weighted_norm_solution(rng):
    for n, m in [(3, 2), (5, 3), (4, 1)]:
        J = rng.normal(size=(m, n))
        W = _spd(rng, n)
        xdot = rng.normal(size=m)
        # Independent: KKT system of min ½ qᵀ W q s.t. J q = ẋ.
        kkt = np.block([[W, J.T], [J, np.zeros((m, m))]])
        sol = np.linalg.solve(kkt, np.concatenate([np.zeros(n), xdot]))[:n]
        Jw = np.asarray(pj.weighted_pinv(J, W))
        np.testing.assert_allclose(Jw @ xdot, sol, rtol=1e-10, atol=1e-12)
        N = np.asarray(pj.nullspace_projector(J, W))
        np.testing.assert_allclose(J @ N, 0, atol=1e-12)
        np.testing.assert_allclose(N @ N, N, atol=1e-12)
        B = np.asarray(pj.task_damping(J, W))
        np.testing.assert_allclose(B, np.linalg.inv(J @ np.linalg.inv(W) @ J.T), rtol=1e-10)
        tau = rng.normal(size=n)
        lam = np.asarray(pj.lambda0(J, W, tau))
        np.testing.assert_allclose(lam, B @ J @ np.linalg.solve(W, tau), rtol=1e-10)


def test_diagonal_weights_and_batch(rng):
    J = rng.normal(size=(7, 2, 4))
    w = rng.uniform(0.1, 1.0, size=(7, 4))
    batched = np.asarray(pj.weighted_pinv(J, w=w))
    for i in range(7):
        np.testing.assert_allclose(batched[i], np.asarray(pj.weighted_pinv(J[i], np.diag(w[i]))), rtol=1e-12)
    with pytest.raises(ValueError, match="exactly one"):
        pj.weighted_pinv(J[0])
    with pytest.raises(ValueError, match="`w`"):
        pj.weighted_pinv(J[0], w=np.ones(3))


def test_batch_axes_broadcast_like_numpy(rng):
    J = rng.normal(size=(4, 3, 2, 5))
    W = np.stack([_spd(rng, 5) for _ in range(3)])  # batch (3,) against J's (4, 3)
    out = np.asarray(pj.weighted_pinv(J, W))
    assert out.shape == (4, 3, 5, 2)
    np.testing.assert_allclose(out[2, 1], np.asarray(pj.weighted_pinv(J[2, 1], W[1])), rtol=1e-12)
    w = rng.uniform(0.2, 1.0, size=5)  # unbatched diagonal weights against batched J
    np.testing.assert_allclose(np.asarray(pj.nullspace_projector(J, w=w))[3, 0],
                               np.asarray(pj.nullspace_projector(J[3, 0], np.diag(w))), atol=1e-12)


@pytest.mark.bad_input("pj.weighted_pinv", "pj.nullspace_projector", "pj.task_damping", "pj.lambda0")
def test_bad_input(rng):
    J = rng.normal(size=(2, 3))
    W = _spd(rng, 3)
    cases = [
        (lambda: pj.weighted_pinv(J, np.eye(2)), "`W`.*shape"),
        (lambda: pj.weighted_pinv(J, -W), "`W`.*positive definite"),
        (lambda: pj.nullspace_projector(J, W + np.triu(np.ones((3, 3)), 1)), "`W`.*symmetric"),
        (lambda: pj.nullspace_projector(J, w=np.array([1.0, 0.0, 1.0])), "`w`.*positive"),
        (lambda: pj.task_damping(J.T, W[:2, :2]), "`J`.*wide"),
        (lambda: pj.task_damping(np.ones(3), W), "`J`.*shape"),
        (lambda: pj.task_damping(np.where(J > 0, np.nan, J), W), "`J`.*NaN"),
        (lambda: pj.lambda0(J, W, np.ones(2)), "`tau_el`.*shape"),
        (lambda: pj.lambda0(J, W, np.array([np.inf, 0.0, 0.0])), "`tau_el`.*NaN"),
    ]
    for call, match in cases:
        with pytest.raises(ValueError, match=match):
            call()
