"""The per-subject fit of the λ0-PMP to HuG-MP movements (``fit_reaching``, ``ReachingFit``).

**Fit** (per subject, on the chosen repetitions only; all subjects in one compiled call, one after
the other inside it by ``lax.map``, so each runs its own number of iterations). Stage 1 fits
``KJ`` and ``q_rest`` to the final postures through ``pmpjax.equilibrium_posture`` (Donders' law of
the arm; implicit gradients), by ``fitting.least_squares`` (Levenberg–Marquardt). Stage 2 starts
there and fits every parameter to the residual ``[(q_sim − q_obs)(s_k) / √49, k = 1..49;
(q_sim − q_obs)(1)]`` per motion [rad]: time-normalised joint trajectories through
``pmpjax.simulate`` (forward-mode derivatives), with the simulated final posture weighted once
more (the model's final posture is the equilibrium to within the motion left at ``s = 1``).
Eq 10 makes the task dynamics stiff (the fastest rate is ``cond(B(q0))/τ0``, thousands per unit
normalised time for anisotropic ``KJ``): the solver and its step count are chosen on the host from
the stage-1 parameters (:func:`_integration`: the L-stable RODAS4 at 2 steps per sample for the
Arimoto model, RK4 where it is stable and cheaper, as for the time-base generator), and the
integration error at the optimum (against twice the steps) is checked and reported; above 0.01°
the step count grows and stage 2 goes on. Both stages hold ``cond(KJ)`` below
``stiffness_cond_max`` and the shoulder rest angles within the recorded range ± 20° (penalty
residuals, smooth and negligible inside; reported when they bind). Converged means a relative cost change below
1e-8 or every parameter within 0.014 standard errors of the optimum (``stol``).
Standard errors: the delete-one-motion jackknife (``fitting._optimise.group_jackknife_covariance``)
after stage 2, the Gauss–Newton ``fitting.covariance`` of stage 1 for a Donders-fitted model. A
motion's samples share errors (its recorded start posture and target, misfit), which make the
Gauss–Newton errors too small: on 16 noise replicates of 16 synthetic motions (0.2°) they were
0.26–0.76 times the spread of the estimates. ``aic``/``bic`` from the Gaussian likelihood of the
residuals (optimistic: samples of one movement are correlated; use them to rank models fitted to
the same motions).
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from functools import partial
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

import pmpjax as pj
from pmpjax import Status, status_message
from pmpjax.internal import fast_compile_jit

from .._ik import estimate_ik_weights, overspecified_joints
from .._optimise import covariance, group_jackknife_covariance, least_squares, lm_iterations
from .model import (
    _N_K,
    _N_P,
    BOUND_WIDTH,
    DAMPINGS,
    INTEGRATION_TOL_DEG,
    MAX_STEPS_PER_SAMPLE,
    MODELS,
    REST_MARGIN_DEG,
    ROSENBROCK_COST,
    ROSENBROCK_H_TAU,
    ROSENBROCK_STEPS,
    STIFFNESS_COND_MAX,
    TIME_CONSTANTS,
    _bound_residual,
    _compiled_config,
    _Config,
    _final_residual,
    _model_and_planner,
    _param_names,
    _rates_host,
    _simulate,
    _stability_steps,
    _stage2_start,
    _tau0_W,
    _trajectory_residual,
    _unpack,
    _unpack_host,
)
from .motions import (
    SAMPLES,
    _chain,
    _check_reps,
    _fk_jac,
    _Motions,
    _motions,
    _reason_counts,
    _subject_name,
)


@partial(fast_compile_jit, static_argnames=("cfg",))
def _stage1_batch(theta0, data, max_steps, *, cfg: _Config):
    """Stage 1 for all subjects (leading axis of ``theta0`` (S, 12) and of ``data``'s leaves):
    ``KJ``, ``q_rest`` from the final postures; the iteration limit is traced (one compilation for
    every limit)."""

    def one(th0, dat):
        r = least_squares(partial(_final_residual, cfg=cfg), th0, dat, max_steps=max_steps,
                          ftol=cfg.ftol, xtol=cfg.xtol, stol=cfg.stol)
        cov, se, sv, _ = covariance(r)
        return dict(x=r.x, cost=r.cost, residual=r.residual, converged=r.converged, status=r.status, steps=r.steps,
                    start=_stage2_start(r.x, cfg), cov=cov, se=se, sv=sv)

    return jax.lax.map(lambda a: one(*a), (theta0, data))


@partial(fast_compile_jit, static_argnames=("cfg",))
def _start_usable(theta0, data, *, cfg: _Config):
    """(S, B) bool: motions whose final-posture equilibrium exists at the stage-1 start."""

    def one(th, dat):
        return jnp.all(jnp.isfinite(_final_residual(th, dat, cfg)[:-4].reshape(-1, 4)), axis=-1)

    return jax.lax.map(lambda a: one(*a), (theta0, data))


@partial(fast_compile_jit, static_argnames=("cfg", "steps", "solver"))
def _stage2_batch(theta0, data, max_steps, *, cfg: _Config, steps: int, solver: str):
    """Stage 2 for all subjects: every parameter from the trajectories; covariance at the end."""

    def one(th0, dat):
        r = least_squares(partial(_trajectory_residual, cfg=cfg, steps=steps, solver=solver), th0, dat,
                          max_steps=max_steps, ftol=cfg.ftol, xtol=cfg.xtol, stol=cfg.stol)
        cov, se, sv, _ = covariance(r)
        return dict(x=r.x, cost=r.cost, residual=r.residual, jac=r.jac, converged=r.converged, status=r.status,
                    steps=r.steps, cov=cov, se=se, sv=sv)

    return jax.lax.map(lambda a: one(*a), (theta0, data))


def _stack_motions(motions: list[_Motions], bucket: int = 16, cond_max: float = STIFFNESS_COND_MAX) -> dict:
    """Pad subjects' motions to a common count (a multiple of ``bucket``; padding = copies of
    the first motion with weight 0) -> dict of ``q_obs`` (S, B, 50, 4), ``t_ratio``, ``weight``
    (S, B), ``elbow`` (S,) (the gauge of the unidentifiable elbow rest angle, module docstring: the
    mean final elbow angle), ``lo``, ``hi`` (S, 3) (the bounds of the shoulder rest angles: the
    recorded range widened by ``REST_MARGIN_DEG``), ``log_cond_max`` (S,) (the bound on cond(KJ),
    inf: none; data rather than configuration, so that every bound shares one compile)."""
    B = max(bucket, -(-max(len(m) for m in motions) // bucket) * bucket)
    q, tr, w = [], [], []
    for m in motions:
        n = len(m)
        pad = B - n
        q.append(np.concatenate([m.q_obs, np.repeat(m.q_obs[:1], pad, 0)]))
        tr.append(np.concatenate([m.t_ratio, np.repeat(m.t_ratio[:1], pad)]))
        w.append(np.concatenate([np.ones(n), np.zeros(pad)]))
    margin = np.deg2rad(REST_MARGIN_DEG)
    return dict(q_obs=np.stack(q), t_ratio=np.stack(tr), weight=np.stack(w),
                elbow=np.array([m.q_obs[:, -1, 3].mean() for m in motions]),
                lo=np.stack([m.q_obs[..., :3].min((0, 1)) - margin for m in motions]),
                hi=np.stack([m.q_obs[..., :3].max((0, 1)) + margin for m in motions]),
                log_cond_max=np.full(len(motions), math.log(cond_max)))


def _integration(theta, motions: list[_Motions], data: dict, cfg: _Config, solver=None, steps=None):
    """``(solver, steps per sample interval)`` for stage 2 at ``theta`` (S, p): RK4 at the fewest
    steps (``cfg.steps`` times a power of two) that keep every motion's fastest rate within half
    of RK4's stability bound, unless RODAS4 at ``ROSENBROCK_STEPS`` costs less (one RODAS4 step
    costs ``ROSENBROCK_COST`` RK4 steps; its step count: ``ROSENBROCK_H_TAU``) or RK4 would need
    more than ``MAX_STEPS_PER_SAMPLE``.
    A given ``solver`` or ``steps`` is kept."""
    rates, taus = [], []
    for th, e, m in zip(theta, data["elbow"], motions):
        if not np.all(np.isfinite(th)):
            continue
        p = {k: v[0] for k, v in _unpack_host(th[None], cfg, np.atleast_1d(e)).items()}
        tau0, W = _tau0_W(p, np.asarray(m.t_ratio, float))
        rates.append(_rates_host(p["KJ"], W, tau0, m.q_obs[:, 0], minjerk=cfg.model != "lambda0"))
        taus.append(np.min(tau0) if cfg.model != "lambda0" else min(np.min(tau0), np.min(p["tau"] * m.t_ratio)))
    rates = np.concatenate(rates) if rates else np.zeros(1)
    rk4_steps = _stability_steps(rates, cfg.steps)
    ros_steps, h_max = ROSENBROCK_STEPS, ROSENBROCK_H_TAU * min(taus, default=1.0)
    while 1.0 / ((SAMPLES - 1) * ros_steps) > h_max and ros_steps < MAX_STEPS_PER_SAMPLE:
        ros_steps *= 2
    if solver is None:
        rk4_ok = _stable(rates, rk4_steps) and rk4_steps <= ROSENBROCK_COST * ros_steps
        solver = "rk4" if rk4_ok else "rodas4"
    if steps is None:
        steps = rk4_steps if solver == "rk4" else ros_steps
    return solver, int(steps)


def _stable(rates, steps) -> bool:
    """Every finite rate within RK4's stability bound (2.5 of 2.78) at ``steps`` per sample."""
    rates = np.asarray(rates, float)
    return bool(np.all(rates[np.isfinite(rates)] / ((SAMPLES - 1) * steps) <= 2.5))


