"""IK-weight identification (Khoramshahi et al. 2022, Eqs 15–24, Algorithm 1), vectorised.

Model (Eq 16), with diagonal ``W = diag(w)``, ``J# = W⁻¹ Jᵀ (J W⁻¹ Jᵀ)⁻¹`` and ``N = I − J# J``:
``q̇̄_k = J#_k ẋ_k + v̄_k``, ``v̄_k = γ N_k q̇_k``, error ``e_k = q̇_k − q̇̄_k`` (= ``(1 − γ) N_k q̇_k``
when ``ẋ_k = J_k q̇_k``, Eq 17). Update (Eqs 18–24): ``W Ψ = Ω`` with ``Ψ = (Q̇ − V̄) Q̇ᵀ``,
``Ω = Ū Q̇ᵀ``, ``ū_k = Jᵀ (J W⁻¹ Jᵀ)⁻¹ ẋ_k``. Because ``W`` is diagonal, the QP of Eq 24,
``½ Σ_ij (w_i Ψ_ij − Ω_ij)²`` on the box ``[w_min, 1]ⁿ``, has the diagonal Hessian
``H_ii = Σ_j Ψ_ij²`` and separates per joint; its exact solution is the clipped ratio
``w_i = clip(Σ_j Ψ_ij Ω_ij / Σ_j Ψ_ij², w_min, 1)`` (tested against a QP solver). Then
``w ← w / max w``.

Convergence: the update is a fixed-point iteration that converges linearly; a run converges when
its weights are within ``tol`` (relative) of the fixed point, judged from the steps and their
contraction, and it reports SUCCESSFUL only if that fixed point is an answer of the model (no
active bound, weights determined by the data, close to the least-squares weights of the same
error). The paper's stopping rule ``e ≤ ε`` is not a convergence test: ``e`` has the floor
``(1 − γ) |N q̇|`` wherever the data hold null-space motion, and it is in the units of q̇.

Arrays are samples-first: ``qdot`` (..., K, n), ``xdot`` (..., K, m), ``J`` (..., K, m, n) with any
leading batch axes (subjects, conditions, bootstrap replicates); one compiled call for all.
"""

from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from pmpjax import Status
from pmpjax.internal import (
    TopLevelOptionsJit,
    as_array,
    check_positive,
    check_positive_int,
    det_lists,
    fast_compile_jit,
    flatten_batch,
    is_concrete,
    mv,
    on_host,
    pinv_apply_diag_soa,
    pinv_diag_lists,
    pytree_dataclass,
    renamed_keywords,
    to_jax,
    to_soa,
    unflatten_batch,
)

from .._optimise import least_squares


@pytree_dataclass
class IKWeightsResult:
    """Per-item result of :func:`estimate_ik_weights` (leading axes = the inputs' batch axes).

    ``w`` (..., n) weights in ``[w_min, 1]`` with ``max w = 1`` (over free joints); ``error`` (...,)
    the mean modelling error ``(1/K) Σ |q̇_k − q̇̄_k|`` of the last evaluation (Algorithm 1, line 8);
    ``error_history`` (..., max_steps) one entry per iteration (NaN after the item stopped);
    ``iterations`` (...,) updates done; ``gamma`` (...,) the null-space ratio at the end;
    ``ls_gap`` (...,) ``max_i |log w_i − log w_i^LS|``, the relative distance from ``w`` to the
    least-squares weights of the same modelling error (one Gauss–Newton step; inf where the data do
    not determine the weights); ``status`` (...,) int ``pj.Status`` code:

    - ``SUCCESSFUL``: converged and an answer of the model: the weights are within ``tol``
      (relative) of the fixed point of the update — the last step Δ times θ/(1 − θ), θ the
      observed contraction factor of the steps — and at that fixed point no bound of the box QP
      is active (a free weight below ``w_min``, or two above ``w_max``), the data determine the
      weight ratios, and ``ls_gap ≤ ls_tol``;
    - ``STALLED``: the steps fell below ``step_tol`` before that (the update crawls), or a fixed
      point that fails the bound or ``ls_gap`` check (``w`` is then that fixed point);
    - ``TOO_FEW_DATA``: a fixed point, but the data do not determine the weight ratios (e.g. a
      joint that never moves, too few samples);
    - ``SCHEDULE_END``: with a γ schedule, the run stopped (γ → 1 stops the updates whatever the
      weights) at weights that fail the checks at the starting ratio, or on ``step_tol``;
    - ``MAX_STEPS``: ``max_steps`` updates without a stop; ``NONFINITE``; ``INVALID_INPUT`` (only
      with ``on_invalid="flag"``).

    ``converged`` (...,) is ``status == SUCCESSFUL``.
    """

    w: jax.Array
    error: jax.Array
    error_history: jax.Array
    iterations: jax.Array
    converged: jax.Array
    gamma: jax.Array
    status: jax.Array
    ls_gap: jax.Array


# ---------------------------------------------------------------------------------------------
# input checks (Python side, before tracing)


def _check_inputs(qdot, xdot, J, mask):
    qdot = as_array("qdot", qdot, tail=(None, None), finite=False)
    xdot = as_array("xdot", xdot, tail=(None, None), finite=False)
    J = as_array("J", J, tail=(None, None, None), finite=False)
    n, m = qdot.shape[-1], xdot.shape[-1]
    if J.shape[-2:] != (m, n):
        raise ValueError(
            f"`J` must have trailing shape (m, n) = ({m}, {n}) to match `xdot` (..., K, {m}) and "
            f"`qdot` (..., K, {n}); got {tuple(J.shape)}"
        )
    if not m < n:
        raise ValueError(f"IK weights need a redundant chain (m < n); got m = {m}, n = {n}")
    lead = tuple(qdot.shape[:-1])
    if tuple(xdot.shape[:-1]) != lead or tuple(J.shape[:-2]) != lead:
        raise ValueError(
            "`qdot` (..., K, n), `xdot` (..., K, m) and `J` (..., K, m, n) must share the batch "
            f"and sample axes (..., K); got {tuple(qdot.shape)}, {tuple(xdot.shape)}, {tuple(J.shape)}"
        )
    if mask is not None:
        mask = np.asarray(mask) if is_concrete(mask) else mask
        if tuple(np.shape(mask)) != lead:
            raise ValueError(f"`mask` must have shape (..., K) = {lead}, got {tuple(np.shape(mask))}")
        if is_concrete(mask) and np.asarray(mask).dtype != bool:
            raise TypeError(f"`mask` must be boolean, got dtype {np.asarray(mask).dtype}")
    return qdot, xdot, J, mask


def _check_gamma(gamma, gamma_rate):
    if is_concrete(gamma):
        g = np.asarray(gamma, dtype=float)
        if not np.all(np.isfinite(g)) or np.any(g < 0) or np.any(g > 1):
            raise ValueError(f"`gamma` must lie in [0, 1], got {g if g.size < 8 else (g.min(), g.max())}")
    if gamma_rate is not None:
        c = float(gamma_rate)
        if not (0.0 <= c <= 1.0):
            raise ValueError(f"`gamma_rate` must lie in [0, 1] (γ ← γ + c (1 − γ)), got {c}")


