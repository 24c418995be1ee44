"""Equilibrium postures (design §3.1): ``argmin ½ (q − q_rest)ᵀ KJ (q − q_rest)`` s.t. ``fk(q) = x``.

This is the final posture of the λ0-PMP (Donders' law). With Lagrangian
``L = ½ (q − q_rest)ᵀ KJ (q − q_rest) − λᵀ (fk(q) − x)`` the KKT system is

    g(q, λ) = KJ (q − q_rest) − Jᵀ λ = 0,      c(q) = fk(q) − x = 0,

and ``λ`` is the task force λ0 of Eq 4 at the equilibrium. It is solved by Newton's method on
(q, λ) with the exact Hessian of the Lagrangian ``H = KJ − Σ_i λ_i ∇²fk_i`` (the second term
by forward-mode differentiation of ``Jᵀλ``), and differentiated by the implicit function
theorem (one extra KKT solve per tangent; forward and reverse mode): the loop and the rule are
the shared :func:`pmpjax._base.newton.newton_solve`; this module supplies the KKT residual and
its solve.

Initial guess (default ``q_init = q_rest``, ``λ = 0``): the first Newton step is then the
``KJ``-weighted projection of ``q_rest`` onto the linearised constraint, which is the exact answer
for a linear chain; curvature corrections converge quadratically. Steps are capped at 0.5 rad
(infinity norm). The KKT matrix ``[[H, −Jᵀ], [J, 0]]`` is indefinite; it is solved by
augmented-Lagrangian elimination with unrolled SPD solves (``_kkt_solve``); ``status`` is
``SUCCESSFUL`` only for a strict local minimum (reduced Hessian positive definite), so a saddle
or maximum of the energy along the task manifold is flagged (``NOT_MINIMUM``). Pass ``q_init`` (e.g. an observed
posture, or the end of a λ0-PMP run) to start elsewhere: the solution is then the local minimum
nearest along Newton's path.
"""

from __future__ import annotations

import math
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from .._base import (
    Status,
    as_array,
    broadcast_batch,
    bucket,
    check_positive,
    check_positive_int,
    check_spd,
    fast_compile_jit,
    flatten_batch,
    is_concrete,
    newton_solve,
    pad_rows,
    pytree_dataclass,
    renamed_keywords,
    row_chunks,
    spd_solve,
    to_jax,
    unflatten_batch,
    warn_without_x64,
)
from .._chains import Chain

_STEP_CAP = 0.5  # rad, infinity norm of a Newton step in q


@pytree_dataclass
class Equilibrium:
    """``q`` (..., n) equilibrium posture [rad]; ``lam`` (..., m) multiplier (= λ0, task force);
    ``status`` (...,) int :class:`pmpjax.Status`: ``SUCCESSFUL`` (KKT residual below tolerance and
    a strict local minimum), ``NONFINITE``, ``MAX_STEPS``, ``STALLED`` (steps stopped above the
    residual tolerance) or ``NOT_MINIMUM`` (a saddle or maximum along the task manifold);
    ``kkt_residual`` (...,) ``max(|g|_∞ / s, |c|_∞)`` with ``s = max |KJ|``; ``steps`` (...,)
    Newton steps taken. ``converged`` = ``status == SUCCESSFUL``."""

    q: jax.Array
    lam: jax.Array
    status: jax.Array
    kkt_residual: jax.Array
    steps: jax.Array

    @property
    def converged(self) -> jax.Array:
        return self.status == Status.SUCCESSFUL


# --- one item: K (n, n), qr (n,), x (m,), q (n,), lam (m,); batches are vmapped ---------------


def _residual(chain, K, qr, x, q, lam):
    fx, J = chain.fk_jac_soa(q)
    return K @ (q - qr) - J.T @ lam, fx - x, J


def _lagrangian_hessian(chain, K, q, lam):
    """``KJ − Σ_i λ_i ∇²fk_i`` (n, n); the curvature term is ∂(Jᵀλ)/∂q by forward mode."""
    return K - jax.jacfwd(lambda qq: chain.fk_jac_soa(qq)[1].T @ lam)(q)


