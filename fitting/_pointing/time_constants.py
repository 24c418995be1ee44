"""Time constants of the λ0-PMP fitted to pointing movements by gradient descent through ``simulate``.

The paper sets ``τ = τ0 = T_sj/5`` by hand (Section 3). Here ``τ0`` (intrinsic, ``W = τ0 KJ``,
Eq 7) and ``τ`` (extrinsic, Eq 8; ``k = b_max/τ0``, Eq 10) are fitted per subject — or per
subject × movement — to the mean normalised paths, speed profiles and durations of
``fitting.analyze_pointing``, by Levenberg–Marquardt (``fitting.least_squares``, the one
optimiser loop) with Jacobians by forward-mode differentiation through ``pmpjax.simulate``.

**Parameters.** ``log τ0`` and ``log τ`` (positive by construction). Per subject
(``per_target=False``) one pair [s] serves all 16 movements of the subject; per target one pair per
subject × movement. Where the time constants scale with each movement's duration (the paper's
``τ = T_sj/5``; ``pmpjax.synthetic_pointing_experiment`` with ``target_spread``), the per-subject
pair estimates the subject's typical values, the geometric mean over its movements, not any
one movement's. The standard errors take ``KJ`` and ``q_rest`` as known: when they come from a
Donders fit, its error moves τ further (tests/test_pointing.py, the main job's pointing part).
The model movement starts at rest in the mean rest posture before the movement and goes to the
target; it is analysed like the data (cut at the analysis threshold of
its peak speed, half a data sample wider on each side as the sample-level cut of the data is on
average, and resampled at the analysis' normalised times), after passing it through the
equivalent kernel of the analysis' smoothing spline: the data are smoothed, so the model is
observed through the same filter (without it the blunted onset of the smoothed speed biases
``τ`` up by ~15 % at 0.1° IMU noise).

**Residual** per movement (each term dimensionless): the path at the normalised samples minus
the mean measured path, over the target radius (n × 2); the speed profile minus the mean
measured one, over the measured peak (n); and the relative duration error times √n. Because every
rate of the λ0-PMP scales with ``1/τ0`` apart from the planner's ``t/τ`` (see
``pmpjax._wrist.pointing.normalised_movements``), the shape of the speed profile and path
identify ``τ/τ0`` and the duration identifies ``τ0``.

All items (subjects, or subjects × movements) are fitted in one ``jit``+``vmap`` call, each with
its own convergence, status and standard errors (delta method from the log scale): per subject
clustered by movement (the sandwich of :func:`_clustered_se`: a movement's residual entries share
its trial-to-trial variability, so Gauss–Newton errors that treat them as independent come out
2–3 times too small against the spread over replicate experiments, tests/test_pointing.py);
per subject × movement Gauss–Newton. Converged: a relative cost change below 1e-10, a relative
step below 1e-8, or every parameter within 0.014 Gauss–Newton standard errors of the optimum (:data:`STOL`).
"""

from __future__ import annotations

import dataclasses
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from pmpjax import Status, Wrist
from pmpjax.internal import MODEL_DT, MODEL_SPAN, check_positive_int, fast_compile_jit, normalised_movements

from .._donders import nio_residual
from .._optimise import covariance, least_squares, params_from_stiffness, stiffness_from_params
from .analysis import PointingAnalysis
from .observe import _kernel_halfwidth, _profiles, spline_bandwidth
from .prediction import _check_params, _movement_inputs

#: Static simulation grid of the fits, in units of the movement's duration T_sj: the predictions'
#: span (movements up to ~2 T_sj) at twice their step, ≤ τ/10 for τ ≥ 0.2 T_sj (the paper's T/5).
#: Against a grid four times finer, τ0 and τ move by 0.03 and 0.10 of their standard errors at
#: τ = 0.12 T (τ/6 per step; tests/test_pointing.py) and by ≤ 0.011 at the paper's τ ≈ T/5
#: (benchmarks/pointing.py). The difference is second order in the step (a quarter of it at the
#: predictions' step), where the fits cost twice as much.
FIT_SPAN, FIT_DT = MODEL_SPAN, 2 * MODEL_DT
#: Largest integration error at the optimum a fit reports as converged [deg]: the joint angles
#: of every movement against the same simulation at half the step (``Status.INACCURATE`` above it).
INTEGRATION_TOL_DEG = 0.01
#: Statistical tolerance of the time-constant fit (``fitting.least_squares``' ``stol``): converged
#: once every parameter is within 0.014 Gauss–Newton standard errors of the optimum, which the analysed
#: subjects reach in 3 iterations instead of the 5 that the cost and step tolerances alone take
#: (τ0, τ then differ from those of the tight tolerances by < 0.006 standard errors).
STOL = 1e-4


