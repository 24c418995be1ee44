"""``fitting.fit_movements(model="lambda0_minjerk")`` / ``predict_movements`` on continuous recordings
of a 3-joint planar arm driven by the minimum-jerk time-base generator.

Reference, independent of pmpjax: ``tests/_movement_reference.py`` (SciPy LSODA of the NumPy
λ0-PMP under ``F = γ(t − t_k) (J W⁻¹ Jᵀ)⁻¹ (x_d − x)``, ``γ`` of ``tests/_reference.minjerk_gain``,
a move of 0.8 s from each target's onset, capped at 50 /s; closed-form planar kinematics; a full,
anisotropic ``KJ``; 0.2° noise). What must hold: the fit converges by RK4 (the generator's gain
rises to its cap as the move ends, where RODAS4 loses its order) with an integration error below
0.01°; it finds the move's duration and when each move began in its window (the recording's
target onsets, which the fit never sees); τ0 within three of its standard errors; Donders
equilibria at the held-out targets near SciPy SLSQP's of the true ``KJ``; held-out reaches
predicted within 0.4° median RMSE and at most a quarter of the pseudo-inverse's.
"""

import _movement_reference as ref
import numpy as np
import pytest
from _reference import slsqp_equilibrium

import fitting
import pmpjax as pj

LENGTHS, Q_REST, HOME = ref.PLANAR_LENGTHS, ref.PLANAR_Q_REST, ref.PLANAR_HOME
fk, jac = ref.planar_arm_fk, ref.planar_arm_jac
TAU0, MOVE, CAP = 0.12, 0.8, 50.0


def trial(KJ, q_home, seed):
    t, q, info = ref.planar_trial(KJ, q_home, seed, tau0=TAU0, minjerk=(MOVE, CAP))
    return pj.JointRecording("P1", f"trial{seed}", t, q, ("q1", "q2", "q3")), info


@pytest.fixture(scope="module")
def case():
    KJ = ref.random_spd(np.random.default_rng(11), 3, cond=5.0, trace=3.0)
    q_home = slsqp_equilibrium(fk, jac, KJ, Q_REST, HOME, q0=np.deg2rad([30.0, 80.0, 40.0]))
    made = [trial(KJ, q_home, s) for s in (1, 2)]
    test, info = trial(KJ, q_home, 3)
    chain = pj.PlanarArm(LENGTHS)
    fit = fitting.fit_movements(chain, [m[0] for m in made], model="lambda0_minjerk")
    return KJ, chain, fit, made, test, info


def test_fit_converges_by_rk4_with_the_move_s_duration_and_start(case):
    _, _, fit, made, _, _ = case
    assert fit.status.tolist() == [int(pj.Status.SUCCESSFUL)] and fit.n_reaches[0] == 16
    assert fit.solver == "rk4" and fit.integration_error_deg[0] <= 0.01
    assert abs(fit.duration[0] / MOVE - 1) < 0.01, fit.duration
    # each reach's move began at its target's onset: delay = window start − onset (negative)
    reaches = fit.reaches["P1"]
    onsets = {rec.name: info["t_switch"] for rec, info in made}
    truth = []
    for name, t in zip(reaches.recording, reaches.t[:, 0]):
        on = onsets[name]
        truth.append(t - on[np.argmin(np.abs(on - t))])
    truth = np.array(truth)
    assert np.all(truth < -0.05)  # (the windows start well before the moves)
    err = fit.reach_delays["P1"] - truth
    assert np.median(np.abs(err)) < 0.005 and np.abs(err).max() < 0.02, (fit.reach_delays["P1"], truth)
    i = fit.param_names.index("log(tau0/s)")
    assert abs(np.log(fit.tau0[0] / TAU0)) < 3 * fit.stderr[0, i], (fit.tau0, fit.stderr[0, i])


def test_held_out_equilibria_and_paths(case):
    KJ, chain, fit, _, test, info = case
    q_true = np.stack([slsqp_equilibrium(fk, jac, KJ, Q_REST, x, q0=qf)
                       for x, qf in zip(info["targets"], info["q_final"])])
    eq = pj.equilibrium_posture(chain, fit.KJ[0], fit.q_rest[0], info["targets"], q_init=q_true)
    err = np.rad2deg(np.abs(np.asarray(eq.q) - q_true))
    assert np.median(err) < 0.2 and err.max() < 0.6, err
    pr = fitting.predict_movements(fit, [test])
    assert len(pr) == 8 and np.all(pr.status == 0)
    pinv = pr.baselines["pinv_minjerk"]["rmse_deg"]
    assert np.median(pr.rmse_deg) < 0.4 and np.median(pr.rmse_deg) <= 0.25 * np.median(pinv), (pr.rmse_deg, pinv)
