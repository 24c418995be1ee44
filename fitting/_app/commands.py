"""Subcommands of ``pmpjax`` for users' own files (entry-point group ``pmpjax.commands``).

Each ``add_<name>(subparsers)`` adds a parser whose ``func(args) -> int`` runs the command.
Readers name the file, line and column of bad input; the command line prints one line and exits
with status 2 (see ``pmpjax._app.cli``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pmpjax._app import example_help, plural, positive_int
from pmpjax.internal import output_dir, write_json

from .._ik import read_ik_file
from .output import enable_x64, write_csv

# ----------------------------------------------------------------------------- fit-donders


def add_fit_donders(sub) -> None:
    p = sub.add_parser(
        "fit-donders", help="fit KJ and q_rest per subject to steady wrist postures (Donders' law, NIO)",
        description="Fit joint stiffness KJ (SPD, trace 4) and rest posture q_rest of every subject in a "
        "Donders recording (CSV or NPZ, see pmpjax.read_recordings) by nonlinear inverse optimisation. "
        "CSV columns: subject,sample,qw,qx,qy,qz,x1,x2 (the hand-to-world quaternion, scalar first, and the "
        "screen point [m]) or q_ps,q_fe,q_rud [rad] instead of qw..qz; one row per steady posture; a line "
        "'# d=<metres>' gives the screen distance.",
        epilog=example_help("donders_example.csv"),
    )
    p.add_argument("file", help="Donders recording (.csv or .npz)")
    p.add_argument("--out", default="out_donders", help="output folder (default out_donders)")
    p.add_argument("--starts", type=positive_int, default=4, help="LM starts per subject (default 4)")
    p.set_defaults(func=_fit_donders)


def _fit_donders(args) -> int:
    enable_x64()
    import pmpjax as pj

    from .._donders import fit_donders

    rec = pj.read_recordings(args.file)
    out = Path(args.out)
    out = output_dir("--out", out)
    wrist = pj.Wrist(d=float(rec.d))
    fit = fit_donders(wrist, rec.pointing, pj.joint_angles_from_quat(rec.quat), mask=rec.mask,
                      n_starts=args.starts)
    rows = []
    for i, s in enumerate(rec.subjects):
        K, q = np.asarray(fit.KJ[i]), np.asarray(fit.q_rest[i])
        rows.append({
            "subject": s, "status": pj.status_message(int(fit.status[i])), "converged": bool(fit.converged[i]),
            **{f"KJ_{a}{b} [Nm/rad]": f"{K[a, b]:.6g}" for a in range(3) for b in range(a, 3)},
            **{f"q_rest_{j} [deg]": f"{np.rad2deg(q[k]):.4g}" for k, j in enumerate(("ps", "fe", "rud"))},
            "rms_torsion [deg]": f"{np.rad2deg(float(fit.rms[i])):.4g}",
            "samples": int(np.asarray(rec.mask[i]).sum()),
        })
    write_csv(out / "donders_fit.csv", rows)
    write_json(out / "donders_fit.json", {
        "file": str(args.file), "subjects": list(map(str, rec.subjects)), "KJ": fit.KJ, "q_rest": fit.q_rest,
        "converged": fit.converged, "report": [fit.report(i) for i in range(len(rec.subjects))]}, indent=2)
    n_ok = int(np.asarray(fit.converged).sum())
    print(f"{n_ok} of {plural(len(rows), 'subject')} converged; wrote {out / 'donders_fit.csv'} and donders_fit.json")
    return 0 if n_ok == len(rows) else 1


# ----------------------------------------------------------------------------- ik-weights


def add_ik_weights(sub) -> None:
    p = sub.add_parser(
        "ik-weights", help="estimate IK weights (Khoramshahi et al. 2022, Algorithm 1) from a data file",
        description="Estimate the IK weights of every item (participant, condition, target) of a data file: "
        "the paper's .mat layout (v5 or v7.3), an NPZ with arrays qdot (B, K, n), xdot (B, K, m), J (B, K, m, n) "
        "and optionally mask (B, K), or a CSV with columns item, qdot_1..n, xdot_1..m and J_r_c (row r, column c "
        "of the Jacobian), one row per sample.",
        epilog=example_help("ik_example.csv"),
    )
    p.add_argument("file", help=".mat (the paper's layout), .npz or .csv")
    p.add_argument("--gamma", type=float, default=0.6, help="null-space ratio γ in [0, 1] (default 0.6)")
    p.add_argument("--method", choices=("algorithm1", "lm"), default="algorithm1",
                   help="the paper's Algorithm 1 (default) or the gradient-based LM variant (exact when "
                   "the data follow the weighted pseudo-inverse)")
    p.add_argument("--out", default="out_ik", help="output folder (default out_ik)")
    p.set_defaults(func=_ik_weights)


def _ik_weights(args) -> int:
    enable_x64()
    import pmpjax as pj

    from .._ik import contribution_coefficients, estimate_ik_weights, estimate_ik_weights_lm

    if not 0.0 <= args.gamma <= 1.0:
        raise ValueError(f"--gamma must lie in [0, 1], got {args.gamma}")
    d = read_ik_file(args.file)
    out = output_dir("--out", args.out)
    if args.method == "lm":
        res = estimate_ik_weights_lm(d["qdot"], d["xdot"], d["J"], args.gamma, mask=d["mask"])
        error = np.asarray(res.cost)
    else:
        res = estimate_ik_weights(d["qdot"], d["xdot"], d["J"], args.gamma, mask=d["mask"], on_invalid="flag")
        error = np.asarray(res.error)
    status = np.asarray(getattr(res, "status", np.where(np.asarray(res.converged), 0, 2)))
    w = np.asarray(res.w)
    beta = np.asarray(contribution_coefficients(np.where(np.isfinite(w), w, 1.0)))
    rows = [{"item": lab, "status": pj.status_message(int(status[i])), "converged": bool(res.converged[i]),
             **{f"w{j + 1}": f"{w[i, j]:.6g}" for j in range(w.shape[1])},
             **{f"beta{j + 1}": f"{beta[i, j]:.6g}" for j in range(w.shape[1])},
             "error": f"{float(error[i]):.4g}"} for i, lab in enumerate(d["labels"])]
    write_csv(out / "ik_weights.csv", rows)
    n_ok = int(np.asarray(res.converged).sum())
    print(f"{n_ok} of {plural(len(rows), 'item')} converged; wrote {out / 'ik_weights.csv'}")
    return 0 if n_ok == len(rows) else 1


# ----------------------------------------------------------------------------- analyze-pointing


def add_analyze_pointing(sub) -> None:
    p = sub.add_parser(
        "analyze-pointing", help="analyse a wrist-pointing recording (curvature, t-tests; with a Donders "
        "session: the Donders-fitted λ0-PMP's predictions and fitted time constants)",
        description="Section 2 'Data Analysis' of Tommasino & Campolo (2017) on a pointing recording (CSV or "
        "NPZ, see pmpjax.read_pointing): segmentation at 20 % of peak speed, curvature A_sum/A_net, "
        "hysteresis, t-tests. With --donders (a Donders recording of the same subjects): KJ and q_rest by "
        "NIO, every movement predicted with τ = τ0 = T/5, captured counts, and τ0, τ fitted per subject. "
        "CSV columns: subject,trial,time,qw,qx,qy,qz,target, one row per IMU sample (time [s] from the start of "
        "the trial; the hand-to-world quaternion, scalar first; target C, N, NE, E, SE, S, SW, W or NW, the "
        "target on screen); lines '# d=<metres>' and '# radius=<metres>' give the screen distance and the "
        "target radius. The Donders recording: see fit-donders --help.",
        epilog=example_help("pointing_example.csv"),
    )
    p.add_argument("file", help="pointing recording (.csv or .npz)")
    p.add_argument("--donders", help="Donders recording of the same subjects (.csv or .npz)")
    p.add_argument("--out", default="out_pointing", help="output folder (default out_pointing)")
    p.add_argument("--starts", type=positive_int, default=2,
                   help="LM starts per subject of the Donders fit (default 2)")
    p.add_argument("--no-figures", action="store_true", help="no Figures 5-8")
    p.add_argument("--skip-invalid", action="store_true",
                   help="drop trials with invalid samples (listed in excluded.txt) instead of stopping")
    p.set_defaults(func=_analyze_pointing)


def _analyze_pointing(args) -> int:
    enable_x64()
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    import pmpjax as pj

    from .._pointing import (
        analyze_pointing,
        fit_pointing_models,
        plot_pointing_curvature,
        plot_pointing_joints,
        plot_pointing_paths,
        plot_pointing_speed,
    )

    try:
        rec = pj.read_pointing(args.file, on_invalid="skip" if args.skip_invalid else "raise")
    except ValueError as e:
        raise ValueError(str(e).replace("pass on_invalid='skip'", "pass --skip-invalid")) from None
    don = pj.read_recordings(args.donders) if args.donders else None
    if don is not None:
        missing = [s for s in rec.subjects if s not in don.subjects]
        if missing:
            raise ValueError(f"{args.donders}: no Donders session for subject(s) {missing} of {args.file}")
    out = Path(args.out)
    out = output_dir("--out", out)
    an = analyze_pointing(rec)
    text = an.table()
    pred, tc = None, None
    if don is not None:
        fit, order, heuristic, tc, pred = fit_pointing_models(an, don, n_starts=args.starts)
        text += "\n\nτ = τ0 = T/5:\n" + heuristic.table() + "\n\nfitted τ0, τ:\n" + pred.table()
        write_csv(out / "time_constants.csv", [
            {"subject": s, "status": pj.status_message(int(tc.status[i])), "converged": bool(tc.converged[i]),
             "tau0 [s]": f"{tc.tau0[i]:.6g}", "tau [s]": f"{tc.tau[i]:.6g}",
             "donders_status": pj.status_message(int(fit.status[order[i]])),
             "captured_T5": int(heuristic.n_captured[i]), "captured_fitted": int(pred.n_captured[i])}
            for i, s in enumerate(an.subjects)])
    write_csv(out / "pointing_statistics.csv",
               an.statistics_rows(None if pred is None else {"T5": heuristic, "fitted": pred}))
    (out / "pointing_statistics.txt").write_text(text + "\n")
    (out / "excluded.txt").write_text("".join(f"{reason}\n" for *_, reason in an.excluded))
    if not args.no_figures:
        for i, s in enumerate(an.subjects):
            for tag, plot in (("figure5_paths", plot_pointing_paths), ("figure6_curvature", plot_pointing_curvature),
                              ("figure7_joints", plot_pointing_joints), ("figure8_speed", plot_pointing_speed)):
                fig = plot(an, pred, subject=i)
                fig.savefig(out / f"{tag}_{s}.png", dpi=90)
                plt.close(fig)
    print(f"{plural(len(an.subjects), 'subject')}, {plural(int(an.valid.sum()), 'movement')} analysed, "
          f"{plural(len(an.excluded), 'exclusion')} (excluded.txt); wrote {out / 'pointing_statistics.csv'}"
          + ("" if tc is None else ", time_constants.csv"))
    converged = True if tc is None else bool(np.all(tc.converged) and np.all(np.asarray(fit.converged)[order]))
    return 0 if converged else 1


def add_commands(sub) -> None:
    """All of fitting's subcommands (registered as one entry point)."""
    add_fit_donders(sub)
    add_ik_weights(sub)
    add_analyze_pointing(sub)
    from .movements_command import add_fit_movements
    from .sweep_command import add_sweep

    add_fit_movements(sub)
    add_sweep(sub)
