"""Fits on the springy arm (Williamson 1996): blend weights that place the hand and stiffness from
the gravity sag, on data made by settled C MuJoCo rollouts (``tests/_springy.py``), which are
independent of the equilibrium solver under test; bad input.

Each fit compiles once (batches pad to 8, so the single-item calls reuse the batch's compile). A
file of its own, apart from ``test_primitives.py``, so that ``--dist loadfile`` runs the two fits'
long compiles beside the equilibrium and kinematics compiles.
"""

import numpy as np
import pytest
from _springy import c_settle

import fitting
import pmpjax as pj


def test_fit_blend_weights_reaches_targets(free_arm, P):
    alphas = np.array([[0.4, 0.3, 0.2, 0.1], [0.1, 0.2, 0.3, 0.4]])
    _, hands, speed = c_settle(free_arm, alphas @ P, free_arm.K)
    assert speed < 1e-10
    far = np.array([[1.5, 0.0, 0.0]])  # beyond the arm's reach
    targets = np.concatenate([hands, far])
    fit = fitting.fit_blend_weights(free_arm, P, targets)
    status = np.asarray(fit.status)
    assert status.tolist() == [pj.Status.SUCCESSFUL, pj.Status.SUCCESSFUL, pj.Status.STALLED]
    assert np.asarray(fit.converged).tolist() == [True, True, False]  # per item, the far one flagged
    assert np.abs(np.asarray(fit.alpha[:2]) - alphas).max() < 1e-7
    assert np.asarray(fit.error[:2]).max() < 1e-8  # (the fit's own tolerance is 1e-6 m)
    assert np.allclose(np.asarray(fit.alpha).sum(-1), 1.0, atol=1e-14)
    assert np.isfinite(np.asarray(fit.alpha[2])).all()  # the failing item did not poison anything
    for i in (0, 2):  # batch equals singles
        one = fitting.fit_blend_weights(free_arm, P, targets[i])
        assert int(one.status) == status[i]
        assert np.abs(np.asarray(one.alpha) - np.asarray(fit.alpha[i])).max() < 1e-10


def test_fit_stiffness_from_gravity_sag(free_arm, P):
    rng = np.random.default_rng(1)
    K_true = free_arm.K * rng.uniform(0.7, 1.3, size=(2, 6))
    q_set = np.concatenate([P, [[0.9, 0.5, 0.6, 1.4, 0.6, 0.5]]])
    q_obs, speeds = [], []
    for k in K_true:
        q, _, s = c_settle(free_arm, q_set, k)
        q_obs.append(q)
        speeds.append(s)
    assert max(speeds) < 1e-10
    fit = fitting.fit_stiffness(free_arm, q_set, np.stack(q_obs))
    assert np.asarray(fit.converged).all() and (np.asarray(fit.status) == pj.Status.SUCCESSFUL).all()
    assert np.allclose(np.asarray(fit.K), K_true, rtol=1e-6)
    assert np.asarray(fit.rms).max() < 1e-9
    one = fitting.fit_stiffness(free_arm, q_set, q_obs[1])  # batch equals singles
    assert np.abs(np.asarray(one.K) - np.asarray(fit.K[1])).max() < 1e-8 * np.abs(K_true).max()


# ----------------------------------------------------------------------------------------------
# Bad input: clear errors naming the argument, raised before tracing


@pytest.mark.bad_input("fitting.fit_blend_weights", "fitting.fit_stiffness")
def test_bad_input_fits(free_arm, P):
    with pytest.raises(ValueError, match="target"):
        fitting.fit_blend_weights(free_arm, P, np.zeros(2))
    with pytest.raises(ValueError, match="`P`"):
        fitting.fit_blend_weights(free_arm, P[:1], np.zeros(3))
    with pytest.raises(ValueError, match="`K`"):
        fitting.fit_blend_weights(free_arm, P, np.zeros(3), K=np.tile(free_arm.K, (2, 1)))
    with pytest.raises(ValueError, match="max_steps"):
        fitting.fit_blend_weights(free_arm, P, np.zeros(3), max_steps=0)
    with pytest.raises(ValueError, match="tol"):
        fitting.fit_blend_weights(free_arm, P, np.zeros(3), tol=-1.0)
    with pytest.raises(TypeError, match="arm"):
        fitting.fit_blend_weights(None, P, np.zeros(3))
    with pytest.raises(ValueError, match="q_set"):
        fitting.fit_stiffness(free_arm, P[0], P[0])
    with pytest.raises(ValueError, match="q_observed"):
        fitting.fit_stiffness(free_arm, P, P[:3])
    with pytest.raises(ValueError, match="q_observed"):
        fitting.fit_stiffness(free_arm, P, np.full_like(P, np.nan))
    with pytest.raises(ValueError, match="K0"):
        fitting.fit_stiffness(free_arm, P, P, K0=np.zeros(6))
