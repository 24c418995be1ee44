"""Time constants of the λ0-PMP fitted to pointing movements by gradient descent through ``simulate``.

The paper sets ``τ = τ0 = T_sj/5`` by hand (Section 3). Here ``τ0`` (intrinsic, ``W = τ0 KJ``,
Eq 7) and ``τ`` (extrinsic, Eq 8; ``k = b_max/τ0``, Eq 10) are fitted per subject — or per
subject × movement — to the mean normalised paths, speed profiles and durations of
``fitting.analyze_pointing``, by Levenberg–Marquardt (``fitting.least_squares``, the one
optimiser loop) with Jacobians by forward-mode differentiation through ``pmpjax.simulate``.

**Parameters.** ``log τ0`` and ``log τ`` (positive by construction). Per subject
(``per_target=False``) one pair serves all 16 movements of the subject; per target one pair per
subject × movement. The model movement starts at rest in the mean rest posture before the
movement and goes to the target; it is analysed like the data (cut at the analysis threshold of
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
its own convergence, status and Gauss–Newton standard errors (delta method from the log scale).
"""

from __future__ import annotations

import dataclasses
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from pmpjax._base.status import Status
from pmpjax._base.validate import check_positive_int
from pmpjax._wrist.pointing import normalised_movements

from ._optimise import covariance, least_squares
from ._pointing import (
    PointingAnalysis,
    _check_params,
    _kernel_halfwidth,
    _movement_inputs,
    _profiles,
    spline_bandwidth,
)

#: Static simulation grid of the fits, in units of the movement's duration T_sj: long enough for
#: movements up to ~2 T_sj, steps ≤ τ/10 for τ ≥ 0.1 T_sj.
FIT_SPAN, FIT_DT = 2.5, 0.01


@dataclasses.dataclass(frozen=True)
class TimeConstantFit:
    """Result of :func:`fit_time_constants` (numpy arrays).

    ``tau0``, ``tau`` [s]: (S,) per subject, or (S, L) per subject × movement (``per_target``);
    ``tau0_movement``, ``tau_movement`` (S, L) the values each movement uses; ``stderr``
    (…, 2) standard errors of (τ0, τ) [s]; ``loss`` (…) ½|r|² at the optimum; ``rms`` (…) RMS
    residual; ``steps`` (…) LM iterations; ``status`` (…) int (``pmpjax.Status``: SUCCESSFUL,
    MAX_STEPS, NONFINITE, TOO_FEW_DATA for items without data); ``converged`` = status == 0;
    ``subjects``, ``labels``, ``per_target``.
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


def path_residual(r0, r, KJ, q_rest, data, *, threshold, n_samples, radius, d, J, span=FIT_SPAN, dt=FIT_DT):
    """Residual (M·(3n + 1),) of M movements of one subject for time constants ``r0``, ``r`` (M,)
    in units of each movement's T (module docstring). ``data``: dict of ``q0`` (M, 3), ``target``
    (M, 2), ``T`` (M,), ``half`` (M,), ``bandwidth`` (M,) of the analysis' smoothing in units
    of T (``J`` grid steps each side), ``w`` (M,) weights (0 for cells without data),
    ``mean_path`` (M, n, 2), ``mean_speed`` (M, n). Differentiable in ``r0``, ``r``, ``KJ``
    (3, 3), ``q_rest`` (3,)."""
    M = data["q0"].shape[0]
    KJb = jnp.broadcast_to(KJ, (M, 3, 3))
    tr = normalised_movements(KJb, jnp.broadcast_to(q_rest, (M, 3)), r0, r, data["q0"], data["target"],
                              span=span, dt=dt, d=d, pad=False)
    prof = _profiles(tr, data["T"], data["half"], data["bandwidth"], h=dt, J=J, threshold=threshold,
                     n_samples=n_samples, radius=radius, joints=False)
    w = data["w"]
    peak = jnp.max(data["mean_speed"], axis=1)
    r_path = (prof["path"] - data["mean_path"]) / radius * w[:, None, None]
    r_speed = (prof["speed"] - data["mean_speed"]) / jnp.where(peak > 0, peak, 1.0)[:, None] * w[:, None]
    r_dur = (prof["duration"] / data["T"] - 1.0) * np.sqrt(n_samples) * w
    return jnp.concatenate([r_path.reshape(-1), r_speed.reshape(-1), r_dur])


@partial(jax.jit, static_argnames=("opts", "max_steps"))
def _fit_items(theta0, KJ, q_rest, data, *, opts, max_steps):
    opts = dict(opts)

    def residual(theta, args):
        K, qr, dat = args
        return path_residual(jnp.exp(theta[0]) / dat["T"], jnp.exp(theta[1]) / dat["T"], K, qr, dat, **opts)

    def one(th0, K, qr, dat):
        res = least_squares(residual, th0, (K, qr, dat), max_steps=max_steps, gtol=1e-10, ftol=1e-10, xtol=1e-8)
        _, se, _, _ = covariance(res)
        return res, se

    return jax.vmap(one)(theta0, KJ, q_rest, data)


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
    Returns a :class:`TimeConstantFit`; items without data get status TOO_FEW_DATA and NaN.
    """
    KJ, q_rest = _check_params(analysis, KJ, q_rest)
    check_positive_int("max_steps", max_steps)
    if not isinstance(per_target, bool):
        raise TypeError(f"`per_target` must be a bool, got {type(per_target).__name__}")
    data, KJi, qri, Tbar, has, J = _item_data(analysis, KJ, q_rest, per_target)
    S, L = analysis.T.shape
    theta0 = np.log(np.stack([Tbar / 5.0, Tbar / 5.0], -1))
    opts = (("threshold", analysis.threshold), ("n_samples", analysis.mean_path.shape[2]),
            ("radius", analysis.radius), ("d", analysis.d), ("J", J))
    res, se_log = jax.device_get(_fit_items(theta0, KJi, qri, {k: jnp.asarray(v) for k, v in data.items()},
                                            opts=opts, max_steps=int(max_steps)))
    tau = np.exp(res.x)
    n_res = np.asarray(res.residual).shape[-1]
    finite = np.isfinite(res.cost)
    status = np.where(~has, int(Status.TOO_FEW_DATA), np.where(
        ~finite, int(Status.NONFINITE), np.where(res.converged, int(Status.SUCCESSFUL), int(Status.MAX_STEPS))))
    bad = ~has | ~finite
    tau = np.where(bad[:, None], np.nan, tau)
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
    )
