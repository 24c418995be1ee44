"""Held-out predictions of fitted subjects and their baselines (``predict_reaching``).

**Baselines** (``predict_reaching``, same motions, same run): ``pinv_minjerk`` straight hand path
with minimum-jerk timing resolved by the plain pseudo-inverse (PMP1 with ``W = I`` under the
time-base generator: ``q̇ = J# ẋ``); ``ik_weights_minjerk`` the same with ``W = diag(w)`` from
``fitting.estimate_ik_weights`` on the fitted repetitions (γ = 0.6, elbow fixed at 1 as
over-specified); ``lambda0_unfitted`` the λ0-PMP with ``KJ = I``, ``q_rest`` = the subject's mean
recorded posture, ``W = τ0 KJ``, ``τ = τ0 = T/5``; ``joint_minjerk_oracle`` joint-space minimum-jerk
interpolation to the *recorded* final posture (exact end posture by construction: an upper bound
for the path).
"""

from __future__ import annotations

import dataclasses
import warnings
from pathlib import Path

import jax
import numpy as np

import pmpjax as pj
from pmpjax import Status, status_message
from pmpjax.internal import pad_rows, without_unit_checks

from .._movements import simulate_samples
from .fit import ReachingFit
from .model import (
    GAIN_CAP,
    _Config,
    _model_and_planner,
    _rates_host,
    _unpack_host,
)
from .motions import (
    _SAMPLE_TIMES,
    SAMPLES,
    _chain,
    _check_reps,
    _fk,
    _motions,
    _reason_counts,
)

BASELINES = ("pinv_minjerk", "ik_weights_minjerk", "lambda0_unfitted", "joint_minjerk_oracle")


@dataclasses.dataclass(frozen=True)
class BaselinePrediction:
    """One predictor's held-out rows: ``q_pred`` (N, 50, 4) [rad], ``x_pred`` (N, 50, 3) [m],
    ``final_error_deg`` (N,), ``rmse_deg`` (N,), ``status`` (N,). Item access works too
    (``b["rmse_deg"]``)."""

    q_pred: np.ndarray
    x_pred: np.ndarray
    final_error_deg: np.ndarray
    rmse_deg: np.ndarray
    status: np.ndarray

    def __getitem__(self, name):
        return getattr(self, name)


