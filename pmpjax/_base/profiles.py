"""The minimum-jerk profile (Flash & Hogan 1985), shared by the time-base generator
(``MinimumJerkPlanner``, through :func:`minimum_jerk_hazard`), the springy arm's summed set-point
moves (Williamson 1996 Section 2.3) and the IK papers' synthetic movements."""

from __future__ import annotations

import jax.numpy as jnp


def minimum_jerk(s):
    """Fraction of a minimum-jerk move done at phase ``s`` and its rate, both (...) like ``s``.

    ``ξ(s) = 10 s³ − 15 s⁴ + 6 s⁵`` and ``dξ/ds = 30 s² (1 − s)²`` with ``s`` clipped to [0, 1]
    (so ``ξ`` is 0 before and 1 after the move, and ``dξ/ds`` 0 outside it).
    """
    s = jnp.clip(s, 0.0, 1.0)
    return s**3 * (10.0 + s * (-15.0 + 6.0 * s)), 30.0 * s**2 * (1.0 - s) ** 2


def minimum_jerk_hazard(s, cap, duration=1.0):
    """``ξ̇ / (1 − ξ)`` of a minimum-jerk move of ``duration`` at phase ``s = t / duration``, capped at
    ``cap``: the time-base generator's gain, (...) broadcast from ``s``, ``cap`` and ``duration``.

    With ``1 − ξ = (1 − s)³ (6 s² + 3 s + 1)`` and ``dξ/ds = 30 s² (1 − s)²`` the ratio is, exactly,
    ``30 s² / (duration (1 − s)(6 s² + 3 s + 1))`` (``6 s² + 3 s + 1 > 0``): 0 at ``s = 0``, increasing,
    unbounded as ``s → 1``. Returns ``min(that, cap)`` for ``0 ≤ s < 1``, ``cap`` for ``s ≥ 1`` and 0 for
    ``s < 0``, in the units of ``cap`` (1/[unit of ``duration``]). No clamp of ``1 − ξ``: the value is
    accurate to rounding up to the cap, and the derivatives with respect to ``s``, ``cap`` and
    ``duration`` are finite everywhere (the branch not taken is evaluated at a safe denominator).
    """
    s = jnp.maximum(jnp.asarray(s), 0.0)
    num = 30.0 * s * s
    den = duration * (1.0 - s) * (1.0 + s * (3.0 + 6.0 * s))
    below = num < cap * den  # the uncapped ratio is below the cap; False for s >= 1 (den <= 0)
    return jnp.where(below, num / jnp.where(below, den, 1.0), cap)
