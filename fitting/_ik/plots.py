"""Figures for IK weights (matplotlib): estimated weights with confidence intervals."""

from __future__ import annotations

import numpy as np

import pmpjax as pj

HUGMP_JOINTS = pj.ShoulderElbowArm.joint_names


def plot_ik_weights(w, lo=None, hi=None, *, groups=None, panels=None, joints=HUGMP_JOINTS,
                    ax=None, title=None):
    """Grouped bar chart of IK weights with percentile intervals.

    One panel per row of ``w`` (e.g. subjects), one bar group per column (e.g. tasks), one bar per
    joint.

    **Arguments:**

    - ``w``: (P, G, n) or (G, n) weights.
    - ``lo``, ``hi``: optional intervals of the shape of ``w`` (e.g. bootstrap percentiles), both or
      neither.
    - ``groups``: G names of the bar groups.
    - ``panels``: P names of the panels.
    - ``joints``: n joint names (default the HuG-MP arm's).
    - ``ax``: P matplotlib axes to draw into (default a new figure).
    - ``title``: the figure's title.

    **Returns:**

    The matplotlib figure.

    **Raises:**

    - ``ValueError`` naming the argument for non-numeric or misshaped arrays, only one of ``lo`` and
      ``hi``, name lists of the wrong length, or the wrong number of axes.
    """
    import matplotlib.pyplot as plt

    try:
        w = np.asarray(w, dtype=float)
        lo = None if lo is None else np.asarray(lo, dtype=float)
        hi = None if hi is None else np.asarray(hi, dtype=float)
    except (TypeError, ValueError) as e:
        raise ValueError("`w`, `lo` and `hi` must be numeric arrays") from e
    if (lo is None) != (hi is None):
        raise ValueError("give both `lo` and `hi` (an interval) or neither")
    if w.ndim == 2:
        w = w[None]
        lo = None if lo is None else lo[None]
        hi = None if hi is None else hi[None]
    if w.ndim != 3:
        raise ValueError(f"`w` must be (P, G, n) or (G, n), got shape {w.shape}")
    for name, a in (("lo", lo), ("hi", hi)):
        if a is not None and a.shape != w.shape:
            raise ValueError(f"`{name}` must have the shape of `w` {w.shape}, got {a.shape}")
    P, G, n = w.shape
    for name, names, k in (("groups", groups, G), ("panels", panels, P)):
        if names is not None and len(names) != k:
            raise ValueError(f"`{name}` must hold {k} names, got {len(names)}")
    groups = groups or [f"task {g + 1}" for g in range(G)]
    panels = panels or [f"{p + 1}" for p in range(P)]
    if ax is None:
        fig, axes = plt.subplots(P, 1, figsize=(max(6.5, 1.2 * G), 2.2 * P + 0.6), sharex=True, squeeze=False,
                                 layout="constrained")
        axes = axes[:, 0]
    else:
        axes = np.atleast_1d(ax).reshape(-1)
        if len(axes) != P or not all(hasattr(a, "bar") for a in axes):
            raise ValueError(f"`ax` must be {P} matplotlib axes (one per panel), got {ax!r}")
        fig = axes[0].figure
    width = 0.8 / n
    x = np.arange(G)
    labels = [joints[j] if j < len(joints) else f"joint {j + 1}" for j in range(n)]
    for p in range(P):
        a = axes[p]
        for j in range(n):
            err = None
            if lo is not None and hi is not None:
                err = np.stack([np.clip(w[p, :, j] - lo[p, :, j], 0, None),
                                np.clip(hi[p, :, j] - w[p, :, j], 0, None)])
            a.bar(x + (j - (n - 1) / 2) * width, w[p, :, j], width, yerr=err, capsize=2, label=labels[j])
        a.set_ylim(0, 1.1)
        a.set_ylabel(f"{panels[p]}\nweight")
    axes[-1].set_xticks(x, groups)
    # Above the top panel, outside every panel (weights reach 1, the top of the axes): in as many
    # columns as fit the figure's width.
    ncol = n if sum(len(s) for s in labels) <= 90 else max(1, (n + 1) // 2)
    axes[0].legend(ncol=ncol, fontsize=7, loc="lower center", bbox_to_anchor=(0.5, 1.02), frameon=False)
    if title:
        fig.suptitle(title, fontsize=10, wrap=True)
    return fig