def _check_gamma_shape(g, batch):
    try:
        ok = not g.ndim or tuple(np.broadcast_shapes(g.shape, batch)) == batch
    except ValueError:
        ok = False
    if not ok:
        raise ValueError(f"`gamma` must be a scalar or broadcast to the batch shape {batch}, got shape {g.shape}")


def _fixed_mask(fixed, n):
    if fixed is None:
        return (False,) * n
    f = np.asarray(fixed)
    if f.dtype == bool:
        if f.shape != (n,):
            raise ValueError(f"`fixed` must be a boolean (n,) = ({n},) mask or joint indices, got {f.shape}")
        out = tuple(bool(v) for v in f)
    else:
        idx = np.atleast_1d(f).astype(int)
        if np.any((idx < 0) | (idx >= n)):
            raise ValueError(f"`fixed` joint indices must lie in [0, {n}), got {idx}")
        out = tuple(i in set(idx.tolist()) for i in range(n))
    if all(out):
        raise ValueError("`fixed` cannot hold every joint")
    return out


# ---------------------------------------------------------------------------------------------
# kernels (component-leading element lists: vectors are lists of (C, K) arrays, weights (n, C, 1);
# C items of one chunk, K samples contiguous; elementwise, no per-sample matmuls). An iteration is
# ONE fused pass over the samples: the two weighted pseudo-inverse solves (this iteration's weights
# and, for the error, the previous ones — recomputed rather than carried, since writing v̄ out
# would split the pass), the error and all 2n² sums over k (Σ v̄ q̇ᵀ, Σ ū q̇ᵀ) in one variadic
# reduce; the 3 × 3 solve is the adjugate (one division, see ``spd_solve_lists``), which XLA:CPU
# keeps inside the fused loop (an LDLᵀ's divisions each cut it: 2× slower). J q̇ and Q̇ Q̇ᵀ are
# computed once. Large problems run in cache-sized chunks of items (lax.map), each chunk iterating
# until its own items stop; with several devices the items are split over them first (shard_map).

_CHUNK_SAMPLES = 25_000  # items × samples per chunk (≈ 6 MB of inputs; measured best on this CPU)
_DIRECT_SAMPLES = 150_000  # up to this many items × samples (per device): no chunking
# The sample sums may be reassociated (NaN/inf/division/sqrt semantics kept): XLA:CPU then
# vectorises the reductions over k, which it does not do in strict IEEE order (3.8× for the
# whole kernel: 0.23 s instead of 0.86 s for the 1 000-subject benchmark). Results differ from a
# strict left-to-right summation only by rounding (≈ 1e-16 relative per sum; after 50 iterations
# the weights of the Fig 1 data agree with the strict-order ones to 2e-13 for 99 % of subjects,
# 2e-11 for the worst-conditioned one, whose float64 baseline is itself 6e-9 from an
# extended-precision computation).
_FAST_SUMS = {
    "xla_cpu_enable_fast_math": True,
    "xla_cpu_fast_math_honor_nans": True,
    "xla_cpu_fast_math_honor_infs": True,
    "xla_cpu_fast_math_honor_division": True,
    "xla_cpu_fast_math_honor_functions": True,
}


def _sample_sums(ops):
    """``Σ_k`` of every (C, K) array in ``ops`` -> list of (C,), in one fused pass."""
    zero = jnp.zeros((), ops[0].dtype)
    return lax.reduce(ops, [zero] * len(ops), lambda a, b: [x + y for x, y in zip(a, b)], (1,))


def _qp_update(w, psi, omega, w_min, w_max, fixed):
    """Algorithm 1 lines 16–21: the box QP of Eq 24 solved exactly, then normalised.

    ``psi``, ``omega`` (n, n, C); ``w`` (n, C, 1) the current weights (kept where a row of Ψ is 0).
    ``Ψ̃`` stacks ``diag(Ψ_{:, j})``, so ``H = Ψ̃ᵀ Ψ̃`` is diagonal (``H_ii = Σ_j Ψ_ij²``) and the QP
    separates per joint: its minimiser on ``[w_min, w_max]`` is the clipped ratio
    ``clip(−F_i / H_ii)``, ``−F_i = Σ_j Ψ_ij Ω_ij`` (tested against ``scipy.optimize.lsq_linear``
    on the whole Algorithm 1). Returns the weights (n, C) and whether a bound of the box decided
    them (C,): a free weight below ``w_min``, or two or more above ``w_max`` (their ratio is lost)."""
    num = jnp.sum(psi * omega, axis=1)  # −F_i = Σ_j Ψ_ij Ω_ij
    den = jnp.sum(psi * psi, axis=1)  # H_ii = Σ_j Ψ_ij²
    safe = den > 1e-300
    raw = jnp.where(safe, num / jnp.where(safe, den, 1.0), w[:, ..., 0])
    wn = jnp.clip(raw, w_min, w_max)
    free = jnp.asarray([not f for f in fixed]).reshape((-1,) + (1,) * (wn.ndim - 1))
    bound = jnp.any(free & (raw < w_min), axis=0) | (jnp.sum(free & (raw > w_max), axis=0) > 1)
    # over-specified joints (Experiment 1): set back to 1, normalise the others only
    scored = jnp.where(free, wn, -jnp.inf)
    top = jnp.max(scored, axis=0, keepdims=True)
    # XLA may evaluate ``wn`` in the max and in the division with different FMA contractions, so
    # ``wn / top`` can miss 1 by an ulp at the largest weight: set that one to exactly 1.
    joint = jnp.arange(wn.shape[0]).reshape((-1,) + (1,) * (wn.ndim - 1))
    largest = joint == jnp.argmax(scored, axis=0, keepdims=True)
    return jnp.where(free & ~largest, jnp.minimum(wn / top, 1.0), 1.0), bound


def _helmert(k):
    """Orthonormal basis (k, k − 1) of the vectors orthogonal to ``(1, …, 1)`` (NumPy, static)."""
    B = np.zeros((k, max(k - 1, 0)))
    for j in range(1, k):
        B[:j, j - 1] = 1.0
        B[j, j - 1] = -float(j)
        B[:, j - 1] /= np.sqrt(j * (j + 1.0))
    return B


