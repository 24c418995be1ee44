"""Real human reaching (HuG-MP): fit the λ0-PMP per subject, predict held-out movements, baselines.

**Movements as tasks.** Every recorded HuG-MP motion (``pmpjax.load_hugmp``: one motion from one
posture to the next, idle time already removed, 100 Hz) becomes a task: start posture
``q_obs[0]``, target = the recorded final hand position ``fk(q_obs[-1])`` on the 4-DoF chain
(``pmpjax.ShoulderElbowArm``), and two durations: the recording's ``T_rec`` and the movement
duration ``T`` between onset and offset at 20 % of the peak hand speed (``pmpjax.smooth_path``,
``pmpjax.segment_by_speed``; paper Section 2). The recorded joint angles are resampled at 50
equally spaced samples of normalised time ``s = t / T_rec`` (``q_obs`` is the recording itself;
its last sample is the recorded final posture). Skipped, with the reason: motions whose speed
never falls below 20 % of its peak on one side (cut by the recording), shorter than 0.25 s or a
3 cm hand path, touching a mechanical stop (q3 ≥ 27°, q4 ≥ 124.5°: within 1° of the stops the
data README reports; the stop, not the postural energy, then sets the posture), or ending/starting
at the edge of the workspace (elbow nearly straight: singular Jacobian).

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
Standard errors by ``fitting.covariance``; ``aic``/``bic`` from the Gaussian likelihood of the
residuals (optimistic: samples of one movement are correlated; use them to rank models fitted to
the same motions).

**Baselines** (``predict_reaching``, same motions, same run): ``pinv_minjerk`` straight hand path
with minimum-jerk timing resolved by the plain pseudo-inverse (PMP1 with ``W = I`` under the
time-base generator: ``q̇ = J# ẋ``); ``ik_weights_minjerk`` the same with ``W = diag(w)`` from
``fitting.estimate_ik_weights`` on the fitted repetitions (γ = 0.6, elbow fixed at 1 as
over-specified); ``lambda0_unfitted`` the λ0-PMP with ``KJ = I``, ``q_rest`` = the subject's mean
recorded posture, ``W = τ0 KJ``, ``τ = τ0 = T/5``; ``joint_minjerk_oracle`` joint-space minimum-jerk
interpolation to the *recorded* final posture (exact end posture by construction: an upper bound
for the path).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import warnings
from functools import partial
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

import pmpjax as pj
from pmpjax import Status, status_message
from pmpjax.internal import fast_compile_jit, hugmp_directory, pad_rows, row_chunks

from ._donders import _sym_index, log_stiffness, stiffness_from_params
from ._ik.analysis import overspecified_joints
from ._ik.weights import estimate_ik_weights
from ._optimise import covariance, least_squares

SAMPLES = 50
#: smoothing parameter λ of ``pmpjax.smooth_path`` for hand paths [m] against time [s]: the
#: median of the GCV choices over 48 motions of the four subjects (range 3.4e-6 … 6.7e-6); a
#: fixed value because SciPy's GCV search costs ~0.1 s per component, ~6 min for the data set.
SMOOTHING = 5e-6
THRESHOLD = 0.2
FS = 100.0
MIN_DURATION = 0.25  # s, between 20 %-of-peak onset and offset
MIN_PATH = 0.03  # m
STOPS_DEG = {2: 27.0, 3: 124.5}  # q3, q4: 1° inside the mechanical stops of the data README
MIN_MANIPULABILITY = 2e-3  # m³: sqrt det J Jᵀ; ≈ 4° from a straight elbow at nominal lengths
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
#: a bound counts as binding (``bound_active``) within three widths of it or beyond.
BOUND_WIDTH = (0.02, 0.01)
GAIN_CAP = 60.0  # 1/T_rec: cap of the time-base generator's task-velocity gain
FINAL_WEIGHT = 1.0
MODELS = ("lambda0", "lambda0_minjerk")
DAMPINGS = ("tau0_KJ", "diagonal", "full")
TIME_CONSTANTS = ("tied", "fitted")
BASELINES = ("pinv_minjerk", "ik_weights_minjerk", "lambda0_unfitted", "joint_minjerk_oracle")
JOINTS = ("q1", "q2", "q3", "q4")
_N_K = 9  # free numbers of KJ (4×4 SPD, trace 4)
_N_P = _N_K + 3  # postural parameters: KJ and the shoulder rest angles (the elbow's is not identifiable)
_SAMPLE_TIMES = tuple(float(v) for v in np.linspace(0.0, 1.0, SAMPLES))


def _chain():
    return pj.ShoulderElbowArm()


# ---------------------------------------------------------------------------------------------
# movements as tasks


@dataclasses.dataclass(frozen=True)
class _Motions:
    """One subject's usable motions (N of them) on normalised time (``SAMPLES`` samples)."""

    subject: str
    task: np.ndarray  # (N,) int, 1..6
    rep: np.ndarray  # (N,) int
    index: np.ndarray  # (N,) int, 1-based position inside its cell
    q_obs: np.ndarray  # (N, S, 4) [rad]
    x_obs: np.ndarray  # (N, S, 3) [m]
    duration: np.ndarray  # (N,) T [s], 20 %-of-peak onset to offset
    recording: np.ndarray  # (N,) T_rec [s]
    skipped: tuple = ()  # (task, rep, index or None, reason)

    def __len__(self):
        return int(self.task.shape[0])

    @property
    def target(self):
        return self.x_obs[:, -1]

    @property
    def t_ratio(self):
        """``T / T_rec`` (N,): the movement duration in normalised time."""
        return self.duration / self.recording


