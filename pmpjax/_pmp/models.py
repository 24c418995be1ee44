"""PMP1, PMP2 and λ0-PMP (Figure 1B, Eqs 3–5) as pytrees holding ``KJ``, ``q_rest``, ``W``.

Velocity fields, with ``A = W⁻¹``, ``τ_el = KJ (q − q_rest)`` and task force ``F``:

- PMP1:    ``q̇ = A Jᵀ F``
- PMP2:    ``q̇ = A (Jᵀ F − τ_el)``
- λ0-PMP:  ``q̇ = A (Jᵀ (F + λ0) − τ_el)``, ``λ0 = B J A τ_el`` (Eq 4), hence ``B ẋ = F`` (Eq 5).

(The λ0-PMP field equals ``J#_W B⁻¹ F − (I − J#_W J) A τ_el``: note ``B⁻¹ F``, not ``F``.)
"""

from __future__ import annotations

from typing import ClassVar

import jax
import jax.numpy as jnp
import numpy as np

from .._base import (
    as_array,
    broadcast_batch,
    check_positive,
    check_seconds,
    check_spd,
    is_concrete,
    mv,
    pytree_dataclass,
    spd_inv,
    to_jax,
    to_soa,
)
from .._chains import Chain
from .redundancy import admittance_terms_soa, lambda0_soa


class _PMP:
    """Shared field of the three models; ``elastic`` (τ_el present) and ``blocked`` (λ0 added)
    are class constants, not fields. PMP1 has no ``KJ``/``q_rest`` (class attributes ``None``)."""

    chain: Chain
    W: jax.Array
    elastic: ClassVar[bool] = False
    blocked: ClassVar[bool] = False

    def _validate(self):
        if not isinstance(self.chain, Chain):
            raise TypeError(f"`chain` must be a pmpjax Chain, got {type(self.chain).__name__}")
        n = self.chain.n
        object.__setattr__(self, "W", to_jax(as_array("W", self.W, tail=(n, n)), float))
        check_spd("W", self.W)
        if self.elastic:
            KJ = as_array("KJ", self.KJ, tail=(n, n))
            check_spd("KJ", KJ)
            q_rest = as_array("q_rest", self.q_rest, tail=(n,))
            self.chain.check_angles("q_rest", q_rest)
            object.__setattr__(self, "KJ", jnp.asarray(KJ, float))
            object.__setattr__(self, "q_rest", jnp.asarray(q_rest, float))

    def batch_shape(self) -> tuple[int, ...]:
        if not self.elastic:
            return broadcast_batch(W=(self.W, 2))
        return broadcast_batch(W=(self.W, 2), KJ=(self.KJ, 2), q_rest=(self.q_rest, 1))

    def prepare_soa(self, batch):
        """Per-trajectory constants, component-leading with trailing ``batch``: ``A``, ``G``, ``q_rest``."""
        n = self.chain.n
        A = spd_inv(to_soa(jnp.broadcast_to(self.W, batch + (n, n)), 2))
        if not self.elastic:
            return {"A": A}
        # G = A KJ, so that A τ_el = G (q − q_rest) costs one mat-vec per evaluation.
        KJ = to_soa(jnp.broadcast_to(self.KJ, batch + (n, n)), 2)
        G = jnp.stack([jnp.stack([sum(A[i, k] * KJ[k, j] for k in range(n)) for j in range(n)]) for i in range(n)])
        return {"A": A, "G": G, "q_rest": to_soa(jnp.broadcast_to(self.q_rest, batch + (n,)))}

    def qdot_soa(self, J, P, M, F, qc, consts):
        """Joint velocity (n, ...) from task force ``F`` (m, ...) and ``P = A Jᵀ``, ``M = B⁻¹``."""
        if not self.elastic:
            return mv(P, F)
        g = mv(consts["G"], qc - consts["q_rest"])  # A τ_el
        if self.blocked:
            F = F + lambda0_soa(J, M, g)
        return mv(P, F) - g

    def velocity(self, q, F):
        """Joint velocity ``q̇`` (..., n) [rad/s] at ``q`` (..., n) [rad] under task force ``F``
        (..., m) [N] (the model's field, Figure 1B); leading axes broadcast with the model's.
        Differentiable in ``q``, ``F`` and the model's leaves."""
        q = to_jax(as_array("q", q, tail=(self.chain.n,)))
        F = to_jax(as_array("F", F, tail=(self.chain.m,)))
        batch = broadcast_batch(q=(q, 1), F=(F, 1), model=(np.broadcast_to(0.0, self.batch_shape()), 0))
        qc = to_soa(jnp.broadcast_to(q, batch + q.shape[-1:]))
        consts = self.prepare_soa(batch)
        _, J = self.chain.fk_jac_soa(qc)
        P, M = admittance_terms_soa(J, consts["A"])
        Fc = to_soa(jnp.broadcast_to(F, batch + F.shape[-1:]))
        return jnp.moveaxis(self.qdot_soa(J, P, M, Fc, qc, consts), 0, -1)