@partial(fast_compile_jit, static_argnames=("cfg", "steps", "solver"))
def _integration_error_batch(theta, residual, data, *, cfg: _Config, steps: int, solver: str):
    """(S,) largest joint difference [rad] over every used motion and sample between the fit's
    simulations (read back from its stage-2 ``residual``) and simulations at ``2·steps`` per
    sample: the integration error of the fit's, to within 1/15 (RK4, RODAS4: fourth order)."""

    def one(th, res, dat):
        p = _unpack(th, cfg, dat["elbow"])
        model, planner, _, _ = _model_and_planner(p, dat["t_ratio"], cfg)
        q_obs, w = dat["q_obs"], dat["weight"]
        fine = _simulate(model, planner, q_obs[:, 0], _chain().fk(q_obs[:, -1]), 2 * steps, solver).q[:, 1:]
        per = (SAMPLES - 1) * 4
        r = res[: q_obs.shape[0] * (per + 4)].reshape(q_obs.shape[0], per + 4)[:, :per].reshape(-1, SAMPLES - 1, 4)
        used = w > 0
        fit = q_obs[:, 1:] + r * (math.sqrt(SAMPLES - 1) / jnp.sqrt(jnp.where(used, w, 1.0)))[:, None, None]
        return jnp.max(jnp.where(used[:, None, None], jnp.abs(fit - fine), 0.0))

    return jax.lax.map(lambda a: one(*a), (theta, residual, data))


