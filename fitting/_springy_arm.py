"""Fits on the springy arm (Williamson 1996): blend weights that place the hand, stiffness from sag.

Both go through the shared Levenberg–Marquardt loop (``fitting._optimise.least_squares``) and
differentiate the gravity equilibrium by the implicit function theorem
(``pmpjax._springy_arm.primitives.equilibrium``). Each target / subject is one vmapped item with its own
convergence flag.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp

from pmpjax._base.pytree import pytree_dataclass
from pmpjax._base.validate import as_array
from pmpjax._springy_arm.arm import CogArm
from pmpjax._springy_arm.primitives import _equilibrium_one, check_set_point, check_stiffness

from ._optimise import least_squares


def _softmax_weights(z):
    """``α`` (k,) on the open simplex from ``z`` (k−1,) (last logit fixed at 0): Σα = 1, α > 0."""
    return jax.nn.softmax(jnp.concatenate([z, jnp.zeros(1, z.dtype)]))


@pytree_dataclass
class BlendFit:
    """``alpha`` (..., k) fitted weights (Σα = 1, α > 0); ``hand`` (..., 3) [m] equilibrium hand
    position; ``error`` (...,) [m] distance to the target; ``converged`` (...,) bool (optimiser
    converged and the target reached within ``tol``); ``steps`` (...,)."""

    alpha: jax.Array
    hand: jax.Array
    error: jax.Array
    converged: jax.Array
    steps: jax.Array


def fit_blend_weights(arm: CogArm, P, target, *, K=None, tol: float = 1e-6, max_steps: int = 50) -> BlendFit:
    """Blend weights ``α`` so that the arm's equilibrium under gravity for ``Σ α_i P_i`` puts the
    hand at ``target`` (..., 3) [m]. ``P`` (k, n) primitives [rad]; ``K`` (n,) stiffness.

    ``α = softmax(z, 0)`` keeps the blend a superposition (Σα = 1, α > 0), so targets outside the
    region the primitives span are reported with ``converged=False`` and the closest blend.
    """
    n = arm.n
    P = jnp.asarray(as_array("P", P, tail=(None, n)), float)
    if P.ndim != 2 or P.shape[0] < 2:
        raise ValueError(f"`P` must be (k, {n}) with k >= 2 primitives, got {P.shape}")
    target = jnp.asarray(as_array("target", target, tail=(3,)), float)
    K = check_stiffness("K", arm.K if K is None else K, n)
    if K.shape != (n,):
        raise ValueError(f"`K` must have shape ({n},), got {K.shape}")
    batch = target.shape[:-1]
    res = _fit_blend(arm.mjx_model, arm.layout.hand_site, P, K, target.reshape(-1, 3), int(max_steps))
    alpha, hand, steps, conv = res
    err = jnp.linalg.norm(hand - target.reshape(-1, 3), axis=-1)
    return BlendFit(
        alpha=alpha.reshape(batch + (P.shape[0],)),
        hand=hand.reshape(batch + (3,)),
        error=err.reshape(batch),
        converged=(conv & (err <= tol)).reshape(batch),
        steps=steps.reshape(batch),
    )


@functools.partial(jax.jit, static_argnames=("site_id", "max_steps"))
def _fit_blend(mx, site_id, P, K, targets, max_steps):
    def hand_of(z):
        _, hand, _, _ = _equilibrium_one(mx, site_id, _softmax_weights(z) @ P, K, 12, 0.0, diagnostics=False)
        return hand

    def one(target):
        r = least_squares(lambda z, _: hand_of(z) - target, jnp.zeros(P.shape[0] - 1), max_steps=max_steps)
        return _softmax_weights(r.x), hand_of(r.x), r.steps, r.converged

    return jax.vmap(one)(targets)


@pytree_dataclass
class StiffnessFit:
    """``K`` (..., n) [Nm/rad] fitted joint stiffness; ``rms`` (...,) [rad] RMS posture residual;
    ``converged`` (...,) bool; ``steps`` (...,)."""

    K: jax.Array
    rms: jax.Array
    converged: jax.Array
    steps: jax.Array


def fit_stiffness(arm: CogArm, q_set, q_observed, *, K0=None, max_steps: int = 50) -> StiffnessFit:
    """Joint stiffness ``K`` (n,) from the observed gravity sag: static postures ``q_observed``
    (..., P, n) [rad] held with set-points ``q_set`` (P, n). ``K = exp(κ)`` keeps it positive.

    Use postures that load every joint (the gravity torque on a joint must be non-zero in some
    posture, or its stiffness is unidentifiable). Leading axes of ``q_observed`` are subjects.
    """
    n = arm.n
    q_set = check_set_point("q_set", q_set, n)
    if q_set.ndim != 2:
        raise ValueError(f"`q_set` must be (P, {n}) set-points, got {q_set.shape}")
    q_obs = jnp.asarray(as_array("q_observed", q_observed, tail=q_set.shape), float)
    K0 = check_stiffness("K0", arm.K if K0 is None else K0, n)
    batch = q_obs.shape[:-2]
    flat = q_obs.reshape((-1,) + q_set.shape)
    kappa, rms, steps, conv = _fit_stiffness(
        arm.mjx_model, arm.layout.hand_site, q_set, flat, jnp.log(K0), int(max_steps)
    )
    return StiffnessFit(
        K=jnp.exp(kappa).reshape(batch + (n,)),
        rms=rms.reshape(batch),
        converged=conv.reshape(batch),
        steps=steps.reshape(batch),
    )


@functools.partial(jax.jit, static_argnames=("site_id", "max_steps"))
def _fit_stiffness(mx, site_id, q_set, q_obs, kappa0, max_steps):
    def resid(kappa, q_o):
        K = jnp.exp(kappa)
        q = jax.vmap(lambda qs: _equilibrium_one(mx, None, qs, K, 12, 0.0, diagnostics=False)[0])(q_set)
        return (q - q_o).reshape(-1)

    def one(q_o):
        r = least_squares(resid, kappa0, q_o, max_steps=max_steps)
        return r.x, jnp.sqrt(2.0 * r.cost / r.residual.shape[0]), r.steps, r.converged

    return jax.vmap(one)(q_obs)
