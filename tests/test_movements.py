"""``fitting.fit_movements`` / ``predict_movements`` on continuous multi-reach recordings.

Reference, independent of pmpjax's simulator: ``tests/_movement_reference.py`` (SciPy Radau of the
NumPy λ0-PMP of ``tests/_reference.py``, Arimoto's gain with Eq 10 at each reach's start) generates
the recordings on the 4-joint shoulder–elbow arm (``arm4_fk``/``arm4_jac``, closed form) with a
full, anisotropic ``KJ`` and 0.2° noise; SciPy's SLSQP gives the true equilibria. What must hold:
the fit converges, recovers the time constants within 5 % and each reach's target onset (the
reference's switch times, which the fit never sees), predicts the held-out final postures
and joint paths within 1° (at most half the pseudo-inverse's error), and finds on this arm the one
direction no reach can see: ``q_rest`` along ``KJ⁻¹ e_elbow``.

Compile budget: one fit (stage 1, the gauge, stage 2, the integration check) and one prediction.
"""

import numpy as np
import pytest
from _movement_reference import continuous_recording, random_spd
from _reference import arm4_fk, arm4_jac, slsqp_equilibrium

import fitting
import pmpjax as pj

TAU0, TAU = 0.12, 0.10
Q_REST = np.deg2rad([-30.0, -40.0, -10.0, 60.0])
JOINTS = ("sh_abd", "sh_flex", "sh_rot", "elbow")
HOME = np.array([0.25, -0.2, -0.25])
TRAIN_TRUTH = {}  # recording name -> the reference's switch times and targets (never given to the fit)


def fk_jac(q):
    return arm4_fk(q), arm4_jac(q)


def trial(KJ, q_home, seed, n_out=5):
    """Out-and-back reaches from the home position to ``n_out`` random targets."""
    rng = np.random.default_rng(seed)
    out = HOME + rng.uniform(-0.1, 0.1, size=(n_out, 3))
    targets = np.stack([out, np.broadcast_to(HOME, out.shape)], 1).reshape(-1, 3)
    hold = rng.uniform(1.0, 1.4, size=len(targets))
    t, q, info = continuous_recording(fk_jac, KJ, Q_REST, TAU0, TAU, q_home, targets, hold, fs=100.0,
                                      noise_deg=0.2, seed=seed, lead=0.5)
    return pj.JointRecording("P1", f"trial{seed}", t, q, JOINTS), info


@pytest.fixture(scope="module")
def case():
    KJ = random_spd(np.random.default_rng(4), 4, cond=6.0, trace=4.0)
    q_home = slsqp_equilibrium(arm4_fk, arm4_jac, KJ, Q_REST, HOME, q0=np.deg2rad([-20.0, -30.0, 0.0, 80.0]))
    train, infos = zip(*[trial(KJ, q_home, s) for s in (1, 2)])
    test, info = trial(KJ, q_home, 4)
    fit = fitting.fit_movements(pj.ShoulderElbowArm(), list(train))
    TRAIN_TRUTH.update(zip((r.name for r in train), infos))
    return KJ, fit, test, info


def test_fit_converges_and_recovers_the_time_constants(case):
    KJ, fit, _, _ = case
    assert fit.converged.tolist() == [True] and fit.n_reaches[0] == 20
    se = dict(zip(fit.param_names, fit.stderr[0]))
    assert abs(fit.tau[0] / TAU - 1) < 0.05 and abs(fit.tau0[0] / TAU0 - 1) < 0.05, (fit.tau, fit.tau0, se)
    assert fit.integration_error_deg[0] <= 0.01


def test_each_reach_s_target_onset_is_recovered(case):
    # The reference's target switch times, never given to the fit: each reach's fitted delay is its
    # window's start minus the switch time (one delay for all would miss them by up to 25 ms).
    _, fit, _, _ = case
    sr = fit.reaches["P1"]
    true_delay = np.array([t[0] - TRAIN_TRUTH[r]["t_switch"][k] for r, k, t in zip(sr.recording, sr.index, sr.t)])
    err_ms = 1e3 * np.abs(fit.reach_delays["P1"] - true_delay)
    assert np.median(err_ms) < 8 and err_ms.max() < 20, err_ms
    assert fit.reach_target_offsets["P1"].shape == (20, 3)


def test_the_elbow_gauge_is_found(case):
    # One unidentified direction: q_rest shifted along KJ⁻¹ e_elbow (no stiffness component).
    _, fit, _, _ = case
    V = fit.unidentified_directions[0]
    rows = V[np.any(V != 0, axis=1)]
    assert rows.shape[0] == 1, fit.unidentified
    names = fit.param_names
    rest = [names.index(f"q_rest[{j}]") for j in JOINTS]
    v = rows[0]
    u = np.linalg.solve(fit.KJ[0], np.eye(4)[3])
    cos = abs(v[rest] @ u) / (np.linalg.norm(v[rest]) * np.linalg.norm(u))
    assert cos > 0.999 and np.linalg.norm(v[rest]) > 0.999
    assert "q_rest[elbow]" in fit.unidentified[0][0]


def test_held_out_final_postures_and_paths(case):
    KJ, fit, test, info = case
    # the fitted model's equilibria (Donders' law) at the held-out targets against the true ones
    targets = info["targets"]
    q_true = np.stack([slsqp_equilibrium(arm4_fk, arm4_jac, KJ, Q_REST, x, q0=qf)
                       for x, qf in zip(targets, info["q_final"])])
    eq = pj.equilibrium_posture(pj.ShoulderElbowArm(), fit.KJ[0], fit.q_rest[0], targets, q_init=q_true)
    err = np.rad2deg(np.abs(np.asarray(eq.q) - q_true))
    assert err.max() < 1.0 and np.median(err) < 0.3, err
    pr = fitting.predict_movements(fit, [test])
    assert len(pr) == 10 and np.all(pr.status == 0)
    # windows in the recording's own clock, starting before each target switch's reach
    assert np.all(np.diff(pr.t[:, 0]) > 0) and pr.t[0, 0] >= test.t[0]
    pinv = pr.baselines["pinv_minjerk"]["rmse_deg"]
    assert np.median(pr.rmse_deg) < 1.0 and np.median(pr.rmse_deg) <= 0.5 * np.median(pinv), (pr.rmse_deg, pinv)


@pytest.mark.bad_input("fitting.fit_movements", "fitting.predict_movements", "fitting.plot_movements",
                       "fitting.plot_movement_parameters")
def test_bad_arguments_are_refused_by_name(case):
    _, fit, test, _ = case
    chain = pj.ShoulderElbowArm()
    with pytest.raises(TypeError, match="`chain`"):
        fitting.fit_movements("arm.xml", [test])
    with pytest.raises(ValueError, match="joints"):
        fitting.fit_movements(pj.PlanarArm([0.3, 0.3, 0.2]), [test])
    for kw, name in ((dict(model="pmp2"), "model"), (dict(damping="none"), "damping"),
                     (dict(time_constants="ms"), "time_constants"), (dict(max_steps=(0, 5)), "max_steps")):
        with pytest.raises(ValueError, match=f"`{name}`"):
            fitting.fit_movements(chain, [test], **kw)
    with pytest.raises(TypeError, match="`recordings`"):
        fitting.fit_movements(chain, [np.zeros((10, 4))])
    with pytest.raises(TypeError, match="`fit`"):
        fitting.predict_movements("fit", [test])
    with pytest.raises(TypeError, match="`fit`"):
        fitting.plot_movement_parameters("fit")
    with pytest.raises(TypeError, match="`pred`"):
        fitting.plot_movements(fit, "P1")
