"""Main-job parts contributed to ``python -m pmpjax`` (entry-point group ``pmpjax.jobs``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def ik_hugmp(out: Path, log) -> dict:
    """IK weights of the bundled HuG-MP recordings per subject × task, with bootstrap intervals."""
    import matplotlib.pyplot as plt

    from ._ik.datasets import hugmp_ik_weights
    from ._ik.plots import plot_ik_weights

    res = hugmp_ik_weights(n_boot=20, key=None)
    w, lo, hi = (np.asarray(res[k]) for k in ("w", "lo", "hi"))
    fig = plot_ik_weights(w, lo, hi, panels=[str(s) for s in res["subjects"]],
                          groups=[f"task {k + 1}" for k in range(w.shape[1])])
    fig.savefig(out / "ik_weights_hugmp.png", dpi=110)
    plt.close(fig)
    log(f"ik_hugmp: {w.shape[0]} subjects x {w.shape[1]} tasks, figure -> {out / 'ik_weights_hugmp.png'}")
    return {
        "subjects": [str(s) for s in res["subjects"]],
        "w": w.round(4).tolist(), "lo": lo.round(4).tolist(), "hi": hi.round(4).tolist(),
        "converged": np.asarray(res["converged"]).tolist(),
        "skipped_cells": {str(k): [str(c) for c in v] for k, v in res["skipped"].items()},
        "failed": {str(k): str(v) for k, v in res.get("failed", {}).items()},
    }


def donders_nio(out: Path, log) -> dict:
    """NIO fits (KJ, q_rest) of the six Table 1–2 subjects from synthetic steady postures
    (500 each, 0.5° orientation noise, seeded), with held-out torsion errors and a Donders plot."""
    import matplotlib.pyplot as plt

    import pmpjax as pj

    from ._donders import donders_coefficients, fit_donders, params_from_stiffness, predicted_torsion

    names, KJ, q_rest = pj.paper_subjects()
    rec = pj.synthetic_recordings(KJ, q_rest, 500, noise_deg=0.5, seed=0, names=names)
    wrist = pj.Wrist()
    res = fit_donders(wrist, rec.pointing, rec.joint_angles, mask=rec.mask, n_starts=2, seed=0)
    held_out = np.stack(np.meshgrid(*(np.linspace(-0.3, 0.3, 7),) * 2), -1).reshape(-1, 2)
    true_tx = np.asarray(predicted_torsion(wrist, KJ, q_rest, np.broadcast_to(held_out, (6,) + held_out.shape)))
    fit_tx = np.asarray(predicted_torsion(wrist, res.KJ, res.q_rest, np.broadcast_to(held_out, (6,) + held_out.shape)))
    rms_deg = np.rad2deg(np.sqrt(np.mean((fit_tx - true_tx) ** 2, axis=-1)))
    surf_data = pj.fit_donders_surface(pj.rotvec_from_quat(rec.quat[0]))
    surf_model = pj.model_donders_surface(res.KJ[0], res.q_rest[0])[0]
    ax = pj.plot_donders(np.asarray(pj.rotvec_from_quat(rec.quat[0])), [surf_data, surf_model],
                         labels=["data surface", "fitted model"])
    ax.set_title(f"{names[0]}: Donders surface, synthetic data vs NIO fit")
    ax.figure.savefig(out / "donders_subject1.png", dpi=110)
    plt.close(ax.figure)
    truth_c = np.stack([np.asarray(donders_coefficients(np.concatenate([params_from_stiffness(K), q]), 3))
                        for K, q in zip(KJ, q_rest)])
    z = np.einsum("spq,sq->sp", res.directions, res.coefficients - truth_c) / res.direction_stderr
    z_ident = np.where(res.identifiable, np.abs(z), 0.0).max(axis=-1)
    log(f"donders_nio: converged {int(res.converged.sum())}/6, held-out torsion RMS "
        f"{rms_deg.max():.3f}° max, coefficient error along identifiable directions "
        f"{z_ident.max():.2f} SE max, figure -> {out / 'donders_subject1.png'}")
    return {
        "subjects": list(names),
        "converged": res.converged.tolist(),
        "KJ_true": KJ.round(4).tolist(), "KJ_fit": res.KJ.round(4).tolist(),
        "q_rest_true": q_rest.round(4).tolist(), "q_rest_fit": res.q_rest.round(4).tolist(),
        "residual_rms_deg": np.rad2deg(res.rms).round(4).tolist(),
        "held_out_torsion_rms_deg": rms_deg.round(4).tolist(),
        "identifiable_directions": res.identifiable.sum(axis=-1).tolist(),
        "max_abs_z_identifiable_coefficients": z_ident.round(3).tolist(),
    }


def reaching_hugmp(out: Path, log) -> dict:
    """Held-out prediction of the bundled HuG-MP movements (repetitions 8–10) by the λ0-PMP fitted
    per subject on repetitions 1–7: the Donders-fitted model of the paper (``KJ``, ``q_rest`` from
    the final postures, ``W = τ0 KJ``, ``τ = τ0 = T/5``; the trajectory stage runs in
    ``benchmarks/reaching.py``), with every baseline; a CSV table and one figure per subject."""
    import json
    import time

    import matplotlib.pyplot as plt

    from ._reaching import fit_reaching, plot_reaching_subject, predict_reaching

    t0 = time.perf_counter()
    fit = fit_reaching([1, 2, 3, 4], max_steps=(40, 0))
    pred = predict_reaching(fit, reps=(8, 9, 10))
    pred.to_csv(out / "reaching_hugmp.csv")
    rows = [r for r in pred.summary() if r["task"] == "all"]
    (out / "reaching_hugmp_summary.json").write_text(json.dumps(rows, indent=1))
    figures = []
    for s in dict.fromkeys(pred.subject.tolist()):
        fig = plot_reaching_subject(pred, s, predictors=("model", "pinv_minjerk", "joint_minjerk_oracle"))
        path = out / f"reaching_hugmp_{s}.png"
        fig.savefig(path, dpi=100)
        plt.close(fig)
        figures.append(path.name)
    mean = {name: float(np.nanmean(b.rmse_deg)) for name, b in pred.predictors().items()}
    log(f"reaching_hugmp: {len(pred.task)} held-out motions of {len(figures)} subjects, RMSE [deg] "
        + ", ".join(f"{k} {v:.1f}" for k, v in mean.items()) + f", figures -> {out}")
    return {
        "subjects": list(fit.subjects), "status": fit.status.tolist(), "n_fitted_motions": fit.n_motions.tolist(),
        "KJ": np.round(fit.KJ, 4).tolist(), "q_rest_deg": np.round(np.rad2deg(fit.q_rest), 2).tolist(),
        "held_out_motions": int(len(pred.task)), "summary": rows, "mean_rmse_deg": mean,
        "mean_final_error_deg": {name: float(np.nanmean(b.final_error_deg)) for name, b in pred.predictors().items()},
        "table": "reaching_hugmp.csv", "figures": figures, "problems": pred.problems,
        "seconds": round(time.perf_counter() - t0, 1),
    }