@dataclasses.dataclass(frozen=True)
class TimeConstantFit:
    """Result of :func:`fit_time_constants` (numpy arrays).

    ``tau0``, ``tau`` [s]: (S,) per subject, or (S, L) per subject × movement (``per_target``);
    ``tau0_movement``, ``tau_movement`` (S, L) the values each movement uses; ``stderr``
    (…, 2) standard errors of (τ0, τ) [s]; ``loss`` (…) ½|r|² at the optimum; ``rms`` (…) RMS
    residual; ``steps`` (…) LM iterations; ``status`` (…) int (``pmpjax.Status``: SUCCESSFUL,
    MAX_STEPS, NONFINITE, INACCURATE, TOO_FEW_DATA for items without data); ``converged`` = status == 0;
    ``subjects``, ``labels``, ``per_target``; ``solver`` of the simulations (``"rk4"``, or the
    L-stable ``"rodas4"`` when RK4 at the fit's step would be unstable at the start);
    ``integration_error_deg`` (…) the largest joint-angle difference [deg] of the item's movements
    at the optimum against half the step: above :data:`INTEGRATION_TOL_DEG` a converged item is
    ``INACCURATE`` (its simulations, not the data, would decide the fit).
    """

    subjects: tuple
    labels: tuple
    tau0: np.ndarray
    tau: np.ndarray
    tau0_movement: np.ndarray
    tau_movement: np.ndarray
    stderr: np.ndarray
    loss: np.ndarray
    rms: np.ndarray
    steps: np.ndarray
    status: np.ndarray
    converged: np.ndarray
    per_target: bool
    solver: str = "rk4"
    integration_error_deg: np.ndarray | None = None


def path_residual(r0, r, KJ, q_rest, data, *, threshold, n_samples, radius, d, J, span=FIT_SPAN, dt=FIT_DT,
                  solver="rk4"):
    """Residual (M·(3n + 1),) of M movements of one subject for time constants ``r0``, ``r`` (M,)
    in units of each movement's T (module docstring). ``data``: dict of ``q0`` (M, 3), ``target``
    (M, 2), ``T`` (M,), ``half`` (M,), ``bandwidth`` (M,) of the analysis' smoothing in units
    of T (``J`` grid steps each side), ``w`` (M,) weights (0 for cells without data),
    ``mean_path`` (M, n, 2), ``mean_speed`` (M, n); ``solver`` of ``pmpjax.simulate``.
    Differentiable in ``r0``, ``r``, ``KJ`` (3, 3), ``q_rest`` (3,)."""
    M = data["q0"].shape[0]
    KJb = jnp.broadcast_to(KJ, (M, 3, 3))
    tr = normalised_movements(KJb, jnp.broadcast_to(q_rest, (M, 3)), r0, r, data["q0"], data["target"],
                              span=span, dt=dt, d=d, pad=False, solver=solver)
    prof = _profiles(tr, data["T"], data["half"], data["bandwidth"], h=dt, J=J, threshold=threshold,
                     n_samples=n_samples, radius=radius, joints=False)
    w = data["w"]
    peak = jnp.max(data["mean_speed"], axis=1)
    r_path = (prof["path"] - data["mean_path"]) / radius * w[:, None, None]
    r_speed = (prof["speed"] - data["mean_speed"]) / jnp.where(peak > 0, peak, 1.0)[:, None] * w[:, None]
    r_dur = (prof["duration"] / data["T"] - 1.0) * np.sqrt(n_samples) * w
    return jnp.concatenate([r_path.reshape(-1), r_speed.reshape(-1), r_dur])


