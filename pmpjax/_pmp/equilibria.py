"""Equilibrium postures (design §3.1): ``argmin ½ (q − q_rest)ᵀ KJ (q − q_rest)`` s.t. ``fk(q) = x``.

This is the final posture of the λ0-PMP (Donders' law). With Lagrangian
``L = ½ (q − q_rest)ᵀ KJ (q − q_rest) − λᵀ (fk(q) − x)`` the KKT system is

    g(q, λ) = KJ (q − q_rest) − Jᵀ λ = 0,      c(q) = fk(q) − x = 0,

and ``λ`` is the task force λ0 of Eq 4 at the equilibrium. It is solved by Newton's method on
(q, λ) with the exact Hessian of the Lagrangian ``H = KJ − Σ_i λ_i ∇²fk_i`` (the second term
by forward-mode differentiation of ``Jᵀλ``), and differentiated by the implicit function
theorem (``jax.custom_jvp``: one extra KKT solve per tangent; forward and reverse mode).

Initial guess (default ``q_init = q_rest``, ``λ = 0``): the first Newton step is then the
``KJ``-weighted projection of ``q_rest`` onto the linearised constraint, which is the exact answer
for a linear chain; curvature corrections converge quadratically. Steps are capped at 0.5 rad
(infinity norm). The KKT matrix ``[[H, −Jᵀ], [J, 0]]`` is indefinite; it is solved by
augmented-Lagrangian elimination with unrolled SPD solves (``_kkt_solve``); ``converged``
additionally requires a strict local minimum (reduced Hessian positive definite), so a saddle
or maximum of the energy along the task manifold is flagged. Pass ``q_init`` (e.g. an observed
posture, or the end of a λ0-PMP run) to start elsewhere: the solution is then the local minimum
nearest along Newton's path.
"""

from __future__ import annotations

import math
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from .._base.linalg import spd_solve
from .._base.pytree import pytree_dataclass
from .._base.validate import as_array, check_positive, check_positive_int, check_spd
from .._chains.kinematics import Chain

_STEP_CAP = 0.5  # rad, infinity norm of a Newton step in q


@pytree_dataclass
class Equilibrium:
    """``q`` (..., n) equilibrium posture [rad]; ``lam`` (..., m) multiplier (= λ0, task force);
    ``converged`` (...,) bool: KKT residual below tolerance, finite, and a strict local minimum
    (reduced Hessian positive definite); ``kkt_residual`` (...,) ``max(|g|_∞ / s, |c|_∞)`` with
    ``s = max |KJ|``."""

    q: jax.Array
    lam: jax.Array
    converged: jax.Array
    kkt_residual: jax.Array


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


def _newton(chain, K, qr, x, q0, tol, max_iter):
    def step(q, lam):
        _, c, J = _residual(chain, K, qr, x, q, lam)
        H = _lagrangian_hessian(chain, K, q, lam)
        # Newton on (q, λ): H dq − Jᵀ λ_new = −KJ (q − q_rest),  J dq = −c.
        dq, lam_new = (a[:, 0] for a in _kkt_solve(H, J, -(K @ (q - qr))[:, None], -c[:, None]))
        big = jnp.max(jnp.abs(dq))
        alpha = jnp.minimum(1.0, _STEP_CAP / jnp.where(big > 0, big, 1.0))
        return q + alpha * dq, lam + alpha * (lam_new - lam), big

    def cond(s):
        q, _, big, it = s
        return (it < max_iter) & (big > tol * (1.0 + jnp.max(jnp.abs(q))))

    def body(s):
        q, lam, _, it = s
        q, lam, big = step(q, lam)
        return q, lam, jnp.where(jnp.isnan(big), 0.0, big), it + 1

    init = (q0, jnp.zeros(x.shape, q0.dtype), jnp.asarray(jnp.inf, q0.dtype), jnp.asarray(0))
    q, lam, _, _ = jax.lax.while_loop(cond, body, init)
    return q, lam


@partial(jax.custom_jvp, nondiff_argnums=(5, 6))
def _solve(chain, K, qr, x, q0, tol, max_iter):
    return _newton(chain, K, qr, x, q0, tol, max_iter)


@_solve.defjvp
def _solve_jvp(tol, max_iter, primals, tangents):
    chain, K, qr, x, q0 = primals
    q, lam = _solve(chain, K, qr, x, q0, tol, max_iter)
    # Implicit function theorem: [[H, −Jᵀ], [J, 0]] (q̇, λ̇) = −(ġ, ċ) with θ̇ = (chain, KJ, q_rest, x)˙.
    _, (dg, dc, _) = jax.jvp(lambda ch, k, r, t: _residual(ch, k, r, t, q, lam), primals[:4], tangents[:4])
    _, _, J = _residual(chain, K, qr, x, q, lam)
    H = _lagrangian_hessian(chain, K, q, lam)
    dq, dlam = _kkt_solve(H, J, -dg[:, None], -dc[:, None])
    return (q, lam), (dq[:, 0], dlam[:, 0])


