"""Small dense linear algebra on component-leading arrays.

Matrices are stored as ``(rows, cols, *batch)`` and vectors as ``(rows, *batch)``: the small
dimensions lead and the batch trails, so every operation below is a handful of elementwise
multiply-adds over contiguous batch arrays that XLA fuses into one loop (no batched tiny GEMMs,
no LAPACK calls inside the time loop). Sizes are static and loops unroll at trace time.
"""

from __future__ import annotations

import jax.numpy as jnp


def elements(A):
    """Split a component-leading matrix (r, c, ...) into nested lists of (...) arrays.

    Each entry is sliced once per call instead of once per use, which keeps graphs (and compile
    times) small. (``jnp.unstack`` would be smaller still but blocks XLA's loop fusion on CPU:
    measured 13× slower inside the RK4 loop.)
    """
    return [[A[i, j] for j in range(A.shape[1])] for i in range(A.shape[0])]


def mv(A, v):
    """``A @ v`` for ``A`` (r, k, ...) and ``v`` (k, ...) -> (r, ...)."""
    a, v = elements(A), [v[j] for j in range(v.shape[0])]
    return jnp.stack([sum(ai[j] * v[j] for j in range(len(v))) for ai in a])


def mm(A, B):
    """``A @ B`` for ``A`` (r, k, ...) and ``B`` (k, c, ...) -> (r, c, ...)."""
    a, b = elements(A), elements(B)
    k, c = len(b), len(b[0])
    return jnp.stack([jnp.stack([sum(ai[p] * b[p][j] for p in range(k)) for j in range(c)]) for ai in a])


def spd_solve(M, b):
    """Solve ``M y = b`` for symmetric positive definite ``M`` (m, m, ...), ``b`` (m, ...):
    :func:`spd_solve_lists` on the elements."""
    (x,) = spd_solve_lists(elements(M), [b[j] for j in range(M.shape[0])])
    return jnp.stack(x)


def spd_solve_lists(M, *bs):
    """:func:`spd_solve` on element lists, for fused per-sample kernels: ``M`` nested lists
    (m × m) of (...) arrays, each ``b`` a list of m; returns one solution list per ``b``.

    Closed forms (adjugate over determinant) for m <= 3, LDLᵀ above. Nothing is stacked and the
    adjugate needs a single division, so XLA fuses the whole solve into the loop that reads the
    solutions (an LDLᵀ's divisions each end a fused loop on XLA:CPU: measured 2× slower in the
    IK-weight kernel).
    """
    m = len(M)
    if m == 1:
        return [[b[0] / M[0][0]] for b in bs]
    if m == 2:
        a, c, d = M[0][0], M[0][1], M[1][1]
        inv_det = 1.0 / (a * d - c * c)
        return [[(d * b[0] - c * b[1]) * inv_det, (a * b[1] - c * b[0]) * inv_det] for b in bs]
    if m == 3:
        (a, b_, c), (_, d, e), f = M[0], M[1], M[2][2]
        A00, A01, A02 = d * f - e * e, c * e - b_ * f, b_ * e - c * d
        A11, A12, A22 = a * f - c * c, b_ * c - a * e, a * d - b_ * b_
        inv_det = 1.0 / (a * A00 + b_ * A01 + c * A02)
        adj = ((A00, A01, A02), (A01, A11, A12), (A02, A12, A22))
        return [[sum(adj[r][k] * v[k] for k in range(3)) * inv_det for r in range(3)] for v in bs]
    return _ldl_solve_lists(M, *bs)


def _ldl_solve_lists(M, *bs):
    """Unrolled LDLᵀ (no pivoting: SPD) on element lists, one factorisation for all ``bs``."""
    m = len(M)
    L = [[None] * m for _ in range(m)]
    D = [None] * m
    for j in range(m):
        D[j] = M[j][j] - sum(L[j][k] * L[j][k] * D[k] for k in range(j))
        for i in range(j + 1, m):
            L[i][j] = (M[i][j] - sum(L[i][k] * L[j][k] * D[k] for k in range(j))) / D[j]
    out = []
    for b in bs:
        y = [None] * m
        for i in range(m):
            y[i] = b[i] - sum(L[i][k] * y[k] for k in range(i))
        z = [y[i] / D[i] for i in range(m)]
        x = [None] * m
        for i in reversed(range(m)):
            x[i] = z[i] - sum(L[k][i] * x[k] for k in range(i + 1, m))
        out.append(x)
    return out