def _fit_motions(motions: list[_Motions], cfg: _Config, *, max_steps=(100, 100), theta0=None,
                 keep_jac: bool = False, steps: int | None = None, solver: str | None = None) -> dict:
    """Fit every subject's usable motions (each ``len(m) >= 1``): stage 1, then (on the host) the
    solver and step count for stage 2 from the stage-1 parameters (:func:`_integration`), then
    stage 2 (skipped when ``max_steps[1] == 0``: a Donders-fitted model), then the integration
    error at the optimum; while it exceeds ``INTEGRATION_TOL_DEG`` (up to twice) the step count
    grows by the power of two its fourth order asks for and stage 2 goes on from there.
    ``theta0`` (S, p) skips stage 1 and starts stage 2 there; ``steps``/``solver`` override the
    automatic choice."""
    data = _stack_motions(motions, cond_max=cfg.cond_max)
    jcfg = _compiled_config(cfg)  # (the bound travels in data["log_cond_max"])
    S = len(motions)
    p = len(_param_names(cfg))
    out, s1 = {}, None
    q_final_mean = np.stack([m.q_obs[:, -1].mean(0) for m in motions])
    out["elbow"], out["lo"], out["hi"] = data["elbow"], data["lo"], data["hi"]
    out["dropped"] = [np.zeros(0, int) for _ in motions]
    if theta0 is None:
        th1 = np.concatenate([np.zeros((S, _N_K)), q_final_mean[:, :3]], -1)
        # A motion whose equilibrium fails at the start (KJ = I, q_rest = mean final posture) would
        # make the start non-finite and stop Levenberg–Marquardt for the whole subject: leave it out.
        ok = np.asarray(_start_usable(th1, data, cfg=jcfg))
        out["dropped"] = [np.flatnonzero(~ok[s, : len(m)]) for s, m in enumerate(motions)]
        data["weight"] = data["weight"] * ok
        s1 = jax.device_get(_stage1_batch(th1, data, np.int32(max_steps[0]), cfg=jcfg))
        theta0 = s1["start"]
        out.update(x1=s1["x"], cost1=s1["cost"], converged1=s1["converged"], steps1=s1["steps"])
    else:
        theta0 = np.asarray(theta0, float).reshape(S, p)
        out.update(x1=theta0[:, :_N_P], cost1=np.full(S, np.nan), converged1=np.ones(S, bool),
                   steps1=np.zeros(S, int))
    fixed_steps = steps
    solver, steps = _integration(theta0, motions, data, cfg, solver, steps)
    out.update(solver=solver, steps_per_sample=steps, integration_error_deg=np.full(S, np.nan))
    if max_steps[1] == 0 and s1 is not None:
        # Donders-fitted model: the stage-1 result, extras at their tied start values
        k = _N_P
        pad = lambda a, *shape: np.concatenate([a, np.full(shape, np.nan)], -1)  # noqa: E731
        cov = np.full((S, p, p), np.nan)
        cov[:, :k, :k] = s1["cov"]
        n_res = np.array([(len(m) - len(d)) * 4 for m, d in zip(motions, out["dropped"])])
        fix = (s1["residual"].shape[-1] - k) / np.maximum(n_res - k, 1)
        out.update(x=theta0, cost=s1["cost"], residual=s1["residual"], converged=s1["converged"],
                   status=s1["status"], steps2=np.zeros(S, int), cov=cov * fix[:, None, None],
                   se=pad(s1["se"] * np.sqrt(fix)[:, None], S, p - k), n_residuals=n_res, stage=1)
        return out
    lm_steps = np.zeros(S, int)
    for refine in range(3):
        s2 = jax.device_get(_stage2_batch(theta0, data, np.int32(max_steps[1]), cfg=jcfg, steps=steps, solver=solver))
        lm_steps = lm_steps + s2["steps"]
        if max_steps[1] == 0:  # (the residual and Jacobian at theta0 only)
            err = np.full(S, np.nan)
            break
        err = np.rad2deg(np.asarray(_integration_error_batch(s2["x"], s2["residual"], data, cfg=jcfg, steps=steps,
                                                             solver=solver)))
        finite = np.all(np.isfinite(s2["x"]), axis=-1)
        if fixed_steps is not None or refine == 2 or np.all(~finite | (err <= INTEGRATION_TOL_DEG)):
            break
        theta0 = np.where(finite[:, None], s2["x"], theta0)
        # fourth order: the step count that brings the largest error below the tolerance
        worst = float(np.max(np.where(finite, err, 0.0)))
        steps *= 2 ** max(1, math.ceil(math.log2((worst / INTEGRATION_TOL_DEG) ** 0.25)))
        steps = min(steps, MAX_STEPS_PER_SAMPLE)
    out.update({k if k != "steps" else "steps2": v for k, v in s2.items()})
    out.update(steps2=lm_steps, steps_per_sample=steps, integration_error_deg=err)
    n_res = np.array([(len(m) - len(d)) * ((SAMPLES - 1) * 4 + 4) for m, d in zip(motions, out["dropped"])])
    # The delete-one-motion jackknife (errors shared by a motion's samples: its start posture, its
    # target, misfit); padding and left-out motions (weight 0) are in no group.
    B, rows = data["weight"].shape[1], SAMPLES * 4
    weight = np.asarray(data["weight"])
    jac = out["jac"] if keep_jac else out.pop("jac")
    cov = []
    for i in range(S):
        groups = np.concatenate([np.where(weight[i] > 0, np.arange(B), -1).repeat(rows),
                                 np.full(out["residual"].shape[-1] - B * rows, -1)])
        cov.append(group_jackknife_covariance(jac[i], out["residual"][i], groups, p))
    out["cov"] = np.stack(cov)
    out["se"] = np.sqrt(np.clip(np.diagonal(out["cov"], axis1=1, axis2=2), 0.0, None))
    out["n_residuals"] = n_res
    out["stage"] = 2
    return out


