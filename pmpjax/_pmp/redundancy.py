"""Redundancy operators of a weighted pseudo-inverse (Eqs 3–4): the one implementation.

With admittance ``A = W⁻¹`` (n×n SPD) and Jacobian ``J`` (m×n):
``B = (J A Jᵀ)⁻¹`` task damping, ``J#_W = A Jᵀ B``, null-space projector ``N = I − J#_W J``,
``λ0 = B J A τ_el``. The ``*_soa`` kernels work on component-leading arrays (see ``_linalg``) and
are what integrators and fits call; the public functions take batch-leading arrays
(``J`` (..., m, n), ``W`` (..., n, n) or diagonal weights ``w`` (..., n)).
"""

from __future__ import annotations

from functools import partial

import jax.numpy as jnp
import numpy as np

from .._base import (
    as_array,
    check_positive,
    check_spd,
    elements,
    fast_compile_jit,
    from_soa,
    mm,
    mv,
    spd_inv,
    spd_solve,
    spd_solve_lists,
    to_jax,
    to_soa,
)


def admittance_terms_soa(J, A):
    """``P = A Jᵀ`` (n, m, ...) and ``M = J A Jᵀ = B⁻¹`` (m, m, ...)."""
    P = mm(A, jnp.swapaxes(J, 0, 1))
    return P, mm(J, P)


def _diag_terms(J, a):
    """Nested lists ``P[i][r] = a_i J_ri`` and ``M[r][c] = Σ_i J_ri a_i J_ci`` (no stacking, so
    XLA fuses everything that reads them into one loop). ``J`` (m, n, ...) or nested lists."""
    J = J if isinstance(J, list) else elements(J)
    m, n = len(J), len(J[0])
    P = [[a[i] * J[r][i] for r in range(m)] for i in range(n)]
    M = [[None] * m for _ in range(m)]
    for r in range(m):
        for c in range(r, m):
            M[r][c] = M[c][r] = sum(J[r][i] * P[i][c] for i in range(n))
    return P, M


def pinv_diag_lists(J, a, *rhs):
    """Element-list form of :func:`pinv_apply_diag_soa`: ``J`` nested lists ``J[r][i]`` (or
    (m, n, ...)), ``a`` the n diagonal admittances, each ``b`` in ``rhs`` a list of m arrays;
    returns ``J#_W b`` as one list of n arrays per ``b``."""
    P, M = _diag_terms(J, a)
    m, n = len(M), len(P)
    return [[sum(P[i][r] * y[r] for r in range(m)) for i in range(n)] for y in spd_solve_lists(M, *rhs)]


def pinv_apply_diag_soa(J, a, *rhs):
    """``J#_W b = A Jᵀ (J A Jᵀ)⁻¹ b`` (n, ...) for each ``b`` (m, ...) in ``rhs``, ``A = diag(a)``.

    The weighted pseudo-inverse applied without forming it: one ``M = J A Jᵀ`` shared by all
    right-hand sides, no intermediate stacked ``P`` (several times faster on CPU for large batches).
    """
    lists = pinv_diag_lists(J, a, *([b[j] for j in range(b.shape[0])] for b in rhs))
    return [jnp.stack(x) for x in lists]


def pinv_soa(J, A):
    """Weighted pseudo-inverse ``J#_W = A Jᵀ (J A Jᵀ)⁻¹`` (n, m, ...)."""
    P, M = admittance_terms_soa(J, A)
    return mm(P, spd_inv(M))


def lambda0_soa(J, M, A_tau):
    """``λ0 = B J A τ_el`` (m, ...) given ``M = B⁻¹`` and ``A τ_el`` (n, ...) (Eq 4)."""
    return spd_solve(M, mv(J, A_tau))


def _check_weights(J, W, w):
    """Validated ``W`` (..., n, n) or ``w`` (..., n) as arrays (the other None)."""
    n = J.shape[-1]
    if (W is None) == (w is None):
        raise ValueError("give exactly one of `W` (..., n, n) or diagonal weights `w` (..., n)")
    if w is not None:
        w = to_jax(as_array("w", w, tail=(n,)))
        check_positive("w", w)
        return None, w
    W = to_jax(as_array("W", W, tail=(n, n)))
    check_spd("W", W)
    return W, None


def _admittance(n, W, w):
    """``A = W⁻¹`` (n, n, ...) component-leading, from checked ``W`` or ``w``."""
    if w is not None:
        return to_soa(jnp.eye(n).reshape((1,) * (w.ndim - 1) + (n, n)) / w[..., None, :], 2)
    return spd_inv(to_soa(W, 2))


def _check_J(J):
    J = to_jax(as_array("J", J))
    if J.ndim < 2:
        raise ValueError(f"`J` must have shape (..., m, n), got {J.shape}")
    if J.shape[-2] > J.shape[-1]:
        raise ValueError(f"`J` must be wide (m <= n), got shape {J.shape}")
    return J


