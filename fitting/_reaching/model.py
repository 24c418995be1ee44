"""The λ0-PMP of a subject on normalised time: parameters, configurations, simulation, residuals.

**Normalised time.** Every model is integrated on ``s ∈ [0, 1]`` with all time constants divided
by ``T_rec``: ``τ_s = τ / T_rec``. With ``W = τ0 W̃`` the λ0-PMP velocity scales as ``1/τ0`` and
Eq 10 makes ``k`` independent of the scale of ``W``, so with time constants proportional to the
duration the normalised movement does not depend on ``T`` at all, and motions of any length share
one compiled simulation (the per-motion ratios are array leaves).

**Models** (one subject's parameters, shared by all of its motions):
- ``KJ`` SPD with ``tr KJ = 4`` Nm/rad (9 numbers, ``fitting.stiffness_from_params``) and
  ``q_rest`` (4) [rad];
- damping ``W = τ0 W̃``: ``damping="tau0_KJ"`` the paper's hypothesis ``W̃ = KJ`` (Eq 7);
  ``"diagonal"`` / ``"full"``: ``W̃`` free, SPD with ``tr W̃ = 4`` (3 / 9 more numbers), so
  ``τ0 = tr W / tr KJ`` keeps its meaning; ``W̃ = KJ`` is inside ``"full"`` (nested models, and
  stage 2 starts there) but inside ``"diagonal"`` only for a diagonal ``KJ`` (it starts at
  ``diag KJ``);
- planner: ``model="lambda0"`` Arimoto (Eq 8) with ``k = b_max / τ0`` (Eq 10);
  ``"lambda0_minjerk"`` the minimum-jerk time-base generator (``pmpjax.MinimumJerkPlanner``,
  straight hand path, minimum-jerk timing over ``duration``);
- time constants: ``time_constants="tied"`` — ``τ = τ0 = T/5`` (the paper's heuristic) and, for the
  time-base generator, ``duration = T_rec``; ``"fitted"`` — per subject ``τ/T``, ``τ0/T`` (and
  ``duration/T_rec``) as log-parameters starting at the tied values.

**Identifiability: the elbow's rest angle.** On this arm every null-space motion keeps the elbow
angle (``|p|`` depends on ``q4`` only, so ``J n = 0`` forces ``n4 = 0``). The λ0-PMP field and its
equilibria see the elastic torque only through ``nᵀ KJ (q − q_rest)`` (λ0 blocks the rest), so
shifting ``q_rest`` along ``KJ⁻¹ e4`` changes no movement and no final posture, for every damping
variant: ``(KJ q_rest)_4`` is not identifiable from any reaching data (the residual Jacobian has an
exact zero singular value there; tests/test_reaching.py checks the invariance on an independent
NumPy model). The fit therefore fixes the gauge ``q_rest[3]`` = the subject's mean recorded final
elbow angle and fits the three shoulder rest angles; the other components of ``q_rest`` are then
determined. Compare ``q_rest`` between subjects or with other studies only up to this shift.
"""

from __future__ import annotations

import dataclasses
import math
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

import pmpjax as pj
from pmpjax.internal import fast_compile_jit, row_chunks

from .._optimise import damping_start, log_stiffness, stiffness_from_params, sym_index
from .motions import _SAMPLE_TIMES, JOINTS, SAMPLES, _chain