@dataclasses.dataclass(frozen=True)
class ReachingFit:
    """Per-subject λ0-PMP fits to HuG-MP movements (leading axis S = subjects, NumPy arrays).

    ``subjects`` (S,) names; ``model``, ``damping``, ``time_constants``, ``reps``, ``tasks`` and
    ``directory``: the options of :func:`fit_reaching` that made it;
    ``KJ`` (S, 4, 4) [Nm/rad], trace 4; ``q_rest`` (S, 4) [rad]; ``W`` (S, 4, 4) damping per unit
    intrinsic time constant, trace 4 (the damping of a motion is ``τ0 · W``; ``W = KJ`` under
    ``damping="tau0_KJ"``); time constants as fractions of the movement duration: ``tau_over_T``,
    ``tau0_over_T`` (S,) (0.2 when tied; ``tau_over_T`` NaN for the time-base generator, whose
    duration is ``duration_over_T_rec`` (S,) of the recording, NaN for Arimoto); ``converged``
    (S,) bool, ``status`` (S,) int (``pmpjax.Status``; ``messages`` says what each means);
    ``loss`` (S,) ½ Σ r² of the last stage's residual; ``rmse_deg`` (S,) its training RMSE [deg]
    (joint trajectories; final postures when ``max_steps[1] = 0``); ``params``, ``stderr`` (S, p),
    ``cov`` (S, p, p) with ``param_names`` (the delete-one-motion jackknife after stage 2; module
    docstring); ``aic``, ``bic`` (S,); ``n_motions``,
    ``n_residuals``, ``lm_steps`` (S, 2); ``mean_posture`` (S, 4) [rad] and ``ik_weights`` (S, 4)
    from the fitted repetitions (baselines); ``skipped`` {subject: [(task, rep, index, reason)]}
    (unusable motions, and motions left out because the starting model has no equilibrium for them);
    ``problems`` {subject: message} for subjects that could not be fitted.

    Integration (chosen automatically unless given): ``solver`` ("rk4" or "rodas4") and
    ``steps_per_sample`` (steps per 1/49 of normalised time) of stage 2 and of
    ``predict_reaching``; ``integration_error_deg`` (S,) the largest joint difference between the
    fitted model's movements at that step count and at twice as many [deg] (NaN without stage 2).
    Bounds: ``stiffness_cond`` (S,) cond(KJ) with its bound ``stiffness_cond_max``;
    ``bound_active`` (S, 4) bool: the bound on cond(KJ) and on each shoulder rest angle binds at
    the optimum (within three softplus widths of it or beyond, or its penalty moves the estimate
    by more than 0.1 standard errors: the fit presses against it, the data alone would go further).
    """

    subjects: tuple[str, ...]
    KJ: np.ndarray
    q_rest: np.ndarray
    W: np.ndarray
    tau_over_T: np.ndarray
    tau0_over_T: np.ndarray
    duration_over_T_rec: np.ndarray
    converged: np.ndarray
    status: np.ndarray
    loss: np.ndarray
    rmse_deg: np.ndarray
    params: np.ndarray
    stderr: np.ndarray
    cov: np.ndarray
    param_names: tuple[str, ...]
    aic: np.ndarray
    bic: np.ndarray
    n_motions: np.ndarray
    n_residuals: np.ndarray
    lm_steps: np.ndarray
    mean_posture: np.ndarray
    ik_weights: np.ndarray
    model: str
    damping: str
    time_constants: str
    reps: tuple[int, ...]
    tasks: tuple[int, ...]
    directory: str | None
    steps_per_sample: int
    skipped: dict
    problems: dict
    solver: str = "rk4"
    integration_error_deg: np.ndarray | None = None
    stiffness_cond: np.ndarray | None = None
    stiffness_cond_max: float = STIFFNESS_COND_MAX
    bound_active: np.ndarray | None = None

    @property
    def messages(self) -> list[str]:
        return [status_message(s) for s in self.status]

    def subject_index(self, subject) -> int:
        """The row of a subject.

        **Arguments:**

        - ``subject``: a subject number or name (``1`` or ``"S01"``).

        **Returns:**

        Its index (int).

        **Raises:**

        - ``ValueError`` for a subject that is not in the fit.
        """
        return self.subjects.index(_subject_name(subject))


