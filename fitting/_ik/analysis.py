"""Analysis around IK weights: task/null-space decomposition (Eqs 7–12), contribution
coefficients (Eq 26), the over-specified-joint convention (Experiment 1), bootstrap confidence
intervals over trials, and Hotelling's T² between two conditions.
"""

from __future__ import annotations

import warnings
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

import pmpjax as pj
from pmpjax.internal import (
    as_array,
    as_prng_key,
    check_positive,
    check_positive_int,
    fast_compile_jit,
    pytree_dataclass,
    renamed_keywords,
    to_jax,
)

from .weights import estimate_ik_weights


def ik_decomposition(qdot, xdot, J, w):
    """Split joint velocities into task and null-space parts (Eqs 7–12):
    ``q̇ = q̇_task + q̇_null`` with ``q̇_task = J#_W ẋ`` and ``q̇_null = q̇ − q̇_task``.

    **Arguments:**

    - ``qdot``: (..., K, n) joint velocities [rad/s].
    - ``xdot``: (..., K, m) task velocities.
    - ``J``: (..., K, m, n) Jacobians.
    - ``w``: (..., n) weights (one set per item, shared by its K samples).

    **Returns:**

    ``(qdot_task, qdot_null)``, each (..., K, n) [rad/s].

    **Raises:**

    - ``ValueError`` naming the argument for data that do not share their axes (..., K) or weights
      without the data's batch axes.
    """
    qdot = as_array("qdot", qdot, tail=(None, None))
    n = qdot.shape[-1]
    xdot = as_array("xdot", xdot, tail=(None, None))
    J = as_array("J", J, tail=(None, xdot.shape[-1], n))
    w = as_array("w", w, tail=(n,))
    check_positive("w", w)
    if not (tuple(xdot.shape[:-1]) == tuple(J.shape[:-2]) == tuple(qdot.shape[:-1])):
        raise ValueError(f"`qdot` (..., K, n), `xdot` (..., K, m) and `J` (..., K, m, n) must share the axes (..., K); "
                         f"got {tuple(qdot.shape)}, {tuple(xdot.shape)}, {tuple(J.shape)}")
    batch = tuple(qdot.shape[:-2])
    if tuple(w.shape[:-1]) != batch[len(batch) - (w.ndim - 1):] or w.ndim - 1 > len(batch):
        raise ValueError(f"`w` (..., n) must have the data's batch axes {batch} (or trailing ones), "
                         f"got {tuple(w.shape)}")
    return _decompose(jnp.asarray(qdot), jnp.asarray(xdot), jnp.asarray(J), jnp.asarray(w))


@fast_compile_jit
def _decompose(qdot, xdot, J, w):
    wk = jnp.broadcast_to(w[..., None, :], J.shape[:-2] + w.shape[-1:])
    task = jnp.einsum("...ij,...j->...i", pj.weighted_pinv(J, w=wk), xdot)
    return task, qdot - task


def contribution_coefficients(w):
    """Contribution coefficients ``β_i = w_i⁻¹ / Σ_k w_k⁻¹`` of IK weights (Eq 26); they sum to one.
    Differentiable.

    **Arguments:**

    - ``w``: (..., n) positive weights.

    **Returns:**

    (..., n) the coefficients ``β``.
    """
    w = as_array("w", w, tail=(None,))
    check_positive("w", w)
    return _contributions(to_jax(w))


@fast_compile_jit
def _contributions(w):
    inv = 1.0 / w
    return inv / jnp.sum(inv, axis=-1, keepdims=True)


