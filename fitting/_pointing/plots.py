"""Figures 5–8 of Tommasino & Campolo (2017) for any subject of a pointing analysis (matplotlib).

Each function takes a :class:`PointingAnalysis` (``fitting.analyze_pointing``), optionally a
:class:`PointingPrediction` (``fitting.predict_pointing``; drawn dashed) and a ``subject`` (name
or index), and returns the matplotlib Figure.
"""

from __future__ import annotations

import numpy as np

from pmpjax import DIRECTIONS

from .analysis import PointingAnalysis
from .prediction import PointingPrediction

_JOINT_NAMES = ("pronation–supination", "flexion–extension", "radial–ulnar deviation")
_JOINT_COLORS = ("tab:red", "tab:purple", "tab:green")


def _check(analysis, prediction, subject, alpha):
    if not isinstance(analysis, PointingAnalysis):
        raise TypeError(f"`analysis` must be a PointingAnalysis (fitting.analyze_pointing), got "
                        f"{type(analysis).__name__}")
    if prediction is not None:
        if not isinstance(prediction, PointingPrediction):
            raise TypeError(f"`prediction` must be a PointingPrediction (fitting.predict_pointing) or None, got "
                            f"{type(prediction).__name__}")
        if tuple(prediction.subjects) != tuple(analysis.subjects):
            raise ValueError(f"`prediction` is for subjects {list(prediction.subjects)}, the analysis for "
                             f"{list(analysis.subjects)}")
    if not (np.isfinite(alpha) and 0 < alpha < 1):
        raise ValueError(f"`alpha` must lie in (0, 1), got {alpha}")
    return analysis.subject_index(subject)


def Line2D(*args, **kw):  # noqa: N802 - legend handles; matplotlib imported when drawing
    from matplotlib.lines import Line2D as line

    return line(*args, **kw)


def _figure(fig, **kw):
    import matplotlib.pyplot as plt

    return fig if fig is not None else plt.figure(**kw)


def _band(mean, sd):
    """Polygon of ``mean ± sd`` across a 2-D path (n, 2): the per-axis sd projected on the normal."""
    tangent = np.gradient(mean, axis=0)
    tangent /= np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True), 1e-12)
    normal = np.stack([-tangent[:, 1], tangent[:, 0]], 1)
    width = np.sqrt(np.sum((sd * normal) ** 2, axis=1))[:, None]
    return np.concatenate([mean + width * normal, (mean - width * normal)[::-1]])


def plot_pointing_paths(analysis, prediction=None, *, subject=0, alpha: float = 0.05, fig=None):
    """The paper's Figure 5: mean outbound (blue) and inbound (red) paths with sd bands, thick where
    ``A_net`` differs from 0 (t-test), a star at targets with hysteresis, the model dashed.

    **Arguments:**

    - ``analysis``: the :class:`PointingAnalysis` (:func:`analyze_pointing`).
    - ``prediction``: optional :class:`PointingPrediction` of the same subjects (the model, dashed).
    - ``subject``: a subject name or index.
    - ``alpha``: significance level of the t-tests, in (0, 1).
    - ``fig``: a matplotlib figure to draw into (default a new one).

    **Returns:**

    The matplotlib figure.

    **Raises:**

    - ``TypeError`` for a non-analysis or non-prediction; ``ValueError`` naming the argument for a
      prediction of other subjects, an unknown subject or ``alpha`` outside (0, 1).
    """
    s = _check(analysis, prediction, subject, alpha)
    fig = _figure(fig, figsize=(5.5, 5.5))
    ax = fig.add_subplot(1, 1, 1)
    for j, lab in enumerate(analysis.labels):
        mean, sd = analysis.mean_path[s, j], analysis.sd_path[s, j]
        color = "tab:blue" if lab.startswith("out") else "tab:red"
        if np.all(np.isfinite(mean)):
            if np.all(np.isfinite(sd)):
                ax.fill(*_band(mean, sd).T, color=color, alpha=0.2, lw=0)
            thick = np.isfinite(analysis.p_net[s, j]) and analysis.p_net[s, j] < alpha
            ax.plot(*mean.T, color=color, lw=3.0 if thick else 1.0)
        if prediction is not None and np.all(np.isfinite(prediction.path[s, j])):
            ax.plot(*prediction.path[s, j].T, color=color, lw=1.0, ls="--")
    for i, d in enumerate(DIRECTIONS):
        tgt = analysis.targets[analysis.labels.index(f"out-{d}"), 1]
        ax.annotate(d, tgt * 1.18, ha="center", va="center", fontsize=8)
        if np.isfinite(analysis.p_hyst[s, i]) and analysis.p_hyst[s, i] < alpha:
            ax.plot(*(tgt * 0.55), marker="*", color="k", ms=9)
    ax.scatter(*np.vstack([analysis.targets[::2, 1], [[0.0, 0.0]]]).T, s=60, facecolors="none", edgecolors="k")
    ax.set(aspect="equal", xlabel="x1 [m]", ylabel="x2 [m]")
    ax.set_title(f"{analysis.subjects[s]}: mean paths ± sd", fontsize=9)
    handles = [Line2D([], [], color="tab:blue", label="outbound"), Line2D([], [], color="tab:red", label="inbound"),
               Line2D([], [], color="0.3", lw=3.0, label=f"A_net ≠ 0 (p < {alpha})"),
               Line2D([], [], color="k", marker="*", ls="", ms=8, label=f"hysteresis (p < {alpha})")]
    if prediction is not None:
        handles.append(Line2D([], [], color="0.3", ls="--", label="model"))
    ax.legend(handles=handles, fontsize=7, loc="lower left", bbox_to_anchor=(1.0, 0.0), frameon=False)
    fig.tight_layout()
    return fig


