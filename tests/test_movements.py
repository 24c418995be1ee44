"""``fitting.fit_movements`` / ``predict_movements`` on continuous multi-reach recordings.

Reference, independent of pmpjax's simulator: ``tests/_movement_reference.py`` (SciPy LSODA of the
NumPy λ0-PMP of ``tests/_reference.py``, Arimoto's gain with Eq 10 at each reach's start) generates
the recordings on the 4-joint shoulder–elbow arm (``arm4_fk``/``arm4_jac``, closed form) with a
full, anisotropic ``KJ`` and 0.2° noise; SciPy's SLSQP gives the true equilibria. What must hold:
the fit converges, recovers the time constants within 5 % and each reach's target onset (the
reference's switch times, which the fit never sees), predicts the held-out final postures
and joint paths within 1° (at most half the pseudo-inverse's error), and finds on this arm the one
direction no reach can see: ``q_rest`` along ``KJ⁻¹ e_elbow``. Its standard errors and its
stopping point are checked at the optimum against the fit's objective rebuilt in NumPy (central
differences, SciPy's Levenberg–Marquardt).

Compile budget: one fit (stage 1, the gauge, stage 2, the integration check) and one prediction
(whose simulation the rebuilt objective reuses).
"""

import dataclasses
import math

import jax.numpy as jnp
import numpy as np
import pytest
from _movement_reference import continuous_recording, random_spd
from _reference import arm4_fk, arm4_jac, slsqp_equilibrium
from scipy.optimize import least_squares

import fitting
import pmpjax as pj
from fitting._movements import model as mdl
from fitting._movements.data import SAMPLES
from pmpjax.internal import without_unit_checks

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


def test_predictions_are_accurate_and_failed_reaches_say_so(case, monkeypatch):
    # Predictions simulate by RODAS4 with adaptive steps, whatever the fit's steps: within 0.01° of
    # the fixed-step path at eight times the fit's steps (fourth order, checked against Radau in
    # tests/test_stiff.py). A reach whose simulation fails (a stand-in NONFINITE) is reported with
    # its status and no errors, never SUCCESSFUL, and the others are unchanged.
    _, fit, test, _ = case
    pr = fitting.predict_movements(fit, [test])
    real = mdl.simulate
    seen = []

    def recorded(chain, model, planner, q0, target, steps, solver):
        seen.append((steps, solver))
        fine = real(chain, model, planner, q0, target, 8 * fit.steps_per_sample, "rodas4")
        tr = real(chain, model, planner, q0, target, steps, solver)
        seen.append(np.asarray(fine.q))
        return dataclasses.replace(tr, q=tr.q.at[0].set(jnp.nan),
                                   status=tr.status.at[0].set(int(pj.Status.NONFINITE)))

    monkeypatch.setattr(mdl, "simulate", recorded)
    failed = fitting.predict_movements(fit, [test])
    assert seen[0] == (None, "rodas4")
    np.testing.assert_allclose(np.rad2deg(pr.q_pred), np.rad2deg(seen[1]), rtol=0, atol=0.01)
    assert np.all(pr.status == 0)
    assert failed.status[0] == int(pj.Status.NONFINITE) and np.isnan(failed.rmse_deg[0])
    np.testing.assert_array_equal(failed.status[1:], 0)
    np.testing.assert_array_equal(failed.rmse_deg[1:], pr.rmse_deg[1:])


BATCH = 10  # reaches per simulation: the held-out trial's, so predict_movements' compiled simulation serves


