"""``fit_movements``: the λ0-PMP of each subject, fitted through the trajectories of its reaches,
on any chain, from continuous joint-angle recordings.

**Fit** (per subject; all subjects in one compiled call, one after the other inside it by
``lax.map``). Stage 1 fits ``KJ`` and ``q_rest`` to the final postures through
``pmpjax.equilibrium_posture`` (Donders' law), from ``KJ = I`` and ``q_rest`` = the mean final
posture (a reach whose equilibrium does not exist there is left out and named in ``skipped``).
**Identifiability:** at the optimum the residual Jacobian of the trajectories (data
rows) is decomposed; its right singular vectors with singular values below
``IDENTIFIABILITY_RCOND`` of the largest are directions the data cannot determine (on the HuG-MP
arm: shifting ``q_rest`` along ``KJ⁻¹ e_elbow``, which no movement and no final posture sees).
Stage 2 does not move along them (the residual's gradient there is zero, so Levenberg–Marquardt's
steps have no component there to first order, and the rest-angle bounds hold them within a quarter
turn of the recorded range): their values are a gauge, not an estimate, reported by parameter name (``unidentified``,
``unidentified_directions``). (Projecting stage 2 onto the identified directions of the stage-1
optimum was measured to bias τ by 13–30 % on the shoulder–elbow arm: the directions turn with
``KJ``.) Stage 2 fits every parameter, and each reach's delay and target offsets (nuisance
parameters with weak priors, ``fitting._movements.model``; profiled out of the identifiability
analysis), to the joint trajectories through ``pmpjax.simulate`` (RODAS4 from one step per sample
interval; for the time-base generator RK4 from the fewest steps stable at the start,
``_rk4_start_steps``, and on continuous recordings a start at ``KJ = I`` with the recorded move
timing, ``_minjerk_start``; forward-mode derivatives, the nuisance columns ``k`` JVPs for all
reaches together; with RODAS4 Levenberg–Marquardt steps from approximate Jacobians, the field
Jacobian held fixed along the tangents at about 0.6 times the cost, until near the optimum, then
from exact ones, which alone judge convergence and give the standard errors: on HuG-MP's S01 the
optimum lies within 0.001 standard errors of exact steps throughout, the fit 1.22× faster,
``benchmarks/reaching.py``); the integration error at the optimum (against twice the steps) is checked and
the step count doubled while it exceeds ``INTEGRATION_TOL_DEG`` (or, at the first count, is not
finite). That check, not ``simulate``'s status, judges the fit's simulations: ``simulate``'s
embedded estimate bounds the error of RODAS4's third-order companion, and at one step per sample
it often exceeds ``simulate``'s default tolerance (``INACCURATE``) where the reported
fourth-order solution is within 0.002° of twice the steps; predictions double the steps of such
reaches (``predict_movements``). Converged means Levenberg–Marquardt met a tolerance (relative
cost change 1e-8, or every parameter within 0.014 Gauss–Newton standard errors of the optimum).

**Standard errors** by the delete-one-reach jackknife (one Gauss–Newton step from the optimum per
deleted reach, each reach's nuisance parameters profiled out): errors shared by the samples of a
reach (the noise of its start posture and of its target, misfit) make the Gauss–Newton errors
``σ² (JᵀJ)⁻¹``, which take the samples as independent, too small. Monte Carlo, 48 noise
replicates of one subject (3-joint planar arm, 16 reaches, 0.2° noise, SciPy Radau recordings,
``benchmarks/movements_calibration.py``): the jackknife errors are 0.92–1.23 times the spread of
the estimates and their 95 % intervals cover 92–98 %; the Gauss–Newton ones, measured the same
way, were 0.31–0.53 times it (the delay's 0.88). Computed on the host from the Jacobian at the
optimum (milliseconds per subject).
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

import pmpjax as pj
from pmpjax import Status, status_message
from pmpjax.internal import fast_compile_jit

from .._optimise import group_jackknife_covariance, least_squares, lm_iterations, spd_size
from . import model as mdl
from .data import (
    SAMPLES,
    SubjectReaches,
    check_find_options,
    check_recordings,
    group_by_subject,
    segmented_reaches,
    skipped_summary,
    subject_reaches,
)
from .data import hand_positions as _fk

#: Singular values below this fraction of the largest mark unidentified directions.
IDENTIFIABILITY_RCOND = 1e-6
#: Largest integration error at the optimum a fit accepts [deg] (steps are doubled above it).
INTEGRATION_TOL_DEG = 0.01
#: RODAS4's first step count per sample interval (doubled while the integration error at the
#: optimum exceeds ``INTEGRATION_TOL_DEG``): one step is 0.0003–0.002° from twice the steps at the
#: optima of the four HuG-MP subjects, and each doubling doubles a fit's cost.
STEPS_PER_SAMPLE = 1
MAX_STEPS_PER_SAMPLE = 32
#: A Donders-fitted model (no stage 2, so no integration check at the optimum) keeps two steps per
#: sample for its identifiability (from one, 6 of S01's 73 held-out motions needed 16 for
#: simulate's estimate; predictions choose their own steps).
DONDERS_STEPS_PER_SAMPLE = 2
#: RK4 (the time-base generator) starts from at least this many steps, and may start at more
#: steps than the refinement's RODAS4.
RK4_STEPS_PER_SAMPLE = 2
MAX_RK4_STEPS_PER_SAMPLE = 160


@dataclasses.dataclass(frozen=True)
class MovementFit:
    """One row per subject (S subjects, ``n`` joints, ``p`` parameters).

    ``subjects`` (S,); ``KJ`` (S, n, n) [Nm/rad], trace n; ``q_rest`` (S, n) [rad]; ``W`` (S, n, n)
    damping per unit τ0 (trace n; the damping of a reach is ``τ0 W``); ``tau``, ``tau0`` (S,) [s]
    (``time_constants="seconds"``) or fractions of each reach's duration (``"fractions"``; ``tau``
    NaN for the time-base generator, whose duration fraction is ``duration``; 0.2 when
    ``"tied"``); ``delay`` (S,) how long before a reach's window the target appeared (Arimoto)
    or the generator's move began (negative: after; same unit; unseen reaches are predicted with
    it; NaN for segmented recordings) and ``reach_delays``
    {subject: (B,)} each fitted reach's own (``delay`` plus
    its fitted offset, in the order of ``reaches[subject]``); ``reach_target_offsets`` {subject:
    (B, m)} each fitted reach's target minus the hand at the end of its window (the chain's task
    units; where the model says the reach was aimed); ``converged``,
    ``status`` (S,) (``pmpjax.Status``; ``messages``; ``INACCURATE`` when the fit met its tolerance but
    the integration error at the optimum stays above ``INTEGRATION_TOL_DEG``); ``params``, ``stderr`` (S, p), ``cov``
    (S, p, p) with ``param_names`` (the delete-one-reach jackknife, module docstring; zero variance
    along unidentified directions); ``unidentified``
    (S,) tuples of the parameter names that load on each unidentified direction at the optimum, and
    ``unidentified_directions`` (S, p, p) the unit directions as rows (zero rows for the others);
    ``singular_values`` (S, p) of the trajectory Jacobian (data rows) at the optimum; ``loss`` (S,)
    ½ Σ r²; ``rmse_deg`` (S,) training joint RMSE; ``aic``, ``bic`` (S,); ``n_reaches``,
    ``n_residuals`` (S,); ``lm_steps`` (S, 2); ``solver``, ``steps_per_sample`` (the largest used: a subject is fitted
    again at twice the steps while its integration error at the optimum exceeds the tolerance),
    ``integration_error_deg`` (S,) (largest joint difference against twice the steps);
    ``bound_active`` (S, 1 + n) (cond(KJ), each rest angle); ``reaches`` {subject:
    SubjectReaches} the windows fitted; ``skipped`` {subject: [(recording, t_from, t_to, reason)]};
    ``chain`` the chain; ``joint_names``; ``model``, ``damping``, ``time_constants``, ``segmented``,
    ``rest_margin_deg``: the options that made it.
    """

    subjects: tuple[str, ...]
    KJ: np.ndarray
    q_rest: np.ndarray
    W: np.ndarray
    tau: np.ndarray
    tau0: np.ndarray
    duration: np.ndarray
    delay: np.ndarray
    reach_delays: dict
    reach_target_offsets: dict
    converged: np.ndarray
    status: np.ndarray
    params: np.ndarray
    stderr: np.ndarray
    cov: np.ndarray
    param_names: tuple[str, ...]
    unidentified: tuple
    unidentified_directions: np.ndarray
    singular_values: np.ndarray
    loss: np.ndarray
    rmse_deg: np.ndarray
    aic: np.ndarray
    bic: np.ndarray
    n_reaches: np.ndarray
    n_residuals: np.ndarray
    lm_steps: np.ndarray
    solver: str
    steps_per_sample: int
    integration_error_deg: np.ndarray
    bound_active: np.ndarray
    reaches: dict
    skipped: dict
    chain: object
    joint_names: tuple[str, ...]
    model: str
    damping: str
    time_constants: str
    segmented: bool = False
    rest_margin_deg: float = mdl.REST_MARGIN_DEG

    @property
    def messages(self) -> list[str]:
        return [status_message(s) for s in self.status]

    def subject_index(self, subject) -> int:
        """The row of a subject.

        **Arguments:**

        - ``subject``: a subject name.

        **Returns:**

        Its index (int).

        **Raises:**

        - ``ValueError`` for a subject that is not in the fit.
        """
        return self.subjects.index(str(subject))

    def parameter_rows(self) -> list[dict]:
        """One row per subject and parameter: ``subject``, ``parameter``, ``value``, ``stderr`` (of
        the fitted parameter, in ``param_names``' units), ``identified`` (False: the parameter loads on
        an unidentified direction, its value a gauge).

        **Returns:**

        A list of dicts (the rows of ``movement_parameters.csv``).
        """
        rows = []
        for a, s in enumerate(self.subjects):
            gauge = {name for direction in self.unidentified[a] for name in direction}
            rows += [{"subject": s, "parameter": name, "value": float(self.params[a, i]),
                      "stderr": float(self.stderr[a, i]), "identified": name not in gauge}
                     for i, name in enumerate(self.param_names)]
        return rows

    def summary(self) -> list[dict]:
        """One row per subject: status, time constants, training error, integration error, AIC/BIC.

        **Returns:**

        A list of dicts (the rows of ``movement_fit.csv``).
        """
        unit = "s" if self.time_constants == "seconds" else "T"
        rows = []
        for a, s in enumerate(self.subjects):
            rows.append({
                "subject": s, "status": status_message(int(self.status[a])), "converged": bool(self.converged[a]),
                "reaches": int(self.n_reaches[a]), f"tau0 [{unit}]": float(self.tau0[a]),
                f"tau [{unit}]": float(self.tau[a]), f"delay [{unit}]": float(self.delay[a]),
                "train_rmse [deg]": float(self.rmse_deg[a]),
                "integration_error [deg]": float(self.integration_error_deg[a]),
                "cond KJ": float(np.linalg.cond(self.KJ[a])) if np.all(np.isfinite(self.KJ[a])) else math.nan,
                "aic": float(self.aic[a]), "bic": float(self.bic[a]),
                "lm_steps": int(self.lm_steps[a].sum()),
                "unidentified": "; ".join(" + ".join(d) for d in self.unidentified[a]),
            })
        return rows


def _stack(subjects: list[SubjectReaches], chain, bucket: int = 8, margin_deg: float = mdl.REST_MARGIN_DEG) -> dict:
    """Pad subjects' reaches to a common count (a multiple of ``bucket``; padding = copies of the
    first reach with weight 0); ``lo``, ``hi`` the rest-angle bounds (the recorded range widened
    by ``margin_deg``)."""
    B = max(len(s) for s in subjects)
    B = -(-B // bucket) * bucket
    out = {k: [] for k in ("q_obs", "q_start", "q_end", "duration", "t_ratio", "weight", "target", "lo", "hi")}
    margin = np.deg2rad(margin_deg)
    for s in subjects:
        pad = B - len(s)
        idx = np.concatenate([np.arange(len(s)), np.zeros(pad, int)])
        out["q_obs"].append(s.q_obs[idx])
        out["q_start"].append(s.q_start[idx])
        out["q_end"].append(s.q_end[idx])
        out["duration"].append(s.duration[idx])
        out["t_ratio"].append(s.t_ratio[idx])
        out["weight"].append(np.concatenate([np.ones(len(s)), np.zeros(pad)]))
        out["lo"].append(s.q_obs.min((0, 1)) - margin)
        out["hi"].append(s.q_obs.max((0, 1)) + margin)
    data = {k: np.stack(v) for k, v in out.items() if v and k != "target"}
    data["target"] = np.asarray(_fk(chain, data["q_end"]))
    data["amplitude"] = np.maximum(np.linalg.norm(data["target"] - np.asarray(_fk(chain, data["q_start"])), axis=-1),
                                   1e-9)
    return data


def _held(fun, theta, free):
    """``fun`` of the parameters with those where ``free`` (same length, traced) is 0 held at
    ``theta``'s values: ``(f, z0, embed)``. Held parameters get exactly zero Jacobian columns, which
    Levenberg–Marquardt leaves where they are (``fitting.least_squares`` counts only the columns
    that move the residual); a mask, not a static index, so that fits that differ only in what they
    hold (``fit_reaching`` and its generic case) share one compilation."""
    keep = free > 0
    embed = lambda z: jnp.where(keep, z, theta)  # noqa: E731
    return (lambda z, d: fun(embed(z), d)), theta, embed


@partial(fast_compile_jit, static_argnames=("cfg",))
def _start_rates(theta, data, chain, *, cfg):
    """The fastest rate (S, B) [1 / normalised time] of each reach at its start posture
    (``model.rk4_rates``) under the subjects' parameters ``theta`` (S, p); 0 for padding."""

    def one(th, dat):
        p = mdl.unpack(th, cfg)
        _, tau0, W = mdl.reach_damping(p, dat["duration"], cfg, dat["t_ratio"])
        rates = mdl.rk4_rates(chain, p["KJ"], W, tau0, dat["q_start"], minjerk=cfg.model != "lambda0")
        return jnp.where(dat["weight"] > 0, rates, 0.0)

    return jax.vmap(one)(theta, data)