def plot_pointing_curvature(analysis, prediction=None, *, subject=0, alpha: float = 0.05, fig=None):
    """The paper's Figure 6: measured ``A_net`` (mean ± sd) per movement beside the model's, a star
    where they differ (one-sample t-test of the measured areas against the model's value).

    **Arguments:**

    - ``analysis``: the :class:`PointingAnalysis` (:func:`analyze_pointing`).
    - ``prediction``: optional :class:`PointingPrediction` of the same subjects (the model, dashed).
    - ``subject``: a subject name or index.
    - ``alpha``: significance level of the t-tests, in (0, 1).
    - ``fig``: a matplotlib figure to draw into (default a new one).

    **Returns:**

    The matplotlib figure.

    **Raises:**

    - ``TypeError`` for a non-analysis or non-prediction; ``ValueError`` naming the argument for a
      prediction of other subjects, an unknown subject or ``alpha`` outside (0, 1).
    """
    s = _check(analysis, prediction, subject, alpha)
    fig = _figure(fig, figsize=(9, 3.5))
    ax = fig.add_subplot(1, 1, 1)
    pos = np.arange(len(analysis.labels))
    with np.errstate(all="ignore"):
        m = np.array([np.nanmean(a) if np.isfinite(a).any() else np.nan for a in analysis.a_net[s]])
        sd = np.array([np.nanstd(a, ddof=1) if np.isfinite(a).sum() > 1 else np.nan for a in analysis.a_net[s]])
    ax.errorbar(pos - 0.12, m, yerr=sd, fmt="o", color="k", ms=4, capsize=2, label="data (mean ± sd)")
    if prediction is not None:
        ax.plot(pos + 0.12, prediction.a_net[s], "s", color="tab:orange", ms=5, label="model")
        top = np.nanmax(np.abs(np.concatenate([m + np.nan_to_num(sd), prediction.a_net[s]])))
        for j in np.flatnonzero(np.isfinite(prediction.p_model[s]) & (prediction.p_model[s] < alpha)):
            ax.plot(pos[j], 1.1 * top, marker="*", color="k", ms=8)
        ax.set_title(f"{analysis.subjects[s]}: model captures {int(prediction.n_captured[s])} of "
                     f"{len(analysis.labels)} movements (*: p < {alpha})", fontsize=9)
    ax.axhline(0.0, color="0.6", lw=0.8)
    ax.set_xticks(pos, analysis.labels, rotation=60, fontsize=7)
    ax.set_ylabel("A_net (normalised)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    return fig


def plot_pointing_joints(analysis, prediction=None, *, subject=0, labels=("out-E", "in-E", "out-W", "in-W"),
                         alpha: float = 0.05, fig=None):
    """The paper's Figure 7: joint trajectories (PS, FE, RUD; mean ± sd [deg] over the movement's
    duration) of some movements, the model dashed.

    **Arguments:**

    - ``analysis``: the :class:`PointingAnalysis` (:func:`analyze_pointing`).
    - ``prediction``: optional :class:`PointingPrediction` of the same subjects (the model, dashed).
    - ``subject``: a subject name or index.
    - ``alpha``: significance level of the t-tests, in (0, 1).
    - ``fig``: a matplotlib figure to draw into (default a new one).
    - ``labels``: the movements to draw (of ``analysis.labels``).

    **Returns:**

    The matplotlib figure.

    **Raises:**

    - ``TypeError`` for a non-analysis or non-prediction; ``ValueError`` naming the argument for a
      prediction of other subjects, an unknown subject or ``alpha`` outside (0, 1), or labels that name no movement.
    """
    s = _check(analysis, prediction, subject, alpha)
    labels = tuple(labels)
    unknown = [lab for lab in labels if lab not in analysis.labels]
    if unknown or not labels:
        raise ValueError(f"`labels` must name movements of {list(analysis.labels)}, got {list(labels)}")
    fig = _figure(fig, figsize=(3.2 * len(labels), 3.2))
    axes = fig.subplots(1, len(labels), sharey=True, squeeze=False)[0]
    n = analysis.mean_q.shape[2]
    for ax, lab in zip(axes, labels):
        j = analysis.labels.index(lab)
        t = np.linspace(0.0, analysis.T[s, j], n) if np.isfinite(analysis.T[s, j]) else np.linspace(0, 1, n)
        for i, c in enumerate(_JOINT_COLORS):
            m, sd = np.rad2deg(analysis.mean_q[s, j, :, i]), np.rad2deg(analysis.sd_q[s, j, :, i])
            ax.fill_between(t, m - sd, m + sd, color=c, alpha=0.2, lw=0)
            ax.plot(t, m, color=c)
            if prediction is not None:
                tp = np.linspace(0.0, prediction.duration[s, j], n)
                ax.plot(tp, np.rad2deg(prediction.q_path[s, j, :, i]), color=c, ls="--")
        ax.set(title=lab, xlabel="time [s]")
    axes[0].set_ylabel("joint angle [deg]")
    handles = [Line2D([], [], color=c, label=f"{name} (mean ± sd)") for name, c in zip(_JOINT_NAMES, _JOINT_COLORS)]
    if prediction is not None:
        handles.append(Line2D([], [], color="0.3", ls="--", label="model"))
    axes[-1].legend(handles=handles, fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1.0), frameon=False)
    fig.suptitle(f"{analysis.subjects[s]}: joint trajectories", fontsize=9)
    fig.tight_layout()
    return fig


