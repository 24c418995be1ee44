"""Fits on the springy arm (Williamson 1996): blend weights that place the hand, stiffness from sag.

Both go through the shared Levenberg–Marquardt loop (``fitting._optimise.least_squares``) and
differentiate the gravity equilibrium by the implicit function theorem through the documented
internal kernel ``pmpjax._springy_arm.primitives.arm_equilibrium_one``. Each target / subject is
one vmapped item with its own status (:class:`pmpjax.Status`); one failing item never stops or
poisons the others. Flat batches are padded to a power of two (>= 8) so similar calls share one
compile (a single item and a batch of 3 compile once).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp

from pmpjax import CogArm, Status
from pmpjax.internal import (
    arm_equilibrium_one,
    as_array,
    bucket,
    check_arm,
    check_positive,
    check_positive_int,
    check_set_point,
    check_stiffness,
    fast_compile_jit,
    pad_rows,
    pytree_dataclass,
    to_jax,
)

from .._optimise import least_squares

N_NEWTON = 12  # Newton steps per equilibrium inside the fits (quadratic convergence from θ_set)


def _softmax_weights(z):
    """``α`` (k,) on the open simplex from ``z`` (k−1,) (last logit fixed at 0): Σα = 1, α > 0."""
    return jax.nn.softmax(jnp.concatenate([z, jnp.zeros(1, z.dtype)]))


def _fit_status(finite, optimiser_converged, reached=True):
    return jnp.where(
        ~finite,
        Status.NONFINITE,
        jnp.where(optimiser_converged, jnp.where(reached, Status.SUCCESSFUL, Status.STALLED), Status.MAX_STEPS),
    ).astype(jnp.int32)


@pytree_dataclass
class BlendFit:
    """Fitted primitive blend weights (the result of :func:`fit_blend_weights`).

    **Fields:**

    - ``alpha``: (..., k) fitted weights (Σα = 1, α > 0).
    - ``hand``: (..., 3) equilibrium hand position [m].
    - ``error``: (...,) distance to the target [m].
    - ``status``: (...,) int :class:`pmpjax.Status`: ``SUCCESSFUL`` = target reached within ``tol``;
      ``STALLED`` = the optimiser settled on the closest blend of a target outside the region the
      primitives span; ``MAX_STEPS``; ``NONFINITE``.
    - ``steps``: (...,) Levenberg–Marquardt iterations.

    ``converged`` = ``status == 0``.
    """

    alpha: jax.Array
    hand: jax.Array
    error: jax.Array
    status: jax.Array
    steps: jax.Array

    @property
    def converged(self):
        return self.status == Status.SUCCESSFUL


def fit_blend_weights(arm: CogArm, P, target, *, K=None, tol: float = 1e-6, max_steps: int = 50) -> BlendFit:
    """Blend weights ``α`` whose equilibrium under gravity puts the hand at a target.

    ``α = softmax(z, 0)`` keeps the blend a superposition (Σα = 1, α > 0), so targets outside the
    region the primitives span are reported with status ``STALLED`` and the closest blend.
    Levenberg–Marquardt through :func:`pmpjax.arm_equilibrium`.

    **Arguments:**

    - ``arm``: a :class:`pmpjax.CogArm`.
    - ``P``: (k, n) primitives [rad], k ≥ 2.
    - ``target``: (..., 3) hand targets [m].
    - ``K``: (n,) joint stiffness [Nm/rad] (default the arm's).
    - ``tol``: the largest distance to the target that counts as reached [m].
    - ``max_steps``: Levenberg–Marquardt iterations at most.

    **Returns:**

    A :class:`BlendFit`.

    **Raises:**

    - ``TypeError`` for a non-arm; ``ValueError`` naming the argument for wrong shapes, NaN/inf,
      non-positive ``K``, ``tol`` or ``max_steps``.
    """
    check_arm(arm)
    n = arm.n
    P = to_jax(as_array("P", P, tail=(None, n)), float)
    if P.ndim != 2 or P.shape[0] < 2:
        raise ValueError(f"`P` must be (k, {n}) with k >= 2 primitives, got {P.shape}")
    target = to_jax(as_array("target", target, tail=(3,)), float)
    K = check_stiffness("K", arm.K if K is None else K, n)
    if K.shape != (n,):
        raise ValueError(f"`K` must have shape ({n},), got {K.shape}")
    check_positive("tol", tol)
    max_steps = check_positive_int("max_steps", max_steps)
    batch = target.shape[:-1]
    flat = target.reshape(-1, 3)
    B = flat.shape[0]
    padded = pad_rows(flat, bucket(B, minimum=8))
    alpha, hand, steps, conv = (
        a[:B] for a in _fit_blend(arm.mjx_model, arm.layout.hand_site, P, K, padded, max_steps)
    )
    err = jnp.linalg.norm(hand - flat, axis=-1)
    finite = jnp.isfinite(err) & jnp.all(jnp.isfinite(alpha), axis=-1)
    return BlendFit(
        alpha=alpha.reshape(batch + (P.shape[0],)),
        hand=hand.reshape(batch + (3,)),
        error=err.reshape(batch),
        status=_fit_status(finite, conv, err <= tol).reshape(batch),
        steps=steps.reshape(batch),
    )


@functools.partial(fast_compile_jit, static_argnames=("site_id", "max_steps"))
def _fit_blend(mx, site_id, P, K, targets, max_steps):
    def hand_of(z):
        return arm_equilibrium_one(mx, site_id, _softmax_weights(z) @ P, K, max_steps=N_NEWTON)[1]

    def one(target):
        r = least_squares(lambda z, _: hand_of(z) - target, jnp.zeros(P.shape[0] - 1), max_steps=max_steps)
        return _softmax_weights(r.x), hand_of(r.x), r.steps, r.converged

    return jax.vmap(one)(targets)


@pytree_dataclass
class StiffnessFit:
    """Fitted joint stiffness (the result of :func:`fit_stiffness`).

    **Fields:**

    - ``K``: (..., n) fitted joint stiffness [Nm/rad].
    - ``rms``: (...,) RMS posture residual [rad].
    - ``status``: (...,) int :class:`pmpjax.Status`: ``SUCCESSFUL``, ``MAX_STEPS``, ``NONFINITE``.
    - ``steps``: (...,) Levenberg–Marquardt iterations.

    ``converged`` = ``status == 0``.
    """

    K: jax.Array
    rms: jax.Array
    status: jax.Array
    steps: jax.Array

    @property
    def converged(self):
        return self.status == Status.SUCCESSFUL


def fit_stiffness(arm: CogArm, q_set, q_observed, *, K0=None, max_steps: int = 50) -> StiffnessFit:
    """Joint stiffness from the observed gravity sag of static postures.

    ``K = exp(κ)`` keeps it positive. Use postures that load every joint (the gravity torque on a
    joint must be non-zero in some posture, or its stiffness is unidentifiable).

    **Arguments:**

    - ``arm``: a :class:`pmpjax.CogArm`.
    - ``q_set``: (P, n) set-points [rad] the postures were held with.
    - ``q_observed``: (..., P, n) observed static postures [rad]; leading axes are subjects.
    - ``K0``: (n,) starting stiffness [Nm/rad] (default the arm's).
    - ``max_steps``: Levenberg–Marquardt iterations at most.

    **Returns:**

    A :class:`StiffnessFit` with leading axes ``(...)``.

    **Raises:**

    - ``TypeError`` for a non-arm; ``ValueError`` naming the argument for wrong shapes, NaN/inf,
      non-positive ``K0`` or ``max_steps``.
    """
    check_arm(arm)
    n = arm.n
    q_set = check_set_point("q_set", q_set, n)
    if q_set.ndim != 2:
        raise ValueError(f"`q_set` must be (P, {n}) set-points, got {q_set.shape}")
    q_obs = to_jax(as_array("q_observed", q_observed, tail=q_set.shape), float)
    K0 = check_stiffness("K0", arm.K if K0 is None else K0, n)
    if K0.shape != (n,):
        raise ValueError(f"`K0` must have shape ({n},), got {K0.shape}")
    max_steps = check_positive_int("max_steps", max_steps)
    batch = q_obs.shape[:-2]
    flat = q_obs.reshape((-1,) + q_set.shape)
    B = flat.shape[0]
    padded = pad_rows(flat, bucket(B, minimum=8))
    kappa, rms, steps, conv = (
        a[:B] for a in _fit_stiffness(arm.mjx_model, q_set, padded, jnp.log(K0), max_steps)
    )
    finite = jnp.isfinite(rms) & jnp.all(jnp.isfinite(kappa), axis=-1)
    return StiffnessFit(
        K=jnp.exp(kappa).reshape(batch + (n,)),
        rms=rms.reshape(batch),
        status=_fit_status(finite, conv).reshape(batch),
        steps=steps.reshape(batch),
    )


@functools.partial(fast_compile_jit, static_argnames=("max_steps",))
def _fit_stiffness(mx, q_set, q_obs, kappa0, max_steps):
    def resid(kappa, q_o):
        K = jnp.exp(kappa)
        q = jax.vmap(lambda qs: arm_equilibrium_one(mx, None, qs, K, max_steps=N_NEWTON)[0])(q_set)
        return (q - q_o).reshape(-1)

    def one(q_o):
        r = least_squares(resid, kappa0, q_o, max_steps=max_steps)
        return r.x, jnp.sqrt(2.0 * r.cost / r.residual.shape[0]), r.steps, r.converged

    return jax.vmap(one)(q_obs)


