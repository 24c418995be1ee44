"""The minimum-jerk profile (Flash & Hogan 1985), shared by the time-base generator
(``MinimumJerkPlanner``), the springy arm's summed set-point moves (Williamson 1996 Section 2.3)
and the IK papers' synthetic movements."""

from __future__ import annotations

import jax.numpy as jnp


def minimum_jerk(s):
    """Fraction of a minimum-jerk move done at phase ``s`` and its rate, both (...) like ``s``.

    ``ξ(s) = 10 s³ − 15 s⁴ + 6 s⁵`` and ``dξ/ds = 30 s² (1 − s)²`` with ``s`` clipped to [0, 1]
    (so ``ξ`` is 0 before and 1 after the move, and ``dξ/ds`` 0 outside it).
    """
    s = jnp.clip(s, 0.0, 1.0)
    return s**3 * (10.0 + s * (-15.0 + 6.0 * s)), 30.0 * s**2 * (1.0 - s) ** 2
