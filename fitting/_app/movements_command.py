"""``pmpjax fit-movements``: the λ0-PMP fitted through the reaches of a lab's joint-angle
recordings on its own arm model, held-out reaches predicted against the baselines."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from pmpjax._app import plural
from pmpjax.internal import output_dir, write_json

from .output import enable_x64, write_csv

SUBJECT_PATTERN = r"^([^_]+)"


def add_fit_movements(sub) -> None:
    here = Path(__file__).parents[2] / "pmpjax" / "data" / "examples"
    p = sub.add_parser(
        "fit-movements", help="fit the λ0-PMP per subject through the reaches of joint-angle recordings "
        "(OpenSim .mot/.sto, CSV) on your own arm (MJCF), and predict held-out reaches",
        description="Find the reaches inside continuous joint-angle recordings by hand speed, fit per subject "
        "joint stiffness KJ (full SPD, trace n), rest posture q_rest and the time constants τ0, τ of the λ0-PMP "
        "(Tommasino & Campolo 2017, Arimoto planner with Eq 10's gain) through the reaches' joint trajectories "
        "(fitting.fit_movements), then predict the reaches of the held-out recordings against a "
        "pseudo-inverse baseline (fitting.predict_movements). Recordings: .mot/.sto (OpenSim; inDegrees in "
        "the header) or .csv (a 'time' column and one column per joint, in radians, or in degrees with "
        "'_deg' names); columns are matched to the model's joint names. Subjects: each file's subject is "
        "the part of its name matched by --subject-pattern (default: before the first '_', so "
        "S1_trial1.mot belongs to S1). Writes movement_fit.csv/.json, movement_parameters.csv, reaches.csv, "
        "and with --holdout movement_predictions.csv, movement_prediction_summary.csv and one figure per "
        "subject.",
        epilog=f"Example (synthetic recordings on a 5-joint arm): pmpjax fit-movements --chain {here / 'arm5.xml'} "
        f"--site hand {here / 'reaching' / 'S1_trial1.mot'} {here / 'reaching' / 'S2_trial1.mot'} --holdout "
        f"{here / 'reaching' / 'S1_trial2.mot'} {here / 'reaching' / 'S2_trial2.mot'} --out out_movements",
    )
    p.add_argument("recordings", nargs="+", help="recordings to fit (.mot, .sto, .csv)")
    p.add_argument("--chain", required=True, help="the arm: an MJCF file (.xml) with hinge joints")
    p.add_argument("--site", required=True, help="the MJCF site whose position is the hand")
    p.add_argument("--holdout", nargs="+", default=(), metavar="RECORDING",
                   help="recordings held out from the fit and predicted")
    p.add_argument("--subject-pattern", default=SUBJECT_PATTERN,
                   help=f"regular expression on the file name; its first group (or whole match) names the "
                   f"subject (default {SUBJECT_PATTERN!r}: before the first '_')")
    p.add_argument("--model", choices=("lambda0", "lambda0_minjerk"), default="lambda0",
                   help="planner: Arimoto with Eq 10's gain (default) or the minimum-jerk time-base generator")
    p.add_argument("--damping", choices=("tau0_KJ", "diagonal", "full"), default="tau0_KJ",
                   help="W = τ0 KJ (Eq 7, default), diagonal or full")
    p.add_argument("--time-constants", choices=("seconds", "fractions", "tied"), default="seconds",
                   help="one τ0, τ per subject in seconds (default), as fractions of each reach's duration, or "
                   "tied (τ = τ0 = T/5, not fitted)")
    p.add_argument("--segmented", action="store_true",
                   help="each recording is one motion (idle time removed): no search for reaches; the first and "
                   "last samples are the start and final postures; fractions are of the time between the onset "
                   "and the offset at 20 %% of the peak hand speed")
    p.add_argument("--rest-margin", type=float, default=90.0, metavar="DEG",
                   help="the rest angles stay within each joint's recorded range widened by DEG degrees "
                   "(default 90)")
    p.add_argument("--out", default="out_movements", help="output folder (default out_movements)")
    p.add_argument("--max-gap", type=float, default=0.05, metavar="S",
                   help="longest run of missing samples (NaN) [s] filled by linear interpolation (default 0.05)")
    p.add_argument("--sample-tol", type=float, default=0.01, metavar="R",
                   help="largest relative deviation of a sample interval from the recording's median interval "
                   "(default 0.01)")
    p.add_argument("--no-figures", action="store_true", help="no figures")
    p.set_defaults(func=_fit_movements)


def _subject(path: Path, pattern: re.Pattern) -> str:
    m = pattern.search(path.name)
    if m is None:
        raise ValueError(f"{path}: --subject-pattern {pattern.pattern!r} does not match the file name")
    return m.group(1) if m.groups() else m.group(0)


#: read_joint_angles' arguments as the command's options (its messages name them so).
_READER_OPTIONS = {"max_gap": "--max-gap", "sample_tol": "--sample-tol"}


def read_recordings_for(chain, paths, pattern: re.Pattern, max_gap: float = 0.05, sample_tol: float = 0.01) -> list:
    import pmpjax as pj

    try:
        return [pj.read_joint_angles(p, subject=_subject(Path(p), pattern), joints=chain, max_gap=max_gap,
                                     sample_tol=sample_tol) for p in paths]
    except ValueError as e:
        text = str(e)
        for arg, option in _READER_OPTIONS.items():
            text = text.replace(f"{arg} = ", f"{option} ").replace(f"`{arg}`", option)
        raise ValueError(text) from None


def _fit_movements(args) -> int:
    enable_x64()
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    import pmpjax as pj

    from .._movements import fit_movements, plot_movement_parameters, plot_movements, predict_movements

    try:
        pattern = re.compile(args.subject_pattern)
    except re.error as e:
        raise ValueError(f"--subject-pattern {args.subject_pattern!r} is not a regular expression ({e})") from None
    if not (np.isfinite(args.rest_margin) and args.rest_margin >= 0.0):
        raise ValueError(f"--rest-margin must be a finite number of degrees >= 0, got {args.rest_margin}")
    out = output_dir("--out", Path(args.out))
    chain_path = Path(args.chain)
    if not chain_path.is_file():
        raise ValueError(f"--chain {chain_path}: " + ("is a folder, not an MJCF file" if chain_path.is_dir()
                                                        else "no such file"))
    chain = pj.MjcfChain(chain_path, args.site)
    mx = chain.mjx_model  # (hinge: MuJoCo's mjJNT_HINGE = 3; the chain has hinges and slides only)
    kinds = np.asarray(mx.jnt_type)[np.argsort(np.asarray(mx.jnt_qposadr))]
    slides = [name for name, kind in zip(chain.joint_names or range(chain.n), kinds) if int(kind) != 3]
    if slides:
        raise ValueError(f"--chain {chain_path}: slide joint(s) {', '.join(map(repr, slides))}: fit-movements "
                         "fits joint angles, so every joint must be a hinge")
    overlap = sorted(set(map(str, args.recordings)) & set(map(str, args.holdout)))
    if overlap:
        raise ValueError(f"--holdout {overlap[0]}: also given as a recording to fit")
    fitted = {_subject(Path(p), pattern) for p in args.recordings}
    for p in args.holdout:
        if _subject(Path(p), pattern) not in fitted:
            raise ValueError(f"--holdout {p}: its subject {_subject(Path(p), pattern)!r} has no recording to fit "
                             f"(subjects fitted: {', '.join(sorted(fitted))}; --subject-pattern names them)")
    train = read_recordings_for(chain, args.recordings, pattern, args.max_gap, args.sample_tol)
    held = read_recordings_for(chain, args.holdout, pattern, args.max_gap, args.sample_tol)
    fit = fit_movements(chain, train, model=args.model, damping=args.damping, time_constants=args.time_constants,
                        segmented=args.segmented, rest_margin_deg=args.rest_margin)
    write_csv(out / "movement_fit.csv", fit.summary())
    write_csv(out / "movement_parameters.csv", fit.parameter_rows())
    reach_rows = []
    for s, found in fit.reaches.items():
        delays = fit.reach_delays.get(s)
        shifts = fit.reach_target_offsets.get(s)
        for k in range(len(found)):
            # the fitted target onset in the recording's clock, and how far the fitted target lies
            # beyond where the hand came to rest (the chain's length unit)
            d = float(delays[k]) * (1.0 if fit.time_constants == "seconds" else float(found.duration[k])) \
                if delays is not None else float("nan")
            shift = float(np.linalg.norm(shifts[k])) if shifts is not None and shifts.shape[1] else float("nan")
            reach_rows.append({"subject": s, "recording": found.recording[k],
                               "t_start [s]": round(float(found.t[k, 0]), 4),
                               "t_end [s]": round(float(found.t[k, -1]), 4), "used": "fitted", "reason": "",
                               "target_onset [s]": round(float(found.t[k, 0]) - d, 4),
                               "target_shift [length]": shift})
        for rec, a, b, why in fit.skipped[s]:
            reach_rows.append({"subject": s, "recording": rec, "t_start [s]": round(float(a), 4),
                               "t_end [s]": round(float(b), 4), "used": "skipped", "reason": why,
                               "target_onset [s]": float("nan"), "target_shift [length]": float("nan")})
    if reach_rows:
        write_csv(out / "reaches.csv", reach_rows)
    result = {
        "chain": str(chain_path), "site": args.site, "joint_names": list(fit.joint_names),
        "recordings": [str(p) for p in args.recordings], "model": fit.model, "damping": fit.damping,
        "time_constants": fit.time_constants, "solver": fit.solver, "steps_per_sample": fit.steps_per_sample,
        "subjects": fit.summary(), "KJ": fit.KJ, "q_rest": fit.q_rest, "W": fit.W,
        "param_names": list(fit.param_names), "params": fit.params, "stderr": fit.stderr,
    }
    if not args.no_figures:
        fig = plot_movement_parameters(fit)
        fig.savefig(out / "movement_parameters.png", dpi=100)
        plt.close(fig)
    n_ok = int(np.sum(fit.converged))
    line = f"{n_ok} of {plural(len(fit.subjects), 'subject')} converged"
    n_failed = 0  # held-out reaches whose simulation did not end successfully (exit status 1)
    if held:
        pred = predict_movements(fit, held)
        write_csv(out / "movement_predictions.csv", pred.movement_rows())
        summary = pred.summary()
        write_csv(out / "movement_prediction_summary.csv", summary)
        result["held_out"] = {"recordings": [str(p) for p in args.holdout], "summary": summary,
                              "problems": pred.problems,
                              "skipped": {k: [list(v) for v in vs] for k, vs in pred.skipped.items()}}
        if not args.no_figures:
            for s in dict.fromkeys(pred.subject.tolist()):
                fig = plot_movements(pred, s)
                fig.savefig(out / f"movements_{s}.png", dpi=90)
                plt.close(fig)
        last = summary[-1]
        line += (f"; {len(pred)} held-out reaches, median joint RMSE {last['model_median_rmse [deg]']:.2f} deg "
                 f"(pseudo-inverse {last['pinv_minjerk_median_rmse [deg]']:.2f} deg)")
        n_failed = int(np.sum(np.asarray(pred.status) != 0))
        if n_failed:
            line += f"; {plural(n_failed, 'held-out reach', 'held-out reaches')} did not simulate successfully"
    write_json(out / "movement_fit.json", result)
    print(f"{line}; wrote {out}")
    return 0 if n_ok == len(fit.subjects) and n_failed == 0 else 1