#: A minimum-jerk speed profile is at 20 % of its peak at these phases of its duration.
_MINJERK_20 = ((1.0 - math.sqrt(1.0 - 4.0 * math.sqrt(0.2 / 16.0))) / 2.0,
               (1.0 + math.sqrt(1.0 - 4.0 * math.sqrt(0.2 / 16.0))) / 2.0)


def _minjerk_start(theta, data, chain, cfg):
    """The time-base generator's stage-2 start (continuous recordings) from stage 1's (S, p):
    ``KJ = I`` with stage 1's ``q_rest``, and the duration and delay from the recorded hand speeds
    (per reach, the times where the speed first and last reaches 20 % of its peak are a
    minimum-jerk move's phases ``_MINJERK_20``; the subject's medians).

    Why not stage 1's ``KJ``: the generator puts the hand on its target at the end of its move, and
    the null space then relaxes at ``1/τ0``, so final postures recorded before that ends pull the
    Donders fit off; from there (and from the whole window without delay) Levenberg–Marquardt was
    drawn to a quasi-static local optimum (τ0 → 7 ms, ten times the cost) on the 3-joint planar
    reference, and from ``KJ = I`` it reached the optimum in 49 iterations."""
    theta = np.array(theta, float)
    k, n = spd_size(cfg.n), cfg.n
    x = np.asarray(_fk(chain, data["q_obs"]))  # (S, B, SAMPLES, m)
    frac = np.linspace(0.0, 1.0, SAMPLES)
    speed = np.linalg.norm(np.diff(x, axis=2), axis=-1)  # per sample interval (mid-interval times)
    mid = 0.5 * (frac[1:] + frac[:-1])
    above = speed >= 0.2 * speed.max(axis=2, keepdims=True)
    first = mid[np.argmax(above, axis=2)]
    last = mid[above.shape[2] - 1 - np.argmax(above[..., ::-1], axis=2)]
    d = (last - first) / (_MINJERK_20[1] - _MINJERK_20[0])  # (S, B) fractions of the window
    begin = first - _MINJERK_20[0] * d
    used = data["weight"] > 0
    t0 = mdl.n_params(cfg) - mdl.n_timing(cfg)
    for i in range(theta.shape[0]):
        if not (np.any(used[i]) and np.all(np.isfinite(theta[i]))):
            continue
        th1 = np.concatenate([np.zeros(k), theta[i, k:k + n]])
        theta[i] = np.asarray(mdl.stage2_start(jnp.asarray(th1), cfg))
        win = data["duration"][i][used[i]] if cfg.time_constants == "seconds" else 1.0
        if cfg.time_constants != "tied":
            theta[i, t0] = math.log(max(float(np.median(d[i][used[i]] * win)), 1e-3))
        theta[i, t0 + mdl.n_timing(cfg) - 1] = -float(np.median(begin[i][used[i]] * win))
    return theta