@partial(fast_compile_jit, static_argnames=("opts", "max_steps"))
def _fit_items(theta0, KJ, q_rest, data, *, opts, max_steps):
    opts = dict(opts)

    def residual(theta, args):
        K, qr, dat = args
        return path_residual(jnp.exp(theta[0]) / dat["T"], jnp.exp(theta[1]) / dat["T"], K, qr, dat, **opts)

    def one(th0, K, qr, dat):
        res = least_squares(residual, th0, (K, qr, dat), max_steps=max_steps, gtol=1e-10, ftol=1e-10, xtol=1e-8,
                            stol=STOL)
        _, se, _, _ = covariance(res)
        return res, se

    return jax.vmap(one)(theta0, KJ, q_rest, data)


def _clustered_se(jac, residual, w, n):
    """(items, 2) standard errors of (log τ0, log τ) with the residual clustered by movement.

    The residual of a movement (its path, speed profile and duration against the means over its
    trials) is correlated along the movement: its error is mostly the movement's own trial-to-trial
    variability, shared by all of its samples, so the Gauss–Newton ``σ² (JᵀJ)⁻¹`` (independent
    entries) understates the spread of the estimates several times. Instead, the sandwich
    ``(JᵀJ)⁻¹ (Σ_m g_m g_mᵀ) (JᵀJ)⁻¹ · M/(M − 2)`` with ``g_m = J_mᵀ r_m`` summed over movement m's
    entries, over the M movements with data (``w`` (items, L) > 0)."""
    items, L = w.shape
    cluster = np.concatenate([np.repeat(np.arange(L), 2 * n), np.repeat(np.arange(L), n), np.arange(L)])
    g = np.zeros((items, L, jac.shape[-1]))
    for i in range(items):
        np.add.at(g[i], cluster, jac[i] * residual[i][:, None])
    M = w.astype(bool).sum(1)
    with np.errstate(all="ignore"):
        bread = np.linalg.pinv(np.einsum("bki,bkj->bij", jac, jac))
        cov = bread @ np.einsum("bmi,bmj->bij", g, g) @ bread * (M / np.maximum(M - 2, 1))[:, None, None]
    return np.sqrt(np.abs(np.diagonal(cov, axis1=1, axis2=2)))


def _solver(KJ, q_rest, tau0, tau, data, d) -> str:
    """``"rk4"`` when RK4 at ``FIT_DT`` is stable for every movement at the starting time constants
    ``tau0``, ``tau`` (items,) [s] (``data`` as :func:`_item_data`'s), else the L-stable
    ``"rodas4"`` (Eq 10's gain at anisotropic stiffness: ``pmpjax.simulate``)."""
    from pmpjax import ArimotoPlanner, Lambda0PMP
    from pmpjax.internal import check_rk4_stability

    M = data["q0"].shape[1]
    T = np.asarray(data["T"], float).reshape(-1)
    ok = np.isfinite(T) & (T > 0) & np.all(np.isfinite(np.asarray(data["q0"]).reshape(-1, 3)), -1)
    flat = lambda a: np.repeat(np.asarray(a), M, axis=0)[ok]  # noqa: E731
    K = flat(KJ)
    r0, r = flat(tau0) / T[ok], flat(tau) / T[ok]
    model = Lambda0PMP(Wrist(d), KJ=K, q_rest=flat(q_rest), W=r0[:, None, None] * K)
    try:
        check_rk4_stability(model, ArimotoPlanner(k=None, tau=r, tau0=r0), data["q0"].reshape(-1, 3)[ok],
                            (int(ok.sum()),), FIT_DT)
    except ValueError as e:
        if "too large for RK4" not in str(e):
            raise
        return "rodas4"
    return "rk4"