MAX_STEPS_PER_SAMPLE = 160  # RK4 steps per 1/49 of normalised time (7840 per movement)
#: RODAS4 steps of the fits: at least 2 per sample interval, doubled until a step is at most
#: ``ROSENBROCK_H_TAU`` of the fastest non-stiff time constant (``τ0``, ``τ``; stiffness itself
#: costs RODAS4 no accuracy): 0.001° on the recordings (2 steps), 0.002° on the stiff synthetic
#: movements of tests/test_reaching.py (4 steps); ``integration_error_deg`` checks it at the optimum.
ROSENBROCK_STEPS = 2
ROSENBROCK_H_TAU = 0.12
#: Cost of one RODAS4 step in RK4 steps in the fits' forward-mode Jacobians (2.2 for a plain
#: simulation; benchmarks/stiff.py): fits take RK4 when its stable step count costs less.
ROSENBROCK_COST = 3.4
#: Largest ``integration_error_deg`` a fit accepts silently (a warning above).
INTEGRATION_TOL_DEG = 0.01
#: Default bound on cond(KJ) (``fit_reaching(stiffness_cond_max=)``).
STIFFNESS_COND_MAX = 100.0
#: The fitted shoulder rest angles stay within the subject's recorded range widened by this [deg].
REST_MARGIN_DEG = 20.0
#: Weight of the bound residuals [rad per unit of violation]: stiff enough to hold a bound within
#: about 1 % (the data residual's gradient is O(10)), soft enough for Levenberg–Marquardt.
BOUND_WEIGHT = 30.0
#: Softplus widths of the bounds: log cond(KJ) (2 % of the condition number), rest angles [rad];
#: a bound counts as binding (``bound_active``) within three widths of it or beyond, or where its
#: penalty moves the estimate by more than 0.1 standard errors (``fit._bound_pull_se``).
BOUND_WIDTH = (0.02, 0.01)
GAIN_CAP = 60.0  # 1/T_rec: cap of the time-base generator's task-velocity gain
FINAL_WEIGHT = 1.0
MODELS = ("lambda0", "lambda0_minjerk")
DAMPINGS = ("tau0_KJ", "diagonal", "full")
TIME_CONSTANTS = ("tied", "fitted")
_N_K = 9  # free numbers of KJ (4×4 SPD, trace 4)
_N_P = _N_K + 3  # postural parameters: KJ and the shoulder rest angles (the elbow's is not identifiable)


@dataclasses.dataclass(frozen=True)
class _Config:
    model: str
    damping: str
    time_constants: str
    steps: int  # least RK4 steps per sample interval (1/49 of normalised time) for accuracy
    ftol: float = 1e-8
    xtol: float = 1e-8
    # Bound on cond(KJ) (inf: none). Read on the host only: the compiled fits take
    # ``log cond_max`` from their data (``_stack_motions``), so every bound shares one compile,
    # and they are called with :func:`_compiled_config` (this field at its default).
    cond_max: float = STIFFNESS_COND_MAX
    stol: float = 1e-4  # converged within 0.014 standard errors (fitting.least_squares)


def _compiled_config(cfg: _Config) -> _Config:
    """``cfg`` as the compiled fits see it (a static argument): ``cond_max`` at its default,
    since they read the bound from ``data["log_cond_max"]``."""
    return dataclasses.replace(cfg, cond_max=STIFFNESS_COND_MAX)


def _damping_size(damping):
    return {"tau0_KJ": 0, "diagonal": 3, "full": _N_K}[damping]


def _param_names(cfg: _Config) -> tuple[str, ...]:
    K = tuple(f"S_K[{JOINTS[i]},{JOINTS[j]}]" for i, j in sym_index(4))
    names = K + tuple(f"q_rest[{j}]" for j in JOINTS[:3])
    if cfg.damping == "diagonal":
        names += tuple(f"log W[{JOINTS[j]}]/W[q1]" for j in range(1, 4))
    elif cfg.damping == "full":
        names += tuple(f"S_W[{JOINTS[i]},{JOINTS[j]}]" for i, j in sym_index(4))
    if cfg.time_constants == "fitted":
        names += ("log(tau/T)", "log(tau0/T)") if cfg.model == "lambda0" else ("log(duration/T_rec)", "log(tau0/T)")
    return names