def lu_factor_lists(M):
    """LU factorisation with partial pivoting of a small general matrix given as nested lists
    (m × m) of (...) arrays, each batch element pivoting on its own: returns ``(L, U, swaps)``
    for :func:`lu_solve_lists` (unrolled at trace time: elementwise selects and multiply-adds
    that XLA fuses into the loop around it; one division per column)."""
    m = len(M)
    A = [list(row) for row in M]
    L = [[None] * m for _ in range(m)]
    swaps = []
    for k in range(m):
        best, idx = A[k][k], jnp.full(jnp.shape(A[k][k]), k)
        for r in range(k + 1, m):
            take = jnp.abs(A[r][k]) > jnp.abs(best)
            best, idx = jnp.where(take, A[r][k], best), jnp.where(take, r, idx)
        for r in range(k + 1, m):
            s = idx == r
            for c in range(m):
                A[k][c], A[r][c] = jnp.where(s, A[r][c], A[k][c]), jnp.where(s, A[k][c], A[r][c])
            for c in range(k):
                L[k][c], L[r][c] = jnp.where(s, L[r][c], L[k][c]), jnp.where(s, L[k][c], L[r][c])
        swaps.append(idx)
        inv = 1.0 / A[k][k]
        for r in range(k + 1, m):
            L[r][k] = A[r][k] * inv
            for c in range(k + 1, m):
                A[r][c] = A[r][c] - L[r][k] * A[k][c]
        A[k][k] = inv  # (U's diagonal kept inverted: solves multiply)
    return L, A, swaps


def lu_solve_lists(lu, b):
    """Solve ``M y = b`` for ``lu = lu_factor_lists(M)`` and ``b`` a list of m (...) arrays."""
    L, U, swaps = lu
    m = len(b)
    y = list(b)
    for k in range(m):
        for r in range(k + 1, m):
            s = swaps[k] == r
            y[k], y[r] = jnp.where(s, y[r], y[k]), jnp.where(s, y[k], y[r])
    for i in range(m):
        for k in range(i):
            y[i] = y[i] - L[i][k] * y[k]
    x = [None] * m
    for i in reversed(range(m)):
        for k in range(i + 1, m):
            y[i] = y[i] - U[i][k] * x[k]
        x[i] = y[i] * U[i][i]
    return x


def spd_inv(M):
    """Inverse of SPD ``M`` (m, m, ...), column by column through :func:`spd_solve`."""
    m = M.shape[0]
    eye = jnp.eye(m, dtype=M.dtype).reshape((m, m) + (1,) * (M.ndim - 2))
    cols = [spd_solve(M, jnp.broadcast_to(eye[:, j], M.shape[1:])) for j in range(m)]
    return jnp.stack(cols, axis=1)


def det(M):
    """Determinant of a small square ``M`` (m, m, ...) by cofactor expansion (m <= 3) or LU."""
    if M.shape[0] > 3:
        return jnp.linalg.det(jnp.moveaxis(M, (0, 1), (-2, -1)))
    return det_lists(elements(M))


def det_lists(M):
    """Determinant of ``M`` given as nested lists (m × m) of (...) arrays: by cofactors for m <= 3
    (nothing is stacked, so XLA fuses it into the loop that reads it), by LU above."""
    m = len(M)
    if m > 3:
        return det(jnp.stack([jnp.stack(r) for r in M]))
    if m == 1:
        return M[0][0]
    if m == 2:
        return M[0][0] * M[1][1] - M[0][1] * M[1][0]
    return (
        M[0][0] * (M[1][1] * M[2][2] - M[1][2] * M[2][1])
        - M[0][1] * (M[1][0] * M[2][2] - M[1][2] * M[2][0])
        + M[0][2] * (M[1][0] * M[2][1] - M[1][1] * M[2][0])
    )


def to_soa(x, k: int = 1):
    """Move the last ``k`` (component) axes of ``x`` to the front (NumPy in, NumPy out)."""
    return x.transpose(tuple(range(x.ndim - k, x.ndim)) + tuple(range(x.ndim - k)))


def from_soa(x, k: int = 1):
    """Inverse of :func:`to_soa`."""
    return x.transpose(tuple(range(k, x.ndim)) + tuple(range(k)))