def _integration_error_deg(KJ, q_rest, tau0, tau, data, d, solver):
    """(items,) largest joint-angle difference [deg] over each item's movements with data between
    the fits' grid and one of half the step, at ``tau0``, ``tau`` (items,) [s]; ``KJ`` (items, 3,
    3), ``q_rest`` (items, 3), ``data`` as :func:`_item_data`'s. NaN for an item without a finite
    movement; inf for all when RK4 is unstable at the optimum."""
    T = np.asarray(data["T"], float)
    items = T.shape[0]
    with np.errstate(invalid="ignore"):
        ok = (np.asarray(data["w"]) > 0) & np.isfinite(T) & (T > 0) \
            & (np.isfinite(tau0) & np.isfinite(tau) & (tau0 > 0) & (tau > 0))[:, None]
    if not ok.any():
        return np.full(items, np.nan)
    item, mov = np.nonzero(ok)
    args = (np.asarray(KJ)[item], np.asarray(q_rest)[item], tau0[item] / T[item, mov], tau[item] / T[item, mov],
            np.asarray(data["q0"])[item, mov], np.asarray(data["target"])[item, mov])
    try:
        qa, qb = (np.asarray(normalised_movements(*args, span=FIT_SPAN, dt=h, d=d, solver=solver).q)
                  for h in (FIT_DT, FIT_DT / 2))
    except ValueError as e:  # RK4 unstable at the fitted time constants
        if "too large for RK4" not in str(e):
            raise
        return np.where(ok.any(1), np.inf, np.nan)
    e = np.rad2deg(np.max(np.abs(qa - qb[:, ::2]), axis=(1, 2)))
    e = np.where(np.isfinite(e), e, np.inf)
    out = np.full(items, -1.0)
    np.maximum.at(out, item, e)
    return np.where(out >= 0, out, np.nan)


def _item_status(has, finite, converged, integration_error_deg):
    """(items,) ``pmpjax.Status`` of the fits: TOO_FEW_DATA without data, NONFINITE, MAX_STEPS,
    INACCURATE for a converged item whose integration error is not within
    :data:`INTEGRATION_TOL_DEG`, else SUCCESSFUL."""
    accurate = integration_error_deg <= INTEGRATION_TOL_DEG
    return np.select([~has, ~finite, ~np.asarray(converged, bool), ~accurate],
                     [int(Status.TOO_FEW_DATA), int(Status.NONFINITE), int(Status.MAX_STEPS), int(Status.INACCURATE)],
                     int(Status.SUCCESSFUL))


def _item_data(analysis, KJ, q_rest, per_target):
    """Per-item arrays: items are subjects (M = L movements) or subject × movement (M = 1)."""
    q0, target, T, has = _movement_inputs(analysis)
    S, L = T.shape
    bw = spline_bandwidth(analysis.lam, analysis.rate)[:, None] / T
    data = dict(q0=q0, target=target, T=T, half=0.5 / analysis.rate / T, bandwidth=bw, w=has.astype(float),
                mean_path=np.nan_to_num(analysis.mean_path), mean_speed=np.nan_to_num(analysis.mean_speed))
    if per_target:
        data = {k: v.reshape((S * L, 1) + v.shape[2:]) for k, v in data.items()}
        KJ = np.repeat(KJ, L, axis=0)
        q_rest = np.repeat(q_rest, L, axis=0)
        Tbar = T.reshape(S * L)
        has_item = has.reshape(S * L)
    else:
        with np.errstate(all="ignore"):
            Tbar = np.where(has.any(1), (T * has).sum(1) / np.maximum(has.sum(1), 1), 0.5)
        has_item = has.any(1)
    return data, KJ, q_rest, Tbar, has_item, _kernel_halfwidth(bw, FIT_DT)


