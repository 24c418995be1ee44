"""Leading batch axes: broadcast-and-flatten for vmapped kernels, and power-of-two buckets.

Public entry points take arrays with any leading (batch) axes in front of their core axes
(``KJ`` (..., n, n), ``q`` (..., n)); kernels are written for one item and vmapped over one flat
axis. :func:`broadcast_batch` finds the common batch shape (``ValueError`` naming the arguments
when they do not broadcast), :func:`flatten_batch` brings an array to ``(B, *core)``.
:func:`bucket` rounds a size up to a power of two and :func:`pad_rows` pads to it, so calls of
similar size share one compilation.
"""

from __future__ import annotations

import math
from typing import Any

import jax.numpy as jnp
import numpy as np


def broadcast_batch(**arrays: tuple[Any, int]) -> tuple[int, ...]:
    """Common leading shape of ``name=(array, core_ndim)`` pairs (``None`` arrays are skipped).

    Raises ``ValueError`` naming every argument and its batch shape when they do not broadcast.
    """
    shapes = {k: tuple(np.shape(a))[: np.ndim(a) - core] for k, (a, core) in arrays.items() if a is not None}
    try:
        return tuple(np.broadcast_shapes(*shapes.values()))
    except ValueError as e:
        desc = ", ".join(f"`{k}` {s}" for k, s in shapes.items())
        raise ValueError(f"leading (batch) axes of {desc} do not broadcast") from e


def flatten_batch(a, batch: tuple[int, ...], core: int, *, dtype=None, xp=jnp):
    """Broadcast ``a`` (..., *core) to ``batch + core`` and flatten to ``(prod(batch), *core)``
    (``xp=np`` for NumPy in and out, e.g. for C MuJoCo)."""
    a = xp.asarray(a, dtype)
    core_shape = a.shape[a.ndim - core :]
    return xp.broadcast_to(a, batch + core_shape).reshape((math.prod(batch),) + core_shape)


def unflatten_batch(a, batch: tuple[int, ...]):
    """Inverse of :func:`flatten_batch`: ``(B, *core)`` -> ``batch + core``."""
    return a.reshape(batch + a.shape[1:])


def bucket(size: int, *, minimum: int = 1) -> int:
    """Smallest power of two ``>= max(size, minimum)``."""
    return max(int(minimum), 1 << max(int(size) - 1, 0).bit_length())


def pad_rows(a, size: int, *, axis: int = 0, fill: str = "edge"):
    """Pad ``a`` along ``axis`` to ``size`` entries: ``fill="edge"`` repeats the last entry (a
    valid item: padded lanes then do the same work as a real one and cannot fail differently),
    ``"zeros"`` appends zeros (for data whose padding is masked out). NumPy in, NumPy out."""
    xp = np if isinstance(a, np.ndarray) else jnp
    n = a.shape[axis]
    if size < n:
        raise ValueError(f"cannot pad {n} rows down to {size}")
    if size == n:
        return a
    shape = list(a.shape)
    shape[axis] = size - n
    if fill == "edge":
        last = xp.take(a, xp.asarray([n - 1]), axis=axis)
        extra = xp.broadcast_to(last, tuple(shape))
    elif fill == "zeros":
        extra = xp.zeros(tuple(shape), a.dtype)
    else:
        raise ValueError(f"`fill` must be 'edge' or 'zeros', got {fill!r}")
    return xp.concatenate([a, extra], axis=axis)
