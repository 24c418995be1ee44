"""Leading batch axes: broadcast-and-flatten for vmapped kernels, and power-of-two buckets.

Public entry points take arrays with any leading (batch) axes in front of their core axes
(``KJ`` (..., n, n), ``q`` (..., n)); kernels are written for one item and vmapped over one flat
axis. :func:`broadcast_batch` finds the common batch shape (``ValueError`` naming the arguments
when they do not broadcast), :func:`flatten_batch` brings an array to ``(B, *core)``.
:func:`bucket` rounds a size up to a power of two and :func:`pad_rows` pads to it, so calls of
similar size share one compilation.

Concrete arrays (no tracer) are reshaped, padded and sliced in NumPy so that eager calls of the
public functions compile nothing but their kernel (each eager ``jnp`` op on a new shape costs an
XLA compilation of 30-100 ms); ``jax.Array`` in, ``jax.Array`` out. Tracers go through ``jnp``.
"""

from __future__ import annotations

import math
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from .validate import is_concrete, to_jax


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


def on_host(a, op):
    """``op(a)`` for indexing/reshaping: in NumPy for concrete ``a`` (a ``jax.Array`` comes back as
    one, without an XLA compilation), directly on a tracer."""
    if not is_concrete(a):
        return op(a)
    out = op(np.asarray(a))
    return out if isinstance(a, np.ndarray) else to_jax(out)


def flatten_batch(a, batch: tuple[int, ...], core: int, *, dtype=None, xp=jnp):
    """Broadcast ``a`` (..., *core) to ``batch + core`` and flatten to ``(prod(batch), *core)``
    (``xp=np`` for NumPy in and out, e.g. for C MuJoCo; with ``xp=jnp`` a concrete ``a`` is
    reshaped in NumPy and returned as a ``jax.Array``)."""
    if xp is jnp and is_concrete(a):
        return to_jax(flatten_batch(a, batch, core, dtype=dtype, xp=np))
    a = xp.asarray(a, dtype)
    core_shape = a.shape[a.ndim - core :]
    return xp.broadcast_to(a, batch + core_shape).reshape((math.prod(batch),) + core_shape)


def unflatten_batch(a, batch: tuple[int, ...], n: int | None = None):
    """Inverse of :func:`flatten_batch`: the first ``n`` (default all) rows of ``(B, *core)`` ->
    ``batch + core``."""
    return on_host(a, lambda a: a[: a.shape[0] if n is None else n].reshape(batch + a.shape[1:]))


def head_rows(a, n: int):
    """``a[:n]`` (the unpadded rows of a kernel's output) without an eager XLA op for concrete ``a``."""
    return on_host(a, lambda a: a[:n])


def bucket(size: int, *, minimum: int = 1) -> int:
    """Smallest power of two ``>= max(size, minimum)``."""
    return max(int(minimum), 1 << max(int(size) - 1, 0).bit_length())


def pad_rows(a, size: int, *, axis: int = 0, fill: str = "edge"):
    """Pad ``a`` along ``axis`` to ``size`` entries: ``fill="edge"`` repeats the last entry (a
    valid item: padded lanes then do the same work as a real one and cannot fail differently),
    ``"zeros"`` appends zeros (for data whose padding is masked out). NumPy in, NumPy out;
    a concrete ``jax.Array`` is padded in NumPy and returned as a ``jax.Array``."""
    if not isinstance(a, np.ndarray) and is_concrete(a):
        return to_jax(pad_rows(np.asarray(a), size, axis=axis, fill=fill))
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


def row_chunks(fn, *rows, small: int = 64, chunk: int = 1024):
    """``fn(*rows)`` for a row-wise jitted ``fn`` and concrete ``rows`` (R, ...): padded (edge) to
    ``small`` rows, or cut into padded chunks of ``chunk`` rows, so that every R shares at most two
    compilations of ``fn``. Returns ``fn``'s outputs as NumPy with R rows."""
    R = len(rows[0])
    Rp = small if R <= small else -(-R // chunk) * chunk
    rows = [pad_rows(np.asarray(a), Rp) for a in rows]
    size = min(Rp, chunk)
    parts = [jax.device_get(fn(*(a[i : i + size] for a in rows))) for i in range(0, Rp, size)]
    return jax.tree_util.tree_map(lambda *p: np.concatenate(p)[:R], *parts)


def eager_rows(fn, x, core: int, *, small: int = 64, chunk: int = 1024):
    """``fn(x)`` for a row-wise jitted ``fn`` and ``x`` (..., *core) with ``core`` trailing axes.

    A concrete ``x`` is flattened to rows and evaluated by :func:`row_chunks` (two compilations
    of ``fn`` for every batch shape); the outputs' leading row axis is unflattened again
    (``jax.Array``). A tracer goes to ``fn`` as it is.
    """
    if not is_concrete(x) or np.size(x) == 0:
        return fn(x)
    x = np.asarray(x)
    batch = x.shape[: x.ndim - core]
    out = row_chunks(fn, x.reshape((math.prod(batch),) + x.shape[x.ndim - core :]), small=small, chunk=chunk)
    return jax.tree_util.tree_map(lambda a: to_jax(a.reshape(batch + a.shape[1:])), out)