def _unpack(theta, cfg: _Config, elbow) -> dict:
    """Parameters (p,) and the fixed elbow rest angle -> ``KJ`` (4, 4), ``q_rest`` (4,), ``W``
    (4, 4) per unit τ0 (trace 4), ``tau``, ``tau0`` (fractions of T), ``duration`` (of T_rec)."""
    KJ = stiffness_from_params(theta[:_N_K], 4, 4.0)
    out = dict(KJ=KJ, q_rest=jnp.concatenate([theta[_N_K:_N_P], jnp.reshape(elbow, (1,)).astype(theta.dtype)]))
    k = _N_P
    nd = _damping_size(cfg.damping)
    if cfg.damping == "tau0_KJ":
        out["W"] = KJ
    elif cfg.damping == "diagonal":
        e = jnp.exp(jnp.concatenate([jnp.zeros(1, theta.dtype), theta[k:k + 3]]))
        out["W"] = jnp.diag(4.0 * e / jnp.sum(e))
    else:
        out["W"] = stiffness_from_params(theta[k:k + _N_K], 4, 4.0)
    k += nd
    fifth = jnp.asarray(0.2, theta.dtype)
    if cfg.time_constants == "fitted":
        a, a0 = jnp.exp(theta[k]), jnp.exp(theta[k + 1])
    else:
        a, a0 = (1.0 if cfg.model == "lambda0_minjerk" else fifth), fifth
    out["tau0"] = a0 * jnp.ones((), theta.dtype)
    if cfg.model == "lambda0":
        out["tau"], out["duration"] = a * jnp.ones((), theta.dtype), jnp.full((), jnp.nan, theta.dtype)
    else:
        out["tau"], out["duration"] = jnp.full((), jnp.nan, theta.dtype), a * jnp.ones((), theta.dtype)
    return out


def _stage2_start(theta1, cfg: _Config):
    """Stage-2 start: stage-1 ``KJ``, ``q_rest``; free ``W̃`` starts at ``KJ`` (``"full"``: the
    paper's model) or at ``diag KJ`` (``"diagonal"``), time constants at their tied values."""
    KJ = stiffness_from_params(theta1[:_N_K], 4, 4.0)
    parts = [theta1, damping_start(KJ, cfg.damping)]
    if cfg.time_constants == "fitted":
        first = 0.0 if cfg.model == "lambda0_minjerk" else math.log(0.2)
        parts.append(jnp.array([first, math.log(0.2)], theta1.dtype))
    return jax.lax.stop_gradient(jnp.concatenate(parts))


def _tau0_W(p: dict, t_ratio):
    """Normalised ``τ0`` (B,) and ``W = τ0 W̃`` (B, 4, 4) for motions with ``T/T_rec`` = ``t_ratio``
    (NumPy for NumPy ``p``, else JAX)."""
    xp = jnp if any(isinstance(v, jax.Array) for v in (p["tau0"], p["W"], t_ratio)) else np
    tau0 = p["tau0"] * t_ratio  # (B,) normalised
    return tau0, tau0[..., None, None] * xp.broadcast_to(p["W"], tau0.shape + (4, 4))


def _model_and_planner(p: dict, t_ratio, cfg: _Config):
    """λ0-PMP and planner for motions with ``T/T_rec`` = ``t_ratio`` (B,); ``p`` per subject
    (or with a leading (B,) axis per motion). Also returns the normalised ``τ0`` (B,) and ``W``."""
    tau0, W = _tau0_W(p, t_ratio)
    model = pj.Lambda0PMP(_chain(), KJ=p["KJ"], q_rest=p["q_rest"], W=W)
    if cfg.model == "lambda0":
        planner = pj.ArimotoPlanner(k=None, tau=p["tau"] * t_ratio, tau0=tau0)
    else:
        planner = pj.MinimumJerkPlanner(duration=p["duration"] * jnp.ones_like(t_ratio), gain_cap=GAIN_CAP)
    return model, planner, tau0, W


def _rates(KJ, W, tau0, q0, *, minjerk: bool):
    """Fastest rate [1 / normalised time] of each motion at its start, as ``pmpjax.simulate``'s
    RK4 check: the task rate of Eq 10, ``cond(M)/τ0`` with ``M = J W⁻¹ Jᵀ`` (the time-base
    generator: its gain cap), and the elastic rate ``λ_max(W⁻¹ KJ)``. ``W`` (B, 4, 4), ``KJ``
    (4, 4) or (B, 4, 4), ``tau0`` (B,), ``q0`` (B, 4)."""
    J = _chain().jacobian(q0)
    C = jnp.linalg.cholesky(W)
    CiJt = jax.scipy.linalg.solve_triangular(C, jnp.swapaxes(J, -1, -2), lower=True)  # C⁻¹ Jᵀ
    lam = jnp.linalg.eigvalsh(jnp.swapaxes(CiJt, -1, -2) @ CiJt)  # eig(J W⁻¹ Jᵀ)
    task = jnp.full(tau0.shape, GAIN_CAP) if minjerk else lam[..., -1] / lam[..., 0] / tau0
    X = jax.scipy.linalg.solve_triangular(C, jnp.broadcast_to(KJ, W.shape), lower=True)
    S = jax.scipy.linalg.solve_triangular(C, jnp.swapaxes(X, -1, -2), lower=True)  # C⁻¹ KJ C⁻ᵀ
    return jnp.maximum(task, jnp.linalg.eigvalsh(0.5 * (S + jnp.swapaxes(S, -1, -2)))[..., -1])