def _ls_check(w, q, x, Jl, Jq, gamma, fixed, rank_tol):
    """The least-squares view of the modelling error at the weights ``w`` (n, C, 1).

    Residual (Eq 16 with the null-space estimate of the same weights) ``r_k = (1 − γ) q̇_k − t_k``,
    ``t_k = J#(ẋ_k − γ J q̇_k)``; its derivative along ``θ_i = log w_i`` is ``N_k e_i t_ki``
    (``N = I − J# J``). Sums ``G = Σ_k Dᵀ D`` (the Gauss–Newton matrix) and ``g = Σ_k Dᵀ r`` over
    the samples, restricted to the free joints and to the directions that change their ratios
    (the common scale is the normalisation's). Returns per item (C,): whether the data determine
    the ratios (``λ_min(G) > rank_tol λ_max(G)``) and the Gauss–Newton step from ``w`` to the
    least-squares weights ``max_i |Δθ_i|`` (inf when not determined)."""
    n = len(q)
    m = len(x)
    free = [i for i in range(n) if not fixed[i]]
    C = q[0].shape[0]
    if len(free) < 2:  # one free weight: it is 1 by the normalisation
        return jnp.ones((C,), bool), jnp.zeros((C,), q[0].dtype)
    g1 = gamma[:, None]
    b = [x[r] - g1 * Jq[r] for r in range(m)]
    cols = [[Jl[r][i] for r in range(m)] for i in free]
    t, *P = pinv_diag_lists(Jl, [1.0 / w[i] for i in range(n)], b, *cols)  # J# b, J# J e_i
    D = [[((1.0 if a == i else 0.0) - P[c][a]) * t[i] for a in range(n)] for c, i in enumerate(free)]
    r = [(1.0 - g1) * q[a] - t[a] for a in range(n)]
    f = len(free)
    pairs = [(c, d) for c in range(f) for d in range(c, f)]
    sums = _sample_sums([sum(D[c][a] * D[d][a] for a in range(n)) for c, d in pairs]
                        + [sum(D[c][a] * r[a] for a in range(n)) for c in range(f)])
    G = jnp.zeros((C, f, f), q[0].dtype)
    for (c, d), v in zip(pairs, sums[: len(pairs)]):
        G = G.at[:, c, d].set(v).at[:, d, c].set(v)
    g = jnp.stack(sums[len(pairs):], axis=-1)  # (C, f)
    B = jnp.asarray(_helmert(f), q[0].dtype)
    Gr = B.T @ G @ B
    lam = jnp.linalg.eigvalsh(Gr)
    determined = (lam[:, 0] > rank_tol * lam[:, -1]) & (lam[:, -1] > 0)
    step = -jnp.linalg.solve(jnp.where(determined[:, None, None], Gr, jnp.eye(f - 1)), (g @ B)[..., None])[..., 0]
    gap = jnp.max(jnp.abs(step @ B.T), axis=-1)
    return determined, jnp.where(determined & jnp.isfinite(gap), gap, jnp.inf)


def _algorithm1_chunk(qd, xd, Jc, valid, gamma0, rate, w_min, w_max, tol, step_tol, ls_tol, rank_tol, max_steps,
                      fixed):
    """Algorithm 1 on one chunk: ``qd`` (n, C, K), ``xd`` (m, C, K), ``Jc`` (m, n, C, K),
    ``valid`` (C, K), ``gamma0`` (C,). Iterates until every item of the chunk has stopped, then
    checks the weights of the items that reached a fixed point (:func:`_ls_check`).
    Masked samples hold q̇ = ẋ = 0 and a full-rank J (see :func:`_prepare`), so they add exactly
    0 to every sum below."""
    n, C = qd.shape[:2]
    m = xd.shape[0]
    count = jnp.sum(valid.astype(qd.dtype), axis=-1)
    q = [qd[i] for i in range(n)]
    x = [xd[r] for r in range(m)]
    Jl = [[Jc[r, i] for i in range(n)] for r in range(m)]
    # loop invariants, computed once: J q̇ (m × (C, K)) and Q̇ Q̇ᵀ (n, n, C)
    Jq = [sum(Jl[r][i] * q[i] for i in range(n)) for r in range(m)]
    qq = _sample_sums([q[i] * q[j] for i in range(n) for j in range(n)])
    qqT = jnp.stack(qq).reshape((n, n, C))
    scheduled = rate > 0

    def body(s):
        w, g = s["w"], s["gamma"]
        # J# ẋ and J# J q̇ through the one weighted pseudo-inverse (Eq 4), J# = W⁻¹ Jᵀ (J W⁻¹ Jᵀ)⁻¹
        task, proj = pinv_diag_lists(Jl, [1.0 / w[i] for i in range(n)], x, Jq)
        # the previous iteration's null-space estimate v̄ = γ (I − J# J) q̇ is recomputed from its
        # weights, not carried: the whole iteration is then one fused pass over the samples
        (proj_p,) = pinv_diag_lists(Jl, [1.0 / s["w_prev"][i] for i in range(n)], Jq)
        g_p = s["gamma_prev"][:, None]
        # Algorithm 1 lines 7–8: error with the null-space estimate of the previous iteration
        e = jnp.sqrt(sum((q[i] - task[i] - g_p * (q[i] - proj_p[i])) ** 2 for i in range(n)))
        gk = g[:, None]
        Vn = [gk * (q[i] - proj[i]) for i in range(n)]  # line 10: v̄ = γ (I − J# J) q̇
        u = [w[i] * task[i] for i in range(n)]  # ū = Jᵀ B ẋ = W J# ẋ (Eq 18)
        sums = _sample_sums([e] + [a[i] * q[j] for a in (Vn, u) for i in range(n) for j in range(n)])
        S = jnp.stack(sums[1 : 1 + n * n]).reshape((n, n, C))  # V̄ Q̇ᵀ
        omega = jnp.stack(sums[1 + n * n :]).reshape((n, n, C))  # Ω = Ū Q̇ᵀ
        err = sums[0] / count
        psi = qqT - S  # Ψ = (Q̇ − V̄) Q̇ᵀ
        wn, bound = _qp_update(w, psi, omega, w_min, w_max, fixed)
        wn = wn[..., None]
        active = ~s["done"]
        finite = jnp.all(jnp.isfinite(wn), axis=(0, -1)) & jnp.isfinite(err)
        # Convergence to the fixed point of the update, not the paper's e ≤ ε: the error of Eq 17
        # has a floor wherever the data hold null-space motion (e = (1 − γ) N q̇ ≠ 0 at the true
        # weights), and it depends on the units of the velocities. The update converges linearly;
        # with the relative step Δ_t = max |log w_{t+1} − log w_t| and its contraction factor
        # θ = Δ_t / Δ_{t−1} (the larger of the last two), the weights are within Δ_t θ / (1 − θ)
        # of the fixed point (relative); the run stops when that is below tol / 2 (the ratio of the
        # steps approaches θ from below: the estimate runs ≈ 10 % short). A small step alone is
        # no test: at θ = 0.999 a step of 10⁻⁶ leaves 10⁻³ to go.
        step = jnp.max(jnp.abs(jnp.log(wn) - jnp.log(w)), axis=(0, -1))
        prev = s["step"]
        ratio = jnp.where(jnp.isfinite(prev) & (prev > 0), step / jnp.where(prev > 0, prev, 1.0), jnp.inf)
        theta = jnp.maximum(ratio, s["ratio"])
        dist = jnp.where(step == 0, 0.0, jnp.where(theta < 1, step * theta / jnp.where(theta < 1, 1.0 - theta, 1.0),
                                                   jnp.inf))
        status = jnp.select(
            # (``<``: tol = 0 / step_tol = 0 turn the rules off, also at an exact fixed point)
            [~finite, dist < 0.5 * tol, step < step_tol],
            [Status.NONFINITE, Status.SUCCESSFUL, jnp.where(scheduled, Status.SCHEDULE_END, Status.STALLED)],
            Status.MAX_STEPS).astype(jnp.int32)
        stop = status != Status.MAX_STEPS
        it = s["it"]
        a1 = active[:, None]
        keep = active & finite
        return dict(
            w=jnp.where(a1 & finite[:, None], wn, w),
            w_prev=jnp.where(a1, w, s["w_prev"]),
            gamma_prev=jnp.where(active, g, s["gamma_prev"]),
            gamma=jnp.where(active, g + rate * (1.0 - g), g),  # γ_{t+1} = γ_t + c (1 − γ_t)
            err=jnp.where(active, err, s["err"]),
            hist=s["hist"].at[it].set(jnp.where(active, err, jnp.nan)),
            iters=s["iters"] + active.astype(s["iters"].dtype),
            status=jnp.where(active, status, s["status"]),
            done=s["done"] | stop,
            step=jnp.where(active, step, s["step"]),
            ratio=jnp.where(active, ratio, s["ratio"]),
            bound=jnp.where(keep, bound, s["bound"]),
            it=it + 1,
        )

    def cond(s):
        return (s["it"] < max_steps) & ~jnp.all(s["done"])

    s0 = dict(
        w=jnp.ones((n, C, 1), qd.dtype),
        w_prev=jnp.ones((n, C, 1), qd.dtype),
        gamma_prev=jnp.zeros((C,), qd.dtype),  # no null-space estimate before the first update
        gamma=gamma0.astype(qd.dtype),
        err=jnp.full((C,), jnp.nan, qd.dtype),
        hist=jnp.full((max_steps, C), jnp.nan, qd.dtype),
        iters=jnp.zeros((C,), jnp.int32),
        # items without a valid sample (flagged or padding) never start
        status=jnp.where(count == 0, Status.INVALID_INPUT, Status.MAX_STEPS).astype(jnp.int32),
        done=count == 0,
        step=jnp.full((C,), jnp.inf, qd.dtype),
        ratio=jnp.full((C,), jnp.inf, qd.dtype),
        bound=jnp.zeros((C,), bool),
        it=jnp.asarray(0),
    )
    s = lax.while_loop(cond, body, s0)
    # A fixed point is an answer of the model only if no bound of the box QP decided it, the data
    # determine the weights, and it agrees with the least-squares weights of the same modelling
    # error (at the starting ratio γ0) to ``ls_tol``: with null-space motion that is correlated
    # with the task motion (or data that the model does not describe) the quasi-static update has
    # fixed points far from those weights, and from the weights that made the data.
    determined, gap = _ls_check(s["w"], q, x, Jl, Jq, gamma0.astype(qd.dtype), fixed, rank_tol)
    gap = jnp.where(count > 0, gap, jnp.nan)
    not_answer = jnp.where(scheduled, Status.SCHEDULE_END, Status.STALLED)
    status = s["status"]
    # (each sample holds n − m equations on the f − 1 ratios of the f free weights)
    few = count * (n - m) < sum(not f for f in fixed) - 1
    verdict = jnp.select([few, s["bound"], ~determined, ~(gap <= ls_tol)],
                         [Status.TOO_FEW_DATA, not_answer, Status.TOO_FEW_DATA, not_answer], Status.SUCCESSFUL)
    status = jnp.where(status == Status.SUCCESSFUL, verdict, status).astype(jnp.int32)
    return s["w"][..., 0], s["err"], s["hist"], s["iters"], status, s["gamma"], gap