def _kkt_solve(H, J, a, b):
    """Solve the KKT system ``H dq − Jᵀ λ = a``, ``J dq = b`` for right-hand sides ``a`` (n, k),
    ``b`` (m, k); returns ``(dq (n, k), λ (m, k))``.

    Augmented-Lagrangian elimination instead of a pivoted LU of the indefinite (n+m)² matrix:
    adding ``ρ Jᵀ (J dq − b) = 0`` to the first block row gives the equivalent system
    ``M dq − Jᵀ λ = a + ρ Jᵀ b`` with ``M = H + ρ JᵀJ``, which is positive definite whenever the
    reduced Hessian is (Debreu), so ``dq = u + V λ`` with ``u = M⁻¹ (a + ρ Jᵀ b)``,
    ``V = M⁻¹ Jᵀ``, and ``(J V) λ = b − J u`` (m×m Schur complement). Both solves are the
    unrolled closed forms / LDLᵀ of :func:`pmpjax._base.linalg.spd_solve`: elementwise under ``vmap``
    (XLA fuses them; no batched tiny LAPACK calls), and the factors are computed once for all ``k``
    columns — under ``jacfwd`` (a vmap over tangents) it depends on primals only and is shared
    by every tangent. ``ρ = 10 m |H|_F / |J|_F²`` balances the two blocks of ``M``.
    """
    m = J.shape[0]
    rho = 10.0 * m * jnp.sqrt(jnp.sum(H * H)) / jnp.maximum(jnp.sum(J * J), 1e-300)
    M = (H + rho * (J.T @ J))[:, :, None]
    # Two calls (not one on concatenated columns) keep the tangent-linear right-hand side apart
    # from the primal-only ``Jᵀ`` (needed to transpose for reverse mode); XLA CSEs the factors.
    V = spd_solve(M, J.T)
    u = spd_solve(M, a + rho * (J.T @ b))
    lam = spd_solve((J @ V)[:, :, None], b - J @ u)
    return u + V @ lam, lam


def _is_minimum(H, J):
    """Reduced Hessian positive definite ⇔ ``H + ρ JᵀJ`` PD for large ρ (Debreu); ρ scaled to
    ``10³ |H| / |J|²``."""
    rho = 1e3 * jnp.linalg.norm(H) / jnp.maximum(jnp.sum(J * J) / J.shape[0], 1e-300)
    return jnp.all(jnp.isfinite(jnp.linalg.cholesky(H + rho * (J.T @ J))))


# The KKT specialisation of the shared Newton solver: y = (q, λ), params = (chain, KJ, q_rest, x).
def _kkt_residual(y, params, consts):
    g, c, _ = _residual(*params, *y)
    return g, c


def _kkt_newton_solve(y, params, consts, rhs):
    chain, K, _, _ = params
    q, lam = y
    J = chain.fk_jac_soa(q)[1]
    dq, dlam = _kkt_solve(_lagrangian_hessian(chain, K, q, lam), J, rhs[0][:, None], rhs[1][:, None])
    return dq[:, 0], dlam[:, 0]


def _joint_part(y):
    return y[0]


def equilibrium_one(
    chain: Chain, K, qr, x, q0, *, tol: float = 1e-10, max_steps: int = 50, check_minimum: bool = True
):
    """One item (vmap it): ``K`` (n, n), ``qr`` (n,), ``x`` (m,), ``q0`` (n,).

    Returns ``(q (n,), lam (m,), status (), kkt_residual (), steps ())``; ``q`` and ``lam`` are
    differentiable (implicit), the rest are not. ``check_minimum=False`` skips the second-order
    test (KKT residual only; cheaper inside fits).
    """
    (q, lam), steps = newton_solve(
        _kkt_residual,
        _kkt_newton_solve,
        (q0, jnp.zeros(x.shape, q0.dtype)),
        (chain, K, qr, x),
        max_steps=int(max_steps),
        tol=float(tol),
        step_cap=_STEP_CAP,
        measure=_joint_part,
    )
    Ks, qrs, xs, qs, ls = jax.lax.stop_gradient((K, qr, x, q, lam))
    g, c, J = _residual(chain, Ks, qrs, xs, qs, ls)
    res = jnp.maximum(jnp.max(jnp.abs(g)) / jnp.max(jnp.abs(Ks)), jnp.max(jnp.abs(c)))
    finite = jnp.isfinite(res) & jnp.all(jnp.isfinite(qs))
    small = res <= 1e3 * tol * (1.0 + jnp.max(jnp.abs(qs)))
    status = jnp.where(
        ~finite, Status.NONFINITE, jnp.where(small, Status.SUCCESSFUL,
                                             jnp.where(steps >= max_steps, Status.MAX_STEPS, Status.STALLED))
    )
    if check_minimum:
        is_min = _is_minimum(_lagrangian_hessian(chain, Ks, qs, ls), J)
        status = jnp.where((status == Status.SUCCESSFUL) & ~is_min, Status.NOT_MINIMUM, status)
    return q, lam, status, res, steps


