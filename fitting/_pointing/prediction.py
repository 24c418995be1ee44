"""Donders-fitted λ0-PMP predictions of pointing movements (Tommasino & Campolo 2017, Section 3).

**Prediction** (:func:`predict_pointing`, Section 3): every movement of every subject simulated
from the subject's mean rest posture before that movement to the target with the λ0-PMP
(``W = τ0 KJ``, Eq 7; Arimoto ``K(t)``, Eq 8, with ``k = b_max/τ0``, Eq 10), by default
``τ = τ0 = T_sj/5``, all in one batched ``pmpjax.simulate`` call; the model paths are observed through the
analysis' smoothing spline (its equivalent kernel), cut at the same speed threshold, and their
``A_net`` is compared with the measured one by a one-sample t-test.
"""

from __future__ import annotations

import dataclasses
import warnings

import jax
import jax.numpy as jnp
import numpy as np

from pmpjax import (
    Status,
    Wrist,
    task_damping,
)
from pmpjax.internal import (
    as_array,
    check_seconds,
    check_spd,
    model_grid,
    normalised_movements,
)

from .analysis import _ALPHA, PointingAnalysis, _ttest
from .observe import _kernel_halfwidth, _profiles_jit, spline_bandwidth


def _check_params(analysis, KJ, q_rest):
    """``KJ`` (S, 3, 3) and ``q_rest`` (S, 3) (one (3, 3) / (3,) serves all subjects), validated."""
    if not isinstance(analysis, PointingAnalysis):
        raise TypeError(f"`analysis` must be a PointingAnalysis (fitting.analyze_pointing), got "
                        f"{type(analysis).__name__}")
    S = len(analysis.subjects)
    KJ = np.asarray(as_array("KJ", KJ, tail=(3, 3)), dtype=float)
    q_rest = np.asarray(as_array("q_rest", q_rest, tail=(3,)), dtype=float)
    if KJ.ndim == 2:
        KJ = np.broadcast_to(KJ, (S, 3, 3))
    if q_rest.ndim == 1:
        q_rest = np.broadcast_to(q_rest, (S, 3))
    if KJ.shape != (S, 3, 3):
        raise ValueError(f"`KJ` must be (3, 3) or (S, 3, 3) with S = {S} subjects of the analysis, got {KJ.shape}")
    if q_rest.shape != (S, 3):
        raise ValueError(f"`q_rest` must be (3,) or (S, 3) with S = {S} subjects of the analysis, got "
                         f"{q_rest.shape}")
    check_spd("KJ", KJ)
    return KJ, q_rest


def _time_constant(name, v, T):
    """``v`` (scalar, (S,) or (S, L) [s]) broadcast to ``T``'s (S, L); None: the paper's T/5."""
    if v is None:
        return T / 5.0
    a = np.asarray(as_array(name, v), dtype=float)
    if a.ndim == 1 and a.shape[0] == T.shape[0]:
        a = a[:, None]
    try:
        a = np.broadcast_to(a, T.shape)
    except ValueError as e:
        raise ValueError(f"`{name}` must be a scalar, (S,) or (S, L) = {T.shape} [s], got shape {np.shape(v)}") from e
    if np.any(a <= 0):
        raise ValueError(f"`{name}` must be positive [s], got {a.min()}")
    check_seconds(name, a)
    return a


def _movement_inputs(analysis):
    """Per subject × label: mean rest posture (S, L, 3), end target (S, L, 2), T (S, L) and the
    cells with data (S, L). Cells without data get placeholder values (masked by the callers)."""
    S, L = analysis.T.shape
    has = analysis.n_valid >= 1
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        q0 = np.nanmean(analysis.rest_q, axis=2)
    fallback = np.nanmean(q0[has], axis=0) if has.any() else np.zeros(3)
    q0 = np.where(has[..., None], q0, fallback)
    T = np.where(has, analysis.T, np.nanmean(analysis.T) if has.any() else 0.5)
    target = np.broadcast_to(analysis.targets[:, 1], (S, L, 2))
    return q0, target, T, has