def _algorithm1_local(qdot, xdot, J, mask, gamma0, rate, w_min, w_max, tol, step_tol, ls_tol, rank_tol, *,
                      max_steps, fixed, chunk):
    """All items of one device: ``qdot`` (B, K, n), ``xdot`` (B, K, m), ``J`` (B, K, m, n),
    ``mask`` (B, K), ``gamma0`` (B,). Items are padded to whole chunks of ``chunk`` (padding has no
    valid sample, so it stops at once). Returns w (B, n), err (B,), hist (B, max_steps), …"""
    B0 = qdot.shape[0]
    pad = -B0 % chunk
    if pad:
        padB = lambda a: jnp.concatenate([a, jnp.zeros((pad,) + a.shape[1:], a.dtype)])  # noqa: E731
        qdot, xdot, J, mask, gamma0 = (padB(a) for a in (qdot, xdot, J, mask, gamma0))
    B = qdot.shape[0]
    run = partial(_algorithm1_chunk, rate=rate, w_min=w_min, w_max=w_max, tol=tol,
                  step_tol=step_tol, ls_tol=ls_tol, rank_tol=rank_tol, max_steps=max_steps, fixed=fixed)

    def one(c):  # one chunk, item-first -> component-leading (in cache), then iterate
        return run(*_prepare(*c[:4]), c[4])

    items = (qdot, xdot, J, mask, gamma0)
    if chunk >= B:
        return _items_first(one(items), B0)
    nc = B // chunk

    def join(a):  # (nc, …, chunk) -> (…, B)
        return jnp.moveaxis(a, 0, -2).reshape(a.shape[1:-1] + (B,))

    out = lax.map(one, tuple(a.reshape((nc, chunk) + a.shape[1:]) for a in items))
    return _items_first(tuple(join(a) for a in out), B0)


def _algorithm1_all(qdot, xdot, J, mask, gamma0, rate, w_min, w_max, tol, step_tol, ls_tol, rank_tol, *,
                    max_steps, fixed, chunk, mesh=None):
    """:func:`_algorithm1_local` on one device, or (``mesh``: a 1-D mesh with axis "items") on
    each device's share of the items (B divisible by the mesh size), without communication."""
    local = partial(_algorithm1_local, max_steps=max_steps, fixed=fixed, chunk=chunk)
    if mesh is None:
        return local(qdot, xdot, J, mask, gamma0, rate, w_min, w_max, tol, step_tol, ls_tol, rank_tol)
    items, rep = PartitionSpec("items"), PartitionSpec()
    return jax.shard_map(local, mesh=mesh, in_specs=(items,) * 5 + (rep,) * 7, out_specs=items,
                         check_vma=False)(
        qdot, xdot, J, mask, gamma0, rate, w_min, w_max, tol, step_tol, ls_tol, rank_tol)


_STATIC = ("max_steps", "fixed", "chunk", "mesh")
# (inside a caller's jit the options do not apply, JAX takes them at the top level only: strict
# sums, ≈ 4× slower)
_algorithm1 = TopLevelOptionsJit(_algorithm1_all, _FAST_SUMS, static_argnames=_STATIC)