def _rk4_start_steps(theta, data, chain, cfg, minimum: int) -> int:
    """RK4 steps per sample interval stable at the start of every reach of every subject under
    ``theta`` (S, ≥p) (``model.stable_rk4_steps``, at least ``minimum``)."""
    theta = np.asarray(theta, float)[:, : mdl.n_params(cfg)]
    ok = np.all(np.isfinite(theta), axis=1)
    if not np.any(ok):
        return int(minimum)
    rates = np.asarray(_start_rates(theta[ok], {k: v[ok] for k, v in data.items()}, chain, cfg=cfg))
    return mdl.stable_rk4_steps(rates, minimum, MAX_RK4_STEPS_PER_SAMPLE)


@partial(fast_compile_jit, static_argnames=("cfg",))
def _stage1(theta0, data, chain, max_steps, *, cfg):
    """Stage 1 for all subjects (``theta0`` (S, postural)): ``KJ``, ``q_rest`` from the final
    postures. A reach whose equilibrium does not exist at the start would make the start
    non-finite and stop Levenberg–Marquardt for the whole subject: it is left out (``weight`` 0)."""

    def one(th0, dat):
        res = lambda th, d: mdl.final_residual(th, d, chain, cfg)  # noqa: E731
        B = dat["weight"].shape[0]
        ok = jnp.all(jnp.isfinite(res(th0, dat)[: B * cfg.n].reshape(B, cfg.n)), axis=-1)
        dat = dict(dat, weight=jnp.where(ok, dat["weight"], 0.0))
        f, z0, embed = _held(res, th0, dat["free"][: th0.shape[0]])
        r = least_squares(f, z0, dat, max_steps=max_steps, ftol=cfg.ftol, xtol=cfg.xtol, stol=cfg.stol)
        x = embed(r.x)
        return dict(x=x, converged=r.converged, status=r.status, steps=r.steps, cost=r.cost,
                    residual=r.residual, jac=r.jac, weight=dat["weight"], start=mdl.stage2_start(x, cfg))

    return jax.lax.map(lambda a: one(*a), (theta0, data))