@fast_compile_jit
def _fk_jac_rows(chain, q):
    x, J = chain.fk_jac_soa(q.T)
    return x.T, jnp.moveaxis(J, -1, 0)


def _fk_jac(chain, q):
    """Hand positions (K, 3) and Jacobians (K, 3, 4) of postures (K, 4), K >= 1, in chunks of 1024
    of one compiled call (every K shares one compilation)."""
    return row_chunks(lambda r: _fk_jac_rows(chain, r), np.asarray(q, float).reshape(-1, 4), small=1024, chunk=1024)


def _fk(chain, q):
    return _fk_jac(chain, q)[0]


def _subject_name(subject) -> str:
    if isinstance(subject, bool) or not isinstance(subject, int | np.integer | str):
        raise TypeError(f"`subjects` must hold HuG-MP subject numbers (1, 2, ...) or names ('S01'); "
                        f"got {subject!r}")
    name = f"S{int(subject):02d}" if isinstance(subject, int | np.integer) else str(subject)
    if isinstance(subject, int | np.integer) and int(subject) < 1:
        raise ValueError(f"`subjects`: subject numbers start at 1, got {subject}")
    return name


def _file_key(name, directory):
    path = hugmp_directory(directory) / f"{name}_trajs.mat"
    try:
        st = path.stat()
        return str(path.resolve()), st.st_mtime_ns, st.st_size
    except OSError:
        return str(path), None, None


def _motions(subject, directory, reps, tasks, *, smoothing=SMOOTHING) -> _Motions:
    """Load one subject and turn its motions of repetitions ``reps`` and ``tasks`` into tasks
    (cached on the file's path, modification time and size). Raises ``FileNotFoundError`` /
    ``ValueError`` (from ``pmpjax.load_hugmp``) for a missing or malformed file."""
    name = _subject_name(subject)
    return _motions_cached(name, directory, _file_key(name, directory), tuple(reps), tuple(tasks), smoothing)


@functools.lru_cache(maxsize=64)
def _motions_cached(name, directory, _key, reps, tasks, smoothing) -> _Motions:
    sub = pj.load_hugmp(name, directory)
    chain = _chain()
    skipped = [(t, r, None, reason) for r, t, reason in sub.skipped if r in reps and t in tasks]
    items = [(t, r, i, q) for t in tasks for r, i, q in sub.motions.get(t, []) if r in reps]
    keep, durations = [], []
    if items:
        X = np.split(_fk(chain, np.concatenate([q for *_, q in items])), np.cumsum([len(q) for *_, q in items])[:-1])
        for (t, r, i, q), x in zip(items, X):
            reason, T = _analyse(q, x, smoothing)
            if reason is None:
                keep.append((t, r, i, q))
                durations.append(T)
            else:
                skipped.append((t, r, i, reason))
    if keep:
        s = np.linspace(0.0, 1.0, SAMPLES)
        q_obs = np.stack([np.stack([np.interp(s, np.linspace(0.0, 1.0, len(q)), q[:, j]) for j in range(4)], -1)
                          for *_, q in keep])
        x_obs, J = _fk_jac(chain, q_obs)
        x_obs = x_obs.reshape(len(keep), SAMPLES, 3)
        J = J.reshape(len(keep), SAMPLES, 3, 4)[:, [0, -1]]
        w = np.sqrt(np.maximum(np.linalg.det(J @ np.swapaxes(J, -1, -2)), 0.0)).min(-1)
        edge = (w < MIN_MANIPULABILITY) | ~chain.reachable(x_obs[:, -1])
        for k in np.nonzero(edge)[0]:
            t, r, i, _ = keep[k]
            skipped.append((t, r, i, "starts or ends at the edge of the workspace (elbow nearly straight: "
                                      f"sqrt det JJᵀ = {w[k]:.2g} m³ < {MIN_MANIPULABILITY:g})"))
    else:
        q_obs, x_obs, edge = np.zeros((0, SAMPLES, 4)), np.zeros((0, SAMPLES, 3)), np.zeros(0, bool)
    use = ~edge
    col = lambda j: np.array([kk[j] for kk in keep], int).reshape(-1)[use]  # noqa: E731
    return _Motions(
        subject=name, task=col(0), rep=col(1), index=col(2), q_obs=q_obs[use], x_obs=x_obs[use],
        duration=np.array(durations, float).reshape(-1)[use],
        recording=np.array([(len(q) - 1) / FS for *_, q in keep], float).reshape(-1)[use],
        skipped=tuple(sorted(skipped, key=lambda v: (v[1], v[0], v[2] or 0))),
    )