def equilibrium_one(
    chain: Chain, K, qr, x, q0, *, tol: float = 1e-10, max_iter: int = 50, check_minimum: bool = True
):
    """One item (vmap it): ``K`` (n, n), ``qr`` (n,), ``x`` (m,), ``q0`` (n,).

    Returns ``(q (n,), lam (m,), converged (), kkt_residual ())``; ``q`` and ``lam`` are
    differentiable (implicit), the flags are not. ``check_minimum=False`` skips the second-order
    test in ``converged`` (KKT residual only; cheaper inside fits).
    """
    q, lam = _solve(chain, K, qr, x, q0, float(tol), int(max_iter))
    Ks, qrs, xs, qs, ls = jax.lax.stop_gradient((K, qr, x, q, lam))
    g, c, J = _residual(chain, Ks, qrs, xs, qs, ls)
    res = jnp.maximum(jnp.max(jnp.abs(g)) / jnp.max(jnp.abs(Ks)), jnp.max(jnp.abs(c)))
    ok = jnp.isfinite(res) & (res <= 1e3 * tol * (1.0 + jnp.max(jnp.abs(qs))))
    if check_minimum:
        ok = ok & _is_minimum(_lagrangian_hessian(chain, Ks, qs, ls), J)
    return q, lam, ok, res


@partial(jax.jit, static_argnames=("tol", "max_iter"))
def _flat_solve(chain, K, qr, x, q0, *, tol, max_iter):
    return jax.vmap(lambda k, r, t, q: equilibrium_one(chain, k, r, t, q, tol=tol, max_iter=max_iter))(
        K, qr, x, q0
    )


def equilibrium_posture(
    chain: Chain,
    KJ,
    q_rest,
    target,
    q_init=None,
    *,
    tol: float = 1e-10,
    max_iter: int = 50,
    return_info: bool = False,
):
    """Equilibrium posture of the λ0-PMP: ``argmin ½ (q − q_rest)ᵀ KJ (q − q_rest)`` s.t. ``fk(q) = target``.

    **Arguments:**
    - ``chain``: a :class:`Chain` (``Wrist``, ``PlanarArm``, ``FunctionChain``, ...).
    - ``KJ``: (..., n, n) SPD joint stiffness [Nm/rad] (only its shape matters, not its scale).
    - ``q_rest``: (..., n) rest posture [rad].
    - ``target``: (..., m) task position (wrist: screen point [m]); must be reachable.
    - ``q_init``: optional (..., n) initial guess (default ``q_rest``; see module docstring).
    - ``tol``: Newton stops when every step is below ``tol (1 + |q|_∞)``; ``max_iter`` bounds it.
    - ``return_info``: return an :class:`Equilibrium` (``q``, ``lam``, ``converged``,
      ``kkt_residual``) instead of ``q`` alone.

    Leading axes of all arrays broadcast (targets × subjects, ...). Differentiable with respect to
    ``KJ``, ``q_rest``, ``target`` and the chain's parameters (implicit function theorem; forward
    and reverse mode); works under ``jit``/``vmap`` (validation then only checks shapes).

    **Raises:** ``TypeError`` for a non-chain, ``ValueError`` naming the argument for wrong shapes,
    NaN/inf, non-SPD ``KJ``, unreachable ``target``, non-positive ``tol``/``max_iter``.
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
    check_positive_int("max_iter", max_iter)
    shapes = [np.shape(KJ)[:-2], np.shape(q_rest)[:-1], np.shape(target)[:-1]]
    if q_init is not None:
        shapes.append(np.shape(q_init)[:-1])
    try:
        batch = tuple(np.broadcast_shapes(*shapes))
    except ValueError as e:
        raise ValueError(
            f"leading (batch) axes of `KJ` {shapes[0]}, `q_rest` {shapes[1]}, `target` {shapes[2]}"
            + (f", `q_init` {shapes[3]}" if q_init is not None else "")
            + " do not broadcast"
        ) from e
    B = math.prod(batch)
    dtype = jnp.result_type(float)

    def flat(a, core):
        a = jnp.asarray(a, dtype)
        return jnp.broadcast_to(a, batch + a.shape[a.ndim - core :]).reshape((B,) + a.shape[a.ndim - core :])

    q0 = q_rest if q_init is None else q_init
    # Pad the flat batch to a power of two (>= 8) so that calls of similar size share one compile.
    Bp = max(8, 1 << (B - 1).bit_length())

    def padded(a):
        return jnp.concatenate([a, jnp.broadcast_to(a[:1], (Bp - B,) + a.shape[1:])]) if Bp > B else a

    q, lam, ok, res = (
        a[:B]
        for a in _flat_solve(
            chain,
            *(padded(flat(a, c)) for a, c in ((KJ, 2), (q_rest, 1), (target, 1), (q0, 1))),
            tol=float(tol),
            max_iter=int(max_iter),
        )
    )
    q = q.reshape(batch + (n,))
    if not return_info:
        return q
    return Equilibrium(
        q=q, lam=lam.reshape(batch + (m,)), converged=ok.reshape(batch), kkt_residual=res.reshape(batch)
    )