def _unidentified(J, cfg, rows: int, B: int):
    """Singular values (p,) of the trajectory residual's Jacobian ``J`` on its data rows (the first
    ``B·rows``; the bounds' penalties and the offsets' prior would make any direction "identified")
    and the unidentified directions (p, p) of the subject's ``p`` parameters as rows (zero rows for
    the identified ones). The per-reach delay offsets are profiled out first: each reach's rows are
    projected off its own offset column (a direction a reach's timing explains is not identified
    by it); the subject's delay (the last parameter) is kept whole, identified as the offsets'
    common part. Held parameters have zero columns (and come out as unidentified)."""
    p, k = mdl.n_params(cfg), mdl.n_nuisance(cfg)
    Jd = J[: B * rows]
    Jd = jnp.where(jnp.isfinite(Jd), Jd, 0.0)
    G = Jd[:, :p].reshape(B, rows, p)
    if J.shape[1] > p:
        # each reach's own nuisance columns (B, rows, k), projected off its rows by least squares
        C = Jd[:, p:].reshape(B, rows, B, k)[jnp.arange(B), :, jnp.arange(B)]
        coef = jax.vmap(lambda c, g: jnp.linalg.lstsq(c, g, rcond=1e-10)[0])(C, G)  # (B, k, p)
        if mdl.reach_delays(cfg):
            # (not the subject's delay, the offsets' common part: identified as their mean by the prior)
            coef = coef.at[:, :, p - 1].set(0.0)
        G = G - jnp.einsum("brk,bkp->brp", C, coef)
    _, s, Vt = jnp.linalg.svd(G.reshape(B * rows, p), full_matrices=False)
    keep = s > IDENTIFIABILITY_RCOND * s[0]
    return s, jnp.where(keep[:, None], 0.0, Vt)


def _reach_jackknife_covariance(jac, residual, cfg, weight) -> np.ndarray:
    """The delete-one-reach jackknife covariance (p, p) of a subject's fitted parameters (module
    docstring; held ones have no column): the rows of the reaches with ``weight`` (B,) > 0 (their
    samples and their nuisance priors) grouped by reach, each reach's own nuisance columns profiled
    out; padding and left-out reaches in no group."""
    k, n = mdl.n_nuisance(cfg), cfg.n
    used = np.asarray(weight) > 0
    reach = np.where(used, np.arange(used.shape[0]), -1)
    groups = np.concatenate([np.repeat(reach, SAMPLES * n), np.full(1 + n, -1), np.repeat(reach, k)])
    groups = groups[: np.asarray(jac).shape[0]]
    nuisance = np.repeat(reach, k) if k else None
    return group_jackknife_covariance(jac, residual, groups, mdl.n_params(cfg) - len(cfg.hold),
                                      nuisance_groups=nuisance, rcond=IDENTIFIABILITY_RCOND**2)


def _rows(dat, cfg) -> int:
    return dat["q_obs"].shape[1] * cfg.n


def _integration_error_one(th, dat, chain, cfg, steps, solver):
    """Largest joint difference [rad] of the used reaches between ``steps`` and ``2·steps``."""
    t, offsets, shift = mdl.split(th, cfg)
    p = mdl.unpack(t, cfg)
    model, planner = mdl.model_and_planner(chain, p, dat["duration"], cfg, offsets, dat["t_ratio"])
    q0, tg = dat["q_start"], dat["target"] if shift is None else dat["target"] + shift
    a = mdl.simulate(chain, model, planner, q0, tg, steps, solver).q
    b = mdl.simulate(chain, model, planner, q0, tg, 2 * steps, solver).q
    return jnp.max(jnp.where((dat["weight"] > 0)[:, None, None], jnp.abs(a - b), 0.0))


