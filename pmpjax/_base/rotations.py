"""Elementary rotations about the coordinate axes (the one helper for every chain).

``R_x(t) = [[1, 0, 0], [0, c, −s], [0, s, c]]``, ``R_y(t) = [[c, 0, s], [0, 1, 0], [−s, 0, c]]``,
``R_z(t) = [[c, −s, 0], [s, c, 0], [0, 0, 1]]`` with ``c = cos t``, ``s = sin t`` (right-handed,
active rotations). The nested-list form keeps the component-leading (SoA) layout of the chain
kernels: every entry is an array shaped like ``t`` and products are elementwise.
"""

from __future__ import annotations

import jax.numpy as jnp


def rotation_rows(axis: int, angle):
    """Rows of the elementary rotation about ``axis`` (0 = x, 1 = y, 2 = z) by ``angle`` [rad]:
    a nested 3 × 3 list of arrays shaped like ``angle``."""
    c, s = jnp.cos(angle), jnp.sin(angle)
    o, z = jnp.ones_like(c), jnp.zeros_like(c)
    if axis == 0:
        return [[o, z, z], [z, c, -s], [z, s, c]]
    if axis == 1:
        return [[c, z, s], [z, o, z], [-s, z, c]]
    if axis == 2:
        return [[c, -s, z], [s, c, z], [z, z, o]]
    raise ValueError(f"`axis` must be 0, 1 or 2 (x, y, z), got {axis!r}")


def rotation_matrix(axis: int, angle):
    """Elementary rotation about ``axis`` by ``angle`` (...,) [rad] as an array (..., 3, 3)."""
    rows = rotation_rows(axis, jnp.asarray(angle))
    return jnp.stack([jnp.stack(r, axis=-1) for r in rows], axis=-2)


def matmul_rows(A, B):
    """Product of two nested 3 × 3 lists (:func:`rotation_rows` layout), entry by entry."""
    return [[sum(A[i][k] * B[k][j] for k in range(3)) for j in range(3)] for i in range(3)]