def objective(fit, subject="P1", steps=None):
    """The stage-2 objective of ``fit_movements`` for one subject, rebuilt from the model's
    documentation (``fitting._movements.model``) without its residual code: ``(x (p + B·k,),
    residual(x) (N,), owner (N,))``, ``x`` the fitted optimum (the subject's parameters, then each
    reach's delay offset and target offset), ``owner`` the reach of each row (−1: the bounds).
    Rows: per reach ``(q_sim − q_obs)(s_j)/√(S−1)``, j = 1..S−1, and the final posture once more;
    the bounds' softplus hinges on log cond(KJ) and the rest angles; each offset over its prior
    spread, weighed as a ``PRIOR_RMS_DEG`` joint error. The λ0-PMP and its planner from the
    parameters by the model's ``unpack`` and ``model_and_planner``, trajectories by
    ``pmpjax.simulate`` (the fit's solver, at the fit's steps unless ``steps`` says otherwise; its
    embedded error estimate may call them ``INACCURATE``, which the fit accepts: its own check
    against twice the steps judges them), targets by the NumPy arm."""
    chain, a = fit.chain, fit.subject_index(subject)
    sr = fit.reaches[subject]
    cfg = mdl.Config(chain.n, fit.model, fit.damping, fit.time_constants, m=chain.m)
    P, B, n, k = len(fit.param_names), len(sr), chain.n, 1 + chain.m
    assert B % BATCH == 0 and fit.model == "lambda0" and fit.damping == "tau0_KJ"
    target = np.stack([arm4_fk(q) for q in sr.q_end])
    amplitude = np.linalg.norm(target - np.stack([arm4_fk(q) for q in sr.q_start]), axis=1)
    # the documented priors (30 ms; 2 % of the amplitude), bounds (cond 100, rest ± 90°, widths
    # 0.02 and 0.01 rad, weight 30) and prior weight (0.1° RMS): numbers, not the module's constants
    spread = np.c_[np.full(B, 0.03), 0.02 * amplitude[:, None] * np.ones(k - 1)]
    margin = np.deg2rad(90.0)
    lo, hi = sr.q_obs.min((0, 1)) - margin, sr.q_obs.max((0, 1)) + margin
    rest = [fit.param_names.index(f"q_rest[{j}]") for j in fit.joint_names]
    cond_max, (width_c, width_q) = 100.0, (0.02, 0.01)  # (the fit's default bound)

    def hinge(g, width):
        return width * np.logaddexp(0.0, g / width)

    def residual(x):
        th, u = x[:P], x[P:].reshape(B, k)
        par = mdl.unpack(jnp.asarray(th), cfg)
        q = []
        for s in range(0, B, BATCH):
            b = slice(s, s + BATCH)
            with without_unit_checks():
                model, planner = mdl.model_and_planner(chain, par, jnp.asarray(sr.duration[b]), cfg,
                                                       jnp.asarray(u[b, 0]))
                tr = mdl.simulate(chain, model, planner, sr.q_start[b], target[b] + u[b, 1:],
                                  steps or fit.steps_per_sample, fit.solver)
            assert np.all(np.isin(np.asarray(tr.status), [int(pj.Status.SUCCESSFUL), int(pj.Status.INACCURATE)]))
            q.append(np.asarray(tr.q))
        d = np.concatenate(q) - sr.q_obs
        rows = np.concatenate([d[:, 1:].reshape(B, -1) / math.sqrt(SAMPLES - 1), d[:, -1]], axis=1)
        ev = np.linalg.eigvalsh(np.asarray(par["KJ"]))
        q_rest = th[rest]
        bounds = 30.0 * np.r_[hinge(math.log(ev[-1] / ev[0]) - math.log(cond_max), width_c),
                                          hinge(q_rest - hi, width_q) + hinge(lo - q_rest, width_q)]
        prior = u / spread * math.radians(0.1) * math.sqrt(n)
        return np.concatenate([rows.ravel(), bounds, prior.ravel()])

    x = np.r_[fit.params[a], np.c_[fit.reach_delays[subject] - fit.delay[a], fit.reach_target_offsets[subject]].ravel()]
    owner = np.r_[np.repeat(np.arange(B), SAMPLES * n), np.full(1 + n, -1), np.repeat(np.arange(B), k)]
    return x, residual, owner


def central_jacobian(residual, x, owner, P, k, h=1e-6):
    """Central differences (N, p) of ``residual`` at ``x``: the ``P`` shared parameters one by one,
    each of the ``k`` per-reach coordinates of every reach at once (a reach's offsets move only its
    own rows)."""
    B = (x.size - P) // k
    r0 = residual(x)
    J = np.zeros((r0.size, x.size))
    for i in range(P + k):
        e = np.zeros(x.size)
        if i < P:
            e[i] = h
        else:
            e[i::k] = h
        d = (residual(x + e) - residual(x - e)) / (2 * h)
        if i < P:
            J[:, i] = d
        else:
            for b in range(B):
                J[owner == b, P + b * k + i - P] = d[owner == b]
    return r0, J