@pytree_dataclass
class PMP1(_PMP):
    """Purely viscous PMP: ``q̇ = W⁻¹ Jᵀ F``. Solves redundancy, path-dependent postures.

    ``chain``: a Chain; ``W`` (..., n, n) SPD joint damping [Nm s/rad] (array leaf).
    """

    chain: Chain
    W: jax.Array
    KJ: ClassVar[None] = None
    q_rest: ClassVar[None] = None

    def __post_init__(self):
        self._validate()


@pytree_dataclass
class PMP2(_PMP):
    """Visco-elastic PMP: ``q̇ = W⁻¹ (Jᵀ F − KJ (q − q_rest))``. Unique postures, misses targets.

    ``chain``: a Chain; ``KJ`` (..., n, n) SPD [Nm/rad], ``q_rest`` (..., n) [rad], ``W`` (..., n, n)
    SPD [Nm s/rad]: array leaves (vmappable, differentiable).
    """

    chain: Chain
    KJ: jax.Array
    q_rest: jax.Array
    W: jax.Array
    elastic: ClassVar[bool] = True

    def __post_init__(self):
        self._validate()


@pytree_dataclass
class Lambda0PMP(_PMP):
    """λ0-PMP (Eq 4–5): reaches the target and ends in the energy-minimising posture (Donders).

    ``chain``: a Chain; ``KJ`` (..., n, n) SPD joint stiffness [Nm/rad]; ``q_rest`` (..., n) rest
    posture [rad]; ``W`` (..., n, n) SPD joint damping [Nm s/rad]: array leaves. Leading axes batch.
    A ``q_rest`` beyond the chain's range is refused or warned about as degrees typed as radians
    (``Chain.check_angles``: on the wrist, beyond ±180° refused, beyond ±90° a warning).
    """

    chain: Chain
    KJ: jax.Array
    q_rest: jax.Array
    W: jax.Array
    elastic: ClassVar[bool] = True
    blocked: ClassVar[bool] = True

    def __post_init__(self):
        self._validate()


def damping_from_stiffness(KJ, tau0):
    """Damping proportional to stiffness, ``W = τ0 KJ`` (Eq 7).

    **Arguments:**

    - ``KJ``: (..., n, n) joint stiffness [Nm/rad].
    - ``tau0``: (...) intrinsic time constant [s], positive (above 10 s refused as milliseconds
      typed as seconds, above 2 s a warning).

    **Returns:**

    (..., n, n) joint damping ``W`` [Nm s/rad].

    **Raises:**

    - ``ValueError`` naming the argument for a non-square ``KJ``, NaN/inf, or a non-positive or
      too large ``tau0``.
    """
    KJ = as_array("KJ", KJ, tail=(None, None))
    if KJ.shape[-1] != KJ.shape[-2]:
        raise ValueError(f"`KJ` must be square (..., n, n), got shape {KJ.shape}")
    tau0 = as_array("tau0", tau0)
    check_positive("tau0", tau0)
    check_seconds("tau0", tau0)
    if is_concrete(KJ, tau0):  # (on the host: no eager XLA op)
        return to_jax(np.asarray(tau0)[..., None, None] * np.asarray(KJ))
    return jnp.asarray(tau0)[..., None, None] * jnp.asarray(KJ)


def normalize_trace(KJ, trace: float = 4.0):
    """Scale ``KJ`` to a given trace (the paper uses 4 Nm/rad; only the eigenvalue ratios matter).

    **Arguments:**

    - ``KJ``: (..., n, n) joint stiffness [Nm/rad] with positive trace.
    - ``trace``: the target trace [Nm/rad], positive.

    **Returns:**

    (..., n, n) ``KJ · trace / tr(KJ)``.

    **Raises:**

    - ``ValueError`` naming the argument for a non-square ``KJ``, NaN/inf, or a non-positive trace.
    """
    KJ = as_array("KJ", KJ, tail=(None, None))
    if KJ.shape[-1] != KJ.shape[-2]:
        raise ValueError(f"`KJ` must be square (..., n, n), got shape {KJ.shape}")
    check_positive("trace", trace)
    KJ = jnp.asarray(KJ)
    tr = jnp.trace(KJ, axis1=-2, axis2=-1)
    check_positive("trace(KJ)", tr)
    return KJ * (trace / tr)[..., None, None]
