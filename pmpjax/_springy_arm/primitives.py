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
import warnings

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
    fast_compile_jit,
    flatten_batch,
    is_concrete,
    minimum_jerk,
    pad_rows,
    pytree_dataclass,
    renamed_keywords,
    to_jax,
    unflatten_batch,
)
from .._chains import MjcfChain, gravity_gradients, gravity_terms, site_position
from .._pmp import weighted_pinv
from .arm import CogArm, check_arm

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
    """The four postural primitives of the shipped arm, named in ``PRIMITIVE_NAMES``.

    **Returns:**

    (4, 6) set-points ``P`` [rad]: rest, down, up, side.
    """
    return to_jax(np.asarray(PRIMITIVES, dtype=float))


def check_set_point(name: str, q_set, n: int):
    """``q_set`` (..., n) finite set-point(s) [rad]; raises ``ValueError`` naming ``name``."""
    return to_jax(as_array(name, q_set, tail=(n,)), float)


def check_stiffness(name: str, K, n: int):
    """Joint stiffness ``K`` (..., n) [Nm/rad], strictly positive (when concrete)."""
    K = as_array(name, K, tail=(n,))
    check_positive(name, K)
    return jnp.asarray(K, float)


def blend(alpha, P, *, atol: float = 1e-9):
    """Superposition ``Σ_i α_i P_i`` of primitives (Williamson 1996).

    Negative weights are allowed (extrapolation) but leave the region the primitives span.

    **Arguments:**

    - ``alpha``: (..., k) weights with ``Σ α_i = 1``.
    - ``P``: (k, n) primitives (set-points [rad]), e.g. :func:`default_primitives`.
    - ``atol``: tolerance of the check ``|Σ α_i − 1| <= atol`` (made when ``alpha`` is concrete).

    **Returns:**

    (..., n) the blended set-point [rad].

    **Raises:**

    - ``ValueError`` naming ``alpha`` when its weights do not sum to 1, or naming the argument for
      wrong shapes or NaN/inf.
    """
    P = _check_primitives(P)
    k = P.shape[-2]
    alpha = as_array("alpha", alpha, tail=(k,))
    if is_concrete(alpha):
        s = np.sum(np.asarray(alpha, dtype=float), axis=-1)
        if np.any(np.abs(s - 1.0) > atol):
            raise ValueError(f"`alpha` (blend weights) must sum to 1, got sum(s) {np.ravel(s)[:4]}")
    return jnp.einsum("...k,...kn->...n", jnp.asarray(alpha, float), P)


def winner_take_all(scores, P):
    """Winner-take-all: the primitive ``P[argmax(scores)]``; one primitive has control of the arm.

    **Arguments:**

    - ``scores``: (..., k) activations.
    - ``P``: (k, n) primitives (set-points [rad]).

    **Returns:**

    (..., n) the winning set-point [rad].

    **Raises:**

    - ``ValueError`` naming the argument for wrong shapes or NaN/inf.
    """
    P = _check_primitives(P)
    scores = to_jax(as_array("scores", scores, tail=(P.shape[-2],)), float)
    return _winner(scores, P)


@fast_compile_jit
def _winner(scores, P):
    onehot = jax.nn.one_hot(jnp.argmax(scores, axis=-1), P.shape[-2], dtype=P.dtype)
    return jnp.einsum("...k,...kn->...n", onehot, P)


def _check_primitives(P):
    P = as_array("P", P, tail=(None, None))
    if P.ndim != 2 or P.shape[0] < 1:
        raise ValueError(f"`P` must be (k, n) primitives (k >= 1 set-point vectors), got shape {P.shape}")
    return jnp.asarray(P, float)


# ----------------------------------------------------------------------------------------------
# Equilibrium under gravity