def _items_first(out, B0):
    """(…, B) -> (B0, …): drop the padding items, put the item axis first."""
    return tuple(jnp.moveaxis(a[..., :B0], -1, 0) for a in out)


def _prepare(qdot, xdot, J, mask, xp=jnp):
    """Component-leading float arrays with masked samples replaced by harmless values (``xp=np``:
    on the host)."""
    qdot, xdot, J = (xp.asarray(a, dtype=jnp.result_type(float)) for a in (qdot, xdot, J))
    lead = qdot.shape[:-1]
    valid = xp.ones(lead, bool) if mask is None else xp.asarray(mask, bool)
    m, n = J.shape[-2:]
    safe_J = xp.eye(m, n, dtype=J.dtype)
    Jv = xp.where(valid[..., None, None], J, safe_J)
    qv = xp.where(valid[..., None], qdot, 0.0)
    xv = xp.where(valid[..., None], xdot, 0.0)
    return to_soa(qv), to_soa(xv), to_soa(Jv, 2), valid


# per-item screening codes, in the order in which they are reported
_SCREEN_MESSAGES = ("`qdot` contains NaN or inf", "`xdot` contains NaN or inf", "`J` contains NaN or inf",
                    "`J` is rank-deficient (rank < m) at sample {}", "`mask` leaves no valid sample")


@fast_compile_jit
def _screen_codes(qdot, xdot, J, valid, rank_tol):
    """Per item (B,): 0 usable, else 1 + the index of the first problem in ``_SCREEN_MESSAGES``;
    and the first rank-deficient valid sample. ``qdot`` (B, K, n), ``xdot`` (B, K, m),
    ``J`` (B, K, m, n), ``valid`` (B, K)."""
    m = J.shape[-2]
    bad = [jnp.any(~jnp.all(jnp.isfinite(a), axis=tuple(range(2, a.ndim))) & valid, axis=-1)
           for a in (qdot, xdot, J)]
    n = J.shape[-1]
    Jz = [[jnp.where(jnp.isfinite(J[:, :, r, c]), J[:, :, r, c], 0.0) for c in range(n)] for r in range(m)]
    JJ = [[sum(Jz[i][c] * Jz[j][c] for c in range(n)) for j in range(m)] for i in range(m)]
    tr = sum(JJ[i][i] for i in range(m)) / m
    # det(JJᵀ)/(tr/m)^m ≤ λ_min/λ_mean: a scale-free test for a rank-deficient Jacobian
    ratio = det_lists(JJ) / jnp.where(tr > 0, tr, 1.0) ** m
    sing = ((ratio <= rank_tol) | (tr <= 0)) & valid
    bad += [jnp.any(sing, axis=-1), ~jnp.any(valid, axis=-1)]
    code = jnp.zeros(valid.shape[:1], jnp.int32)
    for k in reversed(range(len(bad))):
        code = jnp.where(bad[k], k + 1, code)
    return code, jnp.argmax(sing, axis=-1)


def _screen(qdot, xdot, J, mask, on_invalid, rank_tol, batch):
    """Raise on (or flag, for ``on_invalid='flag'``) items with NaN/inf or rank-deficient data.

    Items flat: ``qdot`` (B, K, n), ``xdot`` (B, K, m), ``J`` (B, K, m, n) (device arrays, possibly
    sharded), ``mask`` (B, K) NumPy bool; ``batch`` the items' shape for messages. Returns the mask
    with flagged items emptied (they stop at once and report status 2) and the flags (B,) or None.
    """
    codes, first = (np.asarray(a) for a in _screen_codes(qdot, xdot, J, mask, float(rank_tol)))
    codes, first = codes[: len(mask)], first[: len(mask)]
    if not codes.any():
        return mask, None
    if on_invalid == "raise":
        b = int(np.argmax(codes == codes[codes > 0].min()))
        msg = _SCREEN_MESSAGES[codes[b] - 1].format(int(first[b]))
        where = f" (item {tuple(int(i) for i in np.unravel_index(b, batch))})" if batch else ""
        raise ValueError(f"{msg}{where}; pass on_invalid='flag' to flag such items instead")
    flags = codes > 0
    mask = mask.copy()
    mask[flags] = False
    return mask, flags


def _item_mesh(devices, B):
    """A 1-D mesh (axis "items") over ``devices`` (default: all local devices), or None for one."""
    if devices is None:
        devs = jax.local_devices()
    else:
        devs = list(devices) if isinstance(devices, list | tuple) else None
        if not devs or not all(isinstance(d, jax.Device) for d in devs):
            raise TypeError(f"`devices` must be None or a non-empty list of jax devices, got {devices!r}")
    devs = devs[: max(1, min(len(devs), B))]
    return Mesh(np.asarray(devs), ("items",)) if len(devs) > 1 else None


