"""Figures of movement fits: recorded against predicted joint paths and hand paths; parameters."""

from __future__ import annotations

import numpy as np

from .fit import MovementFit
from .predict import MovementPrediction


def plot_movements(pred: MovementPrediction, subject, *, predictors=("model", "pinv_minjerk"), max_reaches: int = 6):
    """Held-out reaches of one subject: each joint's recorded (black) and predicted path against
    time [s, the recording's clock], and the hand paths (fk of the joint paths) in two views.

    **Arguments:** ``pred`` a :class:`MovementPrediction`; ``subject`` a subject in it;
    ``predictors`` names from ``pred.predictors()`` to draw; ``max_reaches`` joint paths drawn (of
    the subject's first recording).

    **Returns:** the matplotlib figure.

    **Raises:** ``TypeError`` for a non-prediction; ``ValueError`` for an unknown subject or predictor.
    """
    import matplotlib.pyplot as plt

    if not isinstance(pred, MovementPrediction):
        raise TypeError(f"`pred` must be a fitting.MovementPrediction, got {type(pred).__name__}")
    sel = np.flatnonzero(pred.subject == str(subject))
    if sel.size == 0:
        raise ValueError(f"`subject` {subject!r} has no reach in the prediction (subjects: "
                         f"{sorted(set(pred.subject.tolist()))})")
    preds = pred.predictors()
    unknown = [p for p in predictors if p not in preds]
    if unknown:
        raise ValueError(f"`predictors` {unknown} unknown; choose from {list(preds)}")
    rec = sel[pred.recording[sel] == pred.recording[sel[0]]][:max_reaches]
    n = pred.q_obs.shape[-1]
    names = getattr(pred.chain, "joint_names", None) or [f"q{j + 1}" for j in range(n)]
    cols = max(n, 3)
    fig, axes = plt.subplots(2, cols, figsize=(3.2 * cols, 6.4), squeeze=False)
    colors = {p: f"C{k}" for k, p in enumerate(predictors)}
    for j in range(n):
        ax = axes[0, j]
        for i in rec:
            ax.plot(pred.t[i], np.rad2deg(pred.q_obs[i, :, j]), color="k", lw=1.4)
            for p in predictors:
                ax.plot(pred.t[i], np.rad2deg(preds[p]["q_pred"][i, :, j]), color=colors[p], lw=1, ls="--")
        ax.set_title(f"{names[j]} [deg]", fontsize=9)
        ax.set_xlabel("t [s]", fontsize=8)
    for j in range(n, cols):
        axes[0, j].axis("off")
    chain = pred.chain
    if chain is not None and chain.m >= 2:
        x_obs = np.asarray(chain.fk(pred.q_obs[sel]))
        x_pred = {p: np.asarray(chain.fk(np.nan_to_num(preds[p]["q_pred"][sel]))) for p in predictors}
        views = [(0, 1, "x", "y")] + ([(0, 2, "x", "z")] if chain.m >= 3 else [])
        for c, (a, b, la, lb) in enumerate(views):
            ax = axes[1, c]
            for k in range(len(sel)):
                ax.plot(x_obs[k, :, a], x_obs[k, :, b], color="k", lw=1.2)
                for p in predictors:
                    ax.plot(x_pred[p][k, :, a], x_pred[p][k, :, b], color=colors[p], lw=0.9, ls="--")
            ax.set_xlabel(f"{la} [m]", fontsize=8)
            ax.set_ylabel(f"{lb} [m]", fontsize=8)
            ax.set_aspect("equal", adjustable="datalim")
            ax.set_title(f"hand path, {la}–{lb}", fontsize=9)
        used = len(views)
    else:
        used = 0
    ax = axes[1, used]
    for k, p in enumerate(preds):
        ok = sel[np.isfinite(preds[p]["rmse_deg"][sel])]
        ax.bar(k - 0.2, np.median(preds[p]["rmse_deg"][ok]) if ok.size else np.nan, 0.4, color="C0")
        ax.bar(k + 0.2, np.median(preds[p]["final_error_deg"][ok]) if ok.size else np.nan, 0.4, color="C1")
    ax.set_xticks(range(len(preds)), list(preds), rotation=25, ha="right", fontsize=8)
    ax.set_title("median error [deg]\n(blue: path RMSE, orange: final)", fontsize=9)
    for c in range(used + 1, cols):
        axes[1, c].axis("off")
    handles = [plt.Line2D([], [], color="k", label="recorded")] + [
        plt.Line2D([], [], color=colors[p], ls="--", label=p) for p in predictors]
    fig.legend(handles=handles, loc="lower right", fontsize=8, frameon=False)
    fig.suptitle(f"{subject}: held-out reaches ({len(sel)}; joint paths of {pred.recording[sel[0]]})", fontsize=10)
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    return fig


def plot_movement_parameters(fit: MovementFit):
    """The fitted parameters of every subject as a table (value ± standard error; unidentified
    ones marked as a gauge).

    **Arguments:** ``fit`` a :class:`MovementFit`. **Returns:** the matplotlib figure.
    **Raises:** ``TypeError`` for a non-fit.
    """
    import matplotlib.pyplot as plt

    if not isinstance(fit, MovementFit):
        raise TypeError(f"`fit` must be a fitting.MovementFit, got {type(fit).__name__}")
    rows = fit.parameter_rows()
    names = list(fit.param_names)
    cells = [[""] * len(fit.subjects) for _ in names]
    for r in rows:
        i, a = names.index(r["parameter"]), fit.subjects.index(r["subject"])
        text = f"{r['value']:.3g} ± {r['stderr']:.2g}" if np.isfinite(r["value"]) else "—"
        cells[i][a] = text + ("" if r["identified"] else " (gauge)")
    fig, ax = plt.subplots(figsize=(max(4.6, 2.2 + 1.9 * len(fit.subjects)), 0.24 * len(names) + 1.2))
    ax.axis("off")
    table = ax.table(cellText=cells, rowLabels=names, colLabels=list(fit.subjects), loc="center", cellLoc="right")
    table.auto_set_font_size(False)
    table.set_fontsize(7)
    table.scale(1.0, 1.1)
    # (over the figure, not the axes: the row labels push the axes right of the figure's centre)
    fig.suptitle(f"fitted parameters\n({fit.model}, W: {fit.damping}, time constants in {fit.time_constants})",
                 fontsize=9)
    fig.tight_layout()
    return fig