@dataclasses.dataclass(frozen=True)
class ReachingPrediction:
    """Held-out movements, one row per motion (N rows over all subjects).

    ``subject`` (N,) str; ``task``, ``rep``, ``index`` (N,) int (``index`` = position of the motion
    inside its cell, 1-based); ``q_obs``, ``q_pred`` (N, 50, 4) [rad] on normalised time
    (``q_obs`` the recording resampled; its last sample is the recorded final posture);
    ``x_obs``, ``x_pred`` (N, 50, 3) [m] hand paths; ``final_error_deg`` (N,) RMS over the four
    joints of ``q_pred[:, -1] − q_obs[:, -1]`` [deg]; ``rmse_deg`` (N,) RMS over samples and joints
    [deg]; ``status`` (N,) (``pmpjax.Status``; non-zero rows have NaN errors);
    ``final_error_donders_deg`` (N,) the same final-posture error of the fitted model's Donders
    prediction, its equilibrium posture at the target (``pmpjax.equilibrium_posture``, Newton
    started at the recorded final posture as stage 1 of the fit does; NaN where it does not
    converge), which needs no simulation; ``duration``,
    ``recording`` (N,) [s]; ``baselines[name]`` a :class:`BaselinePrediction` for each of
    ``BASELINES``; ``model``, ``damping``, ``time_constants`` of the fit; ``skipped`` and
    ``problems`` as in :class:`ReachingFit`.
    """

    subject: np.ndarray
    task: np.ndarray
    rep: np.ndarray
    index: np.ndarray
    q_obs: np.ndarray
    q_pred: np.ndarray
    x_obs: np.ndarray
    x_pred: np.ndarray
    final_error_deg: np.ndarray
    rmse_deg: np.ndarray
    status: np.ndarray
    duration: np.ndarray
    recording: np.ndarray
    baselines: dict
    model: str
    damping: str
    time_constants: str
    skipped: dict
    problems: dict
    final_error_donders_deg: np.ndarray | None = None

    def predictors(self) -> dict:
        """The fitted model's and the baselines' predictions.

        **Returns:**

        ``{name: BaselinePrediction}`` with the fitted model first (named ``"model"``).
        """
        own = BaselinePrediction(self.q_pred, self.x_pred, self.final_error_deg, self.rmse_deg, self.status)
        return {"model": own, **self.baselines}

    def summary(self) -> list[dict]:
        """Means over the held-out motions of each subject × task (task "all" pools the tasks), NaN
        rows ignored; the Donders columns (the model's equilibrium postures, over every motion whose
        equilibrium converged) only in the model's rows.

        **Returns:**

        Rows ``{subject, task, predictor, n, final_error_deg, rmse_deg, n_donders,
        final_error_donders_deg}``.
        """
        mean = lambda a, ok: float(np.mean(a[ok])) if ok.any() else np.nan  # noqa: E731
        don = self.final_error_donders_deg
        rows = []
        for s in dict.fromkeys(self.subject.tolist()):
            for t in [*sorted(set(self.task[self.subject == s].tolist())), "all"]:
                sel = (self.subject == s) & ((self.task == t) if t != "all" else True)
                for name, b in self.predictors().items():
                    ok = sel & np.isfinite(b.rmse_deg)
                    row = dict(subject=s, task=t, predictor=name, n=int(ok.sum()),
                               final_error_deg=mean(b.final_error_deg, ok), rmse_deg=mean(b.rmse_deg, ok),
                               n_donders=0, final_error_donders_deg=np.nan)
                    if name == "model" and don is not None:
                        okd = sel & np.isfinite(don)
                        row.update(n_donders=int(okd.sum()), final_error_donders_deg=mean(don, okd))
                    rows.append(row)
        return rows

    def to_csv(self, path) -> None:
        """Write one row per held-out motion and predictor (final error and RMSE [deg]; the model's
        rows also its Donders final-posture error).

        **Arguments:**

        - ``path``: the CSV file to write.
        """
        lines = ["subject,task,rep,index,predictor,status,final_error_deg,rmse_deg,final_error_donders_deg"]
        don = self.final_error_donders_deg
        for name, b in self.predictors().items():
            for k in range(len(self.task)):
                d = f"{don[k]:.4f}" if name == "model" and don is not None else "nan"
                lines.append(f"{self.subject[k]},{self.task[k]},{self.rep[k]},{self.index[k]},{name},"
                             f"{int(b.status[k])},{b.final_error_deg[k]:.4f},{b.rmse_deg[k]:.4f},{d}")
        Path(path).write_text("\n".join(lines) + "\n")


def _errors(q_pred, q_obs, status):
    d = np.rad2deg(q_pred - q_obs)
    final = np.sqrt(np.mean(d[:, -1] ** 2, axis=-1))
    rmse = np.sqrt(np.mean(d**2, axis=(1, 2)))
    bad = status != 0
    return np.where(bad, np.nan, final), np.where(bad, np.nan, rmse)


def _status_from(traj_status):
    return np.asarray(traj_status).astype(int)  # pmpjax.Status codes


def _simulate_rows(model, planner, q0, target):
    """Simulate rows (R,) by RODAS4 with adaptive steps (``simulate``'s PI controller at its
    default tolerances: every row within that tolerance, or its status says why not; one
    compilation per model); returns ``q`` (R, 50, 4), ``x`` (R, 50, 3), ``status`` (R,) as
    ``pmpjax.Status`` codes."""
    minjerk = isinstance(planner, pj.MinimumJerkPlanner)
    KJ = model.KJ if model.KJ is not None else np.zeros(np.shape(model.W))
    tau0 = planner.tau0 if not minjerk else np.ones(len(q0))
    # rows singular at q0: SINGULAR, NaN (simulated as a copy of a good row, since
    # pmpjax.simulate refuses the whole batch)
    bad = ~np.isfinite(_rates_host(KJ, model.W, tau0, q0, minjerk=minjerk))
    R_ = len(q0)
    if bad.all():
        nan = np.full((R_, SAMPLES), np.nan)
        return nan[..., None] * np.ones(4), nan[..., None] * np.ones(3), np.full(R_, int(Status.SINGULAR))
    if bad.any():
        good = np.where(bad, int(np.argmin(bad)), np.arange(R_))
        take = lambda a: a[good] if np.ndim(a) >= 1 and np.shape(a)[0] == R_ else a  # noqa: E731
        model, planner = jax.tree_util.tree_map(take, (model, planner))
        q0, target = np.asarray(q0)[good], np.asarray(target)[good]
    traj = simulate_samples(model.chain, model, planner, q0, target, None, "rodas4")
    q, x, status = np.asarray(traj.q).copy(), np.asarray(traj.x).copy(), _status_from(traj.status)
    q[bad], x[bad], status[bad] = np.nan, np.nan, int(Status.SINGULAR)
    return q, x, status


