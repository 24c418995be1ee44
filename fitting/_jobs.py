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


def ik_figures(ctx) -> dict:
    """IK weights, Khoramshahi et al. (2022) Figures 1–3: Algorithm 1 on random data (Fig 1), several
    γ (Fig 2), and the two-prismatic-joint example where γ = 0 converges to the wrong weights (Fig 3)."""
    import jax
    import matplotlib.pyplot as plt

    from ._ik.examples import ik_fig1_data, ik_fig3_data
    from ._ik.weights import estimate_ik_weights

    reps = 20 if ctx.quick else 100
    q, x, J = ik_fig1_data(jax.random.PRNGKey(ctx.seed), n_reps=reps + 3 * 10)
    gams = np.concatenate([np.full(reps, 0.6), np.repeat([0.0, 0.3, 0.9], 10)])
    res = estimate_ik_weights(q, x, J, gamma=gams, max_iter=150)
    w, hist = np.asarray(res.w), np.asarray(res.error_history)
    fig1 = gams == 0.6
    w_star = np.array([1.0, 0.8, 0.6, 0.4, 0.2])
    final_err = float(np.asarray(res.error)[fig1].mean())
    fig, ax = plt.subplots(1, 3, figsize=(13, 3.6))
    ax[0].errorbar(np.arange(1, 6), w[fig1].mean(0), w[fig1].std(0), fmt="o", label=f"estimate ({reps} reps)")
    ax[0].plot(np.arange(1, 6), w_star, "k_", ms=18, label="w*")
    ax[0].set(xlabel="joint", ylabel="weight", title="Fig 1: weights, γ = 0.6")
    ax[0].legend()
    for g in (0.0, 0.3, 0.6, 0.9):
        ax[1].plot(np.nanmean(hist[gams == g], 0), label=f"γ = {g}")
    ax[1].set(xlabel="iteration", ylabel="mean error", title="Fig 2: convergence for several γ")
    ax[1].legend()
    q3, x3, J3 = ik_fig3_data(k_null=0.3, k_task=2.0)
    g3 = np.array([0.0, 0.6, 0.8, 0.9])
    qb, xb, Jb = (np.broadcast_to(a, (4,) + a.shape) for a in (q3, x3, J3))
    r3 = estimate_ik_weights(qb, xb, Jb, gamma=g3, tol=0.0, step_tol=1e-9, max_iter=3000)
    w3 = np.asarray(r3.w)
    ax[2].bar(np.arange(4) - 0.15, w3[:, 0], 0.3, label="w1")
    ax[2].bar(np.arange(4) + 0.15, w3[:, 1], 0.3, label="w2 (truth 0.01)")
    ax[2].set_xticks(range(4), [f"γ={g}" for g in g3])
    ax[2].set(title="Fig 3: two prismatic joints, w* = (1, 0.01)")
    ax[2].legend()
    fig.tight_layout()
    ctx.figure(fig, "ik_figures_1_3.png",
               "Algorithm 1 on the paper's synthetic examples: recovered weights ± sd over repetitions "
               "(Fig 1), mean error per iteration for several γ (Fig 2), and the two-joint case (Fig 3).",
               "Paper: Fig 1 weights converge to w* = (1, .8, .6, .4, .2), mean final error 0.07; Fig 2 γ = 0 "
               "fastest on i.i.d. data; Fig 3 γ = 0 converges to (0, 1), γ > 0.5 to w* = (1, 0.01).")
    rows = [{"case": "Fig 1 (γ = 0.6)", **{f"w{j + 1}": float(w[fig1].mean(0)[j]) for j in range(5)},
             "sd_max": float(w[fig1].std(0).max()), "mean_final_error": final_err}]
    rows += [{"case": f"Fig 3 (γ = {g})", "w1": float(wi[0]), "w2": float(wi[1]), "w3": "", "w4": "", "w5": "",
              "sd_max": "", "mean_final_error": float(e)} for g, wi, e in zip(g3, w3, np.asarray(r3.error))]
    ctx.table(rows, "ik_figures_1_3.csv", "Weights recovered in the paper's Figures 1 and 3.",
              "Paper: Fig 1 final error 0.07 (100 repetitions); Fig 3 γ = 0 → (0, 1), γ ≥ 0.6 → (1, 0.01).")
    ctx.log(f"Fig 1 mean w {w[fig1].mean(0).round(3)} (w* {w_star}), mean final error {final_err:.3f} (paper 0.07)")
    return {"fig1_mean_w": w[fig1].mean(0).tolist(), "fig1_sd_w": w[fig1].std(0).tolist(),
            "fig1_mean_final_error": final_err, "fig3_w": w3.tolist(), "fig3_gamma": g3.tolist()}


