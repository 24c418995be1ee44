"""Movement metrics (Section 2, "Data Analysis"): curvature areas of paths between targets."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from .._base.validate import as_array


def curvature_areas(path, start, end):
    """Areas between a path and the directed line from ``start`` to ``end`` (Figure 4).

    ``path`` (..., S, 2), ``start``/``end`` (..., 2) in task units. Returns ``(A_R, A_L)``
    (...,), the non-negative raw areas (task units²) enclosed on the right / left of the line,
    integrating the path's signed distance from the line over arc length along the line, with
    the path linearly interpolated between samples and split exactly where it crosses the line.
    Normalise by the squared target distance for the paper's ``A`` values (``curvature_measures``).
    """
    path = jnp.asarray(as_array("path", path, tail=(None, 2)))
    start = jnp.asarray(as_array("start", start, tail=(2,)))
    end = jnp.asarray(as_array("end", end, tail=(2,)))
    if path.shape[-2] < 2:
        raise ValueError(f"`path` needs at least 2 samples, got shape {path.shape}")
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
    """``A_sum``, ``A_net = A_R − A_L`` normalised by ``scale²`` (paper: (π/12)²) (...,)."""
    a_r, a_l = curvature_areas(path, start, end)
    return (a_r + a_l) / scale**2, (a_r - a_l) / scale**2