def _check_choice(name, value, options):
    if value not in options:
        raise ValueError(f"`{name}` must be one of {', '.join(map(repr, options))}; got {value!r}")


def _ik_weights(motions: list[_Motions]) -> np.ndarray:
    """IK weights (S, 4) per subject from its fitted motions (Algorithm 1, γ = 0.6; the
    over-specified elbow fixed at 1). Velocities by central differences on normalised time
    (Algorithm 1 is homogeneous in time, so the scale does not matter)."""
    chain = _chain()
    K = max(len(m) for m in motions) * SAMPLES
    qd = np.zeros((len(motions), K, 4))
    J = np.broadcast_to(np.eye(3, 4), (len(motions), K, 3, 4)).copy()
    mask = np.zeros((len(motions), K), bool)
    J_all = _fk_jac(chain, np.concatenate([m.q_obs.reshape(-1, 4) for m in motions]))[1]
    start = 0
    for a, m in enumerate(motions):
        n = len(m) * SAMPLES
        qd[a, :n] = np.gradient(m.q_obs, 1.0 / (SAMPLES - 1), axis=1).reshape(-1, 4)
        J[a, :n] = J_all[start:start + n]
        mask[a, :n] = True
        start += n
    mask &= np.linalg.norm(qd, axis=-1) > 1e-6
    xd = np.einsum("skij,skj->ski", J, qd)
    fixed = overspecified_joints(J, mask=mask)
    res = estimate_ik_weights(qd, xd, J, gamma=0.6, mask=mask, fixed=fixed, on_invalid="flag")
    return np.asarray(res.w)