def ik_synthetic(ctx) -> dict:
    """IK weights of a synthetic Experiment-1 data set (two conditions, "Natural" and "Viscous",
    4-DoF shoulder–elbow arm) with contribution coefficients and the paired Hotelling T² test."""
    import pmpjax as pj

    from ._ik.analysis import contribution_coefficients, hotelling_t2, overspecified_joints
    from ._ik.datasets import synthetic_ik_dataset
    from ._ik.plots import plot_ik_weights
    from ._ik.weights import estimate_ik_weights_lm

    n_part = 6 if ctx.quick else 17
    data = synthetic_ik_dataset(ctx.seed, n_participants=n_part, n_trials=5 if ctx.quick else 20)
    arr = pj.ik_dataset_arrays(data)
    P, C = arr["qdot"].shape[:2]
    n = arr["qdot"].shape[-1]
    # All targets and trials of a participant × condition pooled into one item.
    qd = arr["qdot"].reshape(P, C, -1, n)
    xd = arr["xdot"].reshape(P, C, qd.shape[2], -1)
    J = arr["J"].reshape(P, C, qd.shape[2], xd.shape[-1], n)
    mask = arr["mask"].reshape(P, C, -1)
    fixed = np.asarray(overspecified_joints(J[0, 0], mask=mask[0, 0]))
    # The LM variant: Algorithm 1's quasi-static update crawls on Experiment-1-like data (its
    # iterates stall far from the truth within a few hundred iterations; see the IK tests).
    res = estimate_ik_weights_lm(qd, xd, J, 0.9, mask=mask, fixed=fixed)
    w = np.asarray(res.w)  # (P, C, n)
    # Weights fixed at 1 (over-specified) or pinned at 1 by the normalisation in every item drop out.
    varying = [j for j in np.flatnonzero(~np.asarray(fixed, bool)) if np.ptp(w[:, :, j]) > 1e-9]
    ht = hotelling_t2(w[:, 0, varying], w[:, 1, varying], paired=True)
    beta = np.asarray(contribution_coefficients(w)).mean(0)
    w_true = np.array([[wt[c] for c in arr["conditions"]] for wt in data["w_true"]])
    err = float(np.abs(w - w_true).max())
    fig = plot_ik_weights(w.mean(0, keepdims=True), np.percentile(w, 2.5, 0)[None], np.percentile(w, 97.5, 0)[None],
                          groups=list(arr["conditions"]), panels=[f"{P} synthetic participants"],
                          title="Synthetic Experiment 1: IK weights per condition (mean, 95 % range)")
    ctx.figure(fig, "ik_synthetic_conditions.png",
               f"IK weights of {P} synthetic participants in two conditions (LM variant, the elbow "
               f"over-specified and fixed at 1), mean and 2.5–97.5 % range over participants.",
               "Paper Fig 6: the third joint's weight rises in the Viscous condition; Hotelling T² = 225.3, "
               "F(2, 15) = 105.6, p < 0.001 (17 real participants).")
    rows = [{"condition": c, **{f"w{j + 1}": float(w[:, i, j].mean()) for j in range(n)},
             **{f"beta{j + 1}": float(beta[i, j]) for j in range(n)}} for i, c in enumerate(arr["conditions"])]
    ctx.table(rows, "ik_synthetic_conditions.csv",
              f"Mean weights and contribution coefficients per condition; paired Hotelling T² = {float(ht.t2):.1f}, "
              f"F = {float(ht.f):.1f}, p = {float(ht.p):.2g}; largest |w − w_true| = {err:.3f}.",
              "Paper: β = (0.04, 0.27, 0.65, 0.04) Natural, (0.09, 0.68, 0.14, 0.09) Viscous; T² = 225.3.")
    ctx.log(f"Hotelling T² {float(ht.t2):.1f}, p = {float(ht.p):.2g}; max |w − w_true| {err:.3f}")
    return {"conditions": list(arr["conditions"]), "w_mean": w.mean(0).tolist(), "beta_mean": beta.tolist(),
            "hotelling_t2": float(ht.t2), "hotelling_f": float(ht.f), "hotelling_p": float(ht.p),
            "max_abs_error_vs_truth": err, "converged": int(np.asarray(res.converged).sum()), "items": int(P * C)}


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
