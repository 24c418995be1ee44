"""The λ0-PMP of one subject on any chain, on normalised time: parameters, simulation, residuals.

**Parameters** (one subject's, shared by all its reaches; ``n`` joints):
- ``KJ`` SPD with ``tr KJ = n`` Nm/rad (``n(n+1)/2 − 1`` numbers, ``fitting.stiffness_from_params``;
  with ``W ∝ KJ`` only its shape matters) and ``q_rest`` (n) [rad];
- damping ``W = τ0 W̃``: ``"tau0_KJ"`` the paper's ``W̃ = KJ`` (Eq 7), ``"diagonal"`` (n − 1 log
  ratios) or ``"full"`` (SPD, trace n);
- the planner: ``"lambda0"`` Arimoto (Eq 8) with ``k = b_max/τ0`` (Eq 10) at each reach's start;
  ``"lambda0_minjerk"`` the minimum-jerk time-base generator over ``d`` of the reach;
- time constants ``log τ``, ``log τ0`` (time-base generator: ``log d``, ``log τ0``), in seconds
  (``time_constants="seconds"``: the same τ, τ0 for reaches of every duration) or as fractions of
  each reach's duration (``"fractions"``: of the window; of the movement duration ``T`` for
  segmented recordings, ``fitting._movements.data``), or not fitted (``"tied"``: ``τ = τ0 = T/5``,
  the paper's heuristic, and the generator's ``d`` the whole window);
- the planner's ``delay`` (same unit; continuous recordings only, ``Config.delay``): how long before
  the window's start (the rest detected before the onset) the target appeared (Arimoto; Eq 8's
  gain rises as ``t²`` at first, so the hand's speed reaches the detection threshold tens of
  milliseconds after the target's onset) or the generator's move began (negative: after; the
  window starts ``ONSET_LEAD`` before the detected onset). A segmented recording begins with its
  motion: no delay.

**Per-reach nuisance parameters** (stage 2 only; ``B·k`` after the subject's ``p``): each reach's
delay offset ``δ_b`` (the lead from the target's onset to the detected onset varies from
reach to reach by tens of milliseconds: the smoothed speed, the reach's direction) and its target
offset ``Δx_b`` (m task coordinates: the model's target is the hand at the end of the window,
``fk(q_end)``, which falls short where the recorded hand was still creeping on when the next reach
began; λ0-PMP approaches are asymptotic). Weak priors ``δ_b ~ N(0, 30 ms)`` (``REACH_DELAY_SD``;
with fractions, 0.03 of the reach's duration) and ``Δx_b ~ N(0, 0.02·|amplitude|)``
(``REACH_TARGET_SD``) (one residual row each, ``u/spread · 0.1° · √n``: one prior spread weighs
as a 0.1° RMS joint error over the reach, ``PRIOR_RMS_DEG``) pin those of padding and of reaches
whose data do not show them. Measured on noise-free recordings of the SciPy reference
(3-joint planar arm, 16 reaches): one delay for all reaches and the targets as recorded left τ
and τ0 6–7 % off; with both offsets, 0.8 % and 1.1 %.

**Bounds** (residual rows after the reaches'): ``30·w·softplus(g/w)`` of how far ``log cond(KJ)``
exceeds ``log 100`` (``w = 0.02``; ``fit_movements(stiffness_cond_max=)``) and how far each rest
angle lies outside its joint's recorded range widened by 90° (``w = 0.01`` rad;
``rest_margin_deg``): smooth, negligible a few widths inside.

**Normalised time.** Every reach (from rest before its onset to rest after its offset, duration
``T``) is integrated on ``s ∈ [0, 1]`` with time constants divided by ``T`` (so reaches of every
length share one compiled simulation).
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np

import pmpjax as pj

from .._optimise import damping_start, log_stiffness, spd_size, stiffness_from_params
from .data import SAMPLE_TIMES, SAMPLES

MODELS = ("lambda0", "lambda0_minjerk")
DAMPINGS = ("tau0_KJ", "diagonal", "full")
TIME_CONSTANTS = ("seconds", "fractions", "tied")
GAIN_CAP = 60.0  # time-base generator's task-velocity cap [1 / reach duration]
FINAL_WEIGHT = 1.0
#: Bounds (smooth softplus penalties, as ``fit_reaching``): cond(KJ) and the rest angles within
#: the recorded range widened by ``REST_MARGIN_DEG`` (a quarter turn: a rest posture lies outside
#: the range a task visits, and 20° biased τ by 7 % on the planar reference, whose rest angles lie
#: 30° beyond it; unidentified directions are found and named, not held by this bound).
STIFFNESS_COND_MAX = 100.0
REST_MARGIN_DEG = 90.0
BOUND_WEIGHT = 30.0
BOUND_WIDTH = (0.02, 0.01)
#: Per-reach nuisance parameters' prior spreads: delay offsets [s, or the reach's duration with
#: fractions]; target offsets [fraction of the reach's amplitude]; and their weight.
REACH_DELAY_SD = 0.03
REACH_TARGET_SD = 0.02
PRIOR_RMS_DEG = 0.1
#: Starting time constants: τ = τ0 = 0.1 s, or T/5 as fractions (the paper's heuristic, and the
#: tied time constants).
START_SECONDS = 0.1
START_FRACTION = 0.2
#: Fitted fractions start the Arimoto planner's τ at T instead: the fitted τ/T of the four HuG-MP
#: subjects lie in 1.07–1.97, and from there stage 2 takes 72 iterations on them instead of 82.
START_TAU_FRACTION = 1.0


@dataclasses.dataclass(frozen=True)
class Config:
    n: int
    model: str
    damping: str
    time_constants: str
    m: int = 0  # task coordinates of the per-reach target offsets (0: the targets as recorded)
    delay: bool = True  # fit the planner's delay and its per-reach offsets (continuous recordings)
    # Parameters held at their start values (indices into the subject's p; without per-reach
    # offsets): a gauge fixed by hand, as fit_reaching's elbow rest angle. Read on the host: the
    # compiled fits take it as the mask ``data["free"]``.
    hold: tuple[int, ...] = ()
    # Bound on cond(KJ), read on the host: the compiled fits take ``log cond_max`` from their data
    # and are called with this field at its default (``compiled``), so every bound shares a compile.
    cond_max: float = STIFFNESS_COND_MAX
    ftol: float = 1e-8
    xtol: float = 1e-8
    stol: float = 1e-4


def compiled(cfg: Config) -> Config:
    """``cfg`` as the compiled fits see it (a static argument): ``cond_max`` at its default and no
    ``hold`` (both travel in the data: ``log_cond_max``, the mask ``free``)."""
    return dataclasses.replace(cfg, cond_max=STIFFNESS_COND_MAX, hold=())


def free_index(cfg: Config, p: int):
    """Indices (p − len(hold),) of the fitted parameters among ``p``."""
    return tuple(i for i in range(p) if i not in cfg.hold)


def n_postural(cfg: Config) -> int:
    return spd_size(cfg.n) + cfg.n


def n_params(cfg: Config) -> int:
    extra = {"tau0_KJ": 0, "diagonal": cfg.n - 1, "full": spd_size(cfg.n)}[cfg.damping]
    return n_postural(cfg) + extra + n_timing(cfg)


def n_timing(cfg: Config) -> int:
    """Timing parameters: the two time constants (none when tied), then the delay."""
    return (0 if cfg.time_constants == "tied" else 2) + int(reach_delays(cfg))


def param_names(cfg: Config, joints: tuple[str, ...]) -> tuple[str, ...]:
    from .._optimise import sym_index

    pairs = sym_index(cfg.n)
    names = tuple(f"S_K[{joints[i]},{joints[j]}]" for i, j in pairs)
    names += tuple(f"q_rest[{j}]" for j in joints)
    if cfg.damping == "diagonal":
        names += tuple(f"log W[{joints[j]}]/W[{joints[0]}]" for j in range(1, cfg.n))
    elif cfg.damping == "full":
        names += tuple(f"S_W[{joints[i]},{joints[j]}]" for i, j in pairs)
    unit = "s" if cfg.time_constants == "seconds" else "T"
    if cfg.time_constants != "tied":
        names += ((f"log(tau/{unit})",) if cfg.model == "lambda0" else (f"log(duration/{unit})",)) + (
            f"log(tau0/{unit})",)
    if reach_delays(cfg):
        names += ("delay [s]" if cfg.time_constants == "seconds" else "delay/T",)
    return names


def reach_delays(cfg: Config) -> bool:
    """Whether the fit has a planner delay, and stage 2 a delay offset per reach (continuous
    recordings)."""
    return cfg.delay


def unpack(theta, cfg: Config) -> dict:
    """Parameters (p,) -> ``KJ`` (n, n), ``q_rest`` (n,), ``W`` (n, n) per unit τ0, ``a`` (τ, or the
    generator's duration fraction) and ``a0`` (τ0), in seconds or fractions as ``cfg`` says."""
    n, k = cfg.n, spd_size(cfg.n)
    KJ = stiffness_from_params(theta[:k], n, float(n))
    out = dict(KJ=KJ, q_rest=theta[k:k + n])
    k += n
    if cfg.damping == "tau0_KJ":
        out["W"] = KJ
    elif cfg.damping == "diagonal":
        e = jnp.exp(jnp.concatenate([jnp.zeros(1, theta.dtype), theta[k:k + n - 1]]))
        out["W"] = jnp.diag(n * e / jnp.sum(e))
        k += n - 1
    else:
        out["W"] = stiffness_from_params(theta[k:k + spd_size(n)], n, float(n))
        k += spd_size(n)
    if cfg.time_constants == "tied":
        out["a"] = jnp.full((), 1.0 if cfg.model == "lambda0_minjerk" else START_FRACTION, theta.dtype)
        out["a0"] = jnp.full((), START_FRACTION, theta.dtype)
    else:
        out["a"], out["a0"] = jnp.exp(theta[k]), jnp.exp(theta[k + 1])
        k += 2
    out["delay"] = theta[k] if reach_delays(cfg) else jnp.zeros((), theta.dtype)
    return out


def stage2_start(theta1, cfg: Config):
    """Stage-2 start from the stage-1 postural parameters: ``W̃`` at ``KJ`` (``"full"``) or
    ``diag KJ`` (``"diagonal"``), time constants at ``START_SECONDS`` / ``START_FRACTION`` (the
    time-base generator's duration at the whole reach): the Donders-fitted model's time constants.
    Stage 2 itself starts the Arimoto planner's fitted ``τ/T`` at ``START_TAU_FRACTION``
    (:func:`stage2_tau_start`)."""
    KJ = stiffness_from_params(theta1[:spd_size(cfg.n)], cfg.n, float(cfg.n))
    parts = [theta1, damping_start(KJ, cfg.damping)]
    t0 = math.log(START_SECONDS if cfg.time_constants == "seconds" else START_FRACTION)
    first = 0.0 if cfg.model == "lambda0_minjerk" else t0
    timing = ([first, t0] if cfg.time_constants != "tied" else []) + ([0.0] if reach_delays(cfg) else [])
    parts.append(jnp.array(timing, theta1.dtype))
    return jnp.concatenate(parts)


def stage2_tau_start(theta0: np.ndarray, cfg: Config) -> np.ndarray:
    """``theta0`` (S, p) of :func:`stage2_start` with the Arimoto planner's fitted ``τ/T`` at
    ``START_TAU_FRACTION`` (the other cases unchanged)."""
    if cfg.model != "lambda0" or cfg.time_constants != "fractions":
        return theta0
    theta0 = np.array(theta0, float)
    theta0[:, n_params(cfg) - n_timing(cfg)] = math.log(START_TAU_FRACTION)
    return theta0


def model_and_planner(chain, p: dict, duration, cfg: Config, offsets=None, t_ratio=None):
    """λ0-PMP and planner of reaches of ``duration`` (B,) [s] on normalised time; ``offsets`` (B,)
    the reaches' delay offsets (None: the subject's delay for every reach, as for unseen reaches);
    ``t_ratio`` (B,) the duration fractions refer to, per unit window (None: ones)."""
    scale, tau0, W = reach_damping(p, duration, cfg, t_ratio)
    model = pj.Lambda0PMP(chain, KJ=p["KJ"], q_rest=p["q_rest"], W=W)
    delay = (p["delay"] if offsets is None else p["delay"] + offsets) * scale
    if cfg.model == "lambda0":
        planner = pj.ArimotoPlanner(k=None, tau=p["a"] * scale, tau0=tau0, delay=delay)
    else:
        d = p["a"] * (scale if cfg.time_constants == "seconds" else jnp.ones_like(duration))
        # (a move longer than the window is unfinished at its end)
        planner = pj.MinimumJerkPlanner(duration=d, gain_cap=GAIN_CAP, delay=delay)
    return model, planner


def reach_damping(p: dict, duration, cfg: Config, t_ratio=None):
    """Per reach (B,) on normalised time: the factor from seconds (or fractions) to it, ``τ0`` and
    the damping ``W = τ0 W̃`` (B, n, n) (arguments as :func:`model_and_planner`'s)."""
    if cfg.time_constants == "seconds":
        scale = 1.0 / duration
    else:
        scale = jnp.ones_like(duration) if t_ratio is None else jnp.asarray(t_ratio, duration.dtype)
    tau0 = p["a0"] * scale
    return scale, tau0, tau0[:, None, None] * p["W"][None]


def simulate(chain, model, planner, q0, target, steps: int | None, solver: str):
    """``pmpjax.simulate`` on normalised time, saved at the ``SAMPLES`` samples: ``steps`` equal
    steps per sample interval, or adaptive steps (``None``: ``simulate``'s PI controller at its
    default tolerances)."""
    dt = None if steps is None else 1.0 / ((SAMPLES - 1) * steps)
    return pj.simulate(model, planner, q0, target, duration=1.0, dt=dt, saveat=pj.SaveAt(ts=SAMPLE_TIMES),
                       solver=solver)


def bound_residual(theta, data, cfg: Config):
    """Bounds as residuals (1 + n,): ``log cond(KJ)`` above ``data["log_cond_max"]`` (traced: every
    bound shares one compile; inf: none) and the rest angles outside ``[data["lo"], data["hi"]]``
    (the recorded range widened by the fit's margin), through softplus hinges."""
    hinge = lambda g, width: width * jax.nn.softplus(g / width)  # noqa: E731
    k = spd_size(cfg.n)
    w = jnp.linalg.eigvalsh(log_stiffness(theta[:k], cfg.n))
    log_max = jnp.asarray(data["log_cond_max"], w.dtype)
    # (no bound: exactly 0 with a zero derivative; softplus(-inf) would give NaN derivatives)
    over_c = jnp.where(jnp.isfinite(log_max),
                       hinge(w[-1] - w[0] - jnp.where(jnp.isfinite(log_max), log_max, 0.0), BOUND_WIDTH[0]),
                       0.0 * w[0])
    q = theta[k:k + cfg.n]
    over_q = hinge(q - data["hi"], BOUND_WIDTH[1]) + hinge(data["lo"] - q, BOUND_WIDTH[1])
    return BOUND_WEIGHT * jnp.concatenate([jnp.reshape(over_c, (1,)), over_q])


def final_residual(theta, data, chain, cfg: Config):
    """Stage 1: ``(q_eq − q_obs(1)) √w`` (B·n,) [rad] through the λ0-PMP's equilibria (Donders' law),
    then the bounds."""
    weight = data["weight"]
    k = spd_size(cfg.n)
    KJ = stiffness_from_params(theta[:k], cfg.n, float(cfg.n))
    q_fin = data["q_end"]
    eq = pj.equilibrium_posture(chain, KJ, theta[k:k + cfg.n], data["target"], q_init=q_fin)
    used = (weight > 0)[:, None]
    r = jnp.where(used, (eq.q - q_fin) * jnp.sqrt(weight)[:, None], 0.0)
    r = jnp.where(eq.converged[:, None] | ~used, r, jnp.nan).reshape(-1)
    return jnp.concatenate([r, bound_residual(theta, data, cfg)])


def n_nuisance(cfg: Config) -> int:
    """Nuisance parameters per reach in stage 2: the delay offset (Arimoto) and the target offset
    (``cfg.m`` task coordinates, when fitted)."""
    return (1 if reach_delays(cfg) else 0) + cfg.m


def split(theta, cfg: Config):
    """Stage-2 parameters ``(p + B·k,)`` -> the subject's ``(p,)``, the reaches' delay offsets
    ``(B,)`` or None, and target offsets ``(B, m)`` or None (``k`` = :func:`n_nuisance`)."""
    p, k = n_params(cfg), n_nuisance(cfg)
    th = theta[:p]
    if k == 0 or theta.shape[0] == p:
        return th, None, None
    u = theta[p:].reshape(-1, k)
    d = 1 if reach_delays(cfg) else 0
    return th, (u[:, 0] if d else None), (u[:, d:] if cfg.m else None)


def nuisance_scale(data, cfg: Config):
    """Prior spreads (B, k) of the nuisance parameters: ``REACH_DELAY_SD`` for delays,
    ``REACH_TARGET_SD`` of the reach's amplitude for target coordinates."""
    B = data["weight"].shape[0]
    cols = []
    if reach_delays(cfg):
        cols.append(jnp.full((B, 1), REACH_DELAY_SD))
    if cfg.m:
        cols.append(jnp.broadcast_to(REACH_TARGET_SD * data["amplitude"][:, None], (B, cfg.m)))
    return jnp.concatenate(cols, axis=1)


def rk4_rates(chain, KJ, W, tau0, q0, *, minjerk: bool):
    """Fastest rate [1 / normalised time] of each reach at its start, as ``pmpjax.simulate``'s RK4
    check: the task rate of Eq 10, ``cond(M)/τ0`` with ``M = J W⁻¹ Jᵀ`` (the time-base generator:
    its gain cap), and the elastic rate ``λ_max(W⁻¹ KJ)``. ``W`` (B, n, n), ``KJ`` (n, n) or
    (B, n, n), ``tau0`` (B,), ``q0`` (B, n)."""
    J = chain.jacobian(q0)
    C = jnp.linalg.cholesky(W)
    CiJt = jax.scipy.linalg.solve_triangular(C, jnp.swapaxes(J, -1, -2), lower=True)  # C⁻¹ Jᵀ
    lam = jnp.linalg.eigvalsh(jnp.swapaxes(CiJt, -1, -2) @ CiJt)  # eig(J W⁻¹ Jᵀ)
    task = jnp.full(tau0.shape, GAIN_CAP) if minjerk else lam[..., -1] / lam[..., 0] / tau0
    X = jax.scipy.linalg.solve_triangular(C, jnp.broadcast_to(KJ, W.shape), lower=True)
    S = jax.scipy.linalg.solve_triangular(C, jnp.swapaxes(X, -1, -2), lower=True)  # C⁻¹ KJ C⁻ᵀ
    return jnp.maximum(task, jnp.linalg.eigvalsh(0.5 * (S + jnp.swapaxes(S, -1, -2)))[..., -1])


#: RK4 trial parameters whose fastest rate times the step exceeds this (of RK4's 2.78) give NaN
#: residuals: Levenberg–Marquardt rejects them instead of fitting an unstable integration.
RK4_STABLE = 2.5
#: RK4's step count is chosen so that the fastest rate at the start times the step is at most this:
#: half of ``RK4_STABLE``, room for the fit's steps to stiffen the model.
RK4_MARGIN = 1.25


def rk4_stable(rates, steps: int):
    """Whether RK4 at ``steps`` per sample interval is stable for reaches with fastest ``rates``
    [1 / normalised time] (fastest rate × step within :data:`RK4_STABLE`; NumPy or traced)."""
    return rates / ((SAMPLES - 1) * steps) <= RK4_STABLE


def stable_rk4_steps(rates, minimum: int, maximum: int) -> int:
    """RK4 steps per sample interval for reaches with fastest ``rates`` [1 / normalised time]
    (non-finite ones ignored): the fewest ``minimum · 2^j`` with ``rate · h <= RK4_MARGIN``, at most
    ``maximum`` (powers of two, so that fits share compilations; reaches that would need more fail
    by their status or a NaN residual instead of an endless integration)."""
    rates = np.asarray(rates, float)
    rates = rates[np.isfinite(rates)]
    need = max(1.0, float(np.max(rates, initial=0.0)) / (SAMPLES - 1) / RK4_MARGIN)
    steps = int(minimum)
    while steps < need and steps < maximum:
        steps *= 2
    return min(steps, max(int(minimum), int(maximum)))


def trajectory_residual(theta, data, chain, cfg: Config, steps: int, solver: str):
    """Stage 2: per reach ``(q_sim − q_obs)(s_k) √(w/(S−1))``, k = 1..S−1, and the final posture
    once more (``FINAL_WEIGHT``) (B·(S·n),) [rad], then the bounds (1 + n), then the per-reach
    nuisance parameters' prior (B·k). ``theta`` (p + B·k,) or (p,). Failed simulations give NaN
    (Levenberg–Marquardt rejects the step); ``INACCURATE`` ones are judged at the optimum."""
    q_obs, weight = data["q_obs"], data["weight"]
    th, offsets, shift = split(theta, cfg)
    p = unpack(th, cfg)
    model, planner = model_and_planner(chain, p, data["duration"], cfg, offsets, data["t_ratio"])
    target = data["target"] if shift is None else data["target"] + shift
    traj = simulate(chain, model, planner, data["q_start"], target, steps, solver)
    sw = jnp.sqrt(weight)
    d = traj.q - q_obs
    r = jnp.concatenate([(d[:, 1:] * (sw / math.sqrt(SAMPLES - 1))[:, None, None]).reshape(d.shape[0], -1),
                         d[:, -1] * (FINAL_WEIGHT * sw)[:, None]], axis=1)
    used = weight > 0
    r = jnp.where(used[:, None], r, 0.0)
    good = (traj.status == int(pj.Status.SUCCESSFUL)) | (traj.status == int(pj.Status.INACCURATE))
    if solver == "rk4":
        W = jax.lax.stop_gradient(model.W)
        rate = rk4_rates(chain, jax.lax.stop_gradient(p["KJ"]), W, jnp.trace(W, axis1=-2, axis2=-1) / cfg.n,
                         data["q_start"], minjerk=cfg.model != "lambda0")
        good &= rk4_stable(rate, steps)
    good |= ~used
    parts = [jnp.where(good[:, None], r, jnp.nan).reshape(-1), bound_residual(theta, data, cfg)]
    if theta.shape[0] > n_params(cfg):
        u = theta[n_params(cfg):].reshape(-1, n_nuisance(cfg))
        parts.append((u / nuisance_scale(data, cfg) * (math.radians(PRIOR_RMS_DEG) * math.sqrt(cfg.n))).reshape(-1))
    return jnp.concatenate(parts)


def trajectory_linearise(theta, data, chain, cfg: Config, steps: int, solver: str):
    """``(r, J)`` of :func:`trajectory_residual` with the per-reach nuisance columns from ``k`` JVPs:
    reach b's nuisance parameters move only reach b's rows and its prior rows, so the JVP along
    one nuisance coordinate of every reach at once, masked per reach, gives ``B`` block-diagonal
    columns (p + k JVPs instead of p + B·k)."""
    P, k = n_params(cfg), n_nuisance(cfg)
    th, u = theta[:P], theta[P:].reshape(-1, k)
    B = u.shape[0]

    def h(z):
        return trajectory_residual(jnp.concatenate([z[:P], (u + z[P:][None, :]).reshape(-1)]), data, chain, cfg,
                                   steps, solver)

    z0 = jnp.concatenate([th, jnp.zeros(k, theta.dtype)])
    Jz, r = jax.jacfwd(lambda z: (h(z),) * 2, has_aux=True)(z0)
    rows = data["q_obs"].shape[1] * cfg.n  # residual rows per reach
    owner = jnp.concatenate([jnp.repeat(jnp.arange(B), rows), jnp.full(1 + cfg.n, -1), jnp.repeat(jnp.arange(B), k)])
    mask = (owner[:, None] == jnp.arange(B)[None, :]).astype(theta.dtype)
    Jn = (mask[:, :, None] * Jz[:, None, P:]).reshape(Jz.shape[0], B * k)
    return r, jnp.concatenate([Jz[:, :P], Jn], axis=1)