def fit_time_constants(analysis: PointingAnalysis, KJ, q_rest, *, per_target: bool = False,
                       max_steps: int = 50) -> TimeConstantFit:
    """Fit ``τ0`` and ``τ`` to the mean paths, speed profiles and durations (module docstring).

    **Arguments:** ``analysis`` (``fitting.analyze_pointing``); ``KJ`` (S, 3, 3), ``q_rest``
    (S, 3) in the order of ``analysis.subjects`` (one (3, 3) / (3,) serves all), e.g. from
    ``fitting.fit_donders``; ``per_target``: one (τ0, τ) per subject × movement instead of per
    subject; ``max_steps``: LM iterations per item.

    Starts at the paper's ``τ = τ0 = T/5`` (T: the subject's mean duration, or the movement's).

    **Returns:**

    A :class:`TimeConstantFit`; items without data get status ``TOO_FEW_DATA`` and NaN.

    **Raises:**

    ``TypeError`` for a non-analysis; ``ValueError`` naming the argument for ``KJ``/``q_rest`` of
    the wrong shape or a ``KJ`` that is not SPD, or a non-positive ``max_steps``.

    **Compile time:** ≈ 14 s on first use on an idle 2-core CPU (LM through ``simulate`` of every
    movement with forward-mode derivatives: ≈ 9 s tracing, the rest XLA); ≈ 0.6 s to run 2 subjects
    × 3 trials (benchmarks/compile_times.py).
    """
    KJ, q_rest = _check_params(analysis, KJ, q_rest)
    check_positive_int("max_steps", max_steps)
    if not isinstance(per_target, bool):
        raise TypeError(f"`per_target` must be a bool, got {type(per_target).__name__}")
    data, KJi, qri, Tbar, has, J = _item_data(analysis, KJ, q_rest, per_target)
    S, L = analysis.T.shape
    theta0 = np.log(np.stack([Tbar / 5.0, Tbar / 5.0], -1))
    solver = _solver(KJi, qri, np.exp(theta0[:, 0]), np.exp(theta0[:, 1]), data, analysis.d)
    opts = (("threshold", analysis.threshold), ("n_samples", analysis.mean_path.shape[2]),
            ("radius", analysis.radius), ("d", analysis.d), ("J", J), ("solver", solver))
    res, se_log = jax.device_get(_fit_items(theta0, KJi, qri, {k: jnp.asarray(v) for k, v in data.items()},
                                            opts=opts, max_steps=int(max_steps)))
    tau = np.exp(res.x)
    n_res = np.asarray(res.residual).shape[-1]
    finite = np.isfinite(res.cost)
    bad = ~has | ~finite
    if not per_target:  # one (τ0, τ) per subject: movement-clustered standard errors (see below)
        se_log = _clustered_se(np.asarray(res.jac), np.asarray(res.residual), data["w"], analysis.mean_path.shape[2])
    tau = np.where(bad[:, None], np.nan, tau)
    err = _integration_error_deg(KJi, qri, tau[:, 0], tau[:, 1], data, analysis.d, solver)
    status = _item_status(has, finite, res.converged, err)
    stderr = np.where(bad[:, None], np.nan, tau * se_log)
    loss = np.where(bad, np.nan, res.cost)
    shape = (S, L) if per_target else (S,)
    tau0_i, tau_i = tau[:, 0].reshape(shape), tau[:, 1].reshape(shape)
    mov = (lambda a: a) if per_target else (lambda a: np.broadcast_to(a[:, None], (S, L)).copy())
    return TimeConstantFit(
        subjects=analysis.subjects, labels=analysis.labels, tau0=tau0_i, tau=tau_i, tau0_movement=mov(tau0_i),
        tau_movement=mov(tau_i), stderr=stderr.reshape(shape + (2,)), loss=loss.reshape(shape),
        rms=np.sqrt(2 * loss / n_res).reshape(shape), steps=np.asarray(res.steps).reshape(shape),
        status=status.reshape(shape), converged=(status == 0).reshape(shape), per_target=per_target,
        solver=dict(opts)["solver"], integration_error_deg=err.reshape(shape),
    )


# --- the joint fit: KJ, q_rest, τ0, τ to postures and paths ----------------------------------------


@dataclasses.dataclass(frozen=True)
class PointingModelFit:
    """Result of :func:`fit_pointing_model` (numpy arrays, S subjects).

    ``subjects`` (S,) names; ``KJ`` (S, 3, 3) [Nm/rad] (trace 4), ``q_rest`` (S, 3) [rad], ``tau0``, ``tau`` (S,) [s];
    ``params`` (S, 10) the fitted vector (log-stiffness, q_rest, log τ0, log τ; ``param_names``),
    ``stderr`` (S, 10) its Gauss–Newton standard errors; ``loss`` (S,) ½|r|² of the weighted
    residual; ``torsion_rms`` (S,) [rad] of the Donders postures; ``path_rms`` (S,) RMS of the
    path residual (dimensionless, as in :func:`fit_time_constants`); ``weights`` (S, 2) the block
    weights ``1/σ`` (torsion, paths); ``steps``, ``status``, ``converged``, ``solver``,
    ``integration_error_deg`` as in :class:`TimeConstantFit`.
    """

    subjects: tuple
    KJ: np.ndarray
    q_rest: np.ndarray
    tau0: np.ndarray
    tau: np.ndarray
    params: np.ndarray
    stderr: np.ndarray
    loss: np.ndarray
    torsion_rms: np.ndarray
    path_rms: np.ndarray
    weights: np.ndarray
    steps: np.ndarray
    status: np.ndarray
    converged: np.ndarray
    param_names: tuple
    solver: str = "rk4"
    integration_error_deg: np.ndarray | None = None