@partial(fast_compile_jit, static_argnames=("cfg", "steps", "solver"))
def _identifiability(theta, data, chain, *, cfg, steps, solver):
    """Singular values (S, p) and unidentified directions (S, p, p) at ``theta`` (S, p) (a
    Donders-fitted model: stage 2 reports them itself)."""

    def one(th, dat):
        f, z, _ = _held(lambda t, d: mdl.trajectory_residual(t, d, chain, cfg, steps, solver), th, dat["free"])
        J = jax.jacfwd(lambda t: f(t, dat))(z)
        return _unidentified(J, cfg, _rows(dat, cfg), dat["weight"].shape[0])

    return jax.lax.map(lambda a: one(*a), (theta, data))


@partial(fast_compile_jit, static_argnames=("cfg", "steps", "solver", "approximate"))
def _stage2(theta0, data, chain, max_steps, *, cfg, steps, solver, approximate: bool = True):
    def one(th0, dat):
        res = lambda th, d: mdl.trajectory_residual(th, d, chain, cfg, steps, solver)  # noqa: E731
        lin = lambda th, d: mdl.trajectory_linearise(th, d, chain, cfg, steps, solver)  # noqa: E731
        free = jnp.concatenate([dat["free"], jnp.ones(th0.shape[0] - dat["free"].shape[0], th0.dtype)])
        f, z0, embed = _held(res, th0, free)

        def lin_held(z, d):
            r, J = lin(embed(z), d)
            return r, J * (free > 0)[None, :]

        r = least_squares(f, z0, dat, max_steps=max_steps, ftol=cfg.ftol, xtol=cfg.xtol, stol=cfg.stol,
                          linearise=lin_held if mdl.n_nuisance(cfg) else None,
                          approximate=approximate and solver == "rodas4")
        sv, V0 = _unidentified(r.jac, cfg, _rows(dat, cfg), dat["weight"].shape[0])
        x = embed(r.x)
        err = _integration_error_one(x, dat, chain, cfg, steps, solver)
        return dict(x=x, cost=r.cost, residual=r.residual, converged=r.converged, status=r.status,
                    steps=r.steps, jac=r.jac, singular_values=sv, V0=V0, integration_error=err)

    return jax.lax.map(lambda a: one(*a), (theta0, data))


def _check_choice(name, value, options):
    if value not in options:
        raise ValueError(f"`{name}` must be one of {', '.join(map(repr, options))}; got {value!r}")


def _check_chain(chain):
    if not isinstance(chain, pj.Chain):
        raise TypeError(f"`chain` must be a pmpjax chain (MjcfChain, ShoulderElbowArm, PlanarArm, Wrist, "
                        f"FunctionChain), got {type(chain).__name__}")
    return chain


def fit_movements(
    chain,
    recordings,
    *,
    model: str = "lambda0",
    damping: str = "tau0_KJ",
    time_constants: str = "seconds",
    max_steps=(100, 100),
    stiffness_cond_max: float | None = mdl.STIFFNESS_COND_MAX,
    find_options: dict | None = None,
    segmented: bool = False,
    rest_margin_deg: float = mdl.REST_MARGIN_DEG,
) -> MovementFit:
    """Fit the λ0-PMP per subject to the reaches inside continuous joint-angle recordings.

    **Arguments:**
    - ``chain``: the arm (``pmpjax.MjcfChain``, ``ShoulderElbowArm``, ``PlanarArm``, ``Wrist``,
      ``FunctionChain``; n joints).
    - ``recordings``: :class:`pmpjax.JointRecording` objects (``pmpjax.read_joint_angles``) with the
      chain's joints, grouped by their ``subject``; reaches are found by
      :func:`pmpjax.find_movements` (``find_options`` passed on), cut-short ones left out.
    - ``segmented``: each recording is one motion, idle time removed (HuG-MP's ``.mat`` motions:
      ``fitting.fit_reaching`` is this case): the whole recording is the window, its first and last
      samples the start and final postures, no target-onset delay and no per-reach offsets;
      fractions are of the movement duration between the 20 %-of-peak-speed onset and offset
      (``find_options``: ``onset``, ``smoothing``; ``fitting._movements.data``).
    - ``model``: "lambda0" (Arimoto, Eq 8 with Eq 10's gain) or "lambda0_minjerk" (time-base
      generator); ``damping``: "tau0_KJ" (Eq 7), "diagonal" or "full"; ``time_constants``:
      "seconds" (one τ, τ0 per subject; the default), "fractions" (of each reach's duration) or
      "tied" (``τ = τ0 = T/5``, not fitted; the paper's heuristic).
      Measured on the shipped example (two subjects, trial 1 fitted, trial 2's 12 reaches held
      out; reaches of 1.0–1.4 s): seconds 0.22° and 0.23° held-out median RMSE, fractions 0.61°
      and 0.64°, AIC lower by 670 and 210 for seconds. Those recordings were made with time constants in seconds;
      with reaches of one duration the two coincide (the planar test fits fractions).
    - ``max_steps``: Levenberg–Marquardt iterations of stage 1 (final postures) and stage 2
      (trajectories; 0: a Donders-fitted model).
    - ``stiffness_cond_max``: bound on cond(KJ) (None: none); ``rest_margin_deg``: the rest angles
      stay within each joint's recorded range widened by this [deg] (default a quarter turn).

    **Returns:** a :class:`MovementFit`. **Raises:** ``TypeError``/``ValueError`` naming the
    argument for bad options and recordings whose joints do not match the chain; ``ValueError``
    when no subject has a usable reach. A subject without usable reaches gets ``TOO_FEW_DATA``.

    **Cost:** one compilation of each stage per chain and option set, then a few seconds per
    subject; on 2 cores (under other load) a 4-joint closed-form arm with 30 reaches took about
    1.5 min in all, the 5-joint MJCF example (MJX kinematics) with 6 reaches per subject about 5 min.
    """
    chain = _check_chain(chain)
    recordings = check_recordings(recordings, chain)
    _check_choice("model", model, mdl.MODELS)
    _check_choice("damping", damping, mdl.DAMPINGS)
    _check_choice("time_constants", time_constants, mdl.TIME_CONSTANTS)
    ms = lm_iterations(max_steps)
    cond_max = math.inf if stiffness_cond_max is None else float(stiffness_cond_max)
    if not cond_max > 1.0:
        raise ValueError(f"`stiffness_cond_max` must be > 1 (or None), got {stiffness_cond_max!r}")
    if not isinstance(segmented, bool | np.bool_):
        raise TypeError(f"`segmented` must be True or False, got {segmented!r}")
    margin = float(rest_margin_deg)
    if not (math.isfinite(margin) and margin >= 0.0):
        raise ValueError(f"`rest_margin_deg` must be a finite number >= 0, got {rest_margin_deg!r}")
    cfg = mdl.Config(chain.n, model, damping, time_constants, m=0 if segmented else chain.m,
                     cond_max=cond_max, delay=not segmented)
    joints = tuple(recordings[0].joint_names)
    by_subject = group_by_subject(recordings)
    reaches = segmented_reaches if segmented else subject_reaches
    options = check_find_options(find_options, bool(segmented))
    found = {s: reaches(s, recs, chain, options) for s, recs in by_subject.items()}
    usable = {s: r for s, r in found.items() if len(r) > 0}
    if not usable:
        raise ValueError("no subject has a usable reach: " + "; ".join(
            f"{s}: {skipped_summary(r.skipped)}" for s, r in found.items()))
    empty = [s for s in found if s not in usable]
    if empty:
        warnings.warn(f"fit_movements: no usable reach for {', '.join(empty)} (TOO_FEW_DATA)", stacklevel=2)
    out = _fit(chain, list(usable.values()), cfg, ms, margin)
    return _assemble(chain, found, usable, out, cfg, joints, margin, bool(segmented))


