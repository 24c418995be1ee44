"""The λ0-PMP of a HuG-MP subject on normalised time: parameters, configurations, simulation — the
segmented case of ``fitting._movements.model`` (:func:`_generic_config`), whose residuals the fit
uses, with the elbow's rest angle held at the gauge below.

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
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

import pmpjax as pj
from pmpjax.internal import fast_compile_jit, row_chunks

from .._movements import BOUND_WIDTH as _BOUND_WIDTH
from .._movements import GAIN_CAP as _GAIN_CAP
from .._movements import ReachModelConfig, rk4_rates, stage2_start, unpack_params
from .._optimise import sym_index
from .motions import JOINTS, _chain

#: Largest ``integration_error_deg`` a fit accepts silently (a warning above).
INTEGRATION_TOL_DEG = 0.01
#: Default bound on cond(KJ) (``fit_reaching(stiffness_cond_max=)``).
STIFFNESS_COND_MAX = 100.0
#: The fitted shoulder rest angles stay within the subject's recorded range widened by this [deg].
REST_MARGIN_DEG = 20.0
#: Softplus widths of the bounds (``fitting._movements.model.BOUND_WIDTH``): a bound counts as
#: binding (``bound_active``) within three widths of it or beyond, or where its penalty moves the
#: estimate by more than 0.1 standard errors (``fit._bound_pull_se``).
BOUND_WIDTH = _BOUND_WIDTH
GAIN_CAP = _GAIN_CAP  # 1/T_rec: cap of the time-base generator's task-velocity gain
MODELS = ("lambda0", "lambda0_minjerk")
DAMPINGS = ("tau0_KJ", "diagonal", "full")
TIME_CONSTANTS = ("tied", "fitted")
_N_K = 9  # free numbers of KJ (4×4 SPD, trace 4)
_N_P = _N_K + 3  # postural parameters: KJ and the shoulder rest angles (the elbow's is not identifiable)
_ELBOW = _N_P  # the elbow's rest angle among fit_movements' parameters (after KJ's 9 and q_rest[q1..q3])


@dataclasses.dataclass(frozen=True)
class _Config:
    model: str
    damping: str
    time_constants: str
    steps: int  # least RK4 steps per sample interval of predict_reaching's RK4 simulations
    ftol: float = 1e-8
    xtol: float = 1e-8
    # Bound on cond(KJ) (inf: none; the compiled fits take it from their data: every bound shares a compile)
    cond_max: float = STIFFNESS_COND_MAX
    stol: float = 1e-4  # converged within 0.014 standard errors (fitting.least_squares)


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


def _generic_config(cfg: _Config) -> ReachModelConfig:
    """The model of ``cfg`` as ``fit_movements``' (this module's HuG-MP case): 4 joints, segmented
    motions (no delay, no per-reach offsets), fractions of T (or tied), the elbow's rest angle held
    (the gauge of the module docstring)."""
    return ReachModelConfig(4, cfg.model, cfg.damping, "fractions" if cfg.time_constants == "fitted" else "tied",
                       m=0, delay=False, hold=(_ELBOW,), cond_max=cfg.cond_max, ftol=cfg.ftol, xtol=cfg.xtol,
                       stol=cfg.stol)


def _unpack(theta, cfg: _Config, elbow) -> dict:
    """Parameters (p,) and the fixed elbow rest angle -> ``KJ`` (4, 4), ``q_rest`` (4,), ``W``
    (4, 4) per unit τ0 (trace 4), ``tau``, ``tau0`` (fractions of T), ``duration`` (of T_rec):
    ``fit_movements``' model (``fitting._movements.model.unpack``) with the elbow's rest angle
    inserted."""
    p = unpack_params(jnp.insert(theta, _ELBOW, jnp.asarray(elbow, theta.dtype)), _generic_config(cfg))
    nan = jnp.full((), jnp.nan, theta.dtype)
    out = dict(KJ=p["KJ"], q_rest=p["q_rest"], W=p["W"], tau0=p["a0"] * jnp.ones((), theta.dtype))
    if cfg.model == "lambda0":
        out["tau"], out["duration"] = p["a"] * jnp.ones((), theta.dtype), nan
    else:
        out["tau"], out["duration"] = nan, p["a"] * jnp.ones((), theta.dtype)
    return out


def _stage2_start(theta1, cfg: _Config):
    """Stage-2 start from the stage-1 parameters (``KJ``, the shoulder rest angles):
    ``fit_movements``' (free ``W̃`` at ``KJ`` (``"full"``) or ``diag KJ`` (``"diagonal"``), time
    constants at their tied values)."""
    th = stage2_start(jnp.insert(theta1, _ELBOW, 0.0), _generic_config(cfg))
    return jax.lax.stop_gradient(jnp.delete(th, _ELBOW, assume_unique_indices=True))


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
    """``fitting._movements``' ``rk4_rates`` on the arm: the fastest rate [1 / normalised time] of
    each motion at its start. ``W`` (B, 4, 4), ``KJ`` (4, 4) or (B, 4, 4), ``tau0`` (B,), ``q0`` (B, 4)."""
    return rk4_rates(_chain(), KJ, W, tau0, q0, minjerk=minjerk)


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