JOINT_PARAMS = ("logK[PS,PS]", "logK[FE,FE]", "logK[PS,FE]", "logK[PS,RUD]", "logK[FE,RUD]", "q_rest[PS]",
                "q_rest[FE]", "q_rest[RUD]", "log tau0", "log tau")


def _joint_residual(opts, n_torsion):
    """Residual of one subject: torsion of the Donders postures (``n_torsion`` entries, weighted)
    then the paths (weighted), as a function of θ (10,) and the subject's data."""
    torsion = nio_residual(Wrist(opts["d"]), 5, 4.0, "torsion", 1e-10)
    popts = {k: v for k, v in opts.items()}

    def residual(theta, data):
        KJ = stiffness_from_params(theta[:5], 3, 4.0)
        qr = theta[5:8]
        dat = data["paths"]
        r_t = torsion(theta[:8], (data["x"], data["q_obs"], data["w_obs"])) * data["weights"][0]
        r_p = path_residual(jnp.exp(theta[8]) / dat["T"], jnp.exp(theta[9]) / dat["T"], KJ, qr, dat, **popts)
        return jnp.concatenate([r_t, r_p * data["weights"][1]])

    return residual


@partial(fast_compile_jit, static_argnames=("opts", "max_steps", "n_torsion"))
def _fit_joint(theta0, data, *, opts, max_steps, n_torsion):
    residual = _joint_residual(dict(opts), n_torsion)

    def one(th0, dat):
        res = least_squares(residual, th0, dat, max_steps=max_steps, gtol=1e-10, ftol=1e-10, xtol=1e-8)
        _, se, _, _ = covariance(res)
        return res, se

    return jax.vmap(one)(theta0, data)


def _joint_inputs(analysis, donders, KJ, q_rest, tau0, tau):
    from pmpjax import DondersRecording, fit_donders_surface, rotvec_from_joint_angles

    if not isinstance(donders, DondersRecording):
        raise TypeError(f"`donders` must be a pmpjax.DondersRecording (pmpjax.read_recordings), got "
                        f"{type(donders).__name__}")
    missing = [s for s in analysis.subjects if s not in donders.subjects]
    if missing:
        raise ValueError(f"`donders` has no session for subject(s) {missing} of the analysis")
    KJ, q_rest = _check_params(analysis, KJ, q_rest)
    data, _, _, Tbar, has, J = _item_data(analysis, KJ, q_rest, False)
    S = len(analysis.subjects)
    t0 = Tbar / 5 if tau0 is None else np.broadcast_to(np.asarray(tau0, float), (S,))
    t1 = Tbar / 5 if tau is None else np.broadcast_to(np.asarray(tau, float), (S,))
    if not (np.all(np.isfinite(t0) & (t0 > 0)) and np.all(np.isfinite(t1) & (t1 > 0))):
        raise ValueError("`tau0` and `tau` must be positive scalars or (S,) arrays [s]")
    idx = [donders.subjects.index(s) for s in analysis.subjects]
    x, q_obs, mask = donders.pointing[idx], donders.joint_angles[idx], donders.mask[idx]
    N = x.shape[1]
    Np = max(64, 1 << (N - 1).bit_length())
    pad = lambda a: np.concatenate([a, np.zeros((S, Np - N) + a.shape[2:])], 1)  # noqa: E731
    x, q_obs, w_obs = pad(np.where(mask[..., None], x, 0.0)), pad(np.where(mask[..., None], q_obs, 0.0)), \
        pad(mask.astype(float))
    # Block weights 1/σ: torsion noise = thickness of the subject's Donders surface; path noise =
    # the standard error of the mean normalised path (sd/√n, over the target radius).
    thick = np.asarray(fit_donders_surface(np.asarray(rotvec_from_joint_angles(donders.joint_angles[idx])),
                                           mask=mask).thickness)
    with np.errstate(all="ignore"):
        se_path = analysis.sd_path / np.sqrt(analysis.n_valid)[..., None, None] / analysis.radius
        sig_p = np.sqrt(np.nanmean(se_path.reshape(S, -1) ** 2, axis=1))
    sig_p = np.where(np.isfinite(sig_p) & (sig_p > 0), sig_p, np.nanmedian(sig_p) if np.isfinite(sig_p).any() else 1.0)
    weights = np.stack([1.0 / np.maximum(thick, 1e-6), 1.0 / np.maximum(sig_p, 1e-9)], -1)
    theta0 = np.concatenate([params_from_stiffness(KJ), q_rest, np.log(t0)[:, None], np.log(t1)[:, None]], -1)
    jdata = dict(x=x, q_obs=q_obs, w_obs=w_obs, weights=weights, paths=data)
    opts = (("threshold", analysis.threshold), ("n_samples", analysis.mean_path.shape[2]),
            ("radius", analysis.radius), ("d", analysis.d), ("J", J), ("solver", _solver(KJ, q_rest, t0, t1, data,
                                                                                        analysis.d)))
    return theta0, jdata, opts, has, Np


