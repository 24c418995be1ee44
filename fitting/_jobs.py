"""Main-job parts contributed to ``python -m pmpjax`` (entry-point group ``pmpjax.jobs``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def ik_hugmp(out: Path, log) -> dict:
    """IK weights of the bundled HuG-MP recordings per subject × task, with bootstrap intervals."""
    import matplotlib.pyplot as plt

    from ._ik_data import hugmp_ik_weights
    from ._ik_plots import plot_ik_weights

    res = hugmp_ik_weights(n_boot=50, key=None)
    w, lo, hi = (np.asarray(res[k]) for k in ("w", "lo", "hi"))
    fig = plot_ik_weights(w, lo, hi, panels=[f"S0{s}" for s in res["subjects"]],
                          groups=[f"task {k + 1}" for k in range(w.shape[1])])
    fig.savefig(out / "ik_weights_hugmp.png", dpi=110)
    plt.close(fig)
    log(f"ik_hugmp: {w.shape[0]} subjects x {w.shape[1]} tasks, figure -> {out / 'ik_weights_hugmp.png'}")
    return {
        "subjects": [int(s) for s in res["subjects"]],
        "w": w.round(4).tolist(), "lo": lo.round(4).tolist(), "hi": hi.round(4).tolist(),
        "converged": np.asarray(res["converged"]).tolist(),
        "skipped_cells": {str(k): [str(c) for c in v] for k, v in res["skipped"].items()},
        "failed": {str(k): str(v) for k, v in res.get("failed", {}).items()},
    }