@dataclasses.dataclass(frozen=True)
class PointingPrediction:
    """Donders-fitted λ0-PMP predictions of every movement (:func:`predict_pointing`), numpy arrays.

    ``subjects``, ``labels``; ``tau0``, ``tau``, ``k`` (S, L) the time constants [s] and Eq 10
    gain used (at the mean rest posture); ``t`` (S, L, N) [s], ``x`` (S, L, N, 2) [m], ``q``
    (S, L, N, 3) [rad], ``speed`` (S, L, N) [m/s] the simulated movements (mean over the trials,
    each from its measured rest posture); ``onset``, ``offset``, ``duration`` (S, L) [s] their cut
    at the analysis threshold; ``path`` (S, L, n, 2), ``q_path`` (S, L, n, 3), ``speed_path``
    (S, L, n) at the normalised samples; ``a_sum``, ``a_net`` (S, L) (means over the trials);
    the comparison with the data: ``p_model`` (S, L) p-value of the one-sample t-test of the
    measured ``A_net`` against the model's, ``captured`` (S, L) (tested and p ≥ ``alpha``),
    ``n_tested``, ``n_captured`` (S,) and ``share_captured`` (S,) = captured / 16 (the paper's
    "6 of 16 (37 %)"); ``status`` (S, L) (``pmpjax.Status``: 0 ok, TOO_FEW_DATA without data,
    NONFINITE / SINGULAR from the simulation); ``alpha``.
    """

    subjects: tuple
    labels: tuple
    tau0: np.ndarray
    tau: np.ndarray
    k: np.ndarray
    t: np.ndarray
    x: np.ndarray
    q: np.ndarray
    speed: np.ndarray
    onset: np.ndarray
    offset: np.ndarray
    duration: np.ndarray
    path: np.ndarray
    q_path: np.ndarray
    speed_path: np.ndarray
    a_sum: np.ndarray
    a_net: np.ndarray
    p_model: np.ndarray
    captured: np.ndarray
    n_tested: np.ndarray
    n_captured: np.ndarray
    share_captured: np.ndarray
    status: np.ndarray
    alpha: float

    def table(self) -> str:
        """Per subject: the movements whose ``A_net`` the model captures (paper Results).

        **Returns:**

        The table (str).
        """
        out = []
        for s, name in enumerate(self.subjects):
            caught = [lab for lab, c in zip(self.labels, self.captured[s]) if c]
            out.append(f"{name}: model captures A_net of {int(self.n_captured[s])} of {len(self.labels)} movements "
                       f"({100 * self.share_captured[s]:.0f} %; {int(self.n_tested[s])} tested)"
                       + (f": {', '.join(caught)}" if caught else ""))
        return "\n".join(out)


def compare_curvature(a_net, model_a_net, *, alpha: float = _ALPHA):
    """One-sample t-tests of measured ``a_net`` (S, L, K) (NaN = excluded) against the model's
    ``model_a_net`` (S, L): ``(p (S, L), captured (S, L), n_tested (S,), n_captured (S,))``."""
    S, L = model_a_net.shape
    p = np.array([[_ttest(a_net[s, j], model_a_net[s, j]) if np.isfinite(model_a_net[s, j]) else np.nan
                   for j in range(L)] for s in range(S)])
    tested = np.isfinite(p)
    captured = tested & (p >= alpha)
    return p, captured, tested.sum(1), captured.sum(1)