def overspecified_joints(J, *, mask=None, rtol: float = 1e-6, fraction: float = 0.99):
    """Joints whose Jacobian column lies outside the span of the others (Experiment 1).

    Joint j is over-specified when ``J`` without column j has rank < m at (at least ``fraction`` of
    the valid) samples: every solution of ``J q̇ = ẋ`` then has the same ``q̇_j``, so its IK weight is
    unidentifiable; the paper sets it to 1 and normalises the others
    (``estimate_ik_weights(..., fixed=...)``).

    **Arguments:**

    - ``J``: (..., K, m, n) Jacobians.
    - ``mask``: optional (..., K) bool valid samples.
    - ``rtol``: relative singular-value threshold of the rank test, in (0, 1).
    - ``fraction``: the share of valid samples at which the rank must drop, in (0, 1].

    **Returns:**

    (n,) bool, True for over-specified joints.

    **Raises:**

    - ``ValueError`` naming the argument for a misshaped ``J`` or ``mask``, thresholds out of range, or
      a mask that leaves no valid sample.
    """
    J = np.asarray(as_array("J", J, tail=(None, None)), dtype=float)
    if J.ndim < 2:
        raise ValueError(f"`J` must be (..., m, n) Jacobians, got shape {J.shape}")
    m, n = J.shape[-2:]
    if not 0 < float(rtol) < 1:
        raise ValueError(f"`rtol` must lie in (0, 1), got {rtol}")
    if not 0 < float(fraction) <= 1:
        raise ValueError(f"`fraction` must lie in (0, 1], got {fraction}")
    Jf = J.reshape(-1, m, n)
    if mask is None:
        valid = np.ones(Jf.shape[0], bool)
    else:
        mask = np.asarray(mask)
        if mask.shape != J.shape[:-2] or mask.dtype != bool:
            raise ValueError(f"`mask` must be a boolean array of shape {J.shape[:-2]}, got {mask.dtype} {mask.shape}")
        valid = mask.reshape(-1)
    if not valid.any():
        raise ValueError("`mask` leaves no valid sample")
    Jf = Jf[valid]
    out = np.zeros(n, bool)
    scale = np.linalg.norm(Jf, axis=(-2, -1)) + 1e-300
    for j in range(n):
        s = np.linalg.svd(np.delete(Jf, j, axis=-1), compute_uv=False)
        low = s[:, m - 1] <= rtol * scale if s.shape[-1] >= m else np.ones(len(Jf), bool)
        out[j] = low.mean() >= fraction
    return out


@pytree_dataclass
class BootstrapResult:
    """Bootstrap intervals of IK weights (the result of :func:`bootstrap_ik_weights`).

    **Fields:**

    - ``w``: (..., n) the estimate on all trials, with ``w_status`` (...,) its ``pj.Status``.
    - ``lo``, ``hi``: (..., n) the percentile interval.
    - ``samples``: (B, ..., n) bootstrap replicates, with their ``status`` (B, ...) and
      ``converged`` (B, ...) (``status == SUCCESSFUL``).
    """

    w: jax.Array
    lo: jax.Array
    hi: jax.Array
    samples: jax.Array
    converged: jax.Array
    status: jax.Array
    w_status: jax.Array


def _item_generators(key, batch):
    """One NumPy generator per item (flat order): ``key`` one JAX key per item (batch + key
    shape) -> each item's own stream; one key for a batch -> item i gets the i-th spawned stream
    of the key; one key for an unbatched call -> the key's own stream; an integer (default 0) is
    ``jax.random.PRNGKey`` of it."""
    if key is None or isinstance(key, int | np.integer):
        key = as_prng_key("seed", 0 if key is None else key)
    typed = jnp.issubdtype(getattr(key, "dtype", np.float64), jax.dtypes.prng_key)
    data = np.asarray(jax.random.key_data(key) if typed else key)
    per_item = data.shape[:-1] == batch and data.ndim > 1 and data.shape[-1] == 2
    if per_item:
        if data.dtype != np.uint32:
            raise TypeError(f"`seed` must be an integer or JAX PRNG key(s), got dtype {data.dtype}")
        return [np.random.default_rng(np.random.SeedSequence([int(v) for v in k])) for k in data.reshape(-1, 2)]
    as_prng_key("seed", key)
    entropy = [int(v) for v in data.reshape(-1)]
    if not batch:
        return [np.random.default_rng(np.random.SeedSequence(entropy))]
    B = int(np.prod(batch))
    return [np.random.default_rng(np.random.SeedSequence(entropy, spawn_key=(i,))) for i in range(B)]


#: Bytes of resampled data (``q̇``, ``ẋ``, ``J``, mask) that :func:`bootstrap_ik_weights` hands to the
#: estimator at once: the replicates go in chunks of this size, so that the memory does not grow
#: with ``n_boot`` (the estimator's working arrays are a few times their input).
BOOTSTRAP_CHUNK_BYTES = 96 * 2**20


