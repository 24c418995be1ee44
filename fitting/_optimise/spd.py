"""The one SPD parametrisation of stiffness (and damping) matrices, n×n, NumPy and JAX.

``KJ = t · expm(S) / tr(expm(S))`` with ``S`` symmetric and traceless: ``n(n+1)/2 − 1`` free
entries of ``S`` (:func:`sym_index`: diagonal 0..n−2, then the upper triangle row by row) and the
trace ``t``. This map is a smooth bijection from traceless symmetric matrices onto SPD matrices of
trace ``t`` (matrix log, then normalise), so every parameter vector is valid, no constraint or
penalty is needed, the parameter count equals the true number of degrees of freedom (no built-in
flat direction, unlike a normalised Cholesky factor), and there is no eigenvector-ordering
ambiguity or singularity at equal eigenvalues (unlike eigenvalue + rotation parameterisations).
``S = 0`` is isotropic. Used by the Donders (NIO), time-constant and reaching fits alike.
"""

from __future__ import annotations

from functools import partial

import jax.numpy as jnp
import numpy as np

from pmpjax.internal import as_array, check_spd, fast_compile_jit, to_jax


def sym_index(n):
    """Index pairs of the free entries of a traceless symmetric n×n matrix: diagonal 0..n−2, then
    the upper triangle row by row."""
    return [(i, i) for i in range(n - 1)] + [(i, j) for i in range(n) for j in range(i + 1, n)]


def spd_size(n: int) -> int:
    """Number of parameters of an n×n SPD matrix of fixed trace: ``n(n+1)/2 − 1``."""
    return n * (n + 1) // 2 - 1


def log_stiffness(s, n):
    """The traceless symmetric ``S`` (n, n) of parameters ``s`` (n(n+1)/2 − 1,) (JAX):
    ``KJ ∝ expm(S)``, so ``cond(KJ) = exp(λ_max(S) − λ_min(S))``."""
    S = jnp.zeros((n, n), s.dtype)
    for k, (i, j) in enumerate(sym_index(n)):
        S = S.at[i, j].set(s[k]).at[j, i].set(s[k])
    return S.at[n - 1, n - 1].set(-sum(s[k] for k in range(n - 1)))


def stiffness_from_params(s, n: int, trace: float = 4.0):
    """An SPD stiffness of fixed trace from its log parameters: ``KJ = t expm(S)/tr expm(S)``.

    ``S`` is the symmetric matrix whose free entries are ``s`` (the last diagonal entry makes
    ``tr S = 0``); every ``s`` gives an SPD ``KJ`` with trace ``t``.

    **Arguments:**

    - ``s``: (n(n+1)/2 − 1,) log-stiffness parameters.
    - ``n``: number of joints (≥ 2).
    - ``trace``: ``t``, the trace of ``KJ`` [Nm/rad].

    **Returns:**

    (n, n) SPD ``KJ`` [Nm/rad].

    **Raises:**

    - ``ValueError`` naming the argument for ``n < 2`` or ``s`` of the wrong shape.
    """
    return stiffness_matrix(params_vector("s", s, n, spd_size(n)), n, trace)


@partial(fast_compile_jit, static_argnums=1)
def stiffness_matrix(s, n, trace):
    """:func:`stiffness_from_params` without the argument checks (JAX, compiled per ``n``)."""
    E = _expm_sym(log_stiffness(s, n))
    return trace * E / jnp.trace(E)


def params_vector(name, v, n, size):
    """Shape checks (before tracing) of a parameter vector ``v`` (size,) of an n-joint chain."""
    if int(n) != n or n < 2:
        raise ValueError(f"`n` must be an integer >= 2 (joints), got {n}")
    v = to_jax(as_array(name, v, tail=(size,)))
    if v.ndim != 1:
        raise ValueError(f"`{name}` must be a vector of shape ({size},) for n = {n}, got {v.shape}")
    return v


def _expm_sym(S, squarings: int = 6, order: int = 10):
    """``expm(S)`` by scaling and squaring a degree-10 Taylor polynomial (Horner). For
    ``|S|₂ ≤ 8`` (eigenvalue ratios up to e¹⁶) the truncation error is < 1e-15 relative; a small
    graph (compile time) and exact derivatives. ``S`` is symmetric so ``E`` is too."""
    A = S / 2.0**squarings
    eye = jnp.eye(S.shape[0], dtype=S.dtype)
    E = eye
    for k in range(order, 0, -1):
        E = eye + (A @ E) / k
    for _ in range(squarings):
        E = E @ E
    return 0.5 * (E + E.T)


def params_from_stiffness(KJ):
    """The inverse of :func:`stiffness_from_params` (the trace is dropped):
    ``S = log KJ − tr(log KJ)/n I``.

    **Arguments:**

    - ``KJ``: (..., n, n) SPD stiffness.

    **Returns:**

    (..., n(n+1)/2 − 1) log-stiffness parameters (NumPy).

    **Raises:**

    - ``ValueError`` naming ``KJ`` for a wrong shape, NaN/inf or a matrix that is not SPD.
    """
    KJ = np.asarray(as_array("KJ", KJ, tail=(None, None)), dtype=float)
    check_spd("KJ", KJ)
    n = KJ.shape[-1]
    w, V = np.linalg.eigh(KJ)
    L = (V * np.log(w)[..., None, :]) @ np.swapaxes(V, -1, -2)
    L = L - np.trace(L, axis1=-2, axis2=-1)[..., None, None] / n * np.eye(n)
    return np.stack([L[..., i, j] for i, j in sym_index(n)], -1)


def params_from_stiffness_jax(KJ):
    """:func:`params_from_stiffness` of one SPD ``KJ`` (n, n) in JAX (traceable, no checks)."""
    n = KJ.shape[-1]
    w, V = jnp.linalg.eigh(KJ)
    L = (V * jnp.log(w)[None, :]) @ V.T
    L = L - jnp.trace(L) / n * jnp.eye(n, dtype=KJ.dtype)
    return jnp.stack([L[i, j] for i, j in sym_index(n)])


def damping_start(KJ, damping: str):
    """Starting parameters of a free damping ``W̃`` at the stiffness ``KJ`` (n, n) (JAX):
    ``"diagonal"`` the n − 1 log ratios of ``diag KJ`` to its first entry, ``"full"``
    :func:`params_from_stiffness_jax` (``W̃ = KJ``: the paper's Eq 7 inside the free model), and
    nothing for ``"tau0_KJ"``."""
    if damping == "diagonal":
        d = jnp.log(jnp.diag(KJ))
        return d[1:] - d[0]
    if damping == "full":
        return params_from_stiffness_jax(KJ)
    return jnp.zeros((0,), KJ.dtype)


def lm_iterations(max_steps) -> tuple[int, int]:
    """``max_steps`` of a two-stage fit as ``(stage 1 >= 1, stage 2 >= 0)`` Levenberg–Marquardt
    iterations; ``TypeError``/``ValueError`` naming the argument otherwise."""
    try:
        ms = tuple(int(v) for v in max_steps)
    except (TypeError, ValueError) as e:
        raise TypeError(f"`max_steps` must be a pair of integers, got {max_steps!r}") from e
    if len(ms) != 2 or ms[0] < 1 or ms[1] < 0:
        raise ValueError(f"`max_steps` must be (stage-1 >= 1, stage-2 >= 0) LM iterations, got {max_steps!r}")
    return ms