def _concat(a, b):
    """Rows of two models (or planners) of one kind in one batch; shared scalars (the chain's
    lengths) stay as they are."""
    return jax.tree_util.tree_map(lambda u, v: u if np.ndim(u) == 0 else np.concatenate([u, v]), a, b)


def predict_reaching(fit: ReachingFit, *, reps=(8, 9, 10)) -> ReachingPrediction:
    """Predict the held-out movements of repetitions ``reps`` of every fitted subject.

    Each motion is predicted from its start posture, target hand position and durations only
    (the fitted λ0-PMP simulated on normalised time), together with the baselines of the module
    docstring. ``reps`` must not overlap ``fit.reps``. Subjects that were not fitted, or whose
    held-out motions cannot be loaded, are reported in ``problems`` and left out.

    **Arguments:**

    - ``fit``: the :class:`ReachingFit` (:func:`fit_reaching`).
    - ``reps``: the held-out repetitions (HuG-MP has 10).

    **Returns:**

    A :class:`ReachingPrediction`.

    **Raises:**

    ``TypeError`` for a non-:class:`ReachingFit`, ``ValueError`` for bad or overlapping
    ``reps`` and when no held-out motion is usable.
    """
    if not isinstance(fit, ReachingFit):
        raise TypeError(f"`fit` must be a ReachingFit from fitting.fit_reaching, got {type(fit).__name__}")
    reps = _check_reps("reps", reps)
    overlap = sorted(set(reps) & set(fit.reps))
    if overlap:
        raise ValueError(f"`reps` {list(reps)} overlap the fitted repetitions {list(fit.reps)} at {overlap}: "
                         "held-out prediction needs repetitions the fit has not seen")
    cfg = _Config(fit.model, fit.damping, fit.time_constants, fit.steps_per_sample, cond_max=fit.stiffness_cond_max)
    problems, skipped, rows = dict(fit.problems), {}, []
    for a, name in enumerate(fit.subjects):
        if name in fit.problems or not np.all(np.isfinite(fit.params[a])):
            problems.setdefault(name, f"{name}: not fitted ({status_message(fit.status[a])})")
            continue
        try:
            m = _motions(name, fit.directory, reps, fit.tasks)
        except (OSError, ValueError) as e:
            problems[name] = str(e)
            continue
        skipped[name] = list(m.skipped)
        if len(m) == 0:
            problems[name] = (f"{name}: no usable held-out motion in repetitions {list(reps)} "
                              f"({_reason_counts(m.skipped)})")
            continue
        rows.append((a, m))
    if not rows:
        raise ValueError("no usable held-out motion: " + "; ".join(problems.values()))

    cat = lambda f: np.concatenate([f(a, m) for a, m in rows])  # noqa: E731
    subject = cat(lambda a, m: np.array([m.subject] * len(m)))
    owner = cat(lambda a, m: np.full(len(m), a))
    task, rep, index = cat(lambda a, m: m.task), cat(lambda a, m: m.rep), cat(lambda a, m: m.index)
    q_obs, x_obs = cat(lambda a, m: m.q_obs), cat(lambda a, m: m.x_obs)
    duration, recording = cat(lambda a, m: m.duration), cat(lambda a, m: m.recording)
    N = len(task)
    Bp = max(64, -(-N // 64) * 64)  # padded rows: calls of similar size share one compile
    q0, target, t_ratio = pad_rows(q_obs[:, 0], Bp), pad_rows(x_obs[:, -1], Bp), pad_rows(duration / recording, Bp)
    own = pad_rows(owner, Bp)
    chain = _chain()

    # the fitted model, one parameter set per row, and the unfitted λ0-PMP (KJ = I, q_rest = mean
    # posture, τ = τ0 = T/5): one batch when they share the planner, so one compilation
    p = _unpack_host(fit.params[own], cfg, fit.q_rest[own, 3])
    with without_unit_checks():  # (normalised time: fitted fractions of T, not seconds)
        model, planner, _, _ = _model_and_planner(p, t_ratio, cfg)
    eye = np.broadcast_to(np.eye(4), (Bp, 4, 4))
    tau0_u = 0.2 * t_ratio
    model_u = pj.Lambda0PMP(chain, KJ=eye, q_rest=fit.mean_posture[own], W=tau0_u[:, None, None] * eye)
    planner_u = pj.ArimotoPlanner(k=None, tau=tau0_u, tau0=tau0_u)
    two = lambda a: np.concatenate([a, a])  # noqa: E731
    if cfg.model == "lambda0":
        q2, x2, s2 = _simulate_rows(_concat(model, model_u), _concat(planner, planner_u), two(q0), two(target))
        (qm, qu), (xm, xu), (sm, su) = np.split(q2, 2), np.split(x2, 2), np.split(s2, 2)
    else:
        qm, xm, sm = _simulate_rows(model, planner, q0, target)
        qu, xu, su = _simulate_rows(model_u, planner_u, q0, target)

    # straight hand path, minimum-jerk timing: PMP1 (q̇ = J#_W ẋ) under the time-base generator
    W_ik = np.stack([np.diag(fit.ik_weights[a]) for a in own])
    ik_ok = np.all(np.isfinite(W_ik.reshape(Bp, -1)), axis=-1)
    W_ik = np.where(ik_ok[:, None, None], W_ik, eye)
    mj = pj.MinimumJerkPlanner(duration=np.ones(2 * Bp), gain_cap=GAIN_CAP)
    q2, x2, s2 = _simulate_rows(pj.PMP1(chain, W=np.concatenate([eye, W_ik])), mj, two(q0), two(target))
    (qp, qi), (xp, xi), (sp_, si) = np.split(q2, 2), np.split(x2, 2), np.split(s2, 2)
    si = np.where(ik_ok, si, int(Status.INVALID_INPUT))
    s = np.asarray(_SAMPLE_TIMES)
    xi_s = s**3 * (10 - 15 * s + 6 * s**2)
    qo = q_obs[:, :1] + (q_obs[:, -1:] - q_obs[:, :1]) * xi_s[None, :, None]
    xo = _fk(chain, qo.reshape(-1, 4)).reshape(N, SAMPLES, 3)

    def pack(q, x, st):
        q, x, st = q[:N], x[:N], st[:N]
        f, r = _errors(q, q_obs, st)
        return BaselinePrediction(q_pred=q, x_pred=x, final_error_deg=f, rmse_deg=r, status=st)

    baselines = {
        "pinv_minjerk": pack(qp, xp, sp_),
        "ik_weights_minjerk": pack(qi, xi, si),
        "lambda0_unfitted": pack(qu, xu, su),
        "joint_minjerk_oracle": pack(qo, xo, np.zeros(N, int)),
    }
    main = pack(qm, xm, sm)
    for name in dict.fromkeys(subject.tolist()):  # failed simulations are counted, never silent
        bad = (subject == name) & (main.status != 0)
        if bad.any():
            codes = ", ".join(f"{int(c)}× {Status(int(k)).name}" for k, c in zip(*np.unique(main.status[bad],
                                                                                        return_counts=True)))
            problems[name] = (f"{name}: the fitted model failed on {int(bad.sum())} of {int((subject == name).sum())} "
                              f"held-out motions ({codes}; NaN errors, left out of the summaries)")
    if any(p_ in problems and p_ not in fit.problems for p_ in dict.fromkeys(subject.tolist())):
        warnings.warn("predict_reaching: " + "; ".join(problems[p_] for p_ in dict.fromkeys(subject.tolist())
                                                        if p_ in problems), stacklevel=2)
    # Donders' law of the fitted model: its equilibrium posture at each target, Newton started at
    # the recorded final posture as in stage 1 (from the start posture it fails for ~1 in 5 motions)
    eq = pj.equilibrium_posture(chain, fit.KJ[owner], fit.q_rest[owner], x_obs[:, -1], q_init=q_obs[:, -1])
    q_eq = np.where(np.asarray(eq.converged)[:, None], np.asarray(eq.q), np.nan)
    donders = np.sqrt(np.mean(np.rad2deg(q_eq - q_obs[:, -1]) ** 2, axis=-1))
    return ReachingPrediction(
        subject=subject, task=task, rep=rep, index=index, q_obs=q_obs, q_pred=main.q_pred, x_obs=x_obs,
        x_pred=main.x_pred, final_error_deg=main.final_error_deg, rmse_deg=main.rmse_deg, status=main.status,
        duration=duration, recording=recording, baselines=baselines, model=fit.model, damping=fit.damping,
        time_constants=fit.time_constants, skipped=skipped, problems=problems, final_error_donders_deg=donders,
    )