@pytree_dataclass
class ArmEquilibrium:
    """Static posture of the springy arm (the result of :func:`arm_equilibrium`).

    **Fields:**

    - ``q``: (..., n) posture [rad].
    - ``hand``: (..., 3) hand position [m].
    - ``residual``: (...,) ``|K (q − θ_set) + ∇V|_∞`` [Nm].
    - ``status``: (...,) int :class:`pmpjax.Status`: ``SUCCESSFUL`` = residual small and the Hessian
      ``K + ∇²V`` positive definite, a stable equilibrium; ``NOT_MINIMUM``, ``MAX_STEPS`` (residual
      not small), ``NONFINITE``.

    ``converged`` = ``status == 0``.
    """

    q: jax.Array
    hand: jax.Array
    residual: jax.Array
    status: jax.Array

    @property
    def converged(self):
        return self.status == Status.SUCCESSFUL


def _equilibrium_one(mx, site_id, q_set, K, max_steps, tol, diagnostics=True):
    # The shared Newton solver (pmpjax._base.newton): residual K (θ − θ_set) + ∇V(θ), Newton
    # matrix K + ∇²V from one MJX kinematics pass, 0.5 rad cap, max_steps steps; implicit gradients
    # in (θ_set, K), the model's tangents ignored (consts).
    from .._base import newton_solve

    def residual(q, params, mx):
        qs, Kp = params
        return Kp * (q - qs) + gravity_terms(mx, q)[0]

    def solve(q, params, mx, rhs):
        return jnp.linalg.solve(jnp.diag(params[1]) + gravity_terms(mx, q)[1], rhs)

    q, _ = newton_solve(residual, solve, q_set, (q_set, K), mx, max_steps=int(max_steps), step_cap=0.5)
    if not diagnostics:  # lean version for fits: no residual/stability kinematics passes
        return q, (None if site_id is None else site_position(mx, site_id, q)), None, None
    g, H, d = gravity_terms(mx, jax.lax.stop_gradient(q))
    Ks = jax.lax.stop_gradient(K)
    res = jnp.max(jnp.abs(Ks * (jax.lax.stop_gradient(q) - jax.lax.stop_gradient(q_set)) + g))
    stable = jnp.min(jnp.linalg.eigvalsh(jnp.diag(Ks) + H)) > 0
    # Hand position with its analytic Jacobian, so derivatives never trace MJX kinematics.
    hand = site_position(mx, site_id, q)
    return q, hand, res, (res <= tol * (1.0 + jnp.max(Ks))) & stable


def arm_equilibrium_one(mx, site_id: int | None, q_set, K, *, max_steps: int = 12):
    """Internal surface (used by ``fitting``): equilibrium ``q`` (n,) of one arm for set-point
    ``q_set`` (n,) and stiffness ``K`` (n,), and the hand site position (3,) (``None`` when
    ``site_id`` is ``None``); no diagnostics. Differentiable in ``q_set`` and ``K`` by the
    implicit function theorem (forward and reverse mode). ``mx`` is ``CogArm.mjx_model``."""
    q, hand, _, _ = _equilibrium_one(mx, site_id, q_set, K, int(max_steps), 0.0, diagnostics=False)
    return q, hand


