"""Benchmark: real reaching (HuG-MP) — the 4-subject λ0-PMP trajectory fit in JAX vs a SciPy
loop, and the held-out table of every model variant against the baselines.

1. **Fit cost** (default mode): ``fitting.fit_reaching([1, 2, 3, 4])`` with its defaults (Arimoto
   planner with Eq 10's gain, ``W = τ0 KJ``, ``τ/T`` and ``τ0/T`` fitted per subject; all tasks,
   repetitions 1–7; stage 1 from the final postures, stage 2 from the trajectories with the solver
   it picks), one public call. Compile time is the union of the time spans JAX reports through
   ``jax.monitoring`` for tracing, lowering and XLA compilation during that call; a second call
   with the same shapes gives the run time alone. Against it, on ONE subject (the one with the
   fewest motions) in the same process: ``scipy.optimize.least_squares`` (2-point Jacobian,
   ``method="lm"``) around ``scipy.integrate.solve_ivp`` (LSODA, rtol 1e-6, atol 1e-9) of an
   independent NumPy λ0-PMP on normalised time (the data README's arm formula, design §3.1, Eqs
   3–10), the same residual (49 time-normalised samples / √49 and the final posture per motion).
   The SciPy loop is capped at ``--scipy-nfev`` residual calls and extrapolated as (seconds per
   call) × (p + 1) × (the JAX fit's stage-2 LM iterations of that subject): a lower bound (no
   rejected steps, no stage 1). Same computation: NumPy's cost at the JAX optimum against the JAX
   fit's data cost.
2. **Held-out table** (``--table``): every variant of ``fit_reaching`` — planner (``lambda0``,
   ``lambda0_minjerk``) × damping (``tau0_KJ``, ``diagonal``, ``full``) × time constants (``tied``,
   ``fitted``), defaults otherwise — and the Donders-only model (stage 1 alone) on the four
   subjects, predicting the held-out repetitions 8–10 against the baselines: median/mean
   joint-trajectory RMSE and final-posture error [deg] per subject, fits (status, iterations, AIC,
   binding bounds), paired Wilcoxon tests of held-out RMSE of every variant against
   ``pinv_minjerk`` and against the Donders-only model, and a verdict. Writes
   ``reaching_table.json``/``.md`` (and pickles of each fit and prediction) after every variant,
   and the pooled summary that ships with ``fitting`` for the main job's report
   (``fitting/data/reaching_variants.json``).

``--quick``: one subject, task 1, repetitions 1–2, 3 + 2 LM iterations, 2 SciPy calls; writes
nothing. Usage: ``python benchmarks/reaching.py [--quick] [--table [--variants ...] [--subjects ...]
[--max-steps 100 100] [--name NAME]]``.

Latest figures (2026-12-05, 2-core AMD EPYC Zen 4 KVM, no GPU, jax 0.10.2, float64).

Fit cost (17:15 UTC, idle; defaults: ``max_steps=(100, 100)``, fitted time constants)::

    | | compile [s] | run [s] | per subject [s] |
    |---|---:|---:|---:|
    | fit_reaching, 4 subjects (rodas4 ×2; stage-2 iterations 24, 24, 16, 18) | 24 | 50 | 12.4 |
    | fit_reaching, S01 alone (24 stage-2 iterations) | — | 11.0 | 11.0 |
    | SciPy loop, S01 (1.6 s per residual × 15 × 24 iterations, extrapolated) | — | — | 568 |

    S01: SciPy loop / fit_reaching 52× (target 50×); per subject of the 4-subject call 46×, 30×
    with compilation. NumPy cost at the JAX optimum 3.9073, JAX 3.9073. Every subject converged;
    integration error at the optimum ≤ 0.0001°.

Held-out table (16:31–16:58 UTC, ``--table --max-steps 100 200``; 27 min for 12 variants + the
Donders-only model; ``results/reaching_table.md``): every fit of every variant converged on all
four subjects. Pooled median held-out RMSE [deg]: Donders-only 15.1; Arimoto planner tied
(``tau0_KJ``/diagonal/full) 8.9/13.2/8.5, fitted 5.9/7.1/5.6; time-base generator tied 5.6/5.6/5.6,
fitted 5.3/5.3/5.3; pinv_minjerk 7.5, ik_weights_minjerk 9.9, unfitted λ0-PMP 13.6, joint-space
oracle 5.6. Verdict: the fitted-time-constant Arimoto variants and every time-base-generator
variant beat pinv_minjerk (paired Wilcoxon, median −0.6° to −2.0° per motion, p ≤ 0.006); the
tied Arimoto variants do not (+1.1° to +5.0°). Every variant beats the Donders-only model pooled
(p ≤ 1e-37) and on every subject (p < 1e-4) except lambda0/diagonal/tied on S03 (−0.6°,
p = 0.08). Wall per variant 44–344 s (free full damping the slowest).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402
import scipy.integrate  # noqa: E402
import scipy.optimize  # noqa: E402

sys.path.insert(0, os.path.dirname(__file__))
import _baselines as bl  # noqa: E402
from _baselines import write_results  # noqa: E402

import fitting  # noqa: E402
from fitting import _reaching as R  # noqa: E402

SUBJECTS = (1, 2, 3, 4)
#: Every λ0-PMP variant of fitting.fit_reaching: planner × damping × time constants.
VARIANTS = tuple((m, d, t) for m in R.MODELS for t in R.TIME_CONSTANTS for d in R.DAMPINGS)
VARIANT_NAMES = {f"{m}/{d}/{t}": (m, d, t) for m, d, t in VARIANTS}


def load():
    return os.getloadavg()[0]


def log(msg):
    print(f"[{time.strftime('%H:%M:%S')} load {load():.1f}] {msg}", flush=True)


# --- SciPy loop: an independent NumPy λ0-PMP of the arm on normalised time ----------------------

L1, L2 = 0.30, 0.33  # data README (pmpjax.ShoulderElbowArm defaults)


def _rot(axis, t):
    c, s = np.cos(t), np.sin(t)
    R = {0: [[1, 0, 0], [0, c, -s], [0, s, c]], 1: [[c, 0, s], [0, 1, 0], [-s, 0, c]],
         2: [[c, -s, 0], [s, c, 0], [0, 0, 1]]}[axis]
    dR = {0: [[0, 0, 0], [0, -s, -c], [0, c, -s]], 1: [[-s, 0, c], [0, 0, 0], [-c, 0, -s]],
          2: [[-s, -c, 0], [c, -s, 0], [0, 0, 0]]}[axis]
    return np.array(R, float), np.array(dR, float)


def arm(q):
    """Hand position (3,) and Jacobian (3, 4) of ``p = Rx(q1) Ry(q2) Rz(−q3) ([0,0,−L1] +
    Ry(−q4) [0,0,−L2])`` (the data README's formula, derivatives by the product rule)."""
    (A, dA), (B, dB), (C, dC), (D, dD) = _rot(0, q[0]), _rot(1, q[1]), _rot(2, -q[2]), _rot(1, -q[3])
    u = np.array([0.0, 0.0, -L2])
    v = np.array([0.0, 0.0, -L1]) + D @ u
    BCv = B @ (C @ v)
    J = np.stack([dA @ BCv, A @ (dB @ (C @ v)), -(A @ (B @ (dC @ v))), -(A @ (B @ (C @ (dD @ u))))], 1)
    return A @ BCv, J


def stiffness_np(s):
    """``4 expm(S)/tr expm(S)`` with S traceless symmetric: diagonal s0..s2, then the upper triangle."""
    import scipy.linalg

    S = np.zeros((4, 4))
    S[[0, 1, 2], [0, 1, 2]] = s[:3]
    S[3, 3] = -np.sum(s[:3])
    iu = [(i, j) for i in range(4) for j in range(i + 1, 4)]
    for k, (i, j) in enumerate(iu):
        S[i, j] = S[j, i] = s[3 + k]
    E = scipy.linalg.expm(S)
    return 4.0 * E / np.trace(E)


def movement_np(q0, target, KJ, q_rest, tau, tau0, n=50):
    """λ0-PMP (``W = τ0 KJ``, Arimoto with Eq 10 gain) on normalised time s ∈ [0, 1]: q at n samples."""
    A = np.linalg.inv(tau0 * KJ)
    _, J0 = arm(q0)
    k = 1.0 / (np.linalg.eigvalsh(J0 @ A @ J0.T)[0] * tau0)

    def rhs(t, q):
        x, J = arm(q)
        s = t / tau
        F = k * (1.0 - (1.0 + s) * np.exp(-s)) * (target - x)
        tel = KJ @ (q - q_rest)
        JA = J @ A
        lam0 = np.linalg.solve(JA @ J.T, JA @ tel)
        return A @ (J.T @ (F + lam0) - tel)

    s = np.linspace(0.0, 1.0, n)
    sol = scipy.integrate.solve_ivp(rhs, (0.0, 1.0), q0, method="LSODA", t_eval=s, rtol=1e-6, atol=1e-9)
    if not sol.success or sol.y.shape[1] != n:
        return np.full((n, 4), np.nan)
    return sol.y.T


def residual_np(theta, q_obs, t_ratio, elbow):
    """The fit's stage-2 residual (``W = τ0 KJ``; ``τ = τ0 = T/5`` for 12 parameters, fitted
    ``log τ/T, log τ0/T`` for 14): per motion ``(q − q_obs)(s_k)/√49``, k = 1..49, then
    ``(q − q_obs)(1)`` [rad]."""
    KJ = stiffness_np(theta[:9])
    q_rest = np.append(theta[9:12], elbow)
    a, a0 = (np.exp(theta[12]), np.exp(theta[13])) if len(theta) == 14 else (0.2, 0.2)
    out = []
    for qo, tr in zip(q_obs, t_ratio):
        x_d, _ = arm(qo[-1])
        q = movement_np(qo[0], x_d, KJ, q_rest, a * tr, a0 * tr, qo.shape[0])
        d = q - qo
        out += [d[1:].ravel() / np.sqrt(qo.shape[0] - 1), d[-1]]
    r = np.concatenate(out)
    return np.where(np.isfinite(r), r, 1e3)


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


def _groups(pred):
    return [*dict.fromkeys(pred.subject.tolist()), "all"]


def _select(pred, s):
    return np.ones(len(pred.task), bool) if s == "all" else pred.subject == s


def predictor_rows(pred, name):
    """Per subject (and "all"): held-out final error and RMSE statistics of one predictor."""
    b = pred.predictors()[name]
    return {s: dict(final=_stats(b.final_error_deg[_select(pred, s)]), rmse=_stats(b.rmse_deg[_select(pred, s)]))
            for s in _groups(pred)}


def fit_rows(fit, wall, comp):
    return dict(
        wall_s=wall, compile_s=comp, run_s=wall - comp, load=load(), solver=fit.solver,
        steps_per_sample=fit.steps_per_sample, n_params=len(fit.param_names),
        subjects={s: dict(status=int(fit.status[a]), message=fit.messages[a], n_motions=int(fit.n_motions[a]),
                          n_residuals=int(fit.n_residuals[a]), lm_steps=fit.lm_steps[a].tolist(),
                          loss=float(fit.loss[a]), train_rmse_deg=float(fit.rmse_deg[a]), aic=float(fit.aic[a]),
                          bic=float(fit.bic[a]), tau_over_T=float(fit.tau_over_T[a]),
                          tau0_over_T=float(fit.tau0_over_T[a]),
                          duration_over_T_rec=float(fit.duration_over_T_rec[a]),
                          integration_error_deg=float(fit.integration_error_deg[a]),
                          stiffness_cond=float(fit.stiffness_cond[a]), bound_active=fit.bound_active[a].tolist(),
                          KJ=np.round(fit.KJ[a], 4).tolist(), W=np.round(fit.W[a], 4).tolist(),
                          q_rest_deg=np.round(np.rad2deg(fit.q_rest[a]), 2).tolist())
                  for a, s in enumerate(fit.subjects)})


def wilcoxon(rows, a, b):
    """Paired two-sided Wilcoxon test of the held-out RMSE of predictors ``rows[a]`` and ``rows[b]``
    (the same held-out motions), per subject and pooled: b − a; ``b_better_fraction`` of the motions."""
    from scipy.stats import wilcoxon as w

    ra, rb = rows[a], rows[b]
    assert np.array_equal(ra._pred.rep, rb._pred.rep) and np.array_equal(ra._pred.index, rb._pred.index)
    out = {}
    for s in _groups(ra._pred):
        sel = _select(ra._pred, s)
        x, y = ra.rmse_deg[sel], rb.rmse_deg[sel]
        ok = np.isfinite(x) & np.isfinite(y)
        if ok.sum() < 5:
            out[s] = None
            continue
        d = y[ok] - x[ok]
        out[s] = dict(n=int(ok.sum()), median_diff_deg=float(np.median(d)), p=float(w(x[ok], y[ok]).pvalue),
                      b_better_fraction=float(np.mean(d < 0)))
    return out


class _Rows:
    """One predictor's held-out rows (``rmse_deg``), with the prediction it came from."""

    def __init__(self, pred, name):
        self._pred, self.rmse_deg = pred, pred.predictors()[name].rmse_deg


def _cell(st):
    return "—" if st["median"] is None else f"{st['median']:.1f} / {st['mean']:.1f}" + (
        f" ({st['n_failed']} failed)" if st["n_failed"] else "")


def markdown(res) -> str:
    subs = res["subjects"] + ["all"]
    names = list(res["predictors"])
    lines = []
    for metric, title in (("rmse", "joint-trajectory RMSE"), ("final", "final-posture error")):
        lines += [f"Held-out (repetitions 8–10) {title} [deg], median / mean over motions:", "",
                  "| predictor | " + " | ".join(subs) + " |", "|---|" + "---:|" * len(subs)]
        for n in names:
            lines.append(f"| {n} | " + " | ".join(_cell(res["predictors"][n][s][metric]) for s in subs) + " |")
        lines.append("")
    n0 = res["predictors"][names[0]]
    lines += ["Held-out motions: " + ", ".join(f"{s} {n0[s]['rmse']['n'] + n0[s]['rmse']['n_failed']}"
                                               for s in subs), ""]
    lines += ["Fits (repetitions 1–7): parameters p, solver × steps per sample, training loss ½Σr², AIC, "
              "LM iterations (stage 1, stage 2), status, bounds that bind (cond KJ, q_rest 1–3), wall time:", "",
              "| variant | p | integration | " + " | ".join(res["subjects"]) + " | wall [s] |",
              "|---|---:|---|" + "---|" * len(res["subjects"]) + "---:|"]
    for v, f in res["fits"].items():
        cells = []
        for s in res["subjects"]:
            e = f["subjects"].get(s)
            if e is None:
                cells.append("—")
                continue
            bound = "".join(k for k, b in zip(("K", "1", "2", "3"), e["bound_active"]) if b)
            cells.append(f"{e['loss']:.4g}; {e['aic']:.0f}; {e['lm_steps'][0]},{e['lm_steps'][1]}; "
                         + e["message"].split(":")[0] + (f"; bound {bound}" if bound else ""))
        lines.append(f"| {v} | {f['n_params']} | {f['solver']} ×{f['steps_per_sample']} | " + " | ".join(cells)
                     + f" | {f['wall_s']:.0f} |")
    lines.append("")
    if res.get("wilcoxon"):
        lines += ["Paired Wilcoxon tests of held-out RMSE (median of b − a [deg], p, share of motions where "
                  "b is better):", "", "| b vs a | " + " | ".join(subs) + " |", "|---|" + "---|" * len(subs)]
        for k, w in res["wilcoxon"].items():
            lines.append(f"| {k} | " + " | ".join("—" if w.get(s) is None else
                                                  f"{w[s]['median_diff_deg']:+.2f}, p={w[s]['p']:.2g}, "
                                                  f"{w[s]['b_better_fraction']:.0%}" for s in subs) + " |")
        lines.append("")
    if res.get("verdict"):
        lines += [res["verdict"], ""]
    return "\n".join(lines)


def verdict(res) -> str:
    """Which λ0-PMP variants beat ``pinv_minjerk`` on pooled held-out RMSE (paired test, p < 0.05)."""
    wins, losses = [], []
    for k, w in res["wilcoxon"].items():
        b, a = k.split(" vs ")
        if a != "pinv_minjerk" or w.get("all") is None:
            continue
        (wins if w["all"]["median_diff_deg"] < 0 and w["all"]["p"] < 0.05 else losses).append(
            f"{b} ({w['all']['median_diff_deg']:+.2f}°, p = {w['all']['p']:.2g})")
    if wins:
        return ("**Verdict:** λ0-PMP variants that beat the pseudo-inverse minimum-jerk baseline on held-out "
                "trajectories (pooled, paired): " + "; ".join(wins) + ". The others do not: " + "; ".join(losses) + ".")
    return ("**Verdict:** no λ0-PMP variant beats the pseudo-inverse minimum-jerk baseline on held-out joint "
            "trajectories (pooled, paired; median RMSE difference and p): " + "; ".join(losses) + ".")


#: The pooled summary of the full table, shipped with fitting: the main job's report shows it.
VARIANTS_TABLE = Path(fitting.__file__).parent / "data" / "reaching_variants.json"


def variant_summary(res) -> dict:
    """Per predictor: pooled held-out RMSE and final error (median, mean), fit status counts and
    the paired tests against the pseudo-inverse baseline and the Donders-only model; ``default``
    marks the variant of ``fit_reaching``'s defaults."""
    import inspect

    sig = inspect.signature(fitting.fit_reaching).parameters
    default = "/".join(sig[k].default for k in ("model", "damping", "time_constants"))
    rows = []
    for name, pr in res["predictors"].items():
        fit = res["fits"].get(name)
        row = dict(predictor=name, default=name == default, rmse_median_deg=pr["all"]["rmse"]["median"],
                   rmse_mean_deg=pr["all"]["rmse"]["mean"],
                   final_median_deg=pr["all"]["final"]["median"], n=pr["all"]["rmse"]["n"],
                   n_failed=pr["all"]["rmse"]["n_failed"])
        if fit is not None:
            st = [e["status"] for e in fit["subjects"].values()]
            row.update(converged=f"{sum(v == 0 for v in st)}/{len(st)}",
                       solver=f"{fit['solver']} x{fit['steps_per_sample']}", fit_wall_s=round(fit["wall_s"]))
        for ref in ("pinv_minjerk", "donders_only"):
            w = res["wilcoxon"].get(f"{name} vs {ref}", {}).get("all")
            row[f"vs_{ref}"] = None if w is None else (f"{w['median_diff_deg']:+.2f} deg, p={w['p']:.2g}, "
                                                       f"{w['b_better_fraction']:.0%} better")
        rows.append(row)
    return dict(date=res["date"], machine=res["machine"], subjects=res["subjects"], verdict=res["verdict"],
                rows=rows, source="benchmarks/reaching.py --table")


def table(args):
    import pickle

    variants = tuple(VARIANT_NAMES[v] for v in args.variants) if args.variants else VARIANTS
    kw = dict(max_steps=tuple(args.max_steps)) if args.max_steps else {}
    subjects = tuple(args.subjects)
    if args.quick:
        subjects, kw = (2,), dict(reps=(1, 2), tasks=(1,), max_steps=(3, 2))
        variants = variants[:2]
    res = dict(date=time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), load_start=load(), machine=bl.machine(),
               options={k: list(v) for k, v in kw.items()}, subjects=[f"S{s:02d}" for s in subjects], fits={},
               predictors={}, wilcoxon={})
    base = None if args.quick else write_results(args.name, res).removesuffix(".json")
    rows = {}

    def save():
        order = list(res["predictors"])
        res["predictors"] = {k: res["predictors"][k]
                             for k in sorted(order, key=lambda k: (k in R.BASELINES, order.index(k)))}
        res["load_end"] = load()
        res["verdict"] = verdict(res)
        if base:
            write_results(args.name, res)
            with open(base + ".md", "w") as f:
                f.write(markdown(res) + "\n")
            if args.name == "reaching_table" and set(res["subjects"]) == {f"S{s:02d}" for s in SUBJECTS}:
                VARIANTS_TABLE.parent.mkdir(exist_ok=True)
                VARIANTS_TABLE.write_text(json.dumps(variant_summary(res), indent=1) + "\n")

    # the Donders-only model (final postures, stage 1 only): the reference of every variant
    log("fit donders_only (stage 1 only) ...")
    don, wall, comp = timed_fit(subjects, **{**kw, "max_steps": (kw.get("max_steps", (100, 100))[0], 0)})
    pred = fitting.predict_reaching(don, reps=(8, 9, 10))
    res["fits"]["donders_only"] = fit_rows(don, wall, comp)
    res["predictors"]["donders_only"] = predictor_rows(pred, "model")
    rows["donders_only"] = _Rows(pred, "model")
    for b in R.BASELINES:
        res["predictors"][b] = predictor_rows(pred, b)
        rows[b] = _Rows(pred, b)
    save()
    for model, damping, tc in variants:
        key = f"{model}/{damping}/{tc}"
        log(f"fit {key} ...")
        fit, wall, comp = timed_fit(subjects, model=model, damping=damping, time_constants=tc, **kw)
        res["fits"][key] = fit_rows(fit, wall, comp)
        log(f"  {wall:.0f} s (compile {comp:.0f} s), status {fit.status.tolist()}, lm {fit.lm_steps.tolist()}, "
            f"{fit.solver} x{fit.steps_per_sample}, integration {np.round(fit.integration_error_deg, 4).tolist()}")
        t = time.perf_counter()
        pred = fitting.predict_reaching(fit, reps=(8, 9, 10))
        res["fits"][key]["predict_s"] = time.perf_counter() - t
        if base:
            with open(base + f"_{model}_{damping}_{tc}.pkl", "wb") as f:
                pickle.dump((fit, pred), f)
        res["predictors"][key] = predictor_rows(pred, "model")
        rows[key] = _Rows(pred, "model")
        for ref in ("pinv_minjerk", "donders_only"):
            res["wilcoxon"][f"{key} vs {ref}"] = wilcoxon(rows, ref, key)
        log(f"  held-out RMSE all: {res['predictors'][key]['all']['rmse']}")
        save()
    print(markdown(res))
    return res