def plot_pointing_speed(analysis, prediction=None, *, subject=0, alpha: float = 0.05, fig=None):
    """The paper's Figure 8: tangential speed profiles (mean ± sd [m/s] over the movement's
    duration) of all 16 movements (outbound top row, inbound bottom), the model dashed.

    **Arguments:**

    - ``analysis``: the :class:`PointingAnalysis` (:func:`analyze_pointing`).
    - ``prediction``: optional :class:`PointingPrediction` of the same subjects (the model, dashed).
    - ``subject``: a subject name or index.
    - ``alpha``: significance level of the t-tests, in (0, 1).
    - ``fig``: a matplotlib figure to draw into (default a new one).

    **Returns:**

    The matplotlib figure.

    **Raises:**

    - ``TypeError`` for a non-analysis or non-prediction; ``ValueError`` naming the argument for a
      prediction of other subjects, an unknown subject or ``alpha`` outside (0, 1).
    """
    s = _check(analysis, prediction, subject, alpha)
    fig = _figure(fig, figsize=(14, 3.8))
    axes = fig.subplots(2, len(DIRECTIONS), sharex=True, sharey=True)
    n = analysis.mean_speed.shape[2]
    for row, way in enumerate(("out", "in")):
        for col, d in enumerate(DIRECTIONS):
            ax = axes[row, col]
            j = analysis.labels.index(f"{way}-{d}")
            t = np.linspace(0.0, analysis.T[s, j], n) if np.isfinite(analysis.T[s, j]) else np.linspace(0, 1, n)
            m, sd = analysis.mean_speed[s, j], analysis.sd_speed[s, j]
            ax.fill_between(t, m - sd, m + sd, color="0.6", alpha=0.4, lw=0)
            ax.plot(t, m, color="k")
            if prediction is not None:
                ax.plot(np.linspace(0.0, prediction.duration[s, j], n), prediction.speed_path[s, j], color="tab:orange",
                        ls="--")
            ax.set_title(f"{way}-{d}", fontsize=8)
    for ax in axes[1]:
        ax.set_xlabel("time [s]", fontsize=8)
    for ax in axes[:, 0]:
        ax.set_ylabel("speed [m/s]", fontsize=8)
    handles = [Line2D([], [], color="k", label="data (mean ± sd)")]
    if prediction is not None:
        handles.append(Line2D([], [], color="tab:orange", ls="--", label="model"))
    fig.legend(handles=handles, fontsize=7, loc="upper right", frameon=False)
    fig.suptitle(f"{analysis.subjects[s]}: tangential speed", fontsize=9)
    fig.tight_layout()
    return fig