def fit_reaching(
    subjects,
    *,
    directory=None,
    reps=(1, 2, 3, 4, 5, 6, 7),
    model: str = "lambda0",
    damping: str = "tau0_KJ",
    time_constants: str = "fitted",
    tasks=(1, 2, 3, 4, 5, 6),
    max_steps=(100, 100),
    steps_per_sample: int | None = None,
    solver: str | None = None,
    stiffness_cond_max: float | None = STIFFNESS_COND_MAX,
) -> ReachingFit:
    """Fit the λ0-PMP per HuG-MP subject to the recorded movements of repetitions ``reps``.

    **Arguments:**

    - ``subjects``: HuG-MP subject numbers (1–4 bundled) or names ('S01'); ``directory``: folder of
      ``S0i_trajs.mat`` files (default: the bundled ones; as ``pmpjax.load_hugmp``).
    - ``reps``: repetitions to fit (the others are never read for the fit); ``tasks``: task numbers.
    - ``model``: "lambda0" (Arimoto planner, Eq 8/10) or "lambda0_minjerk" (time-base generator);
      ``damping``: "tau0_KJ" (Eq 7), "diagonal" or "full" (free SPD ``W``, trace-normalised);
      ``time_constants``: "fitted" (per subject ``τ/T``, ``τ0/T``; the default: it predicts held-out
      trajectories better and converges in fewer iterations) or "tied" (``τ = τ0 = T/5``).
    - ``max_steps``: Levenberg–Marquardt iterations of stage 1 (final postures through the
      equilibrium) and stage 2 (trajectories through ``simulate``; 0 = a Donders-fitted model, as
      in the paper). Stage 1 converges in under 80 iterations on the bundled subjects; its
      status is the Donders-only model's.
    - ``solver`` ("rk4", "rodas4") and ``steps_per_sample`` (steps per 1/49 of normalised time) of
      stage 2: chosen from the stage-1 parameters when None (``_integration``: Eq 10's gain makes
      the Arimoto model stiff, so RODAS4 at 2 steps; the time-base generator RK4 at 2), and the
      step count doubled while the integration error at the optimum exceeds 0.01°. The result
      says what was used (``solver``, ``steps_per_sample``, ``integration_error_deg``).
    - ``stiffness_cond_max``: bound on cond(KJ) (None: no bound). Final postures alone leave
      ``KJ`` and ``q_rest`` poorly determined (one redundant joint: one equation per posture), and
      unbounded stage-1 fits drift to near-singular stiffness (cond 6 400 for S01) and rest angles
      far outside the joint range; the bound, and the recorded joint range widened by 20° for the
      shoulder rest angles, hold them (smooth penalty residuals, negligible inside; ``bound_active`` reports
      where a bound binds at the optimum). The bound is data of the compiled fit: fits that differ
      only in it share one compilation.

    **Cost** (2 idle cores, the four bundled subjects, every task, repetitions 1–7, 747 motions,
    defaults): about 2 min with compilation, every subject converged; stage 1 alone
    (``max_steps=(100, 0)``) takes seconds. Free damping costs up to three times more (more
    parameters, more iterations): ``benchmarks/reaching.py`` and its ``--table``.

    All subjects are fitted in one compiled call (see the module docstring). A subject whose file
    is missing or malformed, or that has no usable motion, is reported in ``problems`` with
    ``status`` ``INVALID_INPUT`` / ``TOO_FEW_DATA`` and NaN parameters (and a warning); the others
    go on.

    **Returns:**

    A :class:`ReachingFit`.

    **Raises:**

    ``TypeError``/``ValueError`` naming the argument for bad options, and
    ``ValueError`` when no subject can be fitted (with every subject's reason).
    """
    if isinstance(subjects, int | np.integer | str):
        subjects = (subjects,)
    try:
        subjects = tuple(subjects)
    except TypeError as e:
        raise TypeError(f"`subjects` must be a list of HuG-MP subject numbers, got {subjects!r}") from e
    if not subjects:
        raise ValueError("`subjects` must name at least one HuG-MP subject")
    names = tuple(_subject_name(s) for s in subjects)
    if len(set(names)) != len(names):
        raise ValueError(f"`subjects` has repeated entries: {subjects!r}")
    reps = _check_reps("reps", reps)
    tasks = _check_reps("tasks", tasks)
    if any(t > 6 for t in tasks):
        raise ValueError(f"`tasks` must lie in 1..6 (the HuG-MP tasks), got {tasks}")
    _check_choice("model", model, MODELS)
    _check_choice("damping", damping, DAMPINGS)
    _check_choice("time_constants", time_constants, TIME_CONSTANTS)
    ms = lm_iterations(max_steps)
    if steps_per_sample is not None:
        if isinstance(steps_per_sample, bool) or int(steps_per_sample) != steps_per_sample or steps_per_sample < 1:
            raise ValueError(f"`steps_per_sample` must be a positive integer, got {steps_per_sample!r}")
        steps_per_sample = int(steps_per_sample)
    if solver is not None:
        _check_choice("solver", solver, pj.SOLVERS)
    cond_max = math.inf if stiffness_cond_max is None else float(stiffness_cond_max)
    if not cond_max > 1.0:
        raise ValueError(f"`stiffness_cond_max` must be > 1 (or None), got {stiffness_cond_max!r}")
    if directory is not None and not Path(directory).is_dir():
        raise ValueError(f"`directory` is not a folder: {directory}")
    cfg = _Config(model, damping, time_constants, 5 if model == "lambda0" else 2, cond_max=cond_max)

    problems, skipped, usable = {}, {}, {}
    for name in names:
        try:
            m = _motions(name, directory, reps, tasks)
        except (OSError, ValueError) as e:
            problems[name] = (Status.INVALID_INPUT, str(e))
            continue
        skipped[name] = list(m.skipped)
        if len(m) == 0:
            why = _reason_counts(m.skipped)
            problems[name] = (Status.TOO_FEW_DATA, f"{name}: no usable motion in repetitions {list(reps)} "
                                                   f"of tasks {list(tasks)} ({why})")
            continue
        usable[name] = m
    if not usable:
        raise ValueError("no HuG-MP subject could be fitted: " + "; ".join(v[1] for v in problems.values()))
    if problems:
        warnings.warn("fit_reaching: " + "; ".join(v[1] for v in problems.values()) + " (the other subjects go on)",
                      stacklevel=2)
    mlist = list(usable.values())
    out = _fit_motions(mlist, cfg, max_steps=ms, steps=steps_per_sample, solver=solver)
    for name, m, dropped in zip(usable, mlist, out["dropped"]):
        skipped[name] += [(int(m.task[i]), int(m.rep[i]), int(m.index[i]),
                           "no equilibrium of the starting model (KJ = I, q_rest = mean final posture): "
                           "left out of the fit") for i in dropped]
    err = np.asarray(out["integration_error_deg"], float)
    inaccurate = [name for name, e in zip(usable, err) if e > INTEGRATION_TOL_DEG]
    if inaccurate:
        warnings.warn(f"fit_reaching: the integration error at the optimum exceeds {INTEGRATION_TOL_DEG}° for "
                      f"{', '.join(inaccurate)} ({', '.join(f'{e:.3g}°' for e in err[err > INTEGRATION_TOL_DEG])}) "
                      f"after refining to {out['steps_per_sample']} steps per sample: pass a larger "
                      "`steps_per_sample`", stacklevel=2)
    ikw = _ik_weights(mlist)
    return _assemble_fit(names, usable, out, ikw, problems, skipped, cfg, reps, tasks, directory, ms)