@renamed_keywords(n_iter="max_steps")
def arm_equilibrium(arm: CogArm, q_set, K=None, *, max_steps: int = 12, tol: float = 1e-10) -> ArmEquilibrium:
    """Equilibrium posture of the springy arm under gravity for set-points ``q_set``.

    Solves ``K (θ − θ_set) + ∇V(θ) = 0`` (springs balance gravity, no velocity) by Newton's method
    from ``θ_set`` with ``∇V`` and the exact ``∇²V`` in closed form from one MJX kinematics pass
    (autodiff through MJX kinematics would cost minutes of compile time); derivatives by the
    implicit function theorem (``jax.custom_jvp``, forward and reverse mode). Leading axes
    broadcast. Not :func:`pmpjax.equilibrium_posture`, the λ0-PMP equilibrium of a chain.

    **Arguments:**

    - ``arm``: a :class:`CogArm` (:func:`load_arm`).
    - ``q_set``: (..., n) set-points [rad].
    - ``K``: (..., n) joint stiffness [Nm/rad], positive; default the arm's.
    - ``max_steps``: Newton steps at most.
    - ``tol``: converged when ``residual <= tol·(1 + max K)`` and the equilibrium is stable.

    **Returns:**

    An :class:`ArmEquilibrium` with a ``status`` per item.

    **Raises:**

    - ``TypeError`` for a non-arm; ``ValueError`` naming the argument for wrong shapes, NaN/inf,
      non-positive ``K``, ``max_steps`` or ``tol``.

    **Compile time:** ≈ 5 s on first use per bucketed batch size (MJX kinematics inside Newton's
    loop; benchmarks/compile_times.py).
    """
    check_arm(arm)
    n = arm.n
    q_set = check_set_point("q_set", q_set, n)
    K = check_stiffness("K", arm.K if K is None else K, n)
    max_steps = check_positive_int("max_steps", max_steps)
    check_positive("tol", tol)
    batch = broadcast_batch(q_set=(q_set, 1), K=(K, 1))
    B = math.prod(batch)
    qs, Ks = flatten_batch(q_set, batch, 1), flatten_batch(K, batch, 1)
    Bp = bucket(B, minimum=8)
    q, hand, res, status = (
        unflatten_batch(a, batch, B)
        for a in _equilibrium_batch(
            arm.mjx_model, arm.layout.hand_site, pad_rows(qs, Bp), pad_rows(Ks, Bp), max_steps, float(tol)
        )
    )
    return ArmEquilibrium(q=q, hand=hand, residual=res, status=status)


@renamed_keywords(n_iter="max_steps")
def equilibrium(arm: CogArm, q_set, K=None, *, max_steps: int = 12, tol: float = 1e-10) -> ArmEquilibrium:
    """Deprecated alias of :func:`arm_equilibrium` (the name was easy to confuse with
    :func:`pmpjax.equilibrium_posture`, the λ0-PMP equilibrium).

    **Arguments:**

    - ``arm``, ``q_set``, ``K``, ``max_steps``, ``tol``: as :func:`arm_equilibrium`.

    **Returns:**

    An :class:`ArmEquilibrium`.
    """
    warnings.warn(
        "pmpjax.equilibrium is deprecated; use pmpjax.arm_equilibrium (the springy arm under gravity)",
        DeprecationWarning,
        stacklevel=2,
    )
    return arm_equilibrium(arm, q_set, K, max_steps=max_steps, tol=tol)


@functools.partial(fast_compile_jit, static_argnames=("site_id", "max_steps", "tol"))
def _equilibrium_batch(mx, site_id, q_set, K, max_steps, tol):
    q, hand, res, ok = jax.vmap(lambda a, b: _equilibrium_one(mx, site_id, a, b, max_steps, tol))(q_set, K)
    small = res <= tol * (1.0 + jnp.max(jax.lax.stop_gradient(K), axis=-1))
    finite = jnp.isfinite(res) & jnp.all(jnp.isfinite(q), axis=-1)
    status = jnp.where(
        ~finite,
        Status.NONFINITE,
        jnp.where(ok, Status.SUCCESSFUL, jnp.where(small, Status.NOT_MINIMUM, Status.MAX_STEPS)),
    )
    return q, hand, res, status.astype(jnp.int32)


# ----------------------------------------------------------------------------------------------
# Force field of a posture