def _analyse(q, x, smoothing):
    """``(reason, T)``: why a motion (raw q (N, 4) [rad], hand path x (N, 3) [m]) is unusable
    (None if usable) and its duration T [s] between the 20 %-of-peak onset and offset."""
    t = np.arange(x.shape[0]) / FS
    path = pj.smooth_path(t, x, lam=smoothing)
    a, b = pj.segment_by_speed(path.speed, threshold=THRESHOLD)
    if a is None or b is None:
        side = "onset" if a is None else "offset"
        why = f"hand speed never falls below {THRESHOLD:.0%} of its peak before the {side} (cut by the recording)"
        return why, None
    T = (b - a) / FS
    length = float(np.linalg.norm(np.diff(path.x, axis=0), axis=-1).sum())
    if T < MIN_DURATION:
        return f"too short: {T:.2f} s between {THRESHOLD:.0%}-of-peak onset and offset (< {MIN_DURATION} s)", T
    if length < MIN_PATH:
        return f"too short: hand path {100 * length:.1f} cm (< {100 * MIN_PATH:.0f} cm)", T
    for j, stop in STOPS_DEG.items():
        top = float(np.rad2deg(np.max(q[:, j])))
        if top >= stop:
            return f"at the mechanical stop of {JOINTS[j]} (reaches {top:.1f}°, threshold {stop:.1f}°)", T
    return None, T


# ---------------------------------------------------------------------------------------------
# parameters


@dataclasses.dataclass(frozen=True)
class _Config:
    model: str
    damping: str
    time_constants: str
    steps: int  # least RK4 steps per sample interval (1/49 of normalised time) for accuracy
    ftol: float = 1e-8
    xtol: float = 1e-8
    cond_max: float = STIFFNESS_COND_MAX  # bound on cond(KJ) (inf: none)
    stol: float = 1e-4  # converged within 0.014 standard errors (fitting.least_squares)


def _damping_size(damping):
    return {"tau0_KJ": 0, "diagonal": 3, "full": _N_K}[damping]


def _param_names(cfg: _Config) -> tuple[str, ...]:
    K = tuple(f"S_K[{JOINTS[i]},{JOINTS[j]}]" for i, j in _sym_index(4))
    names = K + tuple(f"q_rest[{j}]" for j in JOINTS[:3])
    if cfg.damping == "diagonal":
        names += tuple(f"log W[{JOINTS[j]}]/W[q1]" for j in range(1, 4))
    elif cfg.damping == "full":
        names += tuple(f"S_W[{JOINTS[i]},{JOINTS[j]}]" for i, j in _sym_index(4))
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


def _log_params_jnp(M):
    """Inverse of ``stiffness_from_params`` (traceless log, free entries) in JAX."""
    w, V = jnp.linalg.eigh(M)
    L = (V * jnp.log(w)[None, :]) @ V.T
    L = L - jnp.trace(L) / 4.0 * jnp.eye(4, dtype=M.dtype)
    return jnp.stack([L[i, j] for i, j in _sym_index(4)])


def _stage2_start(theta1, cfg: _Config):
    """Stage-2 start: stage-1 ``KJ``, ``q_rest``; free ``W̃`` starts at ``KJ`` (``"full"``: the
    paper's model) or at ``diag KJ`` (``"diagonal"``), time constants at their tied values."""
    KJ = stiffness_from_params(theta1[:_N_K], 4, 4.0)
    parts = [theta1]
    if cfg.damping == "diagonal":
        d = jnp.log(jnp.diag(KJ))
        parts.append(d[1:] - d[0])
    elif cfg.damping == "full":
        parts.append(_log_params_jnp(KJ))
    if cfg.time_constants == "fitted":
        first = 0.0 if cfg.model == "lambda0_minjerk" else math.log(0.2)
        parts.append(jnp.array([first, math.log(0.2)], theta1.dtype))
    return jax.lax.stop_gradient(jnp.concatenate(parts))