def _fit(chain, subjects: list[SubjectReaches], cfg: mdl.Config, ms, margin_deg: float = mdl.REST_MARGIN_DEG, *,
         theta0=None, steps: int | None = None, solver: str | None = None, identify: bool = True,
         name: str = "fit_movements", stage1: dict | None = None, first_steps: int | None = None,
         approximate: bool = True) -> dict:
    """Fit every subject (stage 1, then stage 2 with the step refinement of the module docstring).

    ``theta0`` (S, p): skip stage 1 and start stage 2 there (``ms[1] = 0``: the residual and
    Jacobian at ``theta0``); ``steps``/``solver``: fixed instead of RODAS4 refined from
    ``STEPS_PER_SAMPLE``; ``identify``: the identifiability analysis of a Donders-fitted model
    (``ms[1] = 0``); ``name`` in warnings; ``stage1``: the ``"stage1"`` of an earlier call, whose
    stage 2 this one runs; ``first_steps``: the step count the refinement starts from;
    ``approximate``: RODAS4's stage 2 steps from approximate Jacobians until near the optimum
    (``fitting.least_squares(approximate=True)``; False: exact ones throughout, for comparison).
    Returns a dict of NumPy arrays (the fitted parameters
    are the full ``p``, held ones included; ``jac`` has the fitted ones' columns)."""
    data = _stack(subjects, chain, margin_deg=margin_deg)
    data["log_cond_max"] = np.full(len(subjects), math.log(cfg.cond_max))
    P = mdl.n_params(cfg)
    free_cols = np.array(mdl.free_index(cfg, P))
    data["free"] = np.zeros((len(subjects), P))
    data["free"][:, free_cols] = 1.0
    jcfg = mdl.compiled(cfg)  # (the bound and the held parameters travel in data)
    S = len(subjects)
    k = spd_size(cfg.n)
    fixed_steps = steps is not None
    # The time-base generator's gain rises to its cap as the move ends: Rosenbrock steps lose their
    # order there (RODAS4 1.7° off at 32 steps per sample on HuG-MP's S01), RK4 does not. It runs
    # RK4 from the fewest steps stable at the start parameters (``_rk4_start_steps``).
    # (at steps given, RK4 at those; else from the stable count, where trajectories are simulated)
    rk4 = solver is None and cfg.model == "lambda0_minjerk" and (fixed_steps or ms[1] > 0 or identify)
    auto_rk4 = rk4 and not fixed_steps
    solver, steps = solver or ("rk4" if rk4 else "rodas4"), int(
        steps or first_steps or (RK4_STEPS_PER_SAMPLE if rk4 else STEPS_PER_SAMPLE))
    B = data["weight"].shape[1]
    out = dict(stage1=None, solver=solver, B=B)
    used0 = data["weight"] > 0
    if stage1 is not None:
        out["stage1"] = stage1
        data["weight"] = stage1["weight"]
        theta0 = stage1["start"]
    elif theta0 is None:
        th1 = np.concatenate([np.zeros((S, k)), np.stack([s.q_end.mean(0) for s in subjects])], -1)
        s1 = {key: np.asarray(v) for key, v in jax.device_get(
            _stage1(th1, data, chain, np.int32(ms[0]), cfg=jcfg)).items()}
        s1["jac"] = s1["jac"][..., free_cols[free_cols < k + cfg.n]]  # (the fitted ones' columns)
        out["stage1"] = s1
        data["weight"] = s1["weight"]
        theta0 = s1["start"]
    else:
        theta0 = np.asarray(theta0, float)
    out["weight"] = np.asarray(data["weight"])
    if cfg.model == "lambda0_minjerk" and mdl.reach_delays(cfg) and theta0 is not None and out["stage1"] is not None:
        theta0 = _minjerk_start(theta0, data, chain, cfg)
    if auto_rk4:
        steps = _rk4_start_steps(theta0, data, chain, jcfg, steps)
    out["dropped"] = [np.flatnonzero(used0[i, : len(s)] & ~(out["weight"][i, : len(s)] > 0))
                      for i, s in enumerate(subjects)]
    lm2 = np.zeros(S, int)
    if ms[1] == 0 and out["stage1"] is not None:
        s1 = out["stage1"]
        if not fixed_steps and not rk4:
            steps = max(steps, DONDERS_STEPS_PER_SAMPLE)
        if identify:
            sv, V0 = jax.device_get(_identifiability(theta0, data, chain, cfg=jcfg, steps=steps, solver=solver))
        else:
            p = mdl.n_params(cfg) - len(cfg.hold)
            sv, V0 = np.full((S, p), np.nan), np.zeros((S, p, p))
        out.update(singular_values=sv, V0=V0)
        out.update(x=theta0, cost=s1["cost"], converged=s1["converged"], status=s1["status"],
                   jac=None, residual=None, steps=steps,
                   integration_error_deg=np.full(S, np.nan), lm2=lm2)
        return out
    if out["stage1"] is not None:  # (the Donders-fitted model above keeps the paper's T/5)
        theta0 = mdl.stage2_tau_start(theta0, cfg)
    x = np.concatenate([theta0, np.zeros((S, B * mdl.n_nuisance(cfg)))], axis=1) \
        if theta0.shape[1] == mdl.n_params(cfg) and not cfg.hold else theta0
    run = lambda x, d, st: {key: np.array(v) for key, v in jax.device_get(  # noqa: E731
        _stage2(x, d, chain, np.int32(ms[1]), cfg=jcfg, steps=st, solver=solver,
                approximate=approximate)).items()}
    s2 = run(x, data, steps)
    lm2 = lm2 + s2["steps"]
    err = np.rad2deg(s2["integration_error"])
    used = np.full(S, steps)
    # Only the subjects whose integration error at the optimum is above the tolerance are fitted
    # again, from their optimum, at twice the steps; at the first step count also those whose
    # error is not finite (simulations that failed at the start: from their start).
    redo = np.all(np.isfinite(s2["x"]), axis=-1) & ~(err <= INTEGRATION_TOL_DEG) & (ms[1] > 0) & (not fixed_steps)
    while np.any(redo) and steps < MAX_STEPS_PER_SAMPLE:
        steps *= 2
        idx = np.flatnonzero(redo)
        r = run(s2["x"][idx], {key: v[idx] for key, v in data.items()}, steps)
        for key, v in r.items():
            s2[key][idx] = v if key != "steps" else s2[key][idx] + v
        lm2[idx] += r["steps"]
        err[idx] = np.rad2deg(r["integration_error"])
        used[idx] = steps
        redo = np.zeros(S, bool)
        redo[idx] = np.all(np.isfinite(r["x"]), axis=-1) & (err[idx] > INTEGRATION_TOL_DEG)
    out.update(singular_values=s2["singular_values"], V0=s2["V0"])
    cols = np.concatenate([free_cols, np.arange(P, s2["jac"].shape[-1])])  # (the fitted ones' columns)
    out.update(x=s2["x"], cost=s2["cost"], converged=s2["converged"], status=s2["status"], jac=s2["jac"][..., cols],
               residual=s2["residual"], steps=int(used.max()), integration_error_deg=err, lm2=lm2)
    bad = err > INTEGRATION_TOL_DEG
    if np.any(bad) and ms[1] > 0:
        warnings.warn(f"{name}: the integration error at the optimum stays above {INTEGRATION_TOL_DEG}° "
                      f"({', '.join(f'{e:.3g}°' for e in err[bad])}) at {steps} steps per sample", stacklevel=3)
    return out