@pytest.fixture(scope="module")
def at_optimum(case):
    """The rebuilt objective at the fit's optimum: its residual and central-difference Jacobian, the
    unidentified direction ``v`` (the documented gauge, ``q_rest`` along ``KJ⁻¹ e_elbow``), an
    orthonormal basis ``Q`` of the others, and the Gauss–Newton covariance there: ``σ² Q (QᵀJᵀJQ)⁻¹ Qᵀ``
    (the reaches' offsets profiled out with the rest, zero variance along ``v``), ``σ² = |r|²/(N − p)``
    over the real reaches' rows and every fitted number."""
    _, fit, _, _ = case
    x, residual, owner = objective(fit)
    P, k = len(fit.param_names), 1 + fit.chain.m
    r, J = central_jacobian(residual, x, owner, P, k)
    v = np.zeros(x.size)
    rest = [fit.param_names.index(f"q_rest[{j}]") for j in JOINTS]
    u = np.linalg.solve(fit.KJ[0], np.eye(4)[3])
    v[rest] = u / np.linalg.norm(u)
    Q = np.linalg.svd(np.eye(x.size) - np.outer(v, v))[0][:, : x.size - 1]
    sigma2 = r @ r / (r.size - x.size)
    cov = sigma2 * Q @ np.linalg.inv(Q.T @ J.T @ J @ Q) @ Q.T
    return dict(x=x, residual=residual, r=r, J=J, v=v, Q=Q, cov=cov, se=np.sqrt(np.diag(cov)), P=P, owner=owner)


def test_the_rebuilt_objective_is_the_fit_s(case, at_optimum):
    _, fit, _, _ = case
    r = at_optimum["r"]
    assert r.size == 20 * (SAMPLES * 4 + 4) + 5
    np.testing.assert_allclose(0.5 * r @ r, fit.loss[0], rtol=1e-9)
    # the fit's simulations are as accurate as it reports: within 0.01° of four times its steps
    fine = objective(fit, steps=4 * fit.steps_per_sample)[1](at_optimum["x"])
    error_deg = np.rad2deg(np.abs(fine - r).max()) * math.sqrt(SAMPLES - 1)
    assert fit.integration_error_deg[0] < 0.01 and error_deg < 0.01, (fit.integration_error_deg, error_deg)


def test_standard_errors_are_the_delete_one_reach_jackknife(case, at_optimum):
    # The reported errors against the delete-one-reach jackknife rebuilt in NumPy on the rebuilt
    # objective: for each of the 20 reaches, the Gauss–Newton step of the problem without its rows
    # and its offsets (least squares on the central-difference Jacobian of every other row, the
    # gauge left out by the minimum-norm solution), then (G−1)/G Σ (Δ_b − Δ̄)(Δ_b − Δ̄)ᵀ. Errors
    # 1.5 times too large, Gauss–Newton errors (2–3× smaller on such data:
    # benchmarks/movements_calibration.py) or a reach's own offsets left in fail.
    _, fit, _, _ = case
    P, r, J, owner, v = at_optimum["P"], at_optimum["r"], at_optimum["J"], at_optimum["owner"], at_optimum["v"]
    G = int(owner.max()) + 1
    D = np.stack([np.linalg.lstsq(J[owner != b], -r[owner != b], rcond=1e-6)[0][:P] for b in range(G)])
    E = D - D.mean(0)
    cov = (G - 1) / G * E.T @ E
    np.testing.assert_allclose(fit.stderr[0], np.sqrt(np.diag(cov)), rtol=2e-3)
    np.testing.assert_allclose(fit.cov[0], cov, rtol=2e-3, atol=2e-3 * np.abs(cov).max())
    # zero variance along the unidentified direction
    assert np.abs(fit.cov[0] @ v[:P]).max() < 1e-8 * np.abs(fit.cov[0]).max()


def test_converged_means_at_the_optimum_to_a_small_fraction_of_a_standard_error(at_optimum):
    # "Converged": every parameter within 0.014 standard errors of the optimum (statistical
    # tolerance 1e-4) or a relative cost change below 1e-8. SciPy's Levenberg–Marquardt (MINPACK,
    # tight tolerances) from the fit's optimum on the rebuilt objective, the gauge held (the
    # Jacobian at the start, by central differences: over the distances in question it changes far
    # less than they are), may move no parameter, the reaches' offsets included, by 0.05 of its
    # standard error (measured 0.001; with a statistical tolerance of 1 the fit stopped 0.45 away,
    # with a cost tolerance of 1e-3 0.78).
    x, residual, Q, J = at_optimum["x"], at_optimum["residual"], at_optimum["Q"], at_optimum["J"]
    JQ = J @ Q
    sol = least_squares(lambda z: residual(x + Q @ z), np.zeros(Q.shape[1]), jac=lambda z: JQ, method="lm",
                        x_scale="jac", xtol=1e-14, ftol=1e-14, gtol=1e-14, max_nfev=50)
    r = at_optimum["r"]
    assert sol.cost <= 0.5 * r @ r * (1 + 1e-12)
    moved = np.abs(Q @ sol.x) / at_optimum["se"]
    assert moved.max() < 0.05, (moved[: at_optimum["P"]], moved.max())


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
