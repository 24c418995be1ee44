"""Postural primitives (Williamson 1996, design §3.7): set-point vectors, their superposition and
winner-take-all, the equilibrium of a springy arm under gravity, posture force fields, and
minimum-jerk set-point moves that sum when they overlap (Figure 4).

Springy joints: ``τ = −K (θ − θ_set) − B θ̇`` (restoring form; the paper writes the signs
loosely). A primitive is a set-point ``P_i`` (n,); a blend is ``P = Σ α_i P_i`` with
``Σ α_i = 1`` (paper Section 2.2). At rest the arm settles where the springs balance gravity,
``K (θ − θ_set) + ∇V(θ) = 0`` — the minimum of ``U = ½ (θ − θ_set)ᵀ K (θ − θ_set) + V(θ)``.
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np

from .._base.pytree import pytree_dataclass
from .._base.validate import as_array, check_positive, is_concrete
from .._chains.mjcf import MjcfChain, gravity_gradient, gravity_terms, site_position
from .._pmp.redundancy import weighted_pinv
from .arm import CogArm

# ----------------------------------------------------------------------------------------------
# Primitives and their combination

# Four primitives like the paper's Figure 3/5: rest, forward-down, forward-up, out to the side.
# Joint order (sh_flex, sh_abd, sh_rot, el_flex, wr_flex, wr_dev) [rad].
PRIMITIVE_NAMES = ("rest", "down", "up", "side")
PRIMITIVES = (
    (0.0, 0.15, 0.0, 0.6, 0.0, 0.0),
    (0.7, 0.10, 0.0, 0.9, 0.0, 0.0),
    (1.4, 0.10, 0.0, 0.5, 0.0, 0.0),
    (0.6, 0.90, 0.3, 1.0, 0.0, 0.0),
)


def default_primitives():
    """The four primitives ``P`` (4, 6) [rad] named in ``PRIMITIVE_NAMES``."""
    return jnp.asarray(PRIMITIVES, dtype=float)


def check_set_point(name: str, q_set, n: int):
    """``q_set`` (..., n) finite set-point(s) [rad]; raises ``ValueError`` naming ``name``."""
    return jnp.asarray(as_array(name, q_set, tail=(n,)), float)


def check_stiffness(name: str, K, n: int):
    """Joint stiffness ``K`` (..., n) [Nm/rad], strictly positive (when concrete)."""
    K = as_array(name, K, tail=(n,))
    check_positive(name, K)
    return jnp.asarray(K, float)


def blend(alpha, P, *, atol: float = 1e-9):
    """Superposition ``Σ_i α_i P_i`` (..., n) of primitives ``P`` (k, n) with weights ``alpha``
    (..., k), ``Σ α_i = 1`` (checked to ``atol`` when concrete; ``ValueError`` naming ``alpha``).
    Negative weights are allowed (extrapolation) but leave the region the primitives span."""
    P = jnp.asarray(as_array("P", P, tail=(None, None)), float)
    k = P.shape[-2]
    alpha = as_array("alpha", alpha, tail=(k,))
    if is_concrete(alpha):
        s = np.sum(np.asarray(alpha, dtype=float), axis=-1)
        if np.any(np.abs(s - 1.0) > atol):
            raise ValueError(f"`alpha` (blend weights) must sum to 1, got sum(s) {np.ravel(s)[:4]}")
    return jnp.einsum("...k,...kn->...n", jnp.asarray(alpha, float), P)


def winner_take_all(scores, P):
    """Winner-take-all: the primitive ``P[argmax(scores)]`` (..., n) of ``P`` (k, n) for
    activation ``scores`` (..., k) — one primitive has control of the arm."""
    P = jnp.asarray(as_array("P", P, tail=(None, None)), float)
    scores = jnp.asarray(as_array("scores", scores, tail=(P.shape[-2],)), float)
    onehot = jax.nn.one_hot(jnp.argmax(scores, axis=-1), P.shape[-2], dtype=P.dtype)
    return jnp.einsum("...k,...kn->...n", onehot, P)


# ----------------------------------------------------------------------------------------------
# Equilibrium under gravity


@pytree_dataclass
class ArmEquilibrium:
    """Static posture of the springy arm: ``q`` (..., n) [rad], ``hand`` (..., 3) [m],
    ``residual`` (...,) |K (q − θ_set) + ∇V|_∞ [Nm], ``converged`` (...,) bool (residual small
    and the Hessian ``K + ∇²V`` positive definite: a stable equilibrium)."""

    q: jax.Array
    hand: jax.Array
    residual: jax.Array
    converged: jax.Array


@functools.partial(jax.custom_jvp, nondiff_argnums=(0,))
def _solve_equilibrium(n_iter, mx, q_set, K):
    def newton(_, q):
        g, H, _ = gravity_terms(mx, q)
        dq = -jnp.linalg.solve(jnp.diag(K) + H, K * (q - q_set) + g)
        # Cap the step (0.5 rad, ∞-norm) so a far start cannot jump across the workspace.
        return q + dq * jnp.minimum(1.0, 0.5 / jnp.maximum(jnp.max(jnp.abs(dq)), 1e-300))

    return jax.lax.fori_loop(0, n_iter, newton, q_set)


@_solve_equilibrium.defjvp
def _solve_equilibrium_jvp(n_iter, primals, tangents):
    # Implicit function theorem on K (θ − θ_set) + ∇V(θ) = 0:
    # (K + ∇²V) dθ = K dθ_set − dK ⊙ (θ − θ_set).  (The model's tangents are ignored.)
    mx, qs, K = primals
    _, dqs, dK = tangents
    q = _solve_equilibrium(n_iter, mx, qs, K)
    H = gravity_terms(mx, q)[1]
    return q, jnp.linalg.solve(jnp.diag(K) + H, K * dqs - dK * (q - qs))


def _equilibrium_one(mx, site_id, q_set, K, n_iter, tol, diagnostics=True):
    # The shared Newton solver (pmpjax._base.newton): residual K (θ − θ_set) + ∇V(θ), Newton
    # matrix K + ∇²V from one MJX kinematics pass, 0.5 rad cap, n_iter steps; implicit gradients
    # in (θ_set, K), the model's tangents ignored (consts).
    from .._base.newton import newton_solve

    def residual(q, params, mx):
        qs, Kp = params
        return Kp * (q - qs) + gravity_terms(mx, q)[0]

    def solve(q, params, mx, rhs):
        return jnp.linalg.solve(jnp.diag(params[1]) + gravity_terms(mx, q)[1], rhs)

    q, _ = newton_solve(residual, solve, q_set, (q_set, K), mx, max_steps=int(n_iter), step_cap=0.5)
    if not diagnostics:  # lean version for fits: no residual/stability kinematics passes
        return q, (None if site_id is None else site_position(mx, site_id, q)), None, None
    g, H, d = gravity_terms(mx, jax.lax.stop_gradient(q))
    Ks = jax.lax.stop_gradient(K)
    res = jnp.max(jnp.abs(Ks * (jax.lax.stop_gradient(q) - jax.lax.stop_gradient(q_set)) + g))
    stable = jnp.min(jnp.linalg.eigvalsh(jnp.diag(Ks) + H)) > 0
    # Hand position with its analytic Jacobian, so derivatives never trace MJX kinematics.
    hand = site_position(mx, site_id, q)
    return q, hand, res, (res <= tol * (1.0 + jnp.max(Ks))) & stable


def equilibrium(arm: CogArm, q_set, K=None, *, n_iter: int = 12, tol: float = 1e-10) -> ArmEquilibrium:
    """Equilibrium posture of the springy arm under gravity for set-points ``q_set`` (..., n).

    Solves ``K (θ − θ_set) + ∇V(θ) = 0`` (springs balance gravity, no velocity) by Newton's method
    from ``θ_set`` (``n_iter`` steps) with ``∇V`` and the exact ``∇²V`` in closed form from one MJX
    kinematics pass (autodiff through MJX kinematics would cost minutes of compile time);
    derivatives by the implicit function theorem (``jax.custom_jvp``, forward and reverse mode).
    ``K`` (..., n) [Nm/rad], default the arm's. Leading axes broadcast. ``converged`` flags each item.
    """
    n = arm.n
    q_set = check_set_point("q_set", q_set, n)
    K = check_stiffness("K", arm.K if K is None else K, n)
    batch = tuple(np.broadcast_shapes(q_set.shape[:-1], K.shape[:-1]))
    B = math.prod(batch)
    qs = jnp.broadcast_to(q_set, batch + (n,)).reshape(B, n)
    Ks = jnp.broadcast_to(K, batch + (n,)).reshape(B, n)
    q, hand, res, ok = _equilibrium_batch(
        arm.mjx_model, arm.layout.hand_site, qs, Ks, int(n_iter), float(tol)
    )
    return ArmEquilibrium(
        q=q.reshape(batch + (n,)),
        hand=hand.reshape(batch + (3,)),
        residual=res.reshape(batch),
        converged=ok.reshape(batch),
    )


@functools.partial(jax.jit, static_argnames=("site_id", "n_iter", "tol"))
def _equilibrium_batch(mx, site_id, q_set, K, n_iter, tol):
    return jax.vmap(lambda a, b: _equilibrium_one(mx, site_id, a, b, n_iter, tol))(q_set, K)


# ----------------------------------------------------------------------------------------------
# Force field of a posture


def force_field(chain: MjcfChain, q, q_set, K, *, gravity: bool = False):
    """Hand force field ``F`` (..., 3) [N] of set-point ``q_set`` (..., n) at postures ``q`` (..., n).

    The spring torque ``τ = −K (q − θ_set)`` (minus ``∇V`` when ``gravity``) is expressed as a
    hand force by solving ``Jᵀ F = τ`` in least squares (the paper's ``J F = K (θ − θ_set)``,
    restoring sign), ``F = (J#)ᵀ τ`` with the Moore–Penrose ``J# = Jᵀ (J Jᵀ)⁻¹``.
    """
    n = chain.n
    q = check_set_point("q", q, n)
    q_set = check_set_point("q_set", q_set, n)
    K = check_stiffness("K", K, n)
    batch = tuple(np.broadcast_shapes(q.shape, q_set.shape, K.shape))
    q = jnp.broadcast_to(q, batch)
    tau = -jnp.broadcast_to(K, batch) * (q - jnp.broadcast_to(q_set, batch))
    if gravity:
        grad_V = jax.vmap(lambda qq: gravity_gradient(chain.mjx_model, qq))
        tau = tau - grad_V(q.reshape(-1, n)).reshape(batch)
    J = chain.jacobian(q)
    Jp = weighted_pinv(J, w=jnp.ones(J.shape[:-2] + (n,)))  # (..., n, 3), unweighted
    return jnp.einsum("...nm,...n->...m", Jp, tau)


# ----------------------------------------------------------------------------------------------
# Minimum-jerk set-point moves (paper Section 2.3, Figure 4)


def _xi(s):
    """Integral of the normalised minimum-jerk speed ``30 s⁴ − 60 s³ + 30 s²`` from 0 to ``s``."""
    s = jnp.clip(s, 0.0, 1.0)
    return s**3 * (10.0 + s * (-15.0 + 6.0 * s))


def _xi_dot(s):
    inside = (s > 0.0) & (s < 1.0)
    s = jnp.clip(s, 0.0, 1.0)
    return jnp.where(inside, 30.0 * s**2 * (1.0 - s) ** 2, 0.0)


@pytree_dataclass
class Moves:
    """Set-point moves: start times ``t0`` (M,) [s], durations ``duration`` (M,) [s] and
    displacements ``delta`` (M, n) [rad] (``θ_end − θ_start`` of each move)."""

    t0: jax.Array
    duration: jax.Array
    delta: jax.Array


def moves_from_targets(start, targets, t0, duration) -> Moves:
    """Moves from ``start`` (n,) through ``targets`` (M, n) issued at times ``t0`` (M,) with
    durations ``duration`` (M,) [s]: each new move goes from the previous *target* to the new
    one (not from where the arm is), as on Cog."""
    start = jnp.asarray(as_array("start", start, tail=(None,)), float)
    n = start.shape[-1]
    targets = jnp.asarray(as_array("targets", targets, tail=(None, n)), float)
    M = targets.shape[-2]
    t0 = jnp.broadcast_to(jnp.asarray(as_array("t0", t0), float), (M,))
    duration = jnp.broadcast_to(jnp.asarray(as_array("duration", duration), float), (M,))
    check_positive("duration", duration)
    prev = jnp.concatenate([start[None], targets[:-1]], axis=0)
    return Moves(t0=t0, duration=duration, delta=targets - prev)


def move_velocity(moves: Moves, t):
    """Summed set-point velocity (T, n) [rad/s] at times ``t`` (T,) of all ``moves``:
    ``Σ_j Δ_j / d_j · (30 s⁴ − 60 s³ + 30 s²)``, ``s = (t − t0_j) / d_j``."""
    t = jnp.asarray(t, float)
    s = (t[:, None] - moves.t0[None, :]) / moves.duration[None, :]  # (T, M)
    return (_xi_dot(s) / moves.duration[None, :]) @ moves.delta


def summed_moves(moves: Moves, start, t):
    """Set-points ``θ_set`` (T, n) [rad] and velocities (T, n) of summed moves from ``start`` (n,)
    at times ``t`` (T,): the velocities are added and integrated exactly, so each move adds
    ``Δ_j ξ(s_j)`` with ``ξ(s) = ∫₀ˢ 30 u²(1 − u)² du``; overlapping moves sum smoothly."""
    check_positive("moves.duration", moves.duration)
    start = jnp.asarray(start, float)
    t = jnp.asarray(as_array("t", t, tail=(None,)), float)
    s = (t[:, None] - moves.t0[None, :]) / moves.duration[None, :]
    return start[None, :] + _xi(s) @ moves.delta, move_velocity(moves, t)