def predict_pointing(analysis: PointingAnalysis, KJ, q_rest, *, tau0=None, tau=None) -> PointingPrediction:
    """The Donders-fitted λ0-PMP's prediction of every movement (paper Section 3).

    **Arguments:** ``analysis`` (:func:`analyze_pointing`); ``KJ`` (S, 3, 3) SPD [Nm/rad] and
    ``q_rest`` (S, 3) [rad] in the order of ``analysis.subjects`` (one (3, 3) / (3,) serves all),
    e.g. from ``fitting.fit_donders`` on the subjects' Donders sessions; ``tau0``, ``tau`` [s]:
    scalar, (S,) or (S, L); default the paper's ``τ = τ0 = T_sj/5`` with ``T_sj`` the measured
    mean duration.

    Every measured movement is simulated from its measured rest posture before the movement to
    the target: ``W = τ0 KJ`` (Eq 7), Arimoto ``K(t)`` (Eq 8) with ``k = b_max(B(q0))/τ0``
    (Eq 10). All subjects × movements × trials run in one batched ``pmpjax.simulate`` call (in
    time normalised by ``T_sj``, see ``normalised_movements``). The model movements are observed
    through the analysis' smoothing spline (its equivalent kernel) and cut at its speed
    threshold like the data; the model's values per subject × movement are the means over the
    trials. Its ``A_net`` is compared with the measured ones by a one-sample t-test per subject ×
    movement (α = 0.05).

    **Returns:**

    A :class:`PointingPrediction`.

    **Raises:**

    ``TypeError`` for a non-analysis; ``ValueError`` naming the argument for ``KJ``/``q_rest`` of
    the wrong shape, a ``KJ`` that is not SPD, or time constants that are not positive.

    **Compile time:** ≈ 3 s on first use, together with :func:`analyze_pointing`
    (benchmarks/compile_times.py).
    """
    KJ, q_rest = _check_params(analysis, KJ, q_rest)
    q_mean, target, T, has = _movement_inputs(analysis)
    S, L, K = analysis.valid.shape
    tau0_ = _time_constant("tau0", tau0, T)
    tau_ = _time_constant("tau", tau, T)
    r0, r = tau0_ / T, tau_ / T
    span, dt = model_grid(np.concatenate([r0[has], r[has]]) if has.any() else np.array([0.2]))
    valid = analysis.valid
    q0 = np.where(valid[..., None], np.nan_to_num(analysis.rest_q), q_mean[:, :, None])
    B = S * L * K
    flat = lambda a, tail=(): np.broadcast_to(  # noqa: E731
        np.reshape(a, (S, L, 1) + tail) if np.ndim(a) == 2 + len(tail) else a, (S, L, K) + tail).reshape((B,) + tail)
    tr = normalised_movements(flat(KJ[:, None, None], (3, 3)), flat(q_rest[:, None, None], (3,)), flat(r0), flat(r),
                              flat(q0, (3,)), flat(target, (2,)), span=span, dt=dt, d=analysis.d)
    bw = flat(spline_bandwidth(analysis.lam, analysis.rate)[:, None] / T)
    prof = jax.device_get(_profiles_jit(tr, jnp.asarray(flat(T)), jnp.asarray(0.5 / analysis.rate / flat(T)),
                                        jnp.asarray(bw), h=float(dt), J=_kernel_halfwidth(bw, dt),
                                        threshold=analysis.threshold, n_samples=analysis.mean_path.shape[2],
                                        radius=analysis.radius))
    rs = lambda a: np.asarray(a).reshape((S, L, K) + np.shape(a)[1:])  # noqa: E731
    sim_status = rs(tr.status)
    bad = np.where(valid, sim_status, 0)
    status = np.where(~has, int(Status.TOO_FEW_DATA), np.max(bad, axis=2))
    use = valid & (sim_status == 0)

    def mean(a):  # over the valid trials of each subject × movement; NaN where none
        m = use.reshape(use.shape + (1,) * (a.ndim - 3))
        n = np.maximum(use.sum(2), 1).reshape((S, L) + (1,) * (a.ndim - 3))
        out = np.where(m, a, 0.0).sum(2) / n
        return np.where((use.sum(2) > 0).reshape((S, L) + (1,) * (a.ndim - 3)), out, np.nan)

    a_net = mean(rs(prof["a_net"]))
    p, captured, n_tested, n_captured = compare_curvature(analysis.a_net, a_net)
    W = tau0_[..., None, None] * KJ[:, None]
    J = np.asarray(Wrist(analysis.d).jacobian(q_mean))
    k = np.linalg.eigvalsh(np.asarray(task_damping(J, W)))[..., -1] / tau0_
    ok = status == 0
    t = np.asarray(tr.t)[None, None] * T[..., None]
    return PointingPrediction(
        subjects=analysis.subjects, labels=analysis.labels, tau0=tau0_, tau=tau_, k=np.where(ok, k, np.nan), t=t,
        x=mean(rs(tr.x)), q=mean(rs(tr.q)), speed=mean(np.linalg.norm(rs(tr.xdot), axis=-1) / flat(T).reshape(
            S, L, K, 1)), onset=mean(rs(prof["onset"])), offset=mean(rs(prof["offset"])),
        duration=mean(rs(prof["duration"])), path=mean(rs(prof["path"])), q_path=mean(rs(prof["q_path"])),
        speed_path=mean(rs(prof["speed"])), a_sum=mean(rs(prof["a_sum"])), a_net=a_net, p_model=p,
        captured=captured, n_tested=n_tested, n_captured=n_captured, share_captured=n_captured / L, status=status,
        alpha=_ALPHA,
    )