def fit_pointing_model(analysis: PointingAnalysis, donders, KJ, q_rest, *, tau0=None, tau=None,
                       max_steps: int = 50) -> PointingModelFit:
    """Joint fit of ``KJ``, ``q_rest``, ``τ0`` and ``τ`` per subject to the Donders postures and
    the pointing paths together (Levenberg–Marquardt through the equilibria and ``simulate``).

    **Arguments:** ``analysis`` (``fitting.analyze_pointing``); ``donders`` the subjects'
    Donders sessions (``pmpjax.DondersRecording``, matched by subject name); ``KJ`` (S, 3, 3),
    ``q_rest`` (S, 3) starting values in the order of ``analysis.subjects`` (e.g.
    ``fitting.fit_donders``); ``tau0``, ``tau``: starting values [s], scalar or (S,) (default
    T̄/5; e.g. ``fitting.fit_time_constants``); ``max_steps``: LM iterations per subject.

    The residual stacks the torsion of every Donders posture (as ``fit_donders``) and the path
    residual of :func:`fit_time_constants` (per-subject τ0, τ), each block divided by its noise
    scale: the thickness of the subject's Donders surface, and the standard error of the mean
    normalised paths. ``KJ`` keeps trace 4 (log-stiffness parameters as in ``fit_donders``).

    **Returns:**

    A :class:`PointingModelFit`.

    **Raises:**

    ``TypeError`` for a non-analysis or a ``donders`` that is not a ``pmpjax.DondersRecording``;
    ``ValueError`` naming the argument for subjects without a Donders session, ``KJ``/``q_rest``
    of the wrong shape or not SPD, non-positive time constants or ``max_steps``.
    """
    check_positive_int("max_steps", max_steps)
    theta0, jdata, opts, has, Np = _joint_inputs(analysis, donders, KJ, q_rest, tau0, tau)
    res, se = jax.device_get(_fit_joint(theta0, jax.tree_util.tree_map(jnp.asarray, jdata), opts=opts,
                                        max_steps=int(max_steps), n_torsion=Np))
    x = np.asarray(res.x)
    KJf = np.stack([np.asarray(stiffness_from_params(jnp.asarray(v[:5]), 3, 4.0)) for v in x])
    r = np.asarray(res.residual)
    w = jdata["weights"]
    n_t = jdata["w_obs"].sum(1)
    r_t, r_p = r[:, :Np] / w[:, :1], r[:, Np:] / w[:, 1:]
    err = _integration_error_deg(KJf, x[:, 5:8], np.exp(x[:, 8]), np.exp(x[:, 9]), jdata["paths"], analysis.d,
                                 dict(opts)["solver"])
    status = _item_status(has, np.isfinite(res.cost), res.converged, err)
    return PointingModelFit(
        subjects=analysis.subjects, KJ=KJf, q_rest=x[:, 5:8], tau0=np.exp(x[:, 8]), tau=np.exp(x[:, 9]), params=x,
        stderr=np.asarray(se), loss=np.asarray(res.cost), torsion_rms=np.sqrt(np.sum(r_t**2, 1) / n_t),
        path_rms=np.sqrt(np.mean(r_p**2, 1)), weights=w, steps=np.asarray(res.steps), status=status,
        converged=status == 0, param_names=JOINT_PARAMS, solver=dict(opts)["solver"], integration_error_deg=err,
    )