def _unidentified_names(V0, names, cfg) -> tuple:
    """For each unidentified direction (rows of ``V0``, zero rows skipped), the parameter names
    with loadings above a third of the largest."""
    out = []
    for v in np.asarray(V0):
        if not np.any(v):
            continue
        a = np.abs(v)
        out.append(tuple(names[i] for i in np.flatnonzero(a >= a.max() / 3)))
    return tuple(out)


def _assemble(chain, found, usable, out, cfg, joints, margin_deg=mdl.REST_MARGIN_DEG, segmented=False) -> MovementFit:
    names_all = tuple(found)
    S_all, n = len(names_all), cfg.n
    p = mdl.n_params(cfg)
    pnames = mdl.param_names(cfg, joints)
    idx = {s: i for i, s in enumerate(usable)}
    nan = lambda *shape: np.full(shape, np.nan)  # noqa: E731
    params, cov = nan(S_all, p), nan(S_all, p, p)
    KJ, W, q_rest = nan(S_all, n, n), nan(S_all, n, n), nan(S_all, n)
    tau, tau0, dur, delay = nan(S_all), nan(S_all), nan(S_all), nan(S_all)
    status = np.full(S_all, int(Status.TOO_FEW_DATA))
    loss, rmse, aic, bic, err = nan(S_all), nan(S_all), nan(S_all), nan(S_all), nan(S_all)
    n_reach, n_res = np.zeros(S_all, int), np.zeros(S_all, int)
    lm = np.zeros((S_all, 2), int)
    sv, unident, V0 = nan(S_all, p), [()] * S_all, np.zeros((S_all, p, p))
    bound = np.zeros((S_all, 1 + n), bool)
    reach_delay, target_shift, dropped = {}, {}, {}
    stage2 = out["residual"] is not None
    for a, s in enumerate(names_all):
        if s not in idx:
            continue
        i = idx[s]
        x_all = np.asarray(out["x"][i])
        x = x_all[:p]
        params[a] = x
        if out["jac"] is not None:
            cov[a] = _reach_jackknife_covariance(np.asarray(out["jac"][i]), np.asarray(out["residual"][i]), cfg,
                                                 out["weight"][i])
        k_nu = mdl.n_nuisance(cfg)
        nuis = x_all[p:].reshape(-1, k_nu)[: len(usable[s])] if x_all.size > p else np.zeros((len(usable[s]), 0))
        offsets = nuis[:, 0] if mdl.reach_delays(cfg) and nuis.shape[1] else np.zeros(0)
        target_shift[s] = nuis[:, nuis.shape[1] - cfg.m:] if nuis.shape[1] else np.zeros((len(usable[s]), 0))
        pr = jax.device_get(mdl.unpack(jnp.asarray(x), cfg))
        KJ[a], W[a], q_rest[a] = pr["KJ"], pr["W"], pr["q_rest"]
        if cfg.model == "lambda0":
            tau[a] = pr["a"]
        else:
            dur[a] = pr["a"]
        if mdl.reach_delays(cfg):  # (segmented recordings have none: NaN)
            delay[a] = pr["delay"]
            reach_delay[s] = float(pr["delay"]) + (offsets if offsets.size else np.zeros(len(usable[s])))
        tau0[a] = pr["a0"]
        status[a] = int(out["status"][i])
        # (converged on a simulation that is not accurate enough, or whose error is not finite)
        accurate = out["integration_error_deg"][i] <= INTEGRATION_TOL_DEG
        if status[a] == int(Status.SUCCESSFUL) and stage2 and not accurate:
            status[a] = int(Status.INACCURATE)
        n_reach[a] = max(int(np.sum(out["weight"][i][: len(usable[s])] > 0)), 1)  # (left-out reaches: zero rows)
        for j in out["dropped"][i]:
            dropped.setdefault(s, []).append((usable[s].recording[j], float(usable[s].t[j, 0]),
                                              float(usable[s].t[j, -1]), "no equilibrium of the starting model "
                                              "(KJ = I, q_rest = mean final posture): left out of the fit"))
        per = (SAMPLES - 1 + 1) * n
        N = n_reach[a] * per
        n_res[a] = N
        cost = float(out["cost"][i])
        loss[a] = cost
        if out["residual"] is not None:
            r = np.asarray(out["residual"][i])[: out["B"] * per].reshape(out["B"], per)
            r = r[: len(usable[s]), : (SAMPLES - 1) * n]
            rmse[a] = np.rad2deg(np.sqrt(np.sum(r**2) / (n * n_reach[a])))
        sigma2 = 2 * cost / max(N, 1)
        n_free = p + nuis.size  # the reaches' nuisance parameters count as parameters
        aic[a] = N * math.log(max(sigma2, 1e-300)) + 2 * n_free
        bic[a] = N * math.log(max(sigma2, 1e-300)) + n_free * math.log(max(N, 1))
        err[a] = out["integration_error_deg"][i]
        lm[a] = (int(out["stage1"]["steps"][i]) if out["stage1"] is not None else 0, int(out["lm2"][i]))
        sv[a] = out["singular_values"][i]
        unident[a] = _unidentified_names(out["V0"][i], pnames, cfg)
        V0[a] = out["V0"][i]
        k = spd_size(n)
        w = np.linalg.eigvalsh(KJ[a])
        bound[a, 0] = math.log(w[-1] / w[0]) >= math.log(cfg.cond_max) - 3 * mdl.BOUND_WIDTH[0]
        qs = usable[s].q_obs
        margin = np.deg2rad(margin_deg)
        lo, hi = qs.min((0, 1)) - margin, qs.max((0, 1)) + margin
        bound[a, 1:] = (x[k:k + n] >= hi - 3 * mdl.BOUND_WIDTH[1]) | (x[k:k + n] <= lo + 3 * mdl.BOUND_WIDTH[1])
    stderr = np.sqrt(np.clip(np.diagonal(cov, axis1=1, axis2=2), 0.0, None))
    return MovementFit(
        subjects=names_all, KJ=KJ, q_rest=q_rest, W=W, tau=tau, tau0=tau0, duration=dur, delay=delay,
        reach_delays=reach_delay, reach_target_offsets=target_shift,
        converged=status == int(Status.SUCCESSFUL), status=status, params=params, stderr=stderr, cov=cov,
        param_names=pnames, unidentified=tuple(unident), unidentified_directions=V0,
        singular_values=sv, loss=loss, rmse_deg=rmse, aic=aic,
        bic=bic, n_reaches=n_reach, n_residuals=n_res, lm_steps=lm, solver=out["solver"],
        steps_per_sample=int(out["steps"]), integration_error_deg=err, bound_active=bound,
        reaches={s: found[s] for s in names_all},
        skipped={s: list(found[s].skipped) + dropped.get(s, []) for s in names_all},
        chain=chain, joint_names=joints, model=cfg.model, damping=cfg.damping, time_constants=cfg.time_constants,
        segmented=segmented, rest_margin_deg=margin_deg)


def _fit_config(fit: MovementFit) -> mdl.Config:
    """The model configuration of ``fit`` (as its compiled fits saw it)."""
    return mdl.Config(fit.chain.n, fit.model, fit.damping, fit.time_constants, delay=not fit.segmented)


def subject_model(fit: MovementFit, subject: str, duration, t_ratio=None):
    """The fitted subject's model and planner for reaches of ``duration`` (B,) [s] (normalised time;
    ``t_ratio`` (B,): the duration fractions refer to, per unit window)."""
    a = fit.subject_index(subject)
    cfg = _fit_config(fit)
    p = mdl.unpack(jnp.asarray(fit.params[a]), cfg)
    ratio = None if t_ratio is None else jnp.asarray(t_ratio, float)
    return mdl.model_and_planner(fit.chain, p, jnp.asarray(duration, float), cfg, t_ratio=ratio), cfg