@partial(fast_compile_jit, static_argnames=("tol", "max_steps"))
def _flat_solve(chain, K, qr, x, q0, *, tol, max_steps):
    return jax.vmap(lambda k, r, t, q: equilibrium_one(chain, k, r, t, q, tol=tol, max_steps=max_steps))(
        K, qr, x, q0
    )


@renamed_keywords(max_iter="max_steps")
def equilibrium_posture(
    chain: Chain,
    KJ,
    q_rest,
    target,
    q_init=None,
    *,
    tol: float = 1e-10,
    max_steps: int = 50,
) -> Equilibrium:
    """Equilibrium posture of the λ0-PMP: ``argmin ½ (q − q_rest)ᵀ KJ (q − q_rest)`` s.t. ``fk(q) = target``.

    **Arguments:**

    - ``chain``: a :class:`Chain` (``Wrist``, ``PlanarArm``, ``FunctionChain``, ...).
    - ``KJ``: (..., n, n) SPD joint stiffness [Nm/rad] (only its shape matters, not its scale).
    - ``q_rest``: (..., n) rest posture [rad].
    - ``target``: (..., m) task position (wrist: screen point [m]); must be reachable.
    - ``q_init``: optional (..., n) initial guess (default ``q_rest``; see module docstring).
    - ``tol``: Newton stops when every step is below ``tol (1 + |q|_∞)``; ``max_steps`` bounds the steps.

    Leading axes of all arrays broadcast (targets × subjects, ...). ``.q`` and ``.lam`` are
    differentiable with respect to ``KJ``, ``q_rest``, ``target`` and the chain's parameters
    (implicit function theorem; forward and reverse mode); works under ``jit``/``vmap``
    (validation then only checks shapes).

    **Returns:**

    An :class:`Equilibrium` (``.q`` the posture, ``.lam``, ``.status``, ``.converged``,
    ``.kkt_residual``, ``.steps``).

    **Raises:**

    ``TypeError`` for a non-chain, ``ValueError`` naming the argument for wrong shapes,
    NaN/inf, non-SPD ``KJ``, unreachable ``target``, non-positive ``tol``/``max_steps``.

    **Compile time:** ≈ 2.4 s per chain for the first call of up to 64 postures and again for the
    first larger one (then chunks of 1024; under ``jit`` per power-of-two batch size), see
    benchmarks/compile_times.py.
    """
    if not isinstance(chain, Chain):
        raise TypeError(f"`chain` must be a pmpjax Chain, got {type(chain).__name__}")
    n, m = chain.n, chain.m
    KJ = as_array("KJ", KJ, tail=(n, n))
    check_spd("KJ", KJ)
    q_rest = as_array("q_rest", q_rest, tail=(n,))
    target = as_array("target", target, tail=(m,))
    chain.check_target("target", target)
    if q_init is not None:
        q_init = as_array("q_init", q_init, tail=(n,))
    check_positive("tol", tol)
    check_positive_int("max_steps", max_steps)
    warn_without_x64()
    batch = broadcast_batch(KJ=(KJ, 2), q_rest=(q_rest, 1), target=(target, 1), q_init=(q_init, 1))
    dtype = jnp.result_type(float)
    q0 = q_rest if q_init is None else q_init
    B = math.prod(batch)
    args = ((KJ, 2), (q_rest, 1), (target, 1), (q0, 1))
    opts = dict(tol=float(tol), max_steps=int(max_steps))
    if is_concrete(chain, KJ, q_rest, target, q0):
        # Eager: padded to 64 rows or solved in chunks of 1024, so that a chain compiles at most
        # twice whatever the batch sizes (a compile costs seconds, 1024 wrist rows ≈ 5 ms).
        out = row_chunks(lambda *r: _flat_solve(chain, *r, **opts),
                         *(flatten_batch(a, batch, core, dtype=dtype, xp=np) for a, core in args))
    else:
        # Traced: padded to a power of two (>= 8) so that calls of similar size share one compile.
        Bp = bucket(B, minimum=8)
        out = _flat_solve(chain, *(pad_rows(flatten_batch(a, batch, core, dtype=dtype), Bp) for a, core in args),
                          **opts)
    q, lam, status, res, steps = (to_jax(unflatten_batch(a, batch, B)) for a in out)
    return Equilibrium(q=q, lam=lam, status=status, kkt_residual=res, steps=steps)