# ---------------------------------------------------------------------------------------------
# the model on normalised time


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
    ``log cond_max``, and how far each shoulder rest angle lies outside ``[lo, hi]``, each through
    a softplus of width ``BOUND_WIDTH`` (smooth, so Levenberg–Marquardt does not crawl along a
    kink; negligible a few widths inside, where the fit is unregularised)."""
    hinge = lambda g, width: width * jax.nn.softplus(g / width)  # noqa: E731
    w = jnp.linalg.eigvalsh(log_stiffness(theta[:_N_K], 4))
    over_c = hinge(w[-1] - w[0] - math.log(cfg.cond_max), BOUND_WIDTH[0]) if math.isfinite(cfg.cond_max) else 0.0 * w[0]
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
    good = ((traj.status == 0) & stable) | ~used
    return jnp.concatenate([jnp.where(good[:, None], r, jnp.nan).reshape(-1), _bound_residual(theta, data, cfg)])


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


def _stack_motions(motions: list[_Motions], bucket: int = 16) -> dict:
    """Pad subjects' motions to a common count (a multiple of ``bucket``; padding = copies of
    the first motion with weight 0) -> dict of ``q_obs`` (S, B, 50, 4), ``t_ratio``, ``weight``
    (S, B), ``elbow`` (S,) (the gauge of the unidentifiable elbow rest angle, module docstring: the
    mean final elbow angle), ``lo``, ``hi`` (S, 3) (the bounds of the shoulder rest angles: the
    recorded range widened by ``REST_MARGIN_DEG``)."""
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
                hi=np.stack([m.q_obs[..., :3].max((0, 1)) + margin for m in motions]))


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


def _fit_motions(motions: list[_Motions], cfg: _Config, *, max_steps=(40, 100), theta0=None,
                 keep_jac: bool = False, steps: int | None = None, solver: str | None = None) -> dict:
    """Fit every subject's usable motions (each ``len(m) >= 1``): stage 1, then (on the host) the
    solver and step count for stage 2 from the stage-1 parameters (:func:`_integration`), then
    stage 2 (skipped when ``max_steps[1] == 0``: a Donders-fitted model), then the integration
    error at the optimum; while it exceeds ``INTEGRATION_TOL_DEG`` (up to twice) the step count
    grows by the power of two its fourth order asks for and stage 2 goes on from there.
    ``theta0`` (S, p) skips stage 1 and starts stage 2 there; ``steps``/``solver`` override the
    automatic choice."""
    data = _stack_motions(motions)
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
        ok = np.asarray(_start_usable(th1, data, cfg=cfg))
        out["dropped"] = [np.flatnonzero(~ok[s, : len(m)]) for s, m in enumerate(motions)]
        data["weight"] = data["weight"] * ok
        s1 = jax.device_get(_stage1_batch(th1, data, np.int32(max_steps[0]), cfg=cfg))
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
        s2 = _stage2_batch(theta0, data, np.int32(max_steps[1]), cfg=cfg, steps=steps, solver=solver)
        if not keep_jac:
            s2.pop("jac")
        s2 = jax.device_get(s2)
        lm_steps = lm_steps + s2["steps"]
        if max_steps[1] == 0:  # (the residual and Jacobian at theta0 only)
            err = np.full(S, np.nan)
            break
        err = np.rad2deg(np.asarray(_integration_error_batch(s2["x"], s2["residual"], data, cfg=cfg, steps=steps,
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
    N_total = out["residual"].shape[-1]
    # ``covariance`` divides by N − p over the padded residual; padded motions are not data.
    fix = (N_total - p) / np.maximum(n_res - p, 1)
    out["cov"] = out["cov"] * fix[:, None, None]
    out["se"] = out["se"] * np.sqrt(fix)[:, None]
    out["n_residuals"] = n_res
    out["stage"] = 2
    return out


# ---------------------------------------------------------------------------------------------
# results


@dataclasses.dataclass(frozen=True)
class ReachingFit:
    """Per-subject λ0-PMP fits to HuG-MP movements (leading axis S = subjects, NumPy arrays).

    ``KJ`` (S, 4, 4) [Nm/rad], trace 4; ``q_rest`` (S, 4) [rad]; ``W`` (S, 4, 4) damping per unit
    intrinsic time constant, trace 4 (the damping of a motion is ``τ0 · W``; ``W = KJ`` under
    ``damping="tau0_KJ"``); time constants as fractions of the movement duration: ``tau_over_T``,
    ``tau0_over_T`` (S,) (0.2 when tied; ``tau_over_T`` NaN for the time-base generator, whose
    duration is ``duration_over_T_rec`` (S,) of the recording, NaN for Arimoto); ``converged``
    (S,) bool, ``status`` (S,) int (``pmpjax.Status``; ``messages`` says what each means);
    ``loss`` (S,) ½ Σ r² of the last stage's residual; ``rmse_deg`` (S,) its training RMSE [deg]
    (joint trajectories; final postures when ``max_steps[1] = 0``); ``params``, ``stderr`` (S, p),
    ``cov`` (S, p, p) with ``param_names``; ``aic``, ``bic`` (S,); ``n_motions``,
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
    the optimum (within three softplus widths of it or beyond: the fit presses against it, the
    data alone would go further).
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
        return self.subjects.index(_subject_name(subject))


@dataclasses.dataclass(frozen=True)
class BaselinePrediction:
    """One predictor's held-out rows: ``q_pred`` (N, 50, 4) [rad], ``x_pred`` (N, 50, 3) [m],
    ``final_error_deg`` (N,), ``rmse_deg`` (N,), ``status`` (N,). Item access works too
    (``b["rmse_deg"]``)."""

    q_pred: np.ndarray
    x_pred: np.ndarray
    final_error_deg: np.ndarray
    rmse_deg: np.ndarray
    status: np.ndarray

    def __getitem__(self, name):
        return getattr(self, name)