_rates_jit = fast_compile_jit(_rates, static_argnames=("minjerk",))


def _host_rows(fn, *rows):
    """``fn`` (jitted, row-wise) on arrays with a leading row axis R, in padded chunks of 64 rows
    (every row count shares one compile); results as NumPy with R rows."""
    return row_chunks(fn, *rows, small=64, chunk=64)


@partial(fast_compile_jit, static_argnums=1)
def _unpack_rows(theta, cfg: _Config, elbow) -> dict:
    """:func:`_unpack` of rows ``theta`` (B, p), ``elbow`` (B,) in one compiled call."""
    return jax.vmap(lambda th, e: _unpack(th, cfg, e))(theta, elbow)


def _unpack_host(theta, cfg: _Config, elbow) -> dict:
    """:func:`_unpack` of rows ``theta`` (R, p), ``elbow`` (R,) as NumPy arrays (one compile per ``cfg``)."""
    cfg = _Config(cfg.model, cfg.damping, cfg.time_constants, 0)  # (the fields _unpack reads)
    return _host_rows(lambda th, e: _unpack_rows(th, cfg, e), np.asarray(theta, float), np.asarray(elbow, float))


def _rates_host(KJ, W, tau0, q0, *, minjerk: bool):
    """:func:`_rates` (R,) of rows ``W`` (R, 4, 4), ``tau0`` (R,), ``q0`` (R, 4) and ``KJ`` (4, 4) or
    (R, 4, 4), as NumPy (one compile per ``minjerk``)."""
    KJ = np.broadcast_to(np.asarray(KJ, float), np.shape(W))
    return _host_rows(lambda *a: _rates_jit(*a, minjerk=minjerk), KJ, W, tau0, q0)


def _simulate(model, planner, q0, target, steps: int, solver: str):
    """``pmpjax.simulate`` on normalised time, saved at the 50 samples, ``steps`` steps each."""
    return pj.simulate(model, planner, q0, target, duration=1.0, dt=1.0 / ((SAMPLES - 1) * steps),
                       saveat=pj.SaveAt(ts=_SAMPLE_TIMES), solver=solver)


def _equilibria(p, target, q_final):
    eq = pj.equilibrium_posture(_chain(), p["KJ"], p["q_rest"], target, q_init=q_final)
    return eq.q, eq.converged


def _bound_residual(theta, data, cfg: _Config):
    """The bounds as residuals (4,) [rad]: ``BOUND_WEIGHT`` times how far ``log cond(KJ)`` exceeds
    ``data["log_cond_max"]`` (a traced value: every bound shares one compile; inf: no bound), and
    how far each shoulder rest angle lies outside ``[lo, hi]``, each through a softplus of width
    ``BOUND_WIDTH`` (smooth, so Levenberg–Marquardt does not crawl along a kink; negligible a few
    widths inside, where the fit is unregularised)."""
    hinge = lambda g, width: width * jax.nn.softplus(g / width)  # noqa: E731
    w = jnp.linalg.eigvalsh(log_stiffness(theta[:_N_K], 4))
    log_max = jnp.asarray(data["log_cond_max"], w.dtype)
    # (no bound: exactly 0 with a zero derivative, as softplus(-inf) would give NaN derivatives here)
    over_c = jnp.where(jnp.isfinite(log_max),
                       hinge(w[-1] - w[0] - jnp.where(jnp.isfinite(log_max), log_max, 0.0), BOUND_WIDTH[0]),
                       0.0 * w[0])
    q = theta[_N_K:_N_P]
    over_q = hinge(q - data["hi"], BOUND_WIDTH[1]) + hinge(data["lo"] - q, BOUND_WIDTH[1])
    return BOUND_WEIGHT * jnp.concatenate([jnp.reshape(over_c, (1,)), over_q])