def _assemble_fit(names, usable, out, ikw, problems, skipped, cfg, reps, tasks, directory, ms) -> ReachingFit:
    S = len(names)
    p = out["x"].shape[-1]
    nan = lambda *shape: np.full((S, *shape), np.nan)  # noqa: E731
    res = dict(KJ=nan(4, 4), q_rest=nan(4), W=nan(4, 4), tau_over_T=nan(), tau0_over_T=nan(),
               duration_over_T_rec=nan(), loss=nan(), rmse_deg=nan(), params=nan(p), stderr=nan(p),
               cov=nan(p, p), aic=nan(), bic=nan(), mean_posture=nan(4), ik_weights=nan(4))
    status = np.zeros(S, int)
    n_motions, n_res, lm_steps = np.zeros(S, int), np.zeros(S, int), np.zeros((S, 2), int)
    integration, cond, active = nan(), nan(), np.zeros((S, 4), bool)
    order = list(usable)
    for a, name in enumerate(names):
        if name in problems:
            status[a] = int(problems[name][0])
            continue
        k = order.index(name)
        x = out["x"][k]
        pars = {key: v[0] for key, v in _unpack_host(x[None], cfg, np.atleast_1d(out["elbow"][k])).items()}
        n = int(out["n_residuals"][k])
        cost = float(out["cost"][k])
        res["KJ"][a], res["q_rest"][a], res["W"][a] = pars["KJ"], pars["q_rest"], pars["W"]
        res["tau_over_T"][a], res["tau0_over_T"][a] = pars["tau"], pars["tau0"]
        res["duration_over_T_rec"][a] = pars["duration"]
        res["loss"][a] = cost
        res["params"][a], res["stderr"][a], res["cov"][a] = x, out["se"][k], out["cov"][k]
        n_fitted = len(usable[name]) - len(out["dropped"][k])
        res["rmse_deg"][a] = _training_rmse_deg(out["residual"][k], len(usable[name]), max(n_fitted, 1),
                                                out["stage"])
        res["aic"][a] = n * np.log(2 * cost / n) + 2 * p
        res["bic"][a] = n * np.log(2 * cost / n) + p * np.log(n)
        res["mean_posture"][a] = usable[name].q_obs.reshape(-1, 4).mean(0)
        res["ik_weights"][a] = ikw[k]
        n_motions[a], n_res[a] = n_fitted, n
        lm_steps[a] = out["steps1"][k], out["steps2"][k]
        integration[a] = out["integration_error_deg"][k]
        ev = np.linalg.eigvalsh(pars["KJ"])
        cond[a] = ev[-1] / ev[0]
        log_over = np.log(cond[a]) - np.log(cfg.cond_max)
        q3 = pars["q_rest"][:3]
        wc, wq = 3 * BOUND_WIDTH[0], 3 * BOUND_WIDTH[1]
        active[a] = np.r_[log_over > -wc, (q3 - out["hi"][k] > -wq) | (out["lo"][k] - q3 > -wq)]
        active[a] |= _bound_pull_se(x, out["residual"][k], out["cov"][k], cost, n, out["lo"][k], out["hi"][k],
                                    cfg) > BOUND_PULL_SE
        status[a] = int(out["status"][k]) if np.isfinite(cost) else int(Status.NONFINITE)
    return ReachingFit(
        subjects=tuple(names), converged=status == 0, status=status, param_names=_param_names(cfg),
        n_motions=n_motions, n_residuals=n_res, lm_steps=lm_steps, model=cfg.model, damping=cfg.damping,
        time_constants=cfg.time_constants, reps=tuple(reps), tasks=tuple(tasks),
        directory=None if directory is None else str(directory), steps_per_sample=int(out["steps_per_sample"]),
        skipped=skipped, problems={k: v[1] for k, v in problems.items()}, solver=out["solver"],
        integration_error_deg=integration, stiffness_cond=cond, stiffness_cond_max=cfg.cond_max,
        bound_active=active, **res,
    )