@dataclasses.dataclass(frozen=True)
class ReachingPrediction:
    """Held-out movements, one row per motion (N rows over all subjects).

    ``subject`` (N,) str; ``task``, ``rep``, ``index`` (N,) int (``index`` = position of the motion
    inside its cell, 1-based); ``q_obs``, ``q_pred`` (N, 50, 4) [rad] on normalised time
    (``q_obs`` the recording resampled; its last sample is the recorded final posture);
    ``x_obs``, ``x_pred`` (N, 50, 3) [m] hand paths; ``final_error_deg`` (N,) RMS over the four
    joints of ``q_pred[:, -1] − q_obs[:, -1]`` [deg]; ``rmse_deg`` (N,) RMS over samples and joints
    [deg]; ``status`` (N,) (``pmpjax.Status``; non-zero rows have NaN errors);
    ``final_error_donders_deg`` (N,) the same final-posture error of the fitted model's Donders
    prediction, its equilibrium posture at the target (``pmpjax.equilibrium_posture``, Newton
    started at the recorded final posture as stage 1 of the fit does; NaN where it does not
    converge), which needs no simulation; ``duration``,
    ``recording`` (N,) [s]; ``baselines[name]`` a :class:`BaselinePrediction` for each of
    ``BASELINES``; ``model``, ``damping``, ``time_constants`` of the fit; ``skipped`` and
    ``problems`` as in :class:`ReachingFit`.
    """

    subject: np.ndarray
    task: np.ndarray
    rep: np.ndarray
    index: np.ndarray
    q_obs: np.ndarray
    q_pred: np.ndarray
    x_obs: np.ndarray
    x_pred: np.ndarray
    final_error_deg: np.ndarray
    rmse_deg: np.ndarray
    status: np.ndarray
    duration: np.ndarray
    recording: np.ndarray
    baselines: dict
    model: str
    damping: str
    time_constants: str
    skipped: dict
    problems: dict
    final_error_donders_deg: np.ndarray | None = None

    def predictors(self) -> dict:
        """``{name: BaselinePrediction}`` with the fitted model first (named ``"model"``)."""
        own = BaselinePrediction(self.q_pred, self.x_pred, self.final_error_deg, self.rmse_deg, self.status)
        return {"model": own, **self.baselines}

    def summary(self) -> list[dict]:
        """Rows ``{subject, task, predictor, n, final_error_deg, rmse_deg, n_donders,
        final_error_donders_deg}``: means over the held-out motions of each subject × task (task
        "all" pools the tasks), NaN rows ignored; the Donders columns (the model's equilibrium
        postures, over every motion whose equilibrium converged) only in the model's rows."""
        mean = lambda a, ok: float(np.mean(a[ok])) if ok.any() else np.nan  # noqa: E731
        don = self.final_error_donders_deg
        rows = []
        for s in dict.fromkeys(self.subject.tolist()):
            for t in [*sorted(set(self.task[self.subject == s].tolist())), "all"]:
                sel = (self.subject == s) & ((self.task == t) if t != "all" else True)
                for name, b in self.predictors().items():
                    ok = sel & np.isfinite(b.rmse_deg)
                    row = dict(subject=s, task=t, predictor=name, n=int(ok.sum()),
                               final_error_deg=mean(b.final_error_deg, ok), rmse_deg=mean(b.rmse_deg, ok),
                               n_donders=0, final_error_donders_deg=np.nan)
                    if name == "model" and don is not None:
                        okd = sel & np.isfinite(don)
                        row.update(n_donders=int(okd.sum()), final_error_donders_deg=mean(don, okd))
                    rows.append(row)
        return rows

    def to_csv(self, path) -> None:
        """Write one row per held-out motion and predictor (final error and RMSE [deg]; the
        model's rows also its Donders final-posture error)."""
        lines = ["subject,task,rep,index,predictor,status,final_error_deg,rmse_deg,final_error_donders_deg"]
        don = self.final_error_donders_deg
        for name, b in self.predictors().items():
            for k in range(len(self.task)):
                d = f"{don[k]:.4f}" if name == "model" and don is not None else "nan"
                lines.append(f"{self.subject[k]},{self.task[k]},{self.rep[k]},{self.index[k]},{name},"
                             f"{int(b.status[k])},{b.final_error_deg[k]:.4f},{b.rmse_deg[k]:.4f},{d}")
        Path(path).write_text("\n".join(lines) + "\n")


# ---------------------------------------------------------------------------------------------
# public entry points


def _check_reps(name, reps):
    if isinstance(reps, int | np.integer):
        reps = (reps,)
    try:
        out = tuple(int(r) for r in reps)
    except (TypeError, ValueError) as e:
        raise TypeError(f"`{name}` must be an iterable of repetition numbers (1-based), got {reps!r}") from e
    if not out:
        raise ValueError(f"`{name}` must name at least one repetition")
    if any(r < 1 for r in out) or any(int(r) != r for r in reps):
        raise ValueError(f"`{name}` must hold positive integers (1-based repetitions), got {reps!r}")
    if len(set(out)) != len(out):
        raise ValueError(f"`{name}` has repeated entries: {reps!r}")
    return tuple(sorted(out))


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
    time_constants: str = "tied",
    tasks=(1, 2, 3, 4, 5, 6),
    max_steps=(40, 100),
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
      ``time_constants``: "tied" (``τ = τ0 = T/5``) or "fitted" (per subject).
    - ``max_steps``: Levenberg–Marquardt iterations of stage 1 (final postures through the
      equilibrium) and stage 2 (trajectories through ``simulate``; 0 = a Donders-fitted model, as
      in the paper).
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
      where a bound binds at the optimum).

    **Cost** (2 idle cores, the four bundled subjects, every task, repetitions 1–7, 747 motions,
    defaults): about 2.5 min with compilation, every subject converged; stage 1 alone
    (``max_steps=(40, 0)``) takes seconds. Free damping and fitted time constants cost up to
    three times more (more parameters, more iterations): ``benchmarks/reaching.py`` and its
    ``--table``.

    All subjects are fitted in one compiled call (see the module docstring). A subject whose file
    is missing or malformed, or that has no usable motion, is reported in ``problems`` with
    ``status`` ``INVALID_INPUT`` / ``TOO_FEW_DATA`` and NaN parameters (and a warning); the others
    go on. **Raises:** ``TypeError``/``ValueError`` naming the argument for bad options, and
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
    try:
        ms = tuple(int(v) for v in max_steps)
    except (TypeError, ValueError) as e:
        raise TypeError(f"`max_steps` must be a pair of integers, got {max_steps!r}") from e
    if len(ms) != 2 or ms[0] < 1 or ms[1] < 0:
        raise ValueError(f"`max_steps` must be (stage-1 >= 1, stage-2 >= 0) LM iterations, got {max_steps!r}")
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
    ikw = _ik_weights(mlist)
    return _assemble_fit(names, usable, out, ikw, problems, skipped, cfg, reps, tasks, directory, ms)