def force_field(chain: MjcfChain, q, q_set, K, *, gravity: bool = False):
    """Hand force field of a set-point at given postures (Williamson 1996, Figure 2).

    The spring torque ``τ = −K (q − θ_set)`` (minus ``∇V`` when ``gravity``) is expressed as a
    hand force by solving ``Jᵀ F = τ`` in least squares (the paper's ``J F = K (θ − θ_set)``,
    restoring sign), ``F = (J#)ᵀ τ`` with the Moore–Penrose ``J# = Jᵀ (J Jᵀ)⁻¹``.

    **Arguments:**

    - ``chain``: the arm's hand site as a :class:`MjcfChain` (``pj.MjcfChain(arm, "hand")``).
    - ``q``: (..., n) postures [rad].
    - ``q_set``: (..., n) set-point [rad].
    - ``K``: (..., n) joint stiffness [Nm/rad], positive.
    - ``gravity``: include the gravity torque ``−∇V``.

    **Returns:**

    (..., 3) hand forces ``F`` [N] (leading axes of the arguments broadcast).

    **Raises:**

    - ``TypeError`` for a non-``MjcfChain`` or a non-bool ``gravity``; ``ValueError`` naming the
      argument for wrong shapes, NaN/inf, non-positive ``K`` or leading axes that do not broadcast.
    """
    if not isinstance(chain, MjcfChain):
        raise TypeError(f"`chain` must be a pmpjax.MjcfChain, got {type(chain).__name__}")
    if not isinstance(gravity, bool):
        raise TypeError(f"`gravity` must be a bool, got {type(gravity).__name__}")
    n = chain.n
    q = check_set_point("q", q, n)
    q_set = check_set_point("q_set", q_set, n)
    K = check_stiffness("K", K, n)
    try:
        batch = tuple(np.broadcast_shapes(q.shape, q_set.shape, K.shape))
    except ValueError as e:
        raise ValueError(f"leading axes of `q` {q.shape}, `q_set` {q_set.shape}, `K` {K.shape} do not broadcast") from e
    xp = np if is_concrete(q, q_set, K) else jnp  # (the spring torque on the host: no eager XLA ops)
    q = xp.broadcast_to(xp.asarray(q), batch)
    tau = -xp.broadcast_to(xp.asarray(K), batch) * (q - xp.broadcast_to(xp.asarray(q_set), batch))
    if gravity:
        tau = tau - xp.asarray(gravity_gradients(chain.mjx_model, q.reshape(-1, n))).reshape(batch)
    J = chain.jacobian(q)
    Jp = weighted_pinv(J, w=xp.ones(J.shape[:-2] + (n,)))  # (..., n, 3), unweighted
    return jnp.einsum("...nm,...n->...m", Jp, tau)


# ----------------------------------------------------------------------------------------------
# Minimum-jerk set-point moves (paper Section 2.3, Figure 4)


@pytree_dataclass
class Moves:
    """Set-point moves (Williamson 1996, Figure 4).

    **Fields:**

    - ``t0``: (M,) start times [s].
    - ``duration``: (M,) durations [s], positive.
    - ``delta``: (M, n) displacements ``θ_end − θ_start`` of each move [rad].

    Construction raises ``ValueError`` naming the field for wrong shapes or non-positive durations.
    """

    t0: jax.Array
    duration: jax.Array
    delta: jax.Array

    def __post_init__(self):
        delta = as_array("delta", self.delta, tail=(None, None))
        if delta.ndim != 2:
            raise ValueError(f"`delta` must be (M, n) displacements, got shape {delta.shape}")
        M = delta.shape[0]
        t0 = as_array("t0", self.t0, tail=(M,))
        duration = as_array("duration", self.duration, tail=(M,))
        if t0.ndim != 1 or duration.ndim != 1:
            raise ValueError(f"`t0` and `duration` must be ({M},), got {t0.shape} and {duration.shape}")
        check_positive("duration", duration)
        for name, v in (("t0", t0), ("duration", duration), ("delta", delta)):
            object.__setattr__(self, name, jnp.asarray(v, float))