@renamed_keywords(max_iter="max_steps")
def estimate_ik_weights(
    qdot,
    xdot,
    J,
    gamma=0.6,
    *,
    mask=None,
    w_min: float = 1e-3,
    w_max: float | None = 1.0,
    tol: float = 1e-3,
    step_tol: float = 1e-6,
    max_steps: int = 200,
    gamma_rate: float | None = None,
    fixed=None,
    on_invalid: str = "raise",
    rank_tol: float = 1e-10,
    ls_tol: float = 0.15,
    devices=None,
) -> IKWeightsResult:
    """IK weights ``w`` (..., n) by Algorithm 1 of Khoramshahi et al. (2022), for every batch item.

    **Arguments:** ``qdot`` (..., K, n) joint velocities [rad/s]; ``xdot`` (..., K, m) task
    velocities; ``J`` (..., K, m, n) Jacobians; ``gamma`` null-space projection ratio in [0, 1]
    (scalar or (...,) per item); ``mask`` (..., K) bool valid samples (ragged trials); ``w_min`` the
    positive floor of the box ``[w_min, w_max]``; ``w_max`` its upper bound (1 in the paper; ``None``
    drops it, which makes the update scale-free: with the bound, raw weights above 1 are clipped
    before the normalisation and their ratios are lost, which can stall the iteration); ``tol``
    the relative distance of the weights to the fixed point of the update at which the iteration
    has converged (``max_i |log w_i − log w_i*|``, estimated from the last step and the observed
    contraction, see :class:`IKWeightsResult`; 0: never; the default 10⁻³ is below the statistical
    precision of most data, ask for less where the weights are known to better than 1 %, e.g. for
    bootstrap intervals of precise data). The paper's rule ``e ≤ ε`` (line 2) is
    not used: with null-space motion in the data its error has a floor above any small ε even at
    the true weights (Eq 17: ``e_k = (1 − γ) N_k q̇_k``; near 0.1 on the paper's Fig 1 data), and ε
    is in the units of the velocities (scaled-down data meet it at ``W = I``); ``step_tol`` stop
    (status ``STALLED``) when every weight changes by less than this (relative; 0: never) before
    the distance to the fixed point is below ``tol``: the update crawls (contraction factor near
    1), as when the data barely determine the weights; ``max_steps`` iteration cap (status
    ``MAX_STEPS``); ``gamma_rate`` c of the schedule ``γ ← γ + c (1 − γ)`` after each iteration
    (None: constant; γ → 1 makes the updates vanish whatever the weights, so a scheduled run that
    stops is judged by the checks below at the starting ratio γ0, and reports ``SCHEDULE_END``
    where they fail or where it stopped on ``step_tol``); ``ls_tol`` the largest relative
    difference (``max_i |log w_i − log w_i^LS|``) allowed between the fixed point and the
    least-squares weights ``w^LS`` of the same modelling error (Eq 16 at γ0; what
    :func:`estimate_ik_weights_lm` minimises), estimated by one Gauss–Newton step (``ls_gap``):
    on data that follow the IK model with small, uncorrelated null-space motion the two agree
    (Fig 1 data, σ = 0.2: ≤ 0.12), on data the model does not describe they do not (the HuG-MP
    recordings: factors of 4 and more). No check on the data can tell null-space motion that
    mimics other weights from those weights when both estimators agree (Fig 3 data with a weak
    pull, γ = 0.6: w2 ≈ 0.024 from both, truth 0.01); γ is the paper's handle on that;
    ``fixed`` joints (bool (n,) mask or indices) held at 1 and left out of the normalisation (the
    over-specified-joint convention of Experiment 1); ``on_invalid`` 'raise' (default) or 'flag'
    items with NaN/inf velocities or rank-deficient Jacobians (status ``INVALID_INPUT``, ``w``
    NaN) while the others go on; ``rank_tol`` threshold on ``det(JJᵀ)/(tr(JJᵀ)/m)^m``, and on
    ``λ_min/λ_max`` of the Gauss–Newton matrix of the weight ratios (below it the data do not
    determine the weights: ``TOO_FEW_DATA``); ``devices`` the devices
    over which the items are split (default: all of ``jax.local_devices()``; on a CPU, start Python
    with ``XLA_FLAGS=--xla_force_host_platform_device_count=<cores>`` to get one device per core:
    an XLA:CPU device also spreads each large fused loop over its own thread pool). Each device
    iterates on its share of the items without communication; results agree with one device's to
    rounding (the sums over samples are reassociated for vectorisation, so their rounding depends
    on the chunk shape).

    **Returns:**

    :class:`IKWeightsResult`. Not differentiable (clipping, stopping rule); see
    :func:`estimate_ik_weights_lm` for the gradient-based variant.

    **Raises:**

    ``ValueError``/``TypeError`` naming the argument: inconsistent shapes, a chain that is not redundant
    (m ≥ n), a non-boolean or misshaped ``mask``, ``gamma`` outside [0, 1],
    a bad ``w_min``/``w_max``/tolerance, an unknown ``on_invalid``,
    ``devices`` that are not a list of JAX devices, and (with ``on_invalid="raise"``) items with
    NaN/inf velocities or rank-deficient Jacobians.

    **Compile time:** ≈ 4 s on first use per bucketed batch shape (benchmarks/compile_times.py).
    """
    qdot, xdot, J, mask = _check_inputs(qdot, xdot, J, mask)
    _check_gamma(gamma, gamma_rate)
    if not (0.0 < float(w_min) < 1.0):
        raise ValueError(f"`w_min` must lie in (0, 1), got {w_min}")
    if w_max is not None and not float(w_max) >= 1.0:
        raise ValueError(f"`w_max` must be >= 1 or None, got {w_max}")
    check_positive_int("max_steps", max_steps)
    for name, v in (("tol", tol), ("step_tol", step_tol), ("rank_tol", rank_tol), ("ls_tol", ls_tol)):
        if not (np.isfinite(float(v)) and float(v) >= 0):
            raise ValueError(f"`{name}` must be a finite number >= 0, got {v}")
    n = qdot.shape[-1]
    fixed_t = _fixed_mask(fixed, n)
    batch = tuple(qdot.shape[:-2])
    g = to_jax(np.asarray(gamma, float)) if is_concrete(gamma) else jnp.asarray(gamma, dtype=jnp.result_type(float))
    _check_gamma_shape(g, batch)
    K = qdot.shape[-2]
    B = int(np.prod(batch)) if batch else 1
    arrays = [flatten_batch(qdot, batch, 2), flatten_batch(xdot, batch, 2), flatten_batch(J, batch, 3),
              np.ones((B, K), bool) if mask is None else on_host(mask, lambda a: a.reshape(B, K)),
              flatten_batch(g, batch, 0)]
    if on_invalid not in ("raise", "flag"):
        raise ValueError(f"`on_invalid` must be 'raise' or 'flag', got {on_invalid!r}")
    concrete = is_concrete(*arrays)
    mesh = _item_mesh(devices, B) if concrete else None
    flags = None
    if concrete:
        if mesh is not None:
            # each device gets an equal share of the items (padding: items without valid samples)
            arrays = [np.asarray(a) for a in arrays]
            pad = -B % mesh.size
            if pad:
                arrays = [np.concatenate([a, np.zeros((pad,) + a.shape[1:], a.dtype)]) for a in arrays]
        # without a copy where possible (aligned host memory); see the wait at the end
        where = None if mesh is None else NamedSharding(mesh, PartitionSpec("items"))
        put = lambda a: jax.device_put(a, where, may_alias=True)  # noqa: E731
        qf, xf, Jf = (put(a) for a in arrays[:3])
        mf, flags = _screen(qf, xf, Jf, np.asarray(arrays[3]), on_invalid, rank_tol, batch)
        flags = None if flags is None else flags[:B]
        arrays = [qf, xf, Jf, put(mf), put(arrays[4])]
    # small problems in one piece (compiles faster), large ones in cache-sized chunks of items
    Bl = arrays[0].shape[0] // (1 if mesh is None else mesh.size)
    nc = -(-Bl * K // _CHUNK_SAMPLES) if Bl * K > _DIRECT_SAMPLES else 1
    out = _algorithm1(
        *arrays,
        jnp.asarray(0.0 if gamma_rate is None else gamma_rate),
        jnp.asarray(float(w_min)), jnp.asarray(np.inf if w_max is None else float(w_max)),
        jnp.asarray(float(tol)), jnp.asarray(float(step_tol)), jnp.asarray(float(ls_tol)),
        jnp.asarray(float(rank_tol)), max_steps=int(max_steps), fixed=fixed_t, chunk=-(-Bl // nc), mesh=mesh,
    )
    if mesh is not None:  # results back on one device, padding dropped
        out = jax.device_put(out, mesh.devices.flat[0])
    if concrete:  # the device arrays may alias the caller's NumPy inputs: finish before returning
        out = jax.block_until_ready(out)
    w, err, hist, iters, status, gam, gap = (unflatten_batch(a, batch, B) for a in out)
    if flags is not None and flags.any():
        fl = flags.reshape(batch)  # (concrete: on the host)
        status = to_jax(np.where(fl, np.asarray(Status.INVALID_INPUT, np.asarray(status).dtype), status))
        w = to_jax(np.where(fl[..., None], np.nan, w))
        err = to_jax(np.where(fl, np.nan, err))
        gap = to_jax(np.where(fl, np.nan, gap))
    return IKWeightsResult(w=w, error=err, error_history=hist, iterations=iters,
                           converged=on_host(status, lambda s: s == Status.SUCCESSFUL), gamma=gam, status=status,
                           ls_gap=gap)


# ---------------------------------------------------------------------------------------------
# the modelling error as a differentiable function, and the gradient-based variant


def _model_residual(w, qdot, xdot, J, gamma, valid):
    """``e_k = q̇_k − J#ẋ_k − γ (I − J# J) q̇_k = (1 − γ) q̇_k − J# (ẋ_k − γ J q̇_k)`` (n, ..., K)
    for weights ``w`` (n, ..., 1) (Eq 16)."""
    (jb,) = pinv_apply_diag_soa(J, 1.0 / w, xdot - gamma * mv(J, qdot))
    e = (1.0 - gamma) * qdot - jb
    return e * valid[None]


def ik_model_error(w, qdot, xdot, J, gamma=0.0, *, mask=None):
    """Mean modelling error ``(1/K) Σ_k |e_k|`` of IK weights on data (Eqs 16–17).

    Differentiable in ``w`` and the data; invariant to the scale of ``w`` (Eq 4).

    **Arguments:**

    - ``w``: (..., n) positive weights.
    - ``qdot``: (..., K, n) joint velocities [rad/s].
    - ``xdot``: (..., K, m) task velocities.
    - ``J``: (..., K, m, n) Jacobians.
    - ``gamma``: null-space projection ratio in [0, 1].
    - ``mask``: optional (..., K) bool valid samples.

    **Returns:**

    (...,) the mean modelling error (units of ``qdot``).

    **Raises:**

    ``ValueError``/``TypeError`` naming the argument: inconsistent shapes, a chain that is not redundant
    (m ≥ n), a non-boolean or misshaped ``mask``, ``gamma`` outside [0, 1],
    non-positive ``w`` or ``w`` whose batch axes do not broadcast
    to the data's.
    """
    qdot, xdot, J, mask = _check_inputs(qdot, xdot, J, mask)
    _check_gamma(gamma, None)
    w = as_array("w", w, tail=(qdot.shape[-1],))
    check_positive("w", w)
    batch = tuple(qdot.shape[:-2])
    try:
        np.broadcast_shapes(tuple(w.shape[:-1]), batch)
    except ValueError as e:
        raise ValueError(f"`w` (..., n) must broadcast to the data's batch shape {batch}, got {tuple(w.shape)}") from e
    if tuple(np.broadcast_shapes(tuple(w.shape[:-1]), batch)) != batch:
        raise ValueError(f"`w` has batch axes {tuple(w.shape[:-1])} beyond the data's {batch}")
    qd, xd, Jc, valid = _prepare(qdot, xdot, J, mask)
    w = jnp.broadcast_to(jnp.asarray(w, dtype=qd.dtype), tuple(qdot.shape[:-2]) + (qdot.shape[-1],))
    wc = to_soa(w)[..., None]
    g = jnp.asarray(gamma, dtype=qd.dtype)
    g = g.reshape((1,) + g.shape + (1,)) if g.ndim else g
    r = _model_residual(wc, qd, xd, Jc, g, valid.astype(qd.dtype))
    norm = jnp.sqrt(jnp.sum(r * r, axis=0) + 1e-300)
    return jnp.sum(jnp.where(valid, norm, 0.0), axis=-1) / jnp.sum(valid, axis=-1, dtype=norm.dtype)


def _lm_residual(theta, args):
    qd, xd, Jc, valid, gamma, free, base = args
    logw = base.at[free].set(theta)
    r = _model_residual(jnp.exp(logw)[:, None], qd, xd, Jc, gamma, valid)
    scale = 1.0 / jnp.sqrt(jnp.maximum(jnp.sum(valid), 1.0))
    # one gauge residual pins the scale freedom (Eq 4: e is invariant to w → c w)
    return jnp.concatenate([r.reshape(-1) * scale, jnp.atleast_1d(1e-3 * jnp.mean(theta))])


def _lm_cost(theta, data, free):
    r = _lm_residual(theta, tuple(data) + (jnp.asarray(free), jnp.zeros(data[0].shape[0], data[0].dtype)))
    return 0.5 * jnp.sum(r * r)


@partial(jax.custom_jvp, nondiff_argnums=(0, 1))
def _lm_fit(free, max_steps, q, x, Jb, v, g):
    """Free log-weights at the LM optimum of one item, and (steps, converged) as floats."""
    args = (q, x, Jb, v, g, jnp.asarray(free), jnp.zeros(q.shape[0], q.dtype))
    res = least_squares(_lm_residual, jnp.zeros(len(free), q.dtype), args, max_steps=max_steps, ftol=0.0,
                        gtol=1e-13)
    return res.x, jnp.stack([res.steps.astype(q.dtype), res.converged.astype(q.dtype)])


@_lm_fit.defjvp
def _lm_fit_jvp(free, max_steps, primals, tangents):
    """Implicit function theorem at the optimum: ``∇_θ C(θ*, d) = 0`` gives
    ``dθ* = −H⁻¹ ∂_d ∇_θ C · dd`` with the exact Hessian ``H = ∇²_θ C`` (linear in ``dd``, so it
    transposes for reverse mode). The LM iterations are never differentiated."""
    theta, aux = _lm_fit(free, max_steps, *primals)
    grad = lambda th, d: jax.grad(_lm_cost)(th, d, free)  # noqa: E731
    H = jax.jacfwd(grad)(theta, primals)
    _, dg = jax.jvp(lambda d: grad(theta, d), (primals,), (tangents,))
    dtheta = -jnp.linalg.solve(H, dg)
    return (theta, aux), (jnp.where(aux[1] > 0, dtheta, 0.0), jnp.zeros_like(aux))


_LM_RANK_TOL = 1e-10  # λ_min/λ_max of the Gauss–Newton matrix below which the data do not determine w


def _lm_one(q, x, Jb, v, g, *, free, max_steps):
    """One item: normalised weights (n,), cost, LM steps, status (before the ``w_min`` check)."""
    n = q.shape[0]
    theta, aux = _lm_fit(free, max_steps, q, x, Jb, v, g)
    logw = jnp.zeros(n, q.dtype).at[jnp.asarray(free)].set(theta - jnp.max(theta))
    args = (q, x, Jb, v, g, jnp.asarray(free), jnp.zeros(n, q.dtype))
    cost = _lm_cost(theta, (q, x, Jb, v, g), free)
    determined = jnp.asarray(True)
    if len(free) > 1:
        # do the data determine the ratios of the free weights? λ_min/λ_max of the Gauss–Newton
        # matrix of the residual (without the gauge row) on the directions that change them
        Jr = jax.jacfwd(_lm_residual)(theta, args)[:-1]
        B = jnp.asarray(_helmert(len(free)), q.dtype)
        lam = jnp.linalg.eigvalsh(B.T @ (Jr.T @ Jr) @ B)
        determined = (lam[0] > _LM_RANK_TOL * lam[-1]) & (lam[-1] > 0)
    status = jnp.select([~jnp.isfinite(cost), aux[1] <= 0, ~determined],
                        [Status.NONFINITE, Status.MAX_STEPS, Status.TOO_FEW_DATA],
                        Status.SUCCESSFUL).astype(jnp.int32)
    return jnp.exp(logw), cost, aux[0].astype(jnp.int32), status



@partial(fast_compile_jit, static_argnames=("free", "max_steps"))
def _lm_batch(qd, xd, Jc, valid, gamma, *, free, max_steps):
    # batch to the front for vmap: (n, B, K) -> (B, n, K)
    f = lambda a: jnp.moveaxis(a, 1, 0)  # noqa: E731
    one = partial(_lm_one, free=free, max_steps=max_steps)
    return jax.vmap(one)(f(qd), f(xd), jnp.moveaxis(Jc, 2, 0), valid, gamma)


@pytree_dataclass
class IKWeightsLMResult:
    """``w`` (..., n) normalised weights; ``cost`` ½ Σ|e|²/K at the optimum; ``steps`` LM
    iterations; ``status`` (...,) int ``pj.Status``: ``SUCCESSFUL`` (LM converged to an interior
    optimum that the data determine), ``STALLED`` (converged, but a free weight went below
    ``w_min``: the error keeps falling as it goes to 0, and ``w`` holds the floor),
    ``TOO_FEW_DATA`` (the data do not determine the weight ratios: the Gauss–Newton matrix is
    singular), ``MAX_STEPS``, ``NONFINITE``; ``converged`` ``status == SUCCESSFUL``."""

    w: jax.Array
    cost: jax.Array
    steps: jax.Array
    converged: jax.Array
    status: jax.Array


def estimate_ik_weights_lm(qdot, xdot, J, gamma=0.0, *, mask=None, w_min: float = 1e-3,
                           fixed=None, max_steps: int = 100) -> IKWeightsLMResult:
    """Gradient-based variant: minimise ``(1/K) Σ_k |e_k|²`` (Eq 16) over log-weights by LM.

    Same inputs as :func:`estimate_ik_weights` (``gamma`` scalar or (...,) per item). The
    parameters are ``log w`` of the free joints (positivity without bounds); the scale freedom is
    pinned by a small gauge residual and the result normalised to ``max w = 1`` (free joints), then
    floored at ``w_min``. When ``ẋ = J q̇`` holds exactly, ``e_k = (1 − γ) N q̇_k`` and the
    minimiser does not depend on γ. Each item is fitted independently (``jax.vmap`` of
    ``fitting.least_squares``).

    **Arguments:**

    - ``qdot``, ``xdot``, ``J``, ``gamma``, ``mask``, ``fixed``: as :func:`estimate_ik_weights`.
    - ``w_min``: the floor of the normalised weights, in (0, 1).
    - ``max_steps``: Levenberg–Marquardt iterations at most.

    **Returns:**

    :class:`IKWeightsLMResult`.

    **Raises:**

    ``ValueError``/``TypeError`` naming the argument: inconsistent shapes, a chain that is not redundant
    (m ≥ n), a non-boolean or misshaped ``mask``, ``gamma`` outside [0, 1],
    a ``w_min`` outside (0, 1), and items with NaN/inf velocities or
    rank-deficient Jacobians.

    **Differentiable** with respect to ``qdot``, ``xdot``, ``J`` and ``gamma`` (``jax.grad``,
    ``jax.jvp``, inside ``jit``/``vmap``): the fitted optimum is differentiated by the implicit
    function theorem (exact Hessian of the cost at the optimum), not through the iterations. Items
    whose fit did not converge have zero derivative.

    **Compile time:** ≈ 4 s on first use (LM with a forward-mode Jacobian;
    benchmarks/compile_times.py).
    """
    qdot, xdot, J, mask = _check_inputs(qdot, xdot, J, mask)
    _check_gamma(gamma, None)
    if not (0.0 < float(w_min) < 1.0):
        raise ValueError(f"`w_min` must lie in (0, 1), got {w_min}")
    check_positive_int("max_steps", max_steps)
    n = qdot.shape[-1]
    fixed_t = _fixed_mask(fixed, n)
    free = tuple(i for i in range(n) if not fixed_t[i])
    batch = tuple(qdot.shape[:-2])
    g = to_jax(np.asarray(gamma, float)) if is_concrete(gamma) else jnp.asarray(gamma, dtype=jnp.result_type(float))
    _check_gamma_shape(g, batch)
    K = qdot.shape[-2]
    B = int(np.prod(batch)) if batch else 1
    qf, xf, Jf = (on_host(a, lambda a: a.reshape((B, K) + a.shape[len(batch) + 1:])) for a in (qdot, xdot, J))
    mf = None if mask is None else on_host(mask, lambda a: a.reshape(B, K))
    concrete = is_concrete(qf, xf, Jf, mask, g)
    if concrete:
        _screen(qf, xf, Jf, np.ones((B, K), bool) if mask is None else np.asarray(mf, bool), "raise", 1e-10, batch)
    # (concrete: preparation and results on the host, so that the call compiles the kernel only)
    xp = np if concrete else jnp
    qd, xd, Jc, valid = _prepare(qf, xf, Jf, None if mask is None else xp.asarray(mf, bool), xp=xp)
    g = xp.broadcast_to(xp.asarray(g, qd.dtype), batch).reshape(B)
    out = _lm_batch(qd, xd, Jc, valid.astype(qd.dtype), g, free=free, max_steps=int(max_steps))
    w, cost, steps, status = jax.device_get(out) if concrete else out
    # a free weight below the floor: the modelling error keeps falling as it goes to 0, the
    # optimum is not a weight (the joint would do all the work)
    status = xp.where((status == Status.SUCCESSFUL) & xp.any(w < w_min, axis=-1),
                      xp.asarray(Status.STALLED, status.dtype), status)
    w = xp.maximum(w, w_min)
    status = status.reshape(batch)
    w, cost, steps, status, conv = (to_jax(a) if concrete else a for a in (
        w.reshape(batch + (n,)), cost.reshape(batch), steps.reshape(batch), status, status == Status.SUCCESSFUL))
    return IKWeightsLMResult(w=w, cost=cost, steps=steps, converged=conv, status=status)
