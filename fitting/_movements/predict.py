"""``predict_movements``: the fitted λ0-PMP's reaches against held-out recordings, with baselines.

**Baselines** (same reaches, same run): ``pinv_minjerk`` a straight hand path with minimum-jerk
timing resolved by the plain pseudo-inverse (PMP1 with ``W = I`` under the time-base generator:
``q̇ = J# ẋ``); ``joint_minjerk_oracle`` joint-space minimum-jerk interpolation to the *recorded*
final posture (exact end posture by construction: an upper bound for the path).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

import pmpjax as pj
from pmpjax import Status
from pmpjax.internal import without_unit_checks

from . import model as mdl
from .data import (
    SAMPLE_TIMES,
    SAMPLES,
    check_find_options,
    check_recordings,
    group_by_subject,
    segmented_reaches,
    skipped_summary,
    subject_reaches,
)
from .fit import MovementFit, _fk, subject_model

BASELINES = ("pinv_minjerk", "joint_minjerk_oracle")


@dataclasses.dataclass(frozen=True)
class MovementPrediction:
    """One row per reach found in the held-out recordings (N rows, S = 50 samples, n joints).

    ``subject``, ``recording`` (N,); ``t`` (N, S) [s] in the recording's own clock; ``q_obs``,
    ``q_pred`` (N, S, n) [rad]; ``rmse_deg`` (N,) joint RMSE over the reach; ``final_error_deg``
    (N,) RMS over joints of the final posture's error; ``status`` (N,) (``pmpjax.Status`` of the
    simulation; NaN errors where it is not ``SUCCESSFUL``); ``baselines`` {name: dict of
    ``q_pred``, ``rmse_deg``, ``final_error_deg``, ``status``}; ``skipped`` {recording:
    [(t_from, t_to, reason)]}; ``problems`` {subject: message} (subjects not in the fit); ``chain``
    the fit's chain. Tables: :meth:`summary`, :meth:`movement_rows`; figure:
    :func:`fitting.plot_movements`.
    """

    subject: np.ndarray
    recording: np.ndarray
    t: np.ndarray
    q_obs: np.ndarray
    q_pred: np.ndarray
    rmse_deg: np.ndarray
    final_error_deg: np.ndarray
    status: np.ndarray
    baselines: dict
    skipped: dict
    problems: dict
    chain: object = None

    def __len__(self):
        return int(self.rmse_deg.shape[0])

    def predictors(self) -> dict:
        """The fitted model's and the baselines' predictions.

        **Returns:**

        ``{"model": ..., **baselines}``, each a dict of ``q_pred``, ``rmse_deg``, ``final_error_deg``,
        ``status``.
        """
        model = dict(q_pred=self.q_pred, rmse_deg=self.rmse_deg, final_error_deg=self.final_error_deg,
                     status=self.status)
        return {"model": model, **self.baselines}

    def movement_rows(self) -> list[dict]:
        """One row per reach: subject, recording, window [s], and each predictor's RMSE and final
        error [deg] (empty where its simulation failed).

        **Returns:**

        A list of dicts (the rows of ``movement_predictions.csv``).
        """
        preds = self.predictors()
        fmt = lambda v: "" if not np.isfinite(v) else round(float(v), 4)  # noqa: E731
        return [{"subject": str(self.subject[i]), "recording": str(self.recording[i]),
                 "t_start [s]": round(float(self.t[i, 0]), 4), "t_end [s]": round(float(self.t[i, -1]), 4),
                 "status": pj.status_message(int(self.status[i])),
                 **{f"{k}_rmse [deg]": fmt(v["rmse_deg"][i]) for k, v in preds.items()},
                 **{f"{k}_final [deg]": fmt(v["final_error_deg"][i]) for k, v in preds.items()}}
                for i in range(len(self))]

    def summary(self) -> list[dict]:
        """One row per subject and one for all: reaches predicted, and per predictor the median joint
        RMSE and median final-posture error [deg] over its successful simulations.

        **Returns:**

        A list of dicts (the rows of ``movement_prediction_summary.csv``).
        """
        preds = self.predictors()
        groups = [(s, self.subject == s) for s in dict.fromkeys(self.subject.tolist())]
        rows = []
        for name, sel in groups + ([("all", np.ones(len(self), bool))] if len(groups) > 1 else []):
            row = {"subject": name, "reaches": int(sel.sum())}
            for k, v in preds.items():
                ok = sel & np.isfinite(v["rmse_deg"])
                row[f"{k}_n"] = int(ok.sum())
                row[f"{k}_median_rmse [deg]"] = float(np.median(v["rmse_deg"][ok])) if ok.any() else math.nan
                row[f"{k}_median_final [deg]"] = float(np.median(v["final_error_deg"][ok])) if ok.any() else math.nan
            rows.append(row)
        return rows


def _errors(q_pred, q_obs, status):
    d = np.rad2deg(q_pred - q_obs)
    final = np.sqrt(np.mean(d[:, -1] ** 2, axis=-1))
    rmse = np.sqrt(np.mean(d**2, axis=(1, 2)))
    bad = status != int(Status.SUCCESSFUL)
    return np.where(bad, np.nan, rmse), np.where(bad, np.nan, final)


def _simulate_reaches(fit: MovementFit, subject: str, sr, target):
    """The fitted subject's reaches ``sr`` to ``target`` (B, m): ``q`` (B, S, n), ``status`` (B,).
    RODAS4 with adaptive steps (``simulate``'s PI controller at its default tolerances), whatever
    the fit's solver and steps: every reach is within ``simulate``'s tolerance (``SUCCESSFUL``) or
    says why not (``MAX_STEPS``, ``NONFINITE``, ``SINGULAR``), stiff or not, and one compilation
    serves every step count (a Donders-fitted model has no integration check of its own)."""
    with without_unit_checks():  # (fitted values: a reach that fails says so by its status)
        (model, planner), _ = subject_model(fit, subject, sr.duration, sr.t_ratio)
        tr = mdl.simulate(fit.chain, model, planner, sr.q_start, target, None, "rodas4")
    return np.asarray(tr.q), np.asarray(tr.status).astype(int)


def predict_movements(fit: MovementFit, recordings, *, find_options: dict | None = None) -> MovementPrediction:
    """Predict every reach of held-out ``recordings`` with each subject's fitted λ0-PMP.

    Each reach (found as in :func:`fit_movements`; each recording one motion for a fit of
    segmented recordings) is simulated from its recorded start posture to
    the hand position of its recorded end, over its recorded duration, by RODAS4 with adaptive
    steps at ``simulate``'s default tolerances (whatever the fit's solver and steps: each reach is
    within that tolerance, or its status says why not).

    **Arguments:**

    - ``fit``: a :class:`MovementFit` (:func:`fit_movements`).
    - ``recordings``: ``pmpjax.JointRecording`` of subjects in the fit (others are reported in
      ``problems``).
    - ``find_options``: keyword options of ``pmpjax.find_movements`` for finding the reaches
      (default: its defaults).

    **Returns:**

    A :class:`MovementPrediction`.

    **Raises:**

    ``TypeError`` for a non-fit; ``ValueError`` when no reach can be predicted.
    """
    if not isinstance(fit, MovementFit):
        raise TypeError(f"`fit` must be a fitting.MovementFit (fitting.fit_movements), got {type(fit).__name__}")
    chain = fit.chain
    recordings = check_recordings(recordings, chain)
    options = check_find_options(find_options, fit.segmented)
    rows = {k: [] for k in ("subject", "recording", "t", "q_obs", "q_pred", "status")}
    base = {b: {"q_pred": [], "status": []} for b in BASELINES}
    skipped, problems = {}, {}
    for subject, recs in group_by_subject(recordings).items():
        if subject not in fit.subjects or not np.all(np.isfinite(fit.params[fit.subject_index(subject)])):
            problems[subject] = f"{subject}: not fitted (subjects with parameters: {', '.join(fit.subjects)})"
            continue
        reaches = segmented_reaches if fit.segmented else subject_reaches
        sr = reaches(subject, recs, chain, options)
        for rec, a, b, why in sr.skipped:
            skipped.setdefault(rec, []).append((a, b, why))
        if len(sr) == 0:
            continue
        q0 = sr.q_start
        target = np.asarray(_fk(chain, sr.q_end))
        q_pred, status = _simulate_reaches(fit, subject, sr, target)
        rows["q_pred"].append(q_pred)
        rows["status"].append(status)
        for k, v in (("subject", [subject] * len(sr)), ("recording", list(sr.recording)), ("t", sr.t),
                     ("q_obs", sr.q_obs)):
            rows[k].append(np.asarray(v))
        tbg = pj.MinimumJerkPlanner(duration=1.0, gain_cap=mdl.GAIN_CAP)
        pinv = pj.simulate(pj.PMP1(chain, W=np.eye(chain.n)), tbg, q0, target, duration=1.0,
                           dt=1.0 / ((SAMPLES - 1) * 4), saveat=pj.SaveAt(ts=SAMPLE_TIMES))
        base["pinv_minjerk"]["q_pred"].append(np.asarray(pinv.q))
        base["pinv_minjerk"]["status"].append(np.asarray(pinv.status).astype(int))
        s = np.asarray(SAMPLE_TIMES)
        xi = 10 * s**3 - 15 * s**4 + 6 * s**5
        base["joint_minjerk_oracle"]["q_pred"].append(q0[:, None] + (sr.q_end - q0)[:, None] * xi[None, :, None])
        base["joint_minjerk_oracle"]["status"].append(np.zeros(len(sr), int))
    if not rows["status"]:
        raise ValueError("no reach of `recordings` could be predicted: " + "; ".join(
            list(problems.values()) + [skipped_summary([(r, *w) for w in v]) for r, v in skipped.items()]))
    cat = {k: np.concatenate(v) for k, v in rows.items()}
    rmse, final = _errors(cat["q_pred"], cat["q_obs"], cat["status"])
    baselines = {}
    for b, d in base.items():
        q = np.concatenate(d["q_pred"])
        st = np.concatenate(d["status"])
        r, f = _errors(q, cat["q_obs"], st)
        baselines[b] = dict(q_pred=q, rmse_deg=r, final_error_deg=f, status=st)
    return MovementPrediction(subject=cat["subject"], recording=cat["recording"], t=cat["t"], q_obs=cat["q_obs"],
                              q_pred=cat["q_pred"], rmse_deg=rmse, final_error_deg=final, status=cat["status"],
                              baselines=baselines, skipped=skipped, problems=problems, chain=chain)

