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


def sweeps(out: Path, log) -> dict:
    """Parameter sweeps (issue 14) at small size: the curvature map (``A_net`` per target over
    stiffness anisotropy × rest posture, figure) and a Donders-fit power analysis (how many
    postures per subject recover ``KJ``), both through ``fitting.sweep`` with a resumable store."""
    import functools
    import tempfile

    import matplotlib.pyplot as plt

    import pmpjax as pj

    from ._donders import params_from_stiffness
    from ._sweep import grid, sweep
    from ._sweep_examples import curvature_row, donders_power_row, plot_curvature_map

    store = Path(tempfile.mkdtemp(prefix="pmpjax_sweeps_"))
    anisotropy = np.array([0.5, 0.75, 1.0, 4 / 3, 2.0, 3.0])
    rest_ps = np.linspace(-15.0, 15.0, 7)
    cmap = sweep(functools.partial(curvature_row, dt=0.01), grid(anisotropy=anisotropy, rest_ps_deg=rest_ps),
                 chunk_size=16, out=store / "curvature", progress=False)
    a_net = cmap.outputs["A_net"].reshape(len(anisotropy), len(rest_ps), 8)
    fig = plot_curvature_map(anisotropy, rest_ps, a_net)
    fig.savefig(out / "curvature_map.png", dpi=110)
    plt.close(fig)

    names, KJ, q_rest = pj.paper_subjects()
    n_values, reps, n_max = [16, 64, 256], 8, 256
    g = grid(subject=np.arange(len(names)), n_postures=n_values, rep=np.arange(reps))
    s = g["subject"]
    params = {"subject": np.asarray(names)[s], "logK": params_from_stiffness(KJ)[s], "q_rest": q_rest[s],
              "n_postures": g["n_postures"], "noise_deg": np.full(len(s), 0.5),
              "seed": 1000 * s + 10 * g["rep"] + g["n_postures"]}
    power = sweep(functools.partial(donders_power_row, n_max=n_max), params, chunk_size=16,
                  out=store / "donders_power", progress=False)
    err = power.outputs["KJ_error"].reshape(len(names), len(n_values), reps)
    ok = ~power.failed.reshape(err.shape)
    rms = np.sqrt(np.nanmean(np.where(ok, err, np.nan) ** 2, axis=(0, 2)))
    within = {d: np.nanmean(np.where(ok, err < d, np.nan), axis=(0, 2)) for d in (0.1, 0.25, 0.5)}
    log(f"sweeps: curvature map {cmap.outputs['A_net'].shape[0]} rows ({cmap.n_failed} failed), A_net "
        f"{a_net.min():+.3f}..{a_net.max():+.3f}, figure -> {out / 'curvature_map.png'}; Donders power: "
        + ", ".join(f"n={n}: RMS |ΔKJ| {r:.3f} Nm/rad, {100 * within[0.25][k]:.0f}% within 0.25"
                    for k, (n, r) in enumerate(zip(n_values, rms))))
    return {
        "curvature_map": {"anisotropy": anisotropy.round(4).tolist(), "rest_ps_deg": rest_ps.tolist(),
                          "directions": list(pj.DIRECTIONS), "A_net": a_net.round(5).tolist(),
                          "failed": int(cmap.n_failed)},
        "donders_power": {"subjects": list(names), "n_postures": n_values, "replicates": reps, "noise_deg": 0.5,
                          "rms_KJ_error": rms.round(4).tolist(),
                          "fraction_within": {str(d): v.round(3).tolist() for d, v in within.items()},
                          "failed": int(power.n_failed),
                          "reasons": sorted(set(power.reasons[power.failed].tolist()))},
    }
