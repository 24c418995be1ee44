"""The per-subject fit of the λ0-PMP to HuG-MP movements (``fit_reaching``, ``ReachingFit``): the
HuG-MP case of ``fitting.fit_movements``.

**Fit** (per subject, on the chosen repetitions only). The screened HuG-MP motions
(``fitting._reaching.motions``) become the segmented reaches of ``fit_movements`` (the window is
the recording, the postures its first and last samples, fractions of the 20 %-of-peak duration
``T``) and are fitted by its engine (``fitting._movements.fit._fit``; all subjects in one compiled
call, one after the other inside it by ``lax.map``, so each runs its own number of iterations)
on this module's model (``model._generic_config``: no target delay, no per-reach offsets, the
elbow's rest angle held at its gauge). Stage 1 fits ``KJ`` and the shoulder rest angles to the
final postures through ``pmpjax.equilibrium_posture`` (Donders' law of the arm; implicit
gradients), by ``fitting.least_squares`` (Levenberg–Marquardt); a motion whose equilibrium does
not exist at the start (``KJ = I``, ``q_rest`` = the mean final posture) is left out and reported.
Stage 2 starts there and fits every parameter to the residual ``[(q_sim − q_obs)(s_k) / √49,
k = 1..49; (q_sim − q_obs)(1)]`` per motion [rad]: time-normalised joint trajectories through
``pmpjax.simulate`` (the L-stable RODAS4: Eq 10 makes the task dynamics stiff, the fastest rate
``cond(B(q0))/τ0`` is thousands per unit normalised time for anisotropic ``KJ``; forward-mode
derivatives), with the simulated final posture weighted once more. The integration error at the
optimum (against twice the steps) is checked and reported; a subject above 0.01° is fitted again
at twice the steps. Both stages hold ``cond(KJ)`` below ``stiffness_cond_max`` and the shoulder
rest angles within the recorded range ± 20° (penalty residuals, smooth and negligible inside;
reported when they bind). Converged means a relative cost change below 1e-8 or every parameter
within 0.014 standard errors of the optimum (``stol``). Standard errors: the delete-one-motion
jackknife (``fitting._optimise.group_jackknife_covariance``) after stage 2, the Gauss–Newton
covariance of stage 1 for a Donders-fitted model. A motion's samples share errors (its recorded
start posture and target, misfit), which make the Gauss–Newton errors too small: on 16 noise
replicates of 16 synthetic motions (0.2°) they were 0.26–0.76 times the spread of the estimates.
``aic``/``bic`` from the Gaussian likelihood of the residuals (optimistic: samples of one
movement are correlated; use them to rank models fitted to the same motions).
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

import pmpjax as pj
from pmpjax import Status, status_message

from .._ik import estimate_ik_weights, overspecified_joints
from .._movements import (
    SubjectReaches,
    bound_residual,
    fit_subjects,
    free_index,
    n_params,
    reach_jackknife_covariance,
)
from .._optimise import lm_iterations
from .model import (
    _ELBOW,
    _N_P,
    BOUND_WIDTH,
    DAMPINGS,
    INTEGRATION_TOL_DEG,
    MODELS,
    REST_MARGIN_DEG,
    STIFFNESS_COND_MAX,
    TIME_CONSTANTS,
    _Config,
    _generic_config,
    _param_names,
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


def _as_reaches(m: _Motions) -> SubjectReaches:
    """HuG-MP motions as the segmented reaches of ``fit_movements``: the window is the recording
    (``T_rec``), the postures its first and last samples, ``t_ratio = T/T_rec``."""
    t = m.recording[:, None] * np.linspace(0.0, 1.0, SAMPLES)[None]
    return SubjectReaches(m.subject, tuple(f"task{a}_rep{b}_motion{c}" for a, b, c in zip(m.task, m.rep, m.index)),
                          np.asarray(m.index), t, m.q_obs, np.asarray(m.recording, float), m.q_obs[:, 0],
                          m.q_obs[:, -1], (), np.asarray(m.t_ratio, float))


def _fit_motions(motions: list[_Motions], cfg: _Config, *, max_steps=(100, 100), theta0=None,
                 keep_jac: bool = False, steps: int | None = None, solver: str | None = None,
                 approximate: bool = True) -> dict:
    """Fit every subject's usable motions (each ``len(m) >= 1``) by ``fit_movements``' engine
    (``fitting._movements.fit._fit``: stage 1, stage 2 from there unless ``max_steps[1] == 0``,
    the integration error at the optimum and the step refinement) on the HuG-MP model
    (:func:`_generic_config`), the elbow's rest angle held at its gauge. ``theta0`` (S, p) skips
    stage 1 and starts stage 2 there; ``steps``/``solver`` fix the integration; ``approximate`` as
    ``fit_movements``' engine's (False: exact Jacobians throughout). Returns the fit
    in this module's parameters (``_param_names``: the elbow's rest angle left out), with the
    delete-one-motion jackknife covariance after stage 2 (the Gauss–Newton one of stage 1 for a
    Donders-fitted model) and the residual with the four bounds of ``_bound_residual`` last."""
    gcfg = _generic_config(cfg)
    S, P = len(motions), n_params(gcfg)
    free = np.array(free_index(gcfg, P))
    elbow = np.array([m.q_obs[:, -1, 3].mean() for m in motions])
    if theta0 is not None:
        theta0 = np.insert(np.asarray(theta0, float).reshape(S, P - 1), _ELBOW, elbow, axis=1)
    reaches = [_as_reaches(m) for m in motions]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # (fit_reaching warns itself, naming its step option)
        g = fit_subjects(_chain(), reaches, gcfg, max_steps, REST_MARGIN_DEG, theta0=theta0, steps=steps,
                         solver=solver, identify=False, name="fit_reaching", approximate=approximate)
    weight, B = g["weight"], g["B"]
    bounds = B * SAMPLES * 4 + np.array([0, 1, 2, 3])  # (cond(KJ), the shoulder rest angles; not the elbow's)
    margin = np.deg2rad(REST_MARGIN_DEG)
    out = dict(elbow=elbow, dropped=g["dropped"], solver=g["solver"], steps_per_sample=int(g["steps"]),
               integration_error_deg=np.asarray(g["integration_error_deg"], float), x=np.asarray(g["x"])[:, free],
               cost=np.asarray(g["cost"]), converged=np.asarray(g["converged"]), status=np.asarray(g["status"]),
               steps2=np.asarray(g["lm2"]),
               lo=np.stack([m.q_obs[..., :3].min((0, 1)) - margin for m in motions]),
               hi=np.stack([m.q_obs[..., :3].max((0, 1)) + margin for m in motions]))
    s1 = g["stage1"]
    if s1 is not None:
        out.update(x1=np.asarray(s1["x"])[:, free[free < _N_P + 1]], cost1=s1["cost"], converged1=s1["converged"],
                   steps1=s1["steps"])
    else:
        out.update(x1=out["x"][:, :_N_P], cost1=np.full(S, np.nan), converged1=np.ones(S, bool),
                   steps1=np.zeros(S, int))
    used = [int(np.sum(weight[i] > 0)) for i in range(S)]
    p = len(free)
    if g["residual"] is None:  # a Donders-fitted model: stage 1's Gauss–Newton covariance
        r1, J1 = np.asarray(s1["residual"]), np.asarray(s1["jac"])
        keep = np.r_[np.arange(B * 4), B * 4 + np.array([0, 1, 2, 3])]
        cov = np.full((S, p, p), np.nan)
        for i in range(S):
            sigma2 = 2.0 * float(s1["cost"][i]) / max(used[i] * 4 - _N_P, 1)
            Jp = np.linalg.pinv(J1[i], rcond=1e-10)
            cov[i, :_N_P, :_N_P] = sigma2 * Jp @ Jp.T
        out.update(residual=r1[:, keep], cov=cov, n_residuals=np.array(used) * 4, stage=1)
    else:
        keep = np.r_[np.arange(B * SAMPLES * 4), bounds]
        residual, jac = np.asarray(g["residual"])[:, keep], np.asarray(g["jac"])[:, keep]
        # The delete-one-motion jackknife (errors shared by a motion's samples: its start posture,
        # its target, misfit); padding and left-out motions (weight 0) are in no group.
        cov = np.stack([reach_jackknife_covariance(g["jac"][i], g["residual"][i], gcfg, weight[i])
                        for i in range(S)])
        out.update(residual=residual, cov=cov, n_residuals=np.array(used) * SAMPLES * 4, stage=2)
        if keep_jac:
            out["jac"] = jac
    out["se"] = np.sqrt(np.clip(np.diagonal(out["cov"], axis1=1, axis2=2), 0.0, None))
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
      stage 2: when None, RODAS4 from 1 step, doubled for a subject while its integration error
      at the optimum exceeds 0.01° (up to 32); given, they are used as they are. The result says
      what was used (``solver``, ``steps_per_sample``, ``integration_error_deg``).
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
                                    cfg, out["elbow"][k]) > BOUND_PULL_SE
        status[a] = int(out["status"][k]) if np.isfinite(cost) else int(Status.NONFINITE)
        # (converged on simulations that are not accurate enough, or whose error is not finite)
        if status[a] == int(Status.SUCCESSFUL) and out["stage"] == 2 and not integration[a] <= INTEGRATION_TOL_DEG:
            status[a] = int(Status.INACCURATE)
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


def _bound_pull_se(theta, residual, cov, cost, n_res, lo, hi, cfg, elbow) -> np.ndarray:
    """(4,) how far each bound's penalty residual moves the optimum, in standard errors of the
    data alone (the largest over the parameters): the Gauss–Newton step ``H⁻¹ J_bᵀ r_b`` that
    dropping that penalty would take, with ``H`` the data's Gauss–Newton matrix (the fit's
    ``JᵀJ = σ² cov⁻¹`` less the bounds' ``J_bᵀ J_b``). The softplus penalties act some widths
    inside a bound too, and along a direction the data barely determine (a shoulder rest angle,
    say) a small pull moves the estimate far: a bound 5° inside where the data put a rest angle
    holds it 2° inside the bound, beyond the three widths. ``residual``: its last four rows are
    the bounds (cond(KJ), the shoulder rest angles)."""
    use = np.isfinite(np.diag(cov))  # stage 1 only: the postural parameters
    if not np.isfinite(cost) or cost <= 0 or n_res <= use.sum():
        return np.zeros(4)
    gcfg = _generic_config(cfg)
    bounds = {"lo": np.r_[lo, -np.inf], "hi": np.r_[hi, np.inf], "log_cond_max": math.log(cfg.cond_max)}
    full = lambda z: jnp.insert(z, _ELBOW, elbow)  # noqa: E731
    Jb = np.asarray(jax.jacfwd(lambda z: bound_residual(full(z), bounds, gcfg)[:4])(jnp.asarray(theta)))[:, use]
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