class _Cap(Exception):
    pass


def fit_cost(args):
    """The default fit of the bundled subjects (compile apart) against the SciPy loop on one
    subject, extrapolated from its seconds per residual call."""
    subjects, kw = SUBJECTS, (dict(max_steps=tuple(args.max_steps)) if args.max_steps else {})
    nfev = args.scipy_nfev
    if args.quick:
        subjects, kw, nfev = (2,), dict(reps=(1, 2), tasks=(1,), max_steps=(3, 2)), 2
    res = dict(date=time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), load_start=load(), machine=bl.machine(),
               options={k: list(v) for k, v in kw.items()})
    log(f"fit_reaching({list(subjects)}) {kw or 'defaults'} ...")
    fit, wall, comp = timed_fit(subjects, **kw)
    S = len(subjects)
    log(f"  {wall:.0f} s wall, {comp:.0f} s compile, status {fit.status.tolist()}, lm {fit.lm_steps.tolist()}, "
        f"{fit.solver} x{fit.steps_per_sample}")
    # a second call with the same shapes: everything compiled, the run alone
    p0 = time.perf_counter()
    fitting.fit_reaching(subjects, **kw)
    warm = time.perf_counter() - p0
    res["jax"] = dict(wall_s=wall, compile_s=comp, run_s=wall - comp, warm_s=warm, warm_s_per_subject=warm / S,
                      status=fit.status.tolist(), lm_steps=fit.lm_steps.tolist(), n_motions=fit.n_motions.tolist(),
                      loss=fit.loss.tolist(), solver=fit.solver, steps_per_sample=fit.steps_per_sample,
                      integration_error_deg=fit.integration_error_deg.tolist(), load=load(),
                      compile_method="union of jax.monitoring trace/lower/compile time spans inside the call")

    k = int(np.argmin(fit.n_motions))  # the subject with the fewest motions
    m = R._motions(fit.subjects[k], None, fit.reps, fit.tasks)
    p = len(fit.param_names)
    elbow = m.q_obs[:, -1, 3].mean()
    # that subject alone (compiled, then timed): the JAX side of the per-subject comparison
    one = subjects[k] if not args.quick else subjects[0]
    fitting.fit_reaching([one], **kw)
    p0 = time.perf_counter()
    single = fitting.fit_reaching([one], **kw)
    single_s = time.perf_counter() - p0
    res["jax"].update(single_subject=fit.subjects[k], single_subject_s=single_s,
                      single_subject_lm_steps=single.lm_steps[0].tolist())
    log(f"SciPy loop on {m.subject} ({len(m)} motions, p = {p}), capped at {nfev} residual calls ...")
    calls, costs = [], []

    def fun(theta):
        if len(calls) >= nfev:
            raise _Cap
        t = time.perf_counter()
        r = residual_np(theta, m.q_obs, m.t_ratio, elbow)
        calls.append(time.perf_counter() - t)
        costs.append(0.5 * float(r @ r))
        return r

    try:  # the start and the first Jacobian columns: seconds per residual call
        scipy.optimize.least_squares(fun, fit.params[k], method="lm", xtol=1e-8, ftol=1e-8)
    except _Cap:
        pass
    per_eval = float(np.median(calls))
    it = int(single.lm_steps[0][1])
    extrap = per_eval * (p + 1) * max(it, 1)
    # the same computation: NumPy's cost at the JAX optimum against the JAX fit's data cost
    per = (R.SAMPLES - 1) * 4 + 4
    pred_rows = R._fit_motions([m], R._Config(fit.model, fit.damping, fit.time_constants, 5,
                                              cond_max=fit.stiffness_cond_max),
                               theta0=fit.params[k][None], max_steps=(1, 0), steps=fit.steps_per_sample,
                               solver=fit.solver)["residual"][0][: len(m) * per]
    jax_cost = 0.5 * float(pred_rows @ pred_rows)
    res["scipy"] = dict(subject=m.subject, n_motions=len(m), p=p, residual_calls=len(calls),
                        seconds_per_residual=per_eval, numpy_cost_at_jax_optimum=costs[0],
                        jax_data_cost_at_jax_optimum=jax_cost, jax_lm_iterations=it, extrapolated_seconds=extrap,
                        load=load(), integrator="solve_ivp LSODA rtol 1e-6 atol 1e-9",
                        optimiser="least_squares lm, 2-point Jacobian")
    res["ratios"] = {f"{m.subject}: SciPy loop / fit_reaching (run)": extrap / single_s,
                     "4 subjects: SciPy loop (extrapolated per subject) / fit_reaching per subject (run)":
                         extrap / (warm / S),
                     "4 subjects, compile included": extrap / (wall / S)}
    res["targets"] = {f"{m.subject}: SciPy loop / fit_reaching (run)": 50.0}
    res["load_end"] = load()
    print(f"\n| | compile [s] | run [s] | per subject [s] | load |\n|---|---:|---:|---:|---:|\n"
          f"| fit_reaching, {S} subjects ({fit.solver} ×{fit.steps_per_sample}) | {comp:.0f} | {warm:.0f} | "
          f"{warm / S:.1f} | {res['jax']['load']:.1f} |\n"
          f"| fit_reaching, {m.subject} alone ({it} stage-2 iterations) | — | {single_s:.1f} | {single_s:.1f} | |\n"
          f"| SciPy loop, {m.subject} (extrapolated: {per_eval:.1f} s × {p + 1} × {it} iterations) | — | — | "
          f"{extrap:.0f} | {res['scipy']['load']:.1f} |\n")
    print(f"NumPy cost at the JAX optimum {costs[0]:.6g}, JAX {jax_cost:.6g}")
    for name, v in res["ratios"].items():
        print(f"{name}: {v:.0f}x")
    if not args.quick:
        print(f"results -> {write_results('reaching', res)}")
    return res


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--table", action="store_true", help="the held-out table of every variant")
    ap.add_argument("--subjects", type=int, nargs="+", default=SUBJECTS, help="with --table: HuG-MP subjects")
    ap.add_argument("--name", default="reaching_table", help="with --table: results file name")
    ap.add_argument("--variants", nargs="+", choices=sorted(VARIANT_NAMES), help="with --table: these variants")
    ap.add_argument("--max-steps", type=int, nargs=2, default=None, help="LM iterations (default: fit_reaching's)")
    ap.add_argument("--scipy-nfev", type=int, default=3, help="residual calls of the capped SciPy fit")
    args = ap.parse_args()
    if args.table:
        table(args)
    else:
        fit_cost(args)


if __name__ == "__main__":
    main()
