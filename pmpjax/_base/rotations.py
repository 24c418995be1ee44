"""Elementary rotations about the coordinate axes (the one helper for every chain).

``R_x(t) = [[1, 0, 0], [0, c, −s], [0, s, c]]``, ``R_y(t) = [[c, 0, s], [0, 1, 0], [−s, 0, c]]``,
``R_z(t) = [[c, −s, 0], [s, c, 0], [0, 0, 1]]`` with ``c = cos t``, ``s = sin t`` (right-handed,
active rotations). The nested-list form keeps the component-leading (SoA) layout of the chain
kernels: entries are arrays shaped like ``t`` (products are elementwise) or the Python floats
0.0 and 1.0 for the structural zeros and ones, which :func:`matmul_rows` skips (XLA keeps
``x * 0`` for floats: a 3 × 3 product of elementary rotations is 8 multiplications, not 27).
Sines and cosines come from ``sincos`` (vectorised polynomials, see ``trig.py``).
"""

from __future__ import annotations

import jax.numpy as jnp

from .trig import sincos


def rotation_rows(axis: int, angle=None, *, sin_cos=None):
    """Rows of the elementary rotation about ``axis`` (0 = x, 1 = y, 2 = z) by ``angle`` [rad]
    (or from its ``sin_cos = (sin, cos)``): a nested 3 × 3 list of arrays shaped like ``angle``
    and Python 0.0 / 1.0 (structural zeros and ones)."""
    s, c = sincos(angle) if sin_cos is None else sin_cos
    o, z = 1.0, 0.0
    if axis == 0:
        return [[o, z, z], [z, c, -s], [z, s, c]]
    if axis == 1:
        return [[c, z, s], [z, o, z], [-s, z, c]]
    if axis == 2:
        return [[c, -s, z], [s, c, z], [z, z, o]]
    raise ValueError(f"`axis` must be 0, 1 or 2 (x, y, z), got {axis!r}")


def rotation_matrix(axis: int, angle):
    """Elementary rotation about ``axis`` by ``angle`` (...,) [rad] as an array (..., 3, 3)."""
    angle = jnp.asarray(angle)
    rows = rotation_rows(axis, angle)
    full = lambda v: jnp.broadcast_to(jnp.asarray(v, angle.dtype), angle.shape)  # noqa: E731
    return jnp.stack([jnp.stack([full(v) for v in r], axis=-1) for r in rows], axis=-2)


def _is(v, const):
    return isinstance(v, float) and v == const


def mul_const(a, b):
    """``a * b`` where either may be a Python float: structural zeros and ones drop out."""
    if _is(a, 0.0) or _is(b, 0.0):
        return 0.0
    if _is(a, 1.0):
        return b
    if _is(b, 1.0):
        return a
    return a * b


def add_const(a, b):
    """``a + b`` where either may be a Python float: a structural zero drops out."""
    return b if _is(a, 0.0) else a if _is(b, 0.0) else a + b


def matmul_rows(A, B):
    """Product of two nested 3 × 3 lists (:func:`rotation_rows` layout), entry by entry, skipping
    structural zeros and ones."""
    out = [[0.0] * 3 for _ in range(3)]
    for i in range(3):
        for j in range(3):
            for k in range(3):
                out[i][j] = add_const(out[i][j], mul_const(A[i][k], B[k][j]))
    return out
