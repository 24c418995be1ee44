"""Task planners: the extrinsic force ``F = K(t) (x_d − x)`` that pulls the hand to the target.

Each planner is a pytree with ``gain(t)`` (scalar stiffness [N/m], time reset to 0 at each new
target) and ``force_soa``. ``start(M0)`` resolves parameters that depend on the start
posture (Eq 10) and is called once per movement.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from .._base import (
    as_array,
    check_positive,
    check_seconds,
    minimum_jerk_hazard,
    pytree_dataclass,
    replace,
    spd_solve,
    static_field,
)


def _scale(gain, e):
    """``gain`` (*batch) or scalar times component-leading ``e`` (m, *batch)."""
    gain = jnp.asarray(gain)
    return (gain[None] if gain.ndim else gain) * e


class Planner:
    """Base: isotropic gain; ``F = gain(t) (x_d − x)``."""

    def gain(self, t):
        """The isotropic gain ``k(t)`` of the task-space spring ``F = k(t) (x_d − x)``.

        **Arguments:**

        - ``t``: time since the movement's start [s] (array, broadcasts with the planner's leaves).

        **Returns:**

        The gain [N/m] (the minimum-jerk planner's [1/s]).
        """
        raise NotImplementedError

    def start(self, M0):
        """Resolve start-dependent parameters (Eq 10's gain) at a movement's start posture.

        **Arguments:**

        - ``M0``: (m, m, ...) ``B(q0)⁻¹ = J W⁻¹ Jᵀ`` at the start posture, component-leading.

        **Returns:**

        The planner with those parameters set (itself when it has none).
        """
        return self

    def force_soa(self, t, x, target, M):
        """The task force ``F`` of component-leading positions (the kernel integrators use).

        **Arguments:**

        - ``t``: time since the movement's start [s].
        - ``x``: (m, ...) hand positions.
        - ``target``: (m, ...) targets.
        - ``M``: (m, m, ...) ``B(q)⁻¹`` at ``x`` (used by the minimum-jerk planner's task-velocity form).

        **Returns:**

        (m, ...) the force ``F``.
        """
        return _scale(self.gain(t), target - x)

    def max_gain(self):
        """Upper bound of ``gain(t)``, for ``simulate``'s RK4 stability check.

        **Returns:**

        The bound, or None where it is set at the start posture (Eq 10).
        """
        raise NotImplementedError

    def batch_shape(self):
        """The broadcast shape of the planner's array leaves (its batch).

        **Returns:**

        A shape tuple (``()`` for scalar parameters).
        """
        return tuple(np.broadcast_shapes(*[jnp.shape(v) for v in self._leaves()]))

    def _leaves(self):
        return []

    def _positive_leaves(self):
        """Leaves that must be positive (checked per item inside a caller's ``jit``)."""
        return self._leaves()

    def to_soa(self, batch):
        """The planner with its leaves broadcast to ``batch`` and flattened like the state (``simulate``).

        **Arguments:**

        - ``batch``: the batch shape.

        **Returns:**

        A planner of the same type with (prod(batch),) leaves.
        """
        return jax.tree_util.tree_map(lambda v: jnp.broadcast_to(v, batch).reshape(-1), self)


@pytree_dataclass
class ConstantPlanner(Planner):
    """Constant isotropic stiffness ``K = k I`` [N/m]: exponential (first-order) approach.
    ``k`` is an array leaf (scalar or a batch)."""

    k: jax.Array

    def __post_init__(self):
        check_positive("k", self.k)

    def gain(self, t):
        return self.k

    def max_gain(self):
        return np.max(np.asarray(self.k))

    def _leaves(self):
        return [self.k]


def eq10_gain(M0, tau0):
    """The Arimoto gain of Eq 10, ``k = b_max / τ0`` with ``b_max = 1/λ_min(M0)``.

    **Arguments:**

    - ``M0``: (m, m, ...) ``B(q0)⁻¹ = J W⁻¹ Jᵀ`` at the start posture, component-leading (the batch
      trails).
    - ``tau0``: (...) intrinsic time constant [s], positive.

    **Returns:**

    (...) the gain ``k`` [N/m].

    **Raises:**

    - ``ValueError`` naming the argument for an ``M0`` that is not component-leading square, or a
      non-positive ``tau0``.
    """
    M0 = as_array("M0", M0)
    if M0.ndim < 2 or M0.shape[0] != M0.shape[1]:
        raise ValueError(f"`M0` must be a component-leading square matrix (m, m, ...), got shape {M0.shape}")
    tau0 = as_array("tau0", tau0)
    check_positive("tau0", tau0)
    Mt = jnp.moveaxis(jnp.asarray(M0), (0, 1), (-2, -1))
    lam_min = jnp.linalg.eigvalsh(Mt)[..., 0]
    return 1.0 / (lam_min * tau0)


@pytree_dataclass
class ArimotoPlanner(Planner):
    """Arimoto stiffness ``K(t) = k (1 − e^{−t/τ} − (t/τ) e^{−t/τ}) I`` (Eq 8).

    ``k`` [N/m] and extrinsic time constant ``tau`` [s]. With ``k=None`` and ``tau0`` given, ``k``
    is set at the start of every movement by Eq 10: ``k = b_max(B(q0)) / τ0``. Time constants (and
    ``|delay|``) above 10 s are refused as milliseconds (``tau=80`` for 80 ms), above 2 s they run
    with a warning. ``delay`` [s] (default 0): the target appeared ``delay`` before ``t = 0``, so
    ``K(t)`` is Eq 8 at ``t + delay`` (a model started at rest detected after the target's onset); a
    negative ``delay`` starts the gain at ``t = −delay`` (zero before).
    """

    k: jax.Array | None
    tau: jax.Array
    tau0: jax.Array | None = None
    delay: jax.Array = 0.0

    def __post_init__(self):
        check_positive("tau", self.tau)
        check_seconds("tau", self.tau)
        if self.k is None:
            if self.tau0 is None:
                raise ValueError("ArimotoPlanner needs `k`, or `tau0` to set k by Eq 10")
            check_positive("tau0", self.tau0)
            check_seconds("tau0", self.tau0)
        else:
            check_positive("k", self.k)
        as_array("delay", self.delay)
        check_seconds("delay", self.delay)

    def start(self, M0):
        if self.k is None:
            return replace(self, k=eq10_gain(M0, self.tau0))
        return self

    def gain(self, t):
        s = jnp.maximum(t + self.delay, 0.0) / self.tau
        return self.k * (1.0 - (1.0 + s) * jnp.exp(-s))

    def max_gain(self):
        return None if self.k is None else np.max(np.asarray(self.k))

    def _leaves(self):
        return [v for v in (self.k, self.tau, self.tau0, self.delay) if v is not None]

    def _positive_leaves(self):
        return [v for v in (self.k, self.tau, self.tau0) if v is not None]


@pytree_dataclass
class MinimumJerkPlanner(Planner):
    """Time-base generator (Morasso et al. 2010) in task-velocity form.

    ``F = γ(t) B(q) (x_d − x)`` so that, along the λ0-PMP (``B ẋ = F``), ``ẋ = γ(t)(x_d − x)`` and
    the hand follows the straight line with the minimum-jerk profile ``ξ(s) = 10 s³ − 15 s⁴ + 6 s⁵``,
    ``s = t/T``, ``T`` = ``duration`` [s], reaching the target at ``t = T``. The gain [1/s] is

        ``γ(t) = min(ξ̇ / (1 − ξ), gain_cap) = min(30 s² / (T (1 − s)(6 s² + 3 s + 1)), gain_cap)``

    for ``t < T`` (``1 − ξ = (1 − s)³ (6 s² + 3 s + 1)``, ``ξ̇ = 30 s² (1 − s)² / T``), and ``gain_cap``
    [1/s] for ``t ≥ T``. The uncapped ratio grows without bound as ``t → T``; the cap (reached where
    ``1 − s ≈ 3 / (T gain_cap)`` for large caps) turns the end of the movement into an exponential
    approach at rate ``gain_cap`` and bounds the stiffness (RK4 needs ``dt < 2.5 / gain_cap``).
    ``γ`` is exact up to the cap and differentiable in ``t``, ``duration`` and ``gain_cap`` at every
    ``t`` (see ``pmpjax._base.profiles.minimum_jerk_hazard``). A ``duration`` above 60 s is
    refused as milliseconds, above 10 s it runs with a warning.

    **Fields:** ``duration`` ``T`` [s]; ``gain_cap`` [1/s]; ``delay`` [s] (default 0; as
    :class:`ArimotoPlanner`'s): the move began ``delay`` before ``t = 0``, so ``γ(t)`` is the above at
    ``t + delay``; a negative ``delay`` holds the hand (``γ = 0``) until ``t = −delay``, e.g. a model
    started at rest before a detected onset. ``task_velocity`` (static, set by the class) marks the
    task-velocity form ``F = γ B (x_d − x)`` for ``simulate``'s stability check.
    """

    duration: jax.Array
    gain_cap: jax.Array = 200.0
    delay: jax.Array = 0.0
    task_velocity: bool = static_field(default=True)

    def __post_init__(self):
        check_positive("duration", self.duration)
        check_seconds("duration", self.duration, kind="duration")
        check_positive("gain_cap", self.gain_cap)
        as_array("delay", self.delay)
        check_seconds("delay", self.delay)

    def gain(self, t):
        return minimum_jerk_hazard((t + self.delay) / self.duration, self.gain_cap, self.duration)

    def force_soa(self, t, x, target, M):
        return spd_solve(M, _scale(self.gain(t), target - x))

    def max_gain(self):
        return np.max(np.asarray(self.gain_cap))

    def _leaves(self):
        return [self.duration, self.gain_cap, self.delay]

    def _positive_leaves(self):
        return [self.duration, self.gain_cap]
