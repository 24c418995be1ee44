"""Figure of one subject's held-out movements: recorded against predicted (matplotlib)."""

from __future__ import annotations

import numpy as np

import pmpjax as pj

from .motions import _SAMPLE_TIMES, _subject_name
from .predict import ReachingPrediction


def plot_reaching_subject(pred: ReachingPrediction, subject, *, predictors=("model", "pinv_minjerk")):
    """Recorded vs predicted joint trajectories (one held-out motion per task) and hand paths
    (frontal y–z and sagittal x–z views) of one subject. Returns the matplotlib figure."""
    import matplotlib.pyplot as plt

    name = _subject_name(subject)
    sel = np.nonzero(pred.subject == name)[0]
    if sel.size == 0:
        raise ValueError(f"`subject` {name!r} has no rows in the prediction")
    picks = [sel[pred.task[sel] == t][0] for t in sorted(set(pred.task[sel].tolist()))]
    preds = pred.predictors()
    fig, axes = plt.subplots(2, 4, figsize=(15, 7))
    s = np.asarray(_SAMPLE_TIMES)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    styles = {n: dict(color=colors[(k + 1) % len(colors)], ls=("-", "--", ":", "-.")[k % 4])
              for k, n in enumerate(predictors)}
    for j in range(4):
        ax = axes[0, j]
        for k in picks:
            ax.plot(s, np.rad2deg(pred.q_obs[k, :, j]), color="k", lw=1.5)
            for n in predictors:
                ax.plot(s, np.rad2deg(preds[n].q_pred[k, :, j]), lw=1, **styles[n])
        ax.set_title(f"{pj.ShoulderElbowArm.joint_names[j]} [deg]", fontsize=10)
        ax.set_xlabel("normalised time")
    views = ((1, 2, "frontal: y (left) vs z (up) [m]"), (0, 2, "sagittal: x (forward) vs z [m]"))
    for col, (a, b, lab) in enumerate(views):
        ax = axes[1, col]
        for k in sel:
            ax.plot(pred.x_obs[k, :, a], pred.x_obs[k, :, b], color="k", lw=0.5, alpha=0.5)
            ax.plot(preds[predictors[0]].x_pred[k, :, a], preds[predictors[0]].x_pred[k, :, b],
                    lw=0.5, alpha=0.7, **styles[predictors[0]])
        ax.set_title(lab)
        ax.set_aspect("equal")
    ax = axes[1, 2]
    names = list(preds)
    for k, n in enumerate(names):
        ok = (pred.subject == name) & np.isfinite(preds[n].rmse_deg)
        ax.bar(k - 0.2, np.mean(preds[n].rmse_deg[ok]), 0.4, color="C0")
        ax.bar(k + 0.2, np.mean(preds[n].final_error_deg[ok]), 0.4, color="C1")
    ax.set_xticks(range(len(names)), names, rotation=30, ha="right", fontsize=8)
    ax.set_title("held-out error [deg] (blue: RMSE, orange: final)")
    axes[1, 3].axis("off")
    handles = [plt.Line2D([], [], color="k", label="recorded")] + [
        plt.Line2D([], [], label=n, **styles[n]) for n in predictors]
    axes[1, 3].legend(handles=handles, loc="center")
    fig.suptitle(f"HuG-MP {name}: held-out movements, {pred.model} / {pred.damping} / {pred.time_constants}")
    fig.tight_layout()
    return fig