def _bcast(J, A):
    """Broadcast the trailing batch axes of component-leading ``J`` and ``A`` NumPy-style (the
    batch axes were leading in the public arrays, so shorter batches are padded on their left)."""
    batch = tuple(np.broadcast_shapes(J.shape[2:], A.shape[2:]))

    def pad(X):
        X = X.reshape(X.shape[:2] + (1,) * (len(batch) - (X.ndim - 2)) + X.shape[2:])
        return jnp.broadcast_to(X, X.shape[:2] + batch)

    return pad(J), pad(A)


def _operator(which, J, W=None, w=None, tau_el=None):
    """Validate, then evaluate operator ``which`` in one compiled call (eager calls compile once
    per shape instead of once per ``jnp`` op)."""
    J = _check_J(J)
    W, w = _check_weights(J, W, w)
    if tau_el is not None:
        tau_el = to_jax(as_array("tau_el", tau_el, tail=(J.shape[-1],)))
    return _operator_jit(which, J, W, w, tau_el)


@partial(fast_compile_jit, static_argnums=0)
def _operator_jit(which, J, W, w, tau_el):
    n = J.shape[-1]
    Js, A = _bcast(to_soa(J, 2), _admittance(n, W, w))
    if which == "pinv":
        return from_soa(pinv_soa(Js, A), 2)
    if which == "null":
        eye = jnp.eye(n).reshape((n, n) + (1,) * (Js.ndim - 2))
        return from_soa(eye - mm(pinv_soa(Js, A), Js), 2)
    if which == "damping":
        return from_soa(spd_inv(admittance_terms_soa(Js, A)[1]), 2)
    tau = to_soa(jnp.broadcast_to(tau_el, J.shape[:-2] + J.shape[-1:]))
    P, M = admittance_terms_soa(Js, A)
    return from_soa(lambda0_soa(Js, M, mv(A, tau)))


def weighted_pinv(J, W=None, *, w=None):
    """The W-weighted pseudo-inverse ``J#_W = W⁻¹ Jᵀ (J W⁻¹ Jᵀ)⁻¹`` (Eq 3).

    **Arguments:**

    - ``J``: (..., m, n) Jacobians, wide (m <= n).
    - ``W``: (..., n, n) SPD joint damping / weight matrix, or
    - ``w``: (..., n) positive diagonal weights instead (give exactly one of ``W`` and ``w``).

    **Returns:**

    (..., n, m) the pseudo-inverse.

    **Raises:**

    - ``ValueError`` naming the argument for wrong shapes, a tall ``J``, both or neither of ``W`` and ``w``,
      non-SPD ``W`` or non-positive ``w``.
    """
    return _operator("pinv", J, W, w)


def nullspace_projector(J, W=None, *, w=None):
    """The null-space projector ``I − J#_W J``: joint velocities that leave the task position still.

    **Arguments:**

    - ``J``: (..., m, n) Jacobians, wide (m <= n).
    - ``W``: (..., n, n) SPD joint damping / weight matrix, or
    - ``w``: (..., n) positive diagonal weights instead (give exactly one of ``W`` and ``w``).

    **Returns:**

    (..., n, n) the projector.

    **Raises:**

    - ``ValueError`` naming the argument for wrong shapes, a tall ``J``, both or neither of ``W`` and ``w``,
      non-SPD ``W`` or non-positive ``w``.
    """
    return _operator("null", J, W, w)


def task_damping(J, W=None, *, w=None):
    """Task-space damping ``B = (J W⁻¹ Jᵀ)⁻¹`` (Eq 3).

    **Arguments:**

    - ``J``: (..., m, n) Jacobians, wide (m <= n).
    - ``W``: (..., n, n) SPD joint damping / weight matrix, or
    - ``w``: (..., n) positive diagonal weights instead (give exactly one of ``W`` and ``w``).

    **Returns:**

    (..., m, m) the task damping.

    **Raises:**

    - ``ValueError`` naming the argument for wrong shapes, a tall ``J``, both or neither of ``W`` and ``w``,
      non-SPD ``W`` or non-positive ``w``.
    """
    return _operator("damping", J, W, w)


def lambda0(J, W, tau_el):
    """The task force ``λ0 = B J W⁻¹ τ_el`` that blocks the elastic torque in task space (Eq 4).

    **Arguments:**

    - ``J``: (..., m, n) Jacobians, wide (m <= n).
    - ``W``: (..., n, n) SPD joint damping.
    - ``tau_el``: (..., n) elastic torque ``KJ (q − q_rest)`` [Nm].

    **Returns:**

    (..., m) the task force ``λ0``.

    **Raises:**

    - ``ValueError`` naming the argument for wrong shapes, a tall ``J`` or a non-SPD ``W``.
    """
    return _operator("lambda0", J, W, None, tau_el)