def _reason_counts(skipped) -> str:
    counts = {}
    for *_, reason in skipped:
        key = reason.split(":")[0].split("(")[0].strip()
        counts[key] = counts.get(key, 0) + 1
    return ", ".join(f"{v}× {k}" for k, v in counts.items()) or "no motions recorded"


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


def _training_rmse_deg(residual, n_slots, n_fitted, stage):
    """RMS training error [deg] over the ``n_fitted`` fitted motions among the first ``n_slots``
    (left-out motions have zero residual)."""
    if stage == 1:  # final postures only
        return float(np.rad2deg(np.sqrt(np.sum(residual[: n_slots * 4] ** 2) / (n_fitted * 4))))
    per = (SAMPLES - 1) * 4 + 4
    r = residual[: n_slots * per].reshape(n_slots, per)[:, : (SAMPLES - 1) * 4] * math.sqrt(SAMPLES - 1)
    # the sample at s = 0 is the recorded start posture itself (zero error): RMS over all 50
    return float(np.rad2deg(np.sqrt(np.sum(r**2) / (n_fitted * SAMPLES * 4))))


# ---------------------------------------------------------------------------------------------
# prediction


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


def _errors(q_pred, q_obs, status):
    d = np.rad2deg(q_pred - q_obs)
    final = np.sqrt(np.mean(d[:, -1] ** 2, axis=-1))
    rmse = np.sqrt(np.mean(d**2, axis=(1, 2)))
    bad = status != 0
    return np.where(bad, np.nan, final), np.where(bad, np.nan, rmse)


def _status_from(traj_status):
    s = np.asarray(traj_status)
    return np.where(s == 0, int(Status.SUCCESSFUL), np.where(s == 1, int(Status.NONFINITE), int(Status.SINGULAR)))


def _simulate_rows(model, planner, q0, target, solver: str, steps: int):
    """Simulate rows (R,) with ``solver`` at ``steps`` per sample (RK4: at least, more if needed to
    keep it well inside its stability bound); returns ``q`` (R, 50, 4), ``x`` (R, 50, 3),
    ``status`` (R,) as ``pmpjax.Status`` codes."""
    minjerk = isinstance(planner, pj.MinimumJerkPlanner)
    KJ = model.KJ if model.KJ is not None else np.zeros(np.shape(model.W))
    tau0 = planner.tau0 if not minjerk else np.ones(len(q0))
    rates = _rates_host(KJ, model.W, tau0, q0, minjerk=minjerk)
    if solver == "rk4":
        steps = _stability_steps(rates, steps)
    # rows that are singular at q0 or (RK4) too stiff even at the most steps: SINGULAR, NaN
    # (simulated as a copy of a good row, since pmpjax.simulate refuses the whole batch)
    bad = ~np.isfinite(rates) | ((solver == "rk4") & (rates / ((SAMPLES - 1) * steps) > 2.4))
    R_ = len(q0)
    if bad.all():
        nan = np.full((R_, SAMPLES), np.nan)
        return nan[..., None] * np.ones(4), nan[..., None] * np.ones(3), np.full(R_, int(Status.SINGULAR))
    if bad.any():
        good = np.where(bad, int(np.argmin(bad)), np.arange(R_))
        take = lambda a: a[good] if np.ndim(a) >= 1 and np.shape(a)[0] == R_ else a  # noqa: E731
        model, planner = jax.tree_util.tree_map(take, (model, planner))
        q0, target = np.asarray(q0)[good], np.asarray(target)[good]
    traj = _simulate(model, planner, q0, target, steps, solver)
    q, x, status = np.asarray(traj.q).copy(), np.asarray(traj.x).copy(), _status_from(traj.status)
    q[bad], x[bad], status[bad] = np.nan, np.nan, int(Status.SINGULAR)
    return q, x, status


def _concat(a, b):
    """Rows of two models (or planners) of one kind in one batch; shared scalars (the chain's
    lengths) stay as they are."""
    return jax.tree_util.tree_map(lambda u, v: u if np.ndim(u) == 0 else np.concatenate([u, v]), a, b)


