"""Donders' law in coefficients, parameter and coefficient names, and the model's torsion.

The KKT condition of the equilibrium, ``KJ (q − q_rest) = J(q)ᵀ λ``, says ``N(q)ᵀ (KJ q − b) = 0``
with ``N(q)`` spanning the null space of ``J(q)`` and ``b = KJ q_rest``: every posture lies on a
surface whose equation is *linear* in the coefficients ``c = (free entries of KJ, b)``
(:func:`donders_coefficients`; the trace fixes their scale). The fit's identifiability report is
given in ``c`` (``fitting._donders.fit``).
"""

from __future__ import annotations

from functools import partial

import jax.numpy as jnp

from pmpjax import Chain, Wrist, equilibrium_posture, rotvec_from_joint_angles
from pmpjax.internal import fast_compile_jit, on_host

from .._optimise import params_vector, spd_size, stiffness_matrix, sym_index

_WRIST_JOINTS = ("PS", "FE", "RUD")


def donders_coefficients(params, n: int, trace: float = 4.0):
    """Coefficients of Donders' law ``N(q)ᵀ(KJ q − b) = 0`` from the NIO fit's parameters.

    In these coefficients the equilibrium condition is linear, so ``fitting.fit_donders`` reports
    identifiability and standard errors in them.

    **Arguments:**

    - ``params``: (p,) the fitted parameters (:func:`parameter_names`: log-stiffness entries, then
      ``q_rest`` [rad]), ``p = n(n+1)/2 − 1 + n``.
    - ``n``: number of joints (≥ 2).
    - ``trace``: the trace of ``KJ`` [Nm/rad].

    **Returns:**

    (p,) coefficients ``c``: the free entries of ``KJ`` (diagonal 0..n−2, then the upper triangle)
    [Nm/rad] and ``b = KJ q_rest`` [Nm] (:func:`coefficient_names`).

    **Raises:**

    - ``ValueError`` naming the argument for ``n < 2`` or ``params`` of the wrong shape.
    """
    return _donders_coefficients(params_vector("params", params, n, spd_size(n) + n), n, trace)


@partial(fast_compile_jit, static_argnums=1)
def _donders_coefficients(params, n, trace):
    n_k = spd_size(n)
    KJ = stiffness_matrix(params[:n_k], n, trace)
    return jnp.concatenate([jnp.stack([KJ[i, j] for i, j in sym_index(n)]), KJ @ params[n_k:]])


def _labels(chain: Chain):
    if not isinstance(chain, Chain):
        raise TypeError(f"`chain` must be a pmpjax Chain, got {type(chain).__name__}")
    return _WRIST_JOINTS if isinstance(chain, Wrist) else tuple(str(i) for i in range(chain.n))


def coefficient_names(chain: Chain) -> tuple[str, ...]:
    """Names of the coefficients of :func:`donders_coefficients`.

    **Arguments:**

    - ``chain``: the chain (wrist joints are named PS, FE, RUD; other chains' by index).

    **Returns:**

    ``K[i,j]`` for the free entries of ``KJ``, then ``b[i]`` with ``b = KJ q_rest``.

    **Raises:**

    - ``TypeError`` for a non-chain.
    """
    lab = _labels(chain)
    return tuple(f"K[{lab[i]},{lab[j]}]" for i, j in sym_index(chain.n)) + tuple(f"b[{v}]" for v in lab)


def parameter_names(chain: Chain) -> tuple[str, ...]:
    """Names of the NIO fit's parameters.

    **Arguments:**

    - ``chain``: the chain (wrist joints are named PS, FE, RUD; other chains' by index).

    **Returns:**

    The log-stiffness entries ``logK[i,j]``, then ``q_rest[i]``.

    **Raises:**

    - ``TypeError`` for a non-chain.
    """
    lab = _labels(chain)
    n = chain.n
    return tuple(f"logK[{lab[i]},{lab[j]}]" for i, j in sym_index(n)) + tuple(f"q_rest[{v}]" for v in lab)


def predicted_torsion(chain: Wrist, KJ, q_rest, pointing):
    """The model's torsion at pointing targets: the first component of the rotation vector of the
    λ0-PMP's equilibrium posture. Differentiable in ``KJ``, ``q_rest`` and ``pointing``.

    **Arguments:**

    - ``chain``: the :class:`pmpjax.Wrist`.
    - ``KJ``: (..., 3, 3) SPD joint stiffness [Nm/rad].
    - ``q_rest``: (..., 3) rest posture [rad].
    - ``pointing``: (..., P, 2) screen targets [m].

    **Returns:**

    (..., P) torsion ``r_x`` [rad].

    **Raises:**

    - ``TypeError`` for a chain that is not a ``Wrist``; ``ValueError`` as
      :func:`pmpjax.equilibrium_posture` for bad shapes or values.
    """
    if not isinstance(chain, Wrist):
        raise TypeError(f"`chain` must be a pmpjax.Wrist, got {type(chain).__name__}")
    q = equilibrium_posture(
        chain, on_host(jnp.asarray(KJ), lambda a: a[..., None, :, :]),
        on_host(jnp.asarray(q_rest), lambda a: a[..., None, :]), pointing
    ).q
    return on_host(rotvec_from_joint_angles(q), lambda r: r[..., 0])