#: A bound also counts as binding when its penalty moves the estimate by more than this many
#: standard errors (``_bound_pull_se``).
BOUND_PULL_SE = 0.1


def _bound_pull_se(theta, residual, cov, cost, n_res, lo, hi, cfg) -> np.ndarray:
    """(4,) how far each bound's penalty residual moves the optimum, in standard errors of the
    data alone (the largest over the parameters): the Gauss–Newton step ``H⁻¹ J_bᵀ r_b`` that
    dropping that penalty would take, with ``H`` the data's Gauss–Newton matrix (the fit's
    ``JᵀJ = σ² cov⁻¹`` less the bounds' ``J_bᵀ J_b``). The softplus penalties act some widths
    inside a bound too, and along a direction the data barely determine (a shoulder rest angle,
    say) a small pull moves the estimate far: a bound 5° inside where the data put a rest angle
    holds it 2° inside the bound, beyond the three widths."""
    use = np.isfinite(np.diag(cov))  # stage 1 only: the postural parameters
    if not np.isfinite(cost) or cost <= 0 or n_res <= use.sum():
        return np.zeros(4)
    bounds = {"lo": lo, "hi": hi, "log_cond_max": math.log(cfg.cond_max)}
    Jb = np.asarray(jax.jacfwd(_bound_residual)(jnp.asarray(theta), bounds, cfg))[:, use]
    rb = np.asarray(residual)[-4:]
    sigma2 = 2.0 * cost / (n_res - use.sum())
    H = sigma2 * np.linalg.pinv(cov[np.ix_(use, use)]) - Jb.T @ Jb
    H_inv = np.linalg.pinv(H)
    se = np.sqrt(np.maximum(sigma2 * np.diag(H_inv), 1e-300))
    step = H_inv @ (Jb * rb[:, None]).T  # (parameters, bounds)
    return np.max(np.abs(step) / se[:, None], axis=0)


def _training_rmse_deg(residual, n_slots, n_fitted, stage):
    """RMS training error [deg] over the ``n_fitted`` fitted motions among the first ``n_slots``
    (left-out motions have zero residual)."""
    if stage == 1:  # final postures only
        return float(np.rad2deg(np.sqrt(np.sum(residual[: n_slots * 4] ** 2) / (n_fitted * 4))))
    per = (SAMPLES - 1) * 4 + 4
    r = residual[: n_slots * per].reshape(n_slots, per)[:, : (SAMPLES - 1) * 4] * math.sqrt(SAMPLES - 1)
    # the sample at s = 0 is the recorded start posture itself (zero error): RMS over all 50
    return float(np.rad2deg(np.sqrt(np.sum(r**2) / (n_fitted * SAMPLES * 4))))