def predict_reaching(fit: ReachingFit, *, reps=(8, 9, 10)) -> ReachingPrediction:
    """Predict the held-out movements of repetitions ``reps`` of every fitted subject.

    Each motion is predicted from its start posture, target hand position and durations only
    (the fitted λ0-PMP simulated on normalised time), together with the baselines of the module
    docstring. ``reps`` must not overlap ``fit.reps``. Subjects that were not fitted, or whose
    held-out motions cannot be loaded, are reported in ``problems`` and left out.

    **Raises:** ``TypeError`` for a non-:class:`ReachingFit`, ``ValueError`` for bad or overlapping
    ``reps`` and when no held-out motion is usable.
    """
    if not isinstance(fit, ReachingFit):
        raise TypeError(f"`fit` must be a ReachingFit from fitting.fit_reaching, got {type(fit).__name__}")
    reps = _check_reps("reps", reps)
    overlap = sorted(set(reps) & set(fit.reps))
    if overlap:
        raise ValueError(f"`reps` {list(reps)} overlap the fitted repetitions {list(fit.reps)} at {overlap}: "
                         "held-out prediction needs repetitions the fit has not seen")
    cfg = _Config(fit.model, fit.damping, fit.time_constants, fit.steps_per_sample, cond_max=fit.stiffness_cond_max)
    problems, skipped, rows = dict(fit.problems), {}, []
    for a, name in enumerate(fit.subjects):
        if name in fit.problems or not np.all(np.isfinite(fit.params[a])):
            problems.setdefault(name, f"{name}: not fitted ({status_message(fit.status[a])})")
            continue
        try:
            m = _motions(name, fit.directory, reps, fit.tasks)
        except (OSError, ValueError) as e:
            problems[name] = str(e)
            continue
        skipped[name] = list(m.skipped)
        if len(m) == 0:
            problems[name] = (f"{name}: no usable held-out motion in repetitions {list(reps)} "
                              f"({_reason_counts(m.skipped)})")
            continue
        rows.append((a, m))
    if not rows:
        raise ValueError("no usable held-out motion: " + "; ".join(problems.values()))

    cat = lambda f: np.concatenate([f(a, m) for a, m in rows])  # noqa: E731
    subject = cat(lambda a, m: np.array([m.subject] * len(m)))
    owner = cat(lambda a, m: np.full(len(m), a))
    task, rep, index = cat(lambda a, m: m.task), cat(lambda a, m: m.rep), cat(lambda a, m: m.index)
    q_obs, x_obs = cat(lambda a, m: m.q_obs), cat(lambda a, m: m.x_obs)
    duration, recording = cat(lambda a, m: m.duration), cat(lambda a, m: m.recording)
    N = len(task)
    Bp = max(64, -(-N // 64) * 64)  # padded rows: calls of similar size share one compile
    q0, target, t_ratio = pad_rows(q_obs[:, 0], Bp), pad_rows(x_obs[:, -1], Bp), pad_rows(duration / recording, Bp)
    own = pad_rows(owner, Bp)
    chain = _chain()

    # the fitted model, one parameter set per row, and the unfitted λ0-PMP (KJ = I, q_rest = mean
    # posture, τ = τ0 = T/5): one batch when they share the planner, so one compilation
    p = _unpack_host(fit.params[own], cfg, fit.q_rest[own, 3])
    model, planner, _, _ = _model_and_planner(p, t_ratio, cfg)
    eye = np.broadcast_to(np.eye(4), (Bp, 4, 4))
    tau0_u = 0.2 * t_ratio
    model_u = pj.Lambda0PMP(chain, KJ=eye, q_rest=fit.mean_posture[own], W=tau0_u[:, None, None] * eye)
    planner_u = pj.ArimotoPlanner(k=None, tau=tau0_u, tau0=tau0_u)
    two = lambda a: np.concatenate([a, a])  # noqa: E731
    if cfg.model == "lambda0":
        q2, x2, s2 = _simulate_rows(_concat(model, model_u), _concat(planner, planner_u), two(q0), two(target),
                                    fit.solver, fit.steps_per_sample)
        (qm, qu), (xm, xu), (sm, su) = np.split(q2, 2), np.split(x2, 2), np.split(s2, 2)
    else:
        qm, xm, sm = _simulate_rows(model, planner, q0, target, fit.solver, fit.steps_per_sample)
        qu, xu, su = _simulate_rows(model_u, planner_u, q0, target, "rodas4", ROSENBROCK_STEPS)

    # straight hand path, minimum-jerk timing: PMP1 (q̇ = J#_W ẋ) under the time-base generator
    W_ik = np.stack([np.diag(fit.ik_weights[a]) for a in own])
    ik_ok = np.all(np.isfinite(W_ik.reshape(Bp, -1)), axis=-1)
    W_ik = np.where(ik_ok[:, None, None], W_ik, eye)
    mj = pj.MinimumJerkPlanner(duration=np.ones(2 * Bp), gain_cap=GAIN_CAP)
    q2, x2, s2 = _simulate_rows(pj.PMP1(chain, W=np.concatenate([eye, W_ik])), mj, two(q0), two(target), "rk4", 2)
    (qp, qi), (xp, xi), (sp_, si) = np.split(q2, 2), np.split(x2, 2), np.split(s2, 2)
    si = np.where(ik_ok, si, int(Status.INVALID_INPUT))
    s = np.asarray(_SAMPLE_TIMES)
    xi_s = s**3 * (10 - 15 * s + 6 * s**2)
    qo = q_obs[:, :1] + (q_obs[:, -1:] - q_obs[:, :1]) * xi_s[None, :, None]
    xo = _fk(chain, qo.reshape(-1, 4)).reshape(N, SAMPLES, 3)

    def pack(q, x, st):
        q, x, st = q[:N], x[:N], st[:N]
        f, r = _errors(q, q_obs, st)
        return BaselinePrediction(q_pred=q, x_pred=x, final_error_deg=f, rmse_deg=r, status=st)

    baselines = {
        "pinv_minjerk": pack(qp, xp, sp_),
        "ik_weights_minjerk": pack(qi, xi, si),
        "lambda0_unfitted": pack(qu, xu, su),
        "joint_minjerk_oracle": pack(qo, xo, np.zeros(N, int)),
    }
    main = pack(qm, xm, sm)
    for name in dict.fromkeys(subject.tolist()):  # failed simulations are counted, never silent
        bad = (subject == name) & (main.status != 0)
        if bad.any():
            codes = ", ".join(f"{int(c)}× {Status(int(k)).name}" for k, c in zip(*np.unique(main.status[bad],
                                                                                        return_counts=True)))
            problems[name] = (f"{name}: the fitted model failed on {int(bad.sum())} of {int((subject == name).sum())} "
                              f"held-out motions ({codes}; NaN errors, left out of the summaries)")
    if any(p_ in problems and p_ not in fit.problems for p_ in dict.fromkeys(subject.tolist())):
        warnings.warn("predict_reaching: " + "; ".join(problems[p_] for p_ in dict.fromkeys(subject.tolist())
                                                        if p_ in problems), stacklevel=2)
    # Donders' law of the fitted model: its equilibrium posture at each target, Newton started at
    # the recorded final posture as in stage 1 (from the start posture it fails for ~1 in 5 motions)
    eq = pj.equilibrium_posture(chain, fit.KJ[owner], fit.q_rest[owner], x_obs[:, -1], q_init=q_obs[:, -1])
    q_eq = np.where(np.asarray(eq.converged)[:, None], np.asarray(eq.q), np.nan)
    donders = np.sqrt(np.mean(np.rad2deg(q_eq - q_obs[:, -1]) ** 2, axis=-1))
    return ReachingPrediction(
        subject=subject, task=task, rep=rep, index=index, q_obs=q_obs, q_pred=main.q_pred, x_obs=x_obs,
        x_pred=main.x_pred, final_error_deg=main.final_error_deg, rmse_deg=main.rmse_deg, status=main.status,
        duration=duration, recording=recording, baselines=baselines, model=fit.model, damping=fit.damping,
        time_constants=fit.time_constants, skipped=skipped, problems=problems, final_error_donders_deg=donders,
    )


# ---------------------------------------------------------------------------------------------
# figure


def plot_reaching_subject(pred: ReachingPrediction, subject, *, predictors=("model", "pinv_minjerk")):
    """Recorded vs predicted joint trajectories (one held-out motion per task) and hand paths
    (frontal y–z and sagittal x–z views) of one subject. Returns the matplotlib figure."""
    import matplotlib.pyplot as plt

    name = _subject_name(subject)
    sel = np.nonzero(pred.subject == name)[0]
    if sel.size == 0:
        raise ValueError(f"`subject` {name!r} has no rows in the prediction")
    picks = [sel[pred.task[sel] == t][0] for t in sorted(set(pred.task[sel].tolist()))]
    preds = pred.predictors()
    fig, axes = plt.subplots(2, 4, figsize=(15, 7))
    s = np.asarray(_SAMPLE_TIMES)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    styles = {n: dict(color=colors[(k + 1) % len(colors)], ls=("-", "--", ":", "-.")[k % 4])
              for k, n in enumerate(predictors)}
    for j in range(4):
        ax = axes[0, j]
        for k in picks:
            ax.plot(s, np.rad2deg(pred.q_obs[k, :, j]), color="k", lw=1.5)
            for n in predictors:
                ax.plot(s, np.rad2deg(preds[n].q_pred[k, :, j]), lw=1, **styles[n])
        ax.set_title(f"{pj.ShoulderElbowArm.joint_names[j]} [deg]", fontsize=10)
        ax.set_xlabel("normalised time")
    views = ((1, 2, "frontal: y (left) vs z (up) [m]"), (0, 2, "sagittal: x (forward) vs z [m]"))
    for col, (a, b, lab) in enumerate(views):
        ax = axes[1, col]
        for k in sel:
            ax.plot(pred.x_obs[k, :, a], pred.x_obs[k, :, b], color="k", lw=0.5, alpha=0.5)
            ax.plot(preds[predictors[0]].x_pred[k, :, a], preds[predictors[0]].x_pred[k, :, b],
                    lw=0.5, alpha=0.7, **styles[predictors[0]])
        ax.set_title(lab)
        ax.set_aspect("equal")
    ax = axes[1, 2]
    names = list(preds)
    for k, n in enumerate(names):
        ok = (pred.subject == name) & np.isfinite(preds[n].rmse_deg)
        ax.bar(k - 0.2, np.mean(preds[n].rmse_deg[ok]), 0.4, color="C0")
        ax.bar(k + 0.2, np.mean(preds[n].final_error_deg[ok]), 0.4, color="C1")
    ax.set_xticks(range(len(names)), names, rotation=30, ha="right", fontsize=8)
    ax.set_title("held-out error [deg] (blue: RMSE, orange: final)")
    axes[1, 3].axis("off")
    handles = [plt.Line2D([], [], color="k", label="recorded")] + [
        plt.Line2D([], [], label=n, **styles[n]) for n in predictors]
    axes[1, 3].legend(handles=handles, loc="center")
    fig.suptitle(f"HuG-MP {name}: held-out movements, {pred.model} / {pred.damping} / {pred.time_constants}")
    fig.tight_layout()
    return fig
