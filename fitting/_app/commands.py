"""Subcommands of ``pmpjax`` for users' own files (entry-point group ``pmpjax.commands``).

Each ``add_<name>(subparsers)`` adds a parser whose ``func(args) -> int`` runs the command.
Readers name the file, line and column of bad input; the command line prints one line and exits
with status 2 (see ``pmpjax._app.cli``).
"""

from __future__ import annotations

import csv
import re
from pathlib import Path

import numpy as np

from pmpjax.internal import (
    csv_floats,
    example_help,
    input_file,
    open_npz,
    output_dir,
    plain,
    plural,
    positive_int,
    read_text_file,
    write_json,
)


def _x64():
    import jax

    jax.config.update("jax_enable_x64", True)


def _write_csv(path: Path, rows: list[dict]) -> None:
    with path.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


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
    _x64()
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
            "subject": s, "converged": bool(fit.converged[i]), "status": pj.status_message(int(fit.status[i])),
            **{f"KJ_{a}{b}": f"{K[a, b]:.6g}" for a in range(3) for b in range(a, 3)},
            **{f"q_rest_{j}_deg": f"{np.rad2deg(q[k]):.4g}" for k, j in enumerate(("ps", "fe", "rud"))},
            "rms_torsion_deg": f"{np.rad2deg(float(fit.rms[i])):.4g}",
            "samples": int(np.asarray(rec.mask[i]).sum()),
        })
    _write_csv(out / "donders_fit.csv", rows)
    write_json(out / "donders_fit.json", {
        "file": str(args.file), "subjects": list(map(str, rec.subjects)), "KJ": fit.KJ, "q_rest": fit.q_rest,
        "converged": fit.converged, "report": [fit.report(i) for i in range(len(rec.subjects))]}, indent=2)
    n_ok = int(np.asarray(fit.converged).sum())
    print(f"{n_ok} of {plural(len(rows), 'subject')} converged; wrote {out / 'donders_fit.csv'} and donders_fit.json")
    return 0 if n_ok == len(rows) else 1


# ----------------------------------------------------------------------------- ik-weights


def read_ik_file(path) -> dict:
    """Arrays ``qdot (B, K, n)``, ``xdot (B, K, m)``, ``J (B, K, m, n)``, ``mask (B, K)``, ``labels``
    from the paper's ``.mat`` layout, an NPZ with those arrays, or a CSV (columns ``item``,
    ``qdot_1..n``, ``xdot_1..m``, ``J_r_c`` row-major; one row per sample)."""
    import pmpjax as pj

    path = input_file("path", path)
    suffix = path.suffix.lower()
    if suffix == ".mat":
        arr = pj.ik_dataset_arrays(pj.load_ik_dataset(path))
        lead = arr["qdot"].shape[:3]  # participants × conditions × targets; trials and samples pooled
        n, m = arr["qdot"].shape[-1], arr["xdot"].shape[-1]
        labels = [f"participant {a + 1} / {c} / target {t}" for a in range(lead[0])
                  for c in arr["conditions"] for t in arr["targets"]]
        return {"qdot": arr["qdot"].reshape(-1, np.prod(arr["qdot"].shape[3:5]), n),
                "xdot": arr["xdot"].reshape(-1, np.prod(arr["xdot"].shape[3:5]), m),
                "J": arr["J"].reshape(-1, np.prod(arr["J"].shape[3:5]), m, n),
                "mask": arr["mask"].reshape(-1, np.prod(arr["mask"].shape[3:5])), "labels": labels}
    if suffix == ".npz":
        with open_npz(path) as z:
            missing = [k for k in ("qdot", "xdot", "J") if k not in z.files]
            if missing:
                raise ValueError(f"{path}: missing array(s) {missing} (found {z.files})")
            qd, xd, J = (np.asarray(z[k], float) for k in ("qdot", "xdot", "J"))
            mask = np.asarray(z["mask"], bool) if "mask" in z.files else np.ones(qd.shape[:-1], bool)
        if qd.ndim == 2:
            qd, xd, J, mask = qd[None], xd[None], J[None], mask[None]
        return {"qdot": qd, "xdot": xd, "J": J, "mask": mask, "labels": [f"item {i}" for i in range(len(qd))]}
    if suffix == ".csv":
        return _read_ik_csv(path)
    raise ValueError(f"{path}: unknown format {suffix!r} (expected .mat, .npz or .csv)")


_IK_COLUMN = re.compile(r"(?:qdot|xdot)_(\d+)|J_(\d+)_(\d+)")


