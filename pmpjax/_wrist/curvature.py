"""Movement metrics (Section 2, "Data Analysis"): curvature areas of paths between targets."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from .._base import as_array, fast_compile_jit, to_jax


def curvature_areas(path, start, end):
    """Areas between a path and the directed line from ``start`` to ``end`` (the paper's Figure 4).

    **Convention (open paths).** The enclosed region is that of the closed polygon
    ``start → path[0] → … → path[-1] → end → start``: paths that do not begin or end on the line
    (a measured movement cut at 20 % of peak speed never starts exactly on a target) are closed
    by the straight segments from ``start`` to the first sample and from the last sample to
    ``end``, then back along the line. The polygon is split exactly where its edges cross the
    line; the part on the left of the directed line is ``A_L``, on the right ``A_R`` (a region
    enclosed several times counts that many times, as for a shoelace area). For the paper's
    measure, pass the movement's own first and last points as ``start``/``end`` (Figure 4
    caption: the line joins the movement's start and end); the closing segments then vanish.
    Normalise by the squared target distance for the paper's ``A`` values
    (:func:`curvature_measures`). Differentiable in all arguments (except where the line has zero
    length).

    **Arguments:**

    - ``path``: (..., S, 2) path samples in task units (screen [m]).
    - ``start``, ``end``: (..., 2) the line's ends, directed from ``start`` to ``end``.

    **Returns:**

    ``(A_R, A_L)``: (...,) the non-negative raw areas (task units²) on the right and left of the line.

    **Raises:**

    - ``ValueError`` naming the argument for wrong shapes, NaN/inf, or fewer than 2 samples.
    """
    return _areas(*_check_line(path, start, end))


def _check_line(path, start, end):
    path = to_jax(as_array("path", path, tail=(None, 2)))
    start = to_jax(as_array("start", start, tail=(2,)))
    end = to_jax(as_array("end", end, tail=(2,)))
    if path.shape[-2] < 2:
        raise ValueError(f"`path` needs at least 2 samples, got shape {path.shape}")
    return path, start, end


@fast_compile_jit
def _areas(path, start, end):
    lead = jnp.broadcast_shapes(path.shape[:-2], start.shape[:-1], end.shape[:-1])
    path = jnp.concatenate([jnp.broadcast_to(start, lead + (2,))[..., None, :],
                            jnp.broadcast_to(path, lead + path.shape[-2:]),
                            jnp.broadcast_to(end, lead + (2,))[..., None, :]], axis=-2)
    u = end - start
    length = jnp.linalg.norm(u, axis=-1, keepdims=True)
    u = u / length
    rel = path - start[..., None, :]
    s = jnp.sum(rel * u[..., None, :], axis=-1)  # along the line
    d = u[..., None, 0] * rel[..., 1] - u[..., None, 1] * rel[..., 0]  # > 0: left of the line
    s0, s1, d0, d1 = s[..., :-1], s[..., 1:], d[..., :-1], d[..., 1:]
    ds = s1 - s0
    cross = d0 * d1 < 0
    phi = jnp.where(cross, d0 / jnp.where(cross, d0 - d1, 1.0), 0.0)
    # Trapezoids of d over s; a segment that crosses the line is split at the crossing.
    whole = ds * (d0 + d1) / 2
    a, b = phi * ds * d0 / 2, (1 - phi) * ds * d1 / 2
    left = jnp.where(cross, jnp.where(d0 > 0, a, 0.0) + jnp.where(d1 > 0, b, 0.0), jnp.where(d0 + d1 > 0, whole, 0.0))
    right = jnp.where(cross, jnp.where(d0 < 0, a, 0.0) + jnp.where(d1 < 0, b, 0.0), jnp.where(d0 + d1 < 0, whole, 0.0))
    return -jnp.sum(right, axis=-1), jnp.sum(left, axis=-1)


def curvature_measures(path, start, end, *, scale: float = np.pi / 12):
    """The paper's curvature measures ``A_sum = A_R + A_L`` and ``A_net = A_R − A_L``.

    See :func:`curvature_areas` for the convention on open paths.

    **Arguments:**

    - ``path``, ``start``, ``end``: as :func:`curvature_areas`.
    - ``scale``: the normaliser, the nominal target-to-target distance (paper: π/12 m, the default
      target radius of :func:`center_out_targets`).

    **Returns:**

    ``(A_sum, A_net)``: (...,) areas normalised by ``scale²`` (dimensionless).

    **Raises:**

    - ``ValueError`` as :func:`curvature_areas`.
    """
    path, start, end = _check_line(path, start, end)
    return _measures(path, start, end, scale)


@fast_compile_jit
def _measures(path, start, end, scale):
    a_r, a_l = _areas(path, start, end)
    return (a_r + a_l) / scale**2, (a_r - a_l) / scale**2