def _final_residual(theta, data, cfg: _Config):
    """Stage 1: ``(q_eq − q_obs(1)) √w`` (B·4,) [rad], equilibria of the fitted ``KJ``, ``q_rest``,
    then the bounds (4,). ``data``: dict of ``q_obs`` (B, 50, 4), ``t_ratio``, ``weight`` (B,),
    ``elbow`` (), ``lo``, ``hi`` (3,)."""
    q_obs, weight = data["q_obs"], data["weight"]
    # stage 1 has only the postural parameters (KJ, q_rest): unpack them as the paper model
    p = _unpack(theta, dataclasses.replace(cfg, damping="tau0_KJ", time_constants="tied"), data["elbow"])
    q_eq, ok = _equilibria(p, _chain().fk(q_obs[:, -1]), q_obs[:, -1])
    used = (weight > 0)[:, None]
    r = jnp.where(used, (q_eq - q_obs[:, -1]) * jnp.sqrt(weight)[:, None], 0.0)  # left-out motions: 0
    r = jnp.where(ok[:, None] | ~used, r, jnp.nan).reshape(-1)
    return jnp.concatenate([r, _bound_residual(theta, data, cfg)])


def _trajectory_residual(theta, data, cfg: _Config, steps: int, solver: str):
    """Stage 2: per motion ``(q_sim − q_obs)(s_k) √(w/49)``, k = 1..49, and
    ``FINAL_WEIGHT (q_sim − q_obs)(1) √w`` (B·(49·4 + 4),) [rad], then the bounds (4,). Motions
    whose simulation fails, or (RK4) whose fastest rate would make RK4 unstable at this step size
    (``rate·h > 2.5``, the check ``pmpjax.simulate`` makes outside ``jit``), give NaN, so LM
    rejects such parameters."""
    q_obs, t_ratio, weight = data["q_obs"], data["t_ratio"], data["weight"]
    p = _unpack(theta, cfg, data["elbow"])
    model, planner, tau0, W = _model_and_planner(p, t_ratio, cfg)
    traj = _simulate(model, planner, q_obs[:, 0], _chain().fk(q_obs[:, -1]), steps, solver)
    if solver == "rk4":
        rate = _rates(*jax.lax.stop_gradient((p["KJ"], W, tau0, q_obs[:, 0])), minjerk=cfg.model != "lambda0")
        stable = rate / ((SAMPLES - 1) * steps) <= 2.5
    else:
        stable = True
    sw = jnp.sqrt(weight)
    d = traj.q - q_obs
    r = jnp.concatenate([(d[:, 1:] * (sw / math.sqrt(SAMPLES - 1))[:, None, None]).reshape(d.shape[0], -1),
                         d[:, -1] * (FINAL_WEIGHT * sw)[:, None]], axis=1)
    used = weight > 0
    r = jnp.where(used[:, None], r, 0.0)  # left-out and padding motions contribute nothing
    # INACCURATE is judged at the optimum (integration_error_deg), not by rejecting LM's trial steps.
    good = (((traj.status == int(pj.Status.SUCCESSFUL)) | (traj.status == int(pj.Status.INACCURATE))) & stable) | ~used
    return jnp.concatenate([jnp.where(good[:, None], r, jnp.nan).reshape(-1), _bound_residual(theta, data, cfg)])


def _stability_steps(rates, minimum, *, margin=1.25):
    """RK4 steps per sample interval keeping ``rate · h <= margin`` (RK4's real-axis bound is
    2.78); a power of two times ``minimum`` so calls share compilations, at most
    ``MAX_STEPS_PER_SAMPLE`` (motions that would need more fail with a non-finite residual or a
    ``SINGULAR``/``NONFINITE`` status instead of an endless integration)."""
    rates = np.asarray(rates, float)
    rates = rates[np.isfinite(rates)]
    need = max(1.0, float(np.max(rates, initial=0.0)) / (SAMPLES - 1) / margin)
    steps = int(minimum)
    while steps < need and steps < MAX_STEPS_PER_SAMPLE:
        steps *= 2
    return min(steps, max(int(minimum), MAX_STEPS_PER_SAMPLE))
