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


def pointing(out: Path, log) -> dict:
    """The wrist-pointing experiment end to end on synthetic data (Tommasino & Campolo 2017,
    Sections 2–3): six Table subjects × 5 trials × 16 movements written as a pointing recording
    (CSV) with a Donders session each, read back, analysed (segmentation, curvature, t-tests),
    KJ and q_rest fitted to the Donders sessions (NIO), every movement predicted by the
    Donders-fitted λ0-PMP (τ = τ0 = T/5, Eq 10), compared (captured counts), Figures 5–8."""
    import matplotlib.pyplot as plt

    import pmpjax as pj

    from ._donders import fit_donders
    from ._pointing import analyze_pointing, predict_pointing
    from ._pointing_plots import plot_pointing_curvature, plot_pointing_joints, plot_pointing_paths, plot_pointing_speed

    data_dir = out / "pointing_data"
    ex = pj.synthetic_pointing_experiment(data_dir, n_trials=5, seed=0)
    rec = pj.read_pointing(ex.files["pointing"])
    don = pj.read_recordings(ex.files["donders"])
    an = analyze_pointing(rec)
    fit = fit_donders(pj.Wrist(), don.pointing, don.joint_angles, mask=don.mask, n_starts=2, seed=0)
    order = [don.subjects.index(s) for s in an.subjects]
    pr = predict_pointing(an, fit.KJ[order], fit.q_rest[order])
    table = an.table() + "\n\n" + pr.table()
    (out / "pointing_statistics.txt").write_text(table + "\n")
    for s, name in enumerate(an.subjects):
        for tag, plot in (("figure5_paths", plot_pointing_paths), ("figure6_curvature", plot_pointing_curvature)):
            fig = plot(an, pr, subject=s)
            fig.savefig(out / f"pointing_{tag}_{name}.png", dpi=90)
            plt.close(fig)
    for tag, plot in (("figure7_joints", plot_pointing_joints), ("figure8_speed", plot_pointing_speed)):
        fig = plot(an, pr, subject=0)
        fig.savefig(out / f"pointing_{tag}_{an.subjects[0]}.png", dpi=90)
        plt.close(fig)
    log(f"pointing: {len(an.subjects)} subjects, {int(an.valid.sum())} movements analysed, "
        f"{len(an.excluded)} exclusions; Donders fits converged {int(fit.converged.sum())}/{len(fit.converged)}; "
        f"model captures {pr.n_captured.tolist()} of 16; figures and {out / 'pointing_statistics.txt'}")
    with np.errstate(all="ignore"):
        mean_net = np.nanmean(an.a_net, axis=2)

    def js(a, digits=5):  # JSON: NaN (no data / no test) as null
        return [[round(float(v), digits) if np.isfinite(v) else None for v in row] for row in np.atleast_2d(a)]

    return {
        "subjects": list(an.subjects), "labels": list(an.labels),
        "movements_analysed": int(an.valid.sum()), "exclusions": len(an.excluded),
        "donders_converged": fit.converged.tolist(),
        "T_s": js(an.T, 4), "A_net_data": js(mean_net), "A_net_model": js(pr.a_net),
        "p_sum": js(an.p_sum), "p_net": js(an.p_net), "p_hyst": js(an.p_hyst), "p_model": js(pr.p_model),
        "n_captured": pr.n_captured.tolist(), "share_captured": np.round(pr.share_captured, 4).tolist(),
    }