@renamed_keywords(key="seed")
def bootstrap_ik_weights(qdot, xdot, J, *, mask=None, n_boot: int = 200, seed=None,
                         level: float = 0.95, estimator: str = "algorithm1", **options) -> BootstrapResult:
    """Bootstrap confidence intervals of IK weights, resampling whole trials with replacement.

    An item's replicates depend only on its own data and key: with one key per item, a batch gives
    what its items give one by one with their keys; with one key for a batch, item i (flat order)
    draws from the i-th stream spawned from the key (``numpy.random.SeedSequence``). The estimate on
    the data and the ``n_boot`` replicates of every item run in vectorised calls of the estimator;
    the replicates go in chunks of equal shape (one compilation) of about ``BOOTSTRAP_CHUNK_BYTES``
    of data each, so the peak memory does not grow with ``n_boot``.

    **Arguments:**

    - ``qdot``: (..., T, S, n) joint velocities of T trials of S samples [rad/s].
    - ``xdot``: (..., T, S, m) task velocities.
    - ``J``: (..., T, S, m, n) Jacobians.
    - ``mask``: optional (..., T, S) bool valid samples (a trial with no valid sample is never drawn;
      each replicate draws as many trials as the item has valid ones).
    - ``n_boot``: replicates per item (≥ 2).
    - ``seed``: an integer or a JAX PRNG key (default 0, i.e. ``PRNGKey(0)``), or one key per item
      (shape (...,) + key shape).
    - ``level``: the interval's coverage, in (0, 1): ``lo``/``hi`` are the ``(1 ± level)/2``
      percentiles of the replicates.
    - ``estimator``: ``"algorithm1"`` (:func:`estimate_ik_weights`; items with unusable data are
      flagged, giving NaN, not raising) or ``"lm"`` (:func:`estimate_ik_weights_lm`, the
      least-squares weights of Eq 16).
    - ``options``: passed on to the estimator (``gamma``, ``tol``, ``fixed``, ...).

    **Returns:**

    A :class:`BootstrapResult`.

    **Raises:**

    - ``TypeError`` for keys that are not JAX PRNG keys or an ``on_invalid`` option; ``ValueError``
      naming the argument for data that do not share their axes, a misshaped ``mask``, ``level``
      outside (0, 1), ``n_boot < 2`` or an unknown ``estimator``.
    """
    qdot = as_array("qdot", qdot, tail=(None, None, None), finite=False)
    xdot = as_array("xdot", xdot, tail=(None, None, None), finite=False)
    J = as_array("J", J, tail=(None, None, None, None), finite=False)
    if not 0 < float(level) < 1:
        raise ValueError(f"`level` must lie in (0, 1), got {level}")
    n_boot = check_positive_int("n_boot", n_boot)
    if n_boot < 2:
        raise ValueError(f"`n_boot` must be an integer >= 2, got {n_boot}")
    *batch, T, S, n = qdot.shape
    batch = tuple(batch)
    if tuple(xdot.shape[:-1]) != batch + (T, S) or tuple(J.shape[:-2]) != batch + (T, S):
        raise ValueError(f"`qdot` (..., T, S, n), `xdot` (..., T, S, m) and `J` (..., T, S, m, n) must share the axes "
                         f"(..., T, S); got {tuple(qdot.shape)}, {tuple(xdot.shape)}, {tuple(J.shape)}")
    if "on_invalid" in options:
        raise TypeError("`on_invalid` is not an option of bootstrap_ik_weights (unusable items are always flagged)")
    if estimator not in ("algorithm1", "lm"):
        raise ValueError(f"`estimator` must be 'algorithm1' or 'lm', got {estimator!r}")
    mask = np.ones(batch + (T, S), bool) if mask is None else np.asarray(mask)
    if mask.shape != batch + (T, S) or mask.dtype != bool:
        raise ValueError(f"`mask` must be a boolean array of shape {batch + (T, S)}, got {mask.dtype} {mask.shape}")
    gens = _item_generators(seed, batch)
    trial_ok = mask.any(-1)  # (..., T)
    n_ok = trial_ok.sum(-1)[..., None]  # (..., 1)
    # each replicate draws as many trials as the item has: keep max(n_ok) slots, mask the rest
    Tb = max(int(n_ok.max()), 1)
    # replicate 0 is the data itself (valid trials first), so one compiled call does everything
    order = np.argsort(~trial_ok, axis=-1, kind="stable")  # (..., T) valid trials first
    # per item: (n_boot, T) uniforms from its own stream, of which the first n_ok columns are used
    # (so an item's draws do not depend on the other items of the batch)
    u = np.stack([g.random((n_boot, T)) for g in gens], axis=1).reshape((n_boot,) + batch + (T,))
    pick = np.floor(u[..., :Tb] * np.maximum(n_ok, 1)).astype(int)
    boot = np.take_along_axis(np.broadcast_to(order, (n_boot,) + order.shape), pick, axis=-1)
    idx = np.concatenate([order[None, ..., :Tb], boot], axis=0)
    n_rep = n_boot + 1

    def take(a, ix):
        """``a``'s trials drawn by ``ix`` (r, ..., Tb): (r, ..., Tb·S, ...)."""
        a = np.asarray(a)
        rest = a.shape[len(batch) + 2:]
        g = np.take_along_axis(a[None], ix.reshape(ix.shape + (1,) * (1 + len(rest))), axis=len(batch) + 1)
        return g.reshape(ix.shape[:1] + batch + (Tb * S,) + rest)

    used = np.arange(Tb) < n_ok  # (..., Tb)
    m, B = J.shape[-2], int(np.prod(batch, dtype=int))
    per_rep = 8 * B * Tb * S * (m * n + m + n + 1)
    chunk = int(min(n_rep, max(1, BOOTSTRAP_CHUNK_BYTES // max(per_rep, 1))))
    parts = []
    for c0 in range(0, n_rep, chunk):
        sel = np.arange(c0, c0 + chunk)
        sel = np.where(sel < n_rep, sel, 0)  # the last chunk padded to the same shape (one compilation)
        ix = idx[sel]
        mk = take(mask, ix).reshape((chunk,) + batch + (Tb, S)) & used[..., None]
        mk = mk.reshape((chunk,) + batch + (Tb * S,))
        if estimator == "lm":
            from .weights import estimate_ik_weights_lm

            gq, gx, gJ = take(qdot, ix), take(xdot, ix), take(J, ix)
            ok = ~_unusable(gq, gx, gJ, mk)
            res = estimate_ik_weights_lm(np.where(ok[..., None, None], gq, 0.0), np.where(ok[..., None, None], gx, 0.0),
                                         np.where(ok[..., None, None, None], gJ, _padding_jacobian(m, n)),
                                         mask=mk | ~ok[..., None], **options)
            st = np.where(ok, np.asarray(res.status), int(pj.Status.INVALID_INPUT))
            w = np.where(ok[..., None], np.asarray(res.w), np.nan)
        else:
            res = estimate_ik_weights(take(qdot, ix), take(xdot, ix), take(J, ix), on_invalid="flag", mask=mk,
                                      **options)
            st, w = np.asarray(res.status), np.asarray(res.w)
        keep = slice(0, min(chunk, n_rep - c0))
        parts.append((w[keep], st[keep]))
    w_all = np.concatenate([p[0] for p in parts])
    st = np.concatenate([p[1] for p in parts])
    conv = st == int(pj.Status.SUCCESSFUL)
    a = (1.0 - float(level)) / 2.0
    ws = w_all[1:]
    with np.errstate(invalid="ignore"), warnings.catch_warnings():  # (items without data: NaN)
        warnings.filterwarnings("ignore", "All-NaN slice", RuntimeWarning)
        lo, hi = np.nanquantile(ws, a, axis=0), np.nanquantile(ws, 1.0 - a, axis=0)
    return BootstrapResult(w=to_jax(w_all[0]), lo=to_jax(lo), hi=to_jax(hi), samples=to_jax(ws),
                           converged=to_jax(conv[1:]), status=to_jax(st[1:]), w_status=to_jax(st[0]))


def _padding_jacobian(m, n):
    """The Jacobian put in the samples of an unusable item (any full-rank one: they are masked)."""
    return np.eye(m, n)


def _unusable(qdot, xdot, J, mask):
    """(...) items the LM estimator would refuse: no valid sample, or NaN/inf or a rank-deficient
    Jacobian at a valid one (Algorithm 1 flags them itself)."""
    fin = np.isfinite(qdot).all(-1) & np.isfinite(xdot).all(-1) & np.isfinite(J).all((-2, -1))
    JJ = np.einsum("...ij,...kj->...ik", np.nan_to_num(J), np.nan_to_num(J))
    m = J.shape[-2]
    with np.errstate(all="ignore"):
        tr = np.trace(JJ, axis1=-2, axis2=-1) / m
        full = np.linalg.det(JJ) / np.where(tr > 0, tr, 1.0) ** m > 1e-10
    return ~(mask.any(-1)) | np.any(mask & ~(fin & full), axis=-1)


@pytree_dataclass
class HotellingResult:
    """Hotelling's T² test (the result of :func:`hotelling_t2`).

    **Fields:** ``t2`` Hotelling's T²; ``f`` its F statistic with ``df1``, ``df2`` degrees of freedom;
    ``p`` the p-value.
    """

    t2: jax.Array
    f: jax.Array
    df1: jax.Array
    df2: jax.Array
    p: jax.Array


def hotelling_t2(a, b, *, paired: bool = True) -> HotellingResult:
    """Hotelling's T² test that two conditions have equal mean vectors (Experiment 1).

    Paired (the same N subjects in both conditions): ``T² = N d̄ᵀ S_d⁻¹ d̄``,
    ``F = (N − p) / (p (N − 1)) T² ~ F(p, N − p)``. Independent samples: pooled covariance,
    ``F = (N1 + N2 − p − 1) / (p (N1 + N2 − 2)) T² ~ F(p, N1 + N2 − p − 1)``. Drop variables that are
    constant in both conditions (e.g. weights fixed at 1) before calling: S must be invertible.

    **Arguments:**

    - ``a``: (N, p) or (N1, p) the first condition's vectors (e.g. IK weights per subject).
    - ``b``: (N, p) or (N2, p) the second condition's.
    - ``paired``: paired (default) or independent samples.

    **Returns:**

    A :class:`HotellingResult`.

    **Raises:**

    - ``TypeError`` for a non-bool ``paired``; ``ValueError`` for misshaped or unequal (paired)
      inputs, too few subjects for the number of variables, or a singular covariance.
    """
    a = to_jax(as_array("a", a, tail=(None,)), dtype=float)
    b = to_jax(as_array("b", b, tail=(a.shape[-1],)), dtype=float)
    if a.ndim != 2 or b.ndim != 2:
        raise ValueError(f"`a` and `b` must be (N, p) matrices, got {a.shape} and {b.shape}")
    if not isinstance(paired, bool | np.bool_):
        raise TypeError(f"`paired` must be True or False, got {paired!r}")
    p = a.shape[1]
    if paired:
        if a.shape != b.shape:
            raise ValueError(f"paired test needs equal shapes, got {a.shape} and {b.shape}")
        N = a.shape[0]
        if N <= p:
            raise ValueError(f"need more subjects than variables (N = {N}, p = {p})")
        df1, df2 = p, N - p
    else:
        n1, n2 = a.shape[0], b.shape[0]
        if n1 + n2 - p - 1 < 1:
            raise ValueError(f"too few samples (N1 = {n1}, N2 = {n2}) for p = {p} variables")
        df1, df2 = p, n1 + n2 - p - 1
    t2, f, S, pval = _hotelling(a, b, bool(paired))
    Sn = np.asarray(S)
    if np.linalg.matrix_rank(Sn, tol=1e-12 * max(float(np.abs(Sn).max()), 1e-300)) < p:
        raise ValueError("the covariance of `a`/`b` is singular: drop variables that are constant or "
                         "linearly dependent (e.g. weights fixed at 1) before the test")
    return HotellingResult(t2=t2, f=f, df1=to_jax(np.asarray(df1)), df2=to_jax(np.asarray(df2)), p=pval)


@partial(fast_compile_jit, static_argnums=2)
def _hotelling(a, b, paired):
    """``T²``, ``F``, the pooled covariance and the p-value of :func:`hotelling_t2` (one compiled call)."""
    p = a.shape[1]
    if paired:
        N = a.shape[0]
        d = a - b
        dbar = d.mean(0)
        dc = d - dbar[None]
        S = dc.T @ dc / (N - 1)
        t2 = N * dbar @ jnp.linalg.solve(S, dbar)
        df1, df2 = p, N - p
        f = (N - p) / (p * (N - 1)) * t2
    else:
        n1, n2 = a.shape[0], b.shape[0]
        da, db = a - a.mean(0)[None], b - b.mean(0)[None]
        S = (da.T @ da + db.T @ db) / (n1 + n2 - 2)
        diff = a.mean(0) - b.mean(0)
        t2 = n1 * n2 / (n1 + n2) * diff @ jnp.linalg.solve(S, diff)
        df1, df2 = p, n1 + n2 - p - 1
        f = df2 / (p * (n1 + n2 - 2)) * t2
    # F survival function through the regularised incomplete beta function
    x = df2 / (df2 + df1 * f)
    return t2, f, S, jax.scipy.special.betainc(df2 / 2.0, df1 / 2.0, x)
