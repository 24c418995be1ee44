"""Benchmark: real reaching (HuG-MP) — the 4-subject λ0-PMP fit in JAX vs a SciPy loop, and the
held-out error table of every model variant and baseline.

1. **Fit cost** (default mode): ``fitting.fit_reaching([1, 2, 3, 4])`` with the default model
   (Arimoto planner, ``W = τ0 KJ``, ``τ = τ0 = T/5``; all tasks, repetitions 1–7), one public call.
   Compile time is the union of the time spans JAX reports through ``jax.monitoring`` for tracing,
   lowering and XLA compilation during that call; run time is the wall time minus it. Subjects run
   one after the other inside the compiled call (``lax.map``), so the cost per subject is the run
   time over the subjects. Against it, on ONE subject in the same process: ``scipy.optimize.
   least_squares`` (2-point Jacobian, ``method="lm"``) around ``scipy.integrate.solve_ivp`` (LSODA,
   rtol 1e-6, atol 1e-9) of an independent NumPy λ0-PMP on normalised time (the data README's arm
   formula, Eqs 3–10 of design §3.1), the same residual (49 time-normalised samples / √49 and the
   final posture per motion), started from the same stage-1 point (``KJ``, ``q_rest`` fitted to the
   final postures through the equilibria). The SciPy loop is capped at ``--scipy-nfev`` residual
   evaluations; its time for the fit is extrapolated as (seconds per evaluation) × (p + 1) × (the
   JAX fit's LM iterations of that subject) + evaluations of rejected steps are not counted, so the
   extrapolation is a lower bound on SciPy's time. Same computation: the NumPy residual at the
   JAX optimum gives the JAX loss (relative difference reported), and SciPy's capped fit must not
   end above the start loss.
2. **Held-out table** (``--table``): every damping variant (``"tau0_KJ"``, ``"diagonal"``,
   ``"full"``; tied time constants, then the fitted ones if ``--fitted``) fitted to all four
   subjects, and the four baselines; held-out repetitions 8–10: median/mean final-posture error and
   joint-trajectory RMSE [deg] per subject; AIC/BIC per subject; paired Wilcoxon tests of the held-
   out RMSE of free ``W`` against ``W = τ0 KJ``. Writes ``reaching_table.json`` and
   ``reaching_table.md`` after every variant (partial results survive).

``--quick``: one subject, task 1, repetitions 1–2, 3 LM iterations, 2 SciPy evaluations; writes
nothing. Usage: ``python benchmarks/reaching.py [--quick] [--table [--fitted]] [--scipy-nfev N]``.

Latest figures: (filled in below after the run)
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

sys.path.insert(0, os.path.dirname(__file__))
from _baselines import write_results  # noqa: E402

import fitting  # noqa: E402
from fitting import _reaching as R  # noqa: E402

SUBJECTS = (1, 2, 3, 4)
VARIANTS = (("lambda0", "tau0_KJ", "tied"), ("lambda0", "diagonal", "tied"), ("lambda0", "full", "tied"))
FITTED = (("lambda0", "tau0_KJ", "fitted"), ("lambda0", "diagonal", "fitted"), ("lambda0", "full", "fitted"))


def load():
    return os.getloadavg()[0]


def log(msg):
    print(f"[{time.strftime('%H:%M:%S')} load {load():.1f}] {msg}", flush=True)


# --- compile time from jax.monitoring ------------------------------------------------------------

_EVENTS = ("/jax/core/compile/jaxpr_trace_duration", "/jax/core/compile/jaxpr_to_mlir_module_duration",
           "/jax/core/compile/backend_compile_duration")
_SPANS: list = []


def _listener(event, start, end, **_):
    if event in _EVENTS:
        _SPANS.append((start, end))


jax.monitoring.register_event_time_span_listener(_listener)


def compile_seconds(since: float) -> float:
    """Union of the tracing/lowering/compilation time spans that started after ``since`` (nested
    traces counted once)."""
    spans = sorted(s for s in _SPANS if s[0] >= since)
    total, cur = 0.0, None
    for a, b in spans:
        if cur is None or a > cur[1]:
            total += 0.0 if cur is None else cur[1] - cur[0]
            cur = [a, b]
        else:
            cur[1] = max(cur[1], b)
    return total + (0.0 if cur is None else cur[1] - cur[0])


def timed_fit(subjects, **kw):
    t0 = time.time()
    p0 = time.perf_counter()
    fit = fitting.fit_reaching(subjects, **kw)
    wall = time.perf_counter() - p0
    comp = compile_seconds(t0)
    return fit, wall, comp


# --- the held-out table --------------------------------------------------------------------------


def _stats(v):
    v = np.asarray(v, float)
    ok = v[np.isfinite(v)]
    return dict(n=int(ok.size), n_failed=int(v.size - ok.size),
                median=float(np.median(ok)) if ok.size else None, mean=float(np.mean(ok)) if ok.size else None)


def predictor_rows(pred, name):
    """Per subject (and "all"): held-out final error and RMSE statistics of one predictor."""
    b = pred.predictors()[name]
    out = {}
    for s in [*dict.fromkeys(pred.subject.tolist()), "all"]:
        sel = np.ones(len(pred.task), bool) if s == "all" else pred.subject == s
        out[s] = dict(final=_stats(b.final_error_deg[sel]), rmse=_stats(b.rmse_deg[sel]))
    return out


def fit_rows(fit, wall, comp):
    return dict(
        wall_s=wall, compile_s=comp, run_s=wall - comp, load=load(), steps_per_sample=fit.steps_per_sample,
        n_params=len(fit.param_names),
        subjects={s: dict(status=int(fit.status[a]), message=fit.messages[a], n_motions=int(fit.n_motions[a]),
                          n_residuals=int(fit.n_residuals[a]), lm_steps=fit.lm_steps[a].tolist(),
                          loss=float(fit.loss[a]), train_rmse_deg=float(fit.rmse_deg[a]), aic=float(fit.aic[a]),
                          bic=float(fit.bic[a]), tau_over_T=float(fit.tau_over_T[a]),
                          tau0_over_T=float(fit.tau0_over_T[a]), KJ=np.round(fit.KJ[a], 4).tolist(),
                          W=np.round(fit.W[a], 4).tolist(),
                          q_rest_deg=np.round(np.rad2deg(fit.q_rest[a]), 2).tolist())
                  for a, s in enumerate(fit.subjects)})


def wilcoxon(pred_a, pred_b):
    """Paired two-sided Wilcoxon test of the held-out RMSE, per subject and pooled: b − a."""
    from scipy.stats import wilcoxon as w

    out = {}
    for s in [*dict.fromkeys(pred_a.subject.tolist()), "all"]:
        sel = np.ones(len(pred_a.task), bool) if s == "all" else pred_a.subject == s
        a, b = pred_a.rmse_deg[sel], pred_b.rmse_deg[sel]
        ok = np.isfinite(a) & np.isfinite(b)
        if ok.sum() < 5:
            out[s] = None
            continue
        d = b[ok] - a[ok]
        out[s] = dict(n=int(ok.sum()), median_diff_deg=float(np.median(d)), p=float(w(a[ok], b[ok]).pvalue),
                      b_better_fraction=float(np.mean(d < 0)))
    return out


def _cell(st):
    return "—" if st["median"] is None else f"{st['median']:.1f} / {st['mean']:.1f}" + (
        f" ({st['n_failed']} failed)" if st["n_failed"] else "")


def markdown(res) -> str:
    subs = res["subjects"] + ["all"]
    names = list(res["predictors"])
    lines = []
    for metric, title in (("final", "final-posture error"), ("rmse", "joint-trajectory RMSE")):
        lines += [f"Held-out (repetitions 8–10) {title} [deg], median / mean over motions:", "",
                  "| predictor | " + " | ".join(subs) + " |", "|---|" + "---:|" * len(subs)]
        for n in names:
            lines.append(f"| {n} | " + " | ".join(_cell(res["predictors"][n][s][metric]) for s in subs) + " |")
        lines.append("")
    n_held = {s: res["predictors"][names[0]][s]["rmse"]["n"] + res["predictors"][names[0]][s]["rmse"]["n_failed"]
              for s in subs}
    lines += ["Held-out motions: " + ", ".join(f"{s} {n_held[s]}" for s in subs), ""]
    lines += ["Fits (repetitions 1–7): parameters p, training loss ½Σr², AIC / BIC (lower is better), "
              "LM iterations (stage 1, stage 2), status:", "",
              "| variant | p | " + " | ".join(res["subjects"]) + " |", "|---|---:|" + "---|" * len(res["subjects"])]
    for v, f in res["fits"].items():
        cells = []
        for s in res["subjects"]:
            e = f["subjects"][s]
            cells.append(f"{e['loss']:.4g}; {e['aic']:.0f} / {e['bic']:.0f}; {e['lm_steps'][0]},{e['lm_steps'][1]}"
                         + ("" if e["status"] == 0 else f"; {e['message'].split(':')[0]}"))
        lines.append(f"| {v} | {f['n_params']} | " + " | ".join(cells) + " |")
    lines.append("")
    if res.get("wilcoxon"):
        lines += ["Free W against W = τ0 KJ, held-out RMSE, paired Wilcoxon (median difference [deg], p, "
                  "fraction of motions where free W is better):", "",
                  "| comparison | " + " | ".join(subs) + " |", "|---|" + "---|" * len(subs)]
        for k, w in res["wilcoxon"].items():
            lines.append(f"| {k} | " + " | ".join("—" if w[s] is None else
                                                  f"{w[s]['median_diff_deg']:+.2f}, p={w[s]['p']:.2g}, "
                                                  f"{w[s]['b_better_fraction']:.0%}" for s in subs) + " |")
        lines.append("")
    return "\n".join(lines)


def table(args):
    variants = VARIANTS + (FITTED if args.fitted else ())
    kw = dict(max_steps=tuple(args.max_steps))
    subjects = SUBJECTS
    if args.quick:
        subjects, kw = (2,), dict(reps=(1, 2), tasks=(1,), max_steps=(3, 2))
        variants = variants[:2]
    res = dict(date=time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), load_start=load(),
               machine="2-core AMD EPYC Zen 4 KVM, no GPU", options={k: list(v) for k, v in kw.items()},
               subjects=[f"S{s:02d}" for s in subjects], fits={}, predictors={}, wilcoxon={})
    preds = {}
    for model, damping, tc in variants:
        key = f"{model}/{damping}/{tc}"
        log(f"fit {key} ...")
        fit, wall, comp = timed_fit(subjects, model=model, damping=damping, time_constants=tc, **kw)
        res["fits"][key] = fit_rows(fit, wall, comp)
        log(f"  fit {key}: {wall:.0f} s (compile {comp:.0f} s), status {fit.status.tolist()}, "
            f"lm {fit.lm_steps.tolist()}, steps/sample {fit.steps_per_sample}, aic {np.round(fit.aic, 0).tolist()}")
        t = time.perf_counter()
        pred = fitting.predict_reaching(fit, reps=(8, 9, 10))
        res["fits"][key]["predict_s"] = time.perf_counter() - t
        preds[key] = pred
        res["predictors"][key] = predictor_rows(pred, "model")
        if len(preds) == 1:
            for b in R.BASELINES:
                res["predictors"][b] = predictor_rows(pred, b)
        ref = f"{model}/tau0_KJ/{tc}"
        if damping != "tau0_KJ" and ref in preds:
            res["wilcoxon"][f"{damping} vs tau0_KJ ({tc})"] = wilcoxon(preds[ref], pred)
        log(f"  held-out RMSE all: {res['predictors'][key]['all']['rmse']}")
        # baselines last in the table
        res["predictors"] = {k: res["predictors"][k] for k in
                             sorted(res["predictors"], key=lambda k: (k in R.BASELINES, list(res['predictors']).index(k)))}
        res["load_end"] = load()
        md = markdown(res)
        if not args.quick:
            write_results("reaching_table", res)
            path = os.path.join(os.path.dirname(write_results("reaching_table", res)), "reaching_table.md")
            with open(path, "w") as f:
                f.write(md + "\n")
    print(markdown(res))
    return res


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--table", action="store_true")
    ap.add_argument("--fitted", action="store_true", help="with --table: the fitted time-constant variants too")
    ap.add_argument("--max-steps", type=int, nargs=2, default=(40, 25))
    ap.add_argument("--scipy-nfev", type=int, default=30)
    args = ap.parse_args()
    if args.table:
        table(args)
        return
    raise SystemExit("the fit-cost mode is not written yet")


if __name__ == "__main__":
    main()