def _read_ik_csv(path: Path) -> dict:
    text = read_text_file(path)
    lines = [(i + 1, ln) for i, ln in enumerate(text.splitlines()) if ln.strip() and not ln.startswith("#")]
    if not lines:
        raise ValueError(f"{path}: empty file")
    header = [h.strip() for h in next(csv.reader([lines[0][1]]))]
    where = f"{path}: line {lines[0][0]}"
    # n joints and m task coordinates: the largest indices of the velocity and Jacobian columns
    index = {h: [int(g) for g in m.groups() if g] for h in header if (m := _IK_COLUMN.fullmatch(h))}
    unknown = [h for h in header if h != "item" and h not in index]
    n = max((i[-1] for h, i in index.items() if not h.startswith("xdot_")), default=0)
    m = max((i[0] for h, i in index.items() if not h.startswith("qdot_")), default=0)
    qcols, xcols = [f"qdot_{j + 1}" for j in range(n)], [f"xdot_{j + 1}" for j in range(m)]
    jcols = [f"J_{r + 1}_{c + 1}" for r in range(m) for c in range(n)]
    missing = [h for h in ["item", *qcols, *xcols, *jcols] if h not in header]
    if unknown:
        raise ValueError(f"{where}: unknown column(s) {', '.join(map(repr, unknown))}"
                         + (f" (missing: {', '.join(missing)})" if missing else "")
                         + "; the columns are item, qdot_1..n, xdot_1..m and J_r_c (r ≤ m, c ≤ n)")
    if not n or not m:
        raise ValueError(f"{where}: the header needs item, qdot_1..n, xdot_1..m and J_r_c columns; no "
                         + ("qdot_ or xdot_" if not n and not m else "qdot_" if not n else "xdot_") + " columns")
    if missing:
        raise ValueError(f"{where}: missing column(s) {', '.join(missing)} (qdot_1..{n}, xdot_1..{m} and every "
                         f"J_r_c of the {m}x{n} Jacobian)")
    extra = [h for h in header if h in index and h not in {*qcols, *xcols, *jcols}]
    if extra:
        raise ValueError(f"{where}: column(s) {', '.join(extra)} outside qdot_1..{n}, xdot_1..{m} and the {m}x{n} "
                         "Jacobian J_r_c")
    duplicated = sorted({h for h in header if header.count(h) > 1})
    if duplicated:
        raise ValueError(f"{where}: column(s) {', '.join(duplicated)} appear more than once")
    if len(lines) < 2:
        raise ValueError(f"{where}: no data rows after the header")
    idx = {h: header.index(h) for h in header}
    items: dict[str, list] = {}
    for lineno, ln in lines[1:]:
        cells = next(csv.reader([ln]))
        if len(cells) != len(header):
            raise ValueError(f"{path}: line {lineno}: {len(cells)} fields, header has {len(header)}")
        vals = csv_floats(path, lineno, cells, idx, (*qcols, *xcols, *jcols))
        items.setdefault(cells[idx["item"]], []).append(vals)
    K = max(len(v) for v in items.values())
    B = len(items)
    qd, xd, J = np.zeros((B, K, n)), np.zeros((B, K, m)), np.broadcast_to(np.eye(m, n), (B, K, m, n)).copy()
    mask = np.zeros((B, K), bool)
    for b, rows in enumerate(items.values()):
        a = np.asarray(rows)
        k = len(a)
        qd[b, :k], xd[b, :k], J[b, :k] = a[:, :n], a[:, n:n + m], a[:, n + m:].reshape(k, m, n)
        mask[b, :k] = True
    return {"qdot": qd, "xdot": xd, "J": J, "mask": mask, "labels": list(items)}


def add_ik_weights(sub) -> None:
    p = sub.add_parser(
        "ik-weights", help="estimate IK weights (Khoramshahi et al. 2022, Algorithm 1) from a data file",
        description="Estimate the IK weights of every item (participant, condition, target) of a data file: "
        + plain(read_ik_file.__doc__.split("\n\n")[0]),
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
    _x64()
    import pmpjax as pj

    from .._ik.analysis import contribution_coefficients
    from .._ik.weights import estimate_ik_weights, estimate_ik_weights_lm

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
             **{f"w_{j + 1}": f"{w[i, j]:.6g}" for j in range(w.shape[1])},
             **{f"beta_{j + 1}": f"{beta[i, j]:.6g}" for j in range(w.shape[1])},
             "error": f"{float(error[i]):.4g}"} for i, lab in enumerate(d["labels"])]
    _write_csv(out / "ik_weights.csv", rows)
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
    _x64()
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    import pmpjax as pj

    from .._pointing import (
        analyze_pointing,
        plot_pointing_curvature,
        plot_pointing_joints,
        plot_pointing_paths,
        plot_pointing_speed,
    )
    from .pointing import fit_pointing_models

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
        _write_csv(out / "time_constants.csv", [
            {"subject": s, "donders_status": pj.status_message(int(fit.status[order[i]])),
             "tau0_s": f"{tc.tau0[i]:.6g}", "tau_s": f"{tc.tau[i]:.6g}", "status": pj.status_message(int(tc.status[i])),
             "captured_T5": int(heuristic.n_captured[i]), "captured_fitted": int(pred.n_captured[i])}
            for i, s in enumerate(an.subjects)])
    _write_csv(out / "pointing_statistics.csv",
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