def moves_from_targets(start, targets, t0, duration) -> Moves:
    """Moves from ``start`` through a sequence of targets.

    Each new move goes from the previous *target* to the new one (not from where the arm is), as on
    Cog.

    **Arguments:**

    - ``start``: (n,) the first set-point [rad].
    - ``targets``: (M, n) set-point targets [rad].
    - ``t0``: scalar or (M,) times at which the moves are issued [s].
    - ``duration``: scalar or (M,) durations [s], positive.

    **Returns:**

    The :class:`Moves`.

    **Raises:**

    - ``ValueError`` naming the argument for wrong shapes, NaN/inf or non-positive durations.
    """
    start = to_jax(as_array("start", start, tail=(None,)), float)
    if start.ndim != 1:
        raise ValueError(f"`start` must be one set-point (n,), got shape {start.shape}")
    n = start.shape[-1]
    targets = to_jax(as_array("targets", targets, tail=(None, n)), float)
    if targets.ndim != 2:
        raise ValueError(f"`targets` must be (M, {n}), got shape {targets.shape}")
    M = targets.shape[-2]
    t0, duration = as_array("t0", t0), as_array("duration", duration)
    for name, v in (("t0", t0), ("duration", duration)):
        if np.shape(v) not in ((), (M,)):
            raise ValueError(f"`{name}` must be a scalar or ({M},) (one per target), got shape {np.shape(v)}")
    check_positive("duration", duration)
    if is_concrete(start, targets, t0, duration):  # (on the host: no eager XLA ops)
        start, targets = np.asarray(start), np.asarray(targets)
        prev = np.concatenate([start[None], targets[:-1]], axis=0)
        return Moves(t0=to_jax(np.broadcast_to(np.asarray(t0, float), (M,))),
                     duration=to_jax(np.broadcast_to(np.asarray(duration, float), (M,))),
                     delta=to_jax(targets - prev))
    prev = jnp.concatenate([start[None], targets[:-1]], axis=0)
    return Moves(
        t0=jnp.broadcast_to(jnp.asarray(t0, float), (M,)),
        duration=jnp.broadcast_to(jnp.asarray(duration, float), (M,)),
        delta=targets - prev,
    )


def _check_moves(moves):
    if not isinstance(moves, Moves):
        raise TypeError(f"`moves` must be pmpjax.Moves (e.g. from moves_from_targets), got {type(moves).__name__}")
    check_positive("moves.duration", moves.duration)


def _check_times(t):
    t = as_array("t", t)
    if t.ndim != 1:
        raise ValueError(f"`t` must be a 1-D array of times (T,) [s], got shape {t.shape}")
    return to_jax(t, float)


def move_velocity(moves: Moves, t):
    """Summed set-point velocity of all moves at times ``t``.

    ``Σ_j Δ_j / d_j · (30 s⁴ − 60 s³ + 30 s²)`` with ``s = (t − t0_j) / d_j`` (minimum jerk).

    **Arguments:**

    - ``moves``: the :class:`Moves`.
    - ``t``: (T,) times [s].

    **Returns:**

    (T, n) set-point velocities [rad/s].

    **Raises:**

    - ``TypeError`` for a non-``Moves``; ``ValueError`` for non-positive durations or ``t`` not 1-D.
    """
    _check_moves(moves)
    return _move_velocity(moves, _check_times(t))


@fast_compile_jit
def _move_velocity(moves, t):
    s = (t[:, None] - moves.t0[None, :]) / moves.duration[None, :]  # (T, M)
    return (minimum_jerk(s)[1] / moves.duration[None, :]) @ moves.delta


def summed_moves(moves: Moves, start, t):
    """Set-points and velocities of summed minimum-jerk moves (Williamson 1996, Figure 4).

    The velocities are added and integrated exactly, so each move adds ``Δ_j ξ(s_j)`` with
    ``ξ(s) = ∫₀ˢ 30 u²(1 − u)² du``; overlapping moves sum smoothly. Differentiable in ``start``,
    ``moves.t0``, ``moves.duration``, ``moves.delta`` and ``t``.

    **Arguments:**

    - ``moves``: the :class:`Moves`.
    - ``start``: (n,) the set-point before the first move [rad].
    - ``t``: (T,) times [s].

    **Returns:**

    ``(θ_set, θ̇_set)``: (T, n) set-points [rad] and (T, n) their velocities [rad/s].

    **Raises:**

    - ``TypeError`` for a non-``Moves``; ``ValueError`` naming the argument for wrong shapes,
      non-positive durations or ``t`` not 1-D.
    """
    _check_moves(moves)
    n = moves.delta.shape[-1]
    start = as_array("start", start, tail=(n,))
    if start.ndim != 1:
        raise ValueError(f"`start` must be one set-point ({n},), got shape {start.shape}")
    return _summed_moves(moves, to_jax(start, float), _check_times(t))


@fast_compile_jit
def _summed_moves(moves, start, t):
    s = (t[:, None] - moves.t0[None, :]) / moves.duration[None, :]
    return start[None, :] + minimum_jerk(s)[0] @ moves.delta, _move_velocity(moves, t)
