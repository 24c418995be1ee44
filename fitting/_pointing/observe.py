"""Model movements observed like the data (JAX, differentiable): the analysis' smoothing spline as
its equivalent kernel, the speed-threshold cut on a C¹ interpolant, normalised samples and
curvature. Shared by the predictions and the time-constant fits.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from pmpjax import (
    curvature_measures,
)
from pmpjax.internal import (
    fast_compile_jit,
)


def _hermite_uniform(h, y, dy, sq):
    """Cubic Hermite interpolation of ``y`` (B, n, k) with derivatives ``dy`` on the grid ``i·h``."""
    n = y.shape[1]
    i = jnp.clip(jnp.floor(sq / h).astype(int), 0, n - 2)
    u = (sq / h - i)[..., None]
    take = lambda a, idx: jnp.take_along_axis(a, idx[..., None], axis=1)  # noqa: E731
    h00, h10, h01, h11 = 2 * u**3 - 3 * u**2 + 1, u**3 - 2 * u**2 + u, -2 * u**3 + 3 * u**2, u**3 - u**2
    return h00 * take(y, i) + h10 * h * take(dy, i) + h01 * take(y, i + 1) + h11 * h * take(dy, i + 1)


def _slopes(h, y):
    """Derivatives of ``y`` (B, n) on the grid ``i·h`` by central differences (one-sided at the
    ends): the slopes of the Catmull–Rom (C¹ cubic Hermite) interpolant."""
    return jnp.concatenate([y[:, 1:2] - y[:, :1], (y[:, 2:] - y[:, :-2]) / 2, y[:, -1:] - y[:, -2:-1]], 1) / h


def _hermite_pieces(h, y, m, j):
    """Values and slopes (×h) at both ends of interval ``j`` (B,) of the interpolant of ``y``."""
    take = lambda a, k: jnp.take_along_axis(a, k[:, None], axis=1)[:, 0]  # noqa: E731
    return take(y, j), h * take(m, j), take(y, j + 1), h * take(m, j + 1)


def _hermite_at(y0, d0, y1, d1, u):
    """The cubic Hermite piece at ``u`` ∈ [0, 1] and its derivative d/du."""
    p = (2 * u**3 - 3 * u**2 + 1) * y0 + (u**3 - 2 * u**2 + u) * d0 + (-2 * u**3 + 3 * u**2) * y1 + (u**3 - u**2) * d1
    dp = (6 * u**2 - 6 * u) * (y0 - y1) + (3 * u**2 - 4 * u + 1) * d0 + (3 * u**2 - 2 * u) * d1
    return p, dp


def _crossings(h, v, threshold):
    """Onset and offset (B,) [grid units × h] where the speed ``v`` (B, n) crosses ``threshold`` of
    its peak, before and after the peak, on its C¹ (Catmull–Rom) interpolant; the peak is the
    interpolant's maximum next to the largest sample. Both are continuously differentiable in ``v``
    (linear interpolation and a discrete maximum made the fits' residual piecewise smooth, and
    Levenberg–Marquardt crawled along its kinks)."""
    n = v.shape[1]
    idx = jnp.arange(n)
    m = _slopes(h, v)
    i = jnp.clip(jnp.argmax(v, axis=1), 1, n - 2)
    peak = jnp.take_along_axis(v, i[:, None], axis=1)[:, 0]
    for j in (i - 1, i):  # p'(u) = a u² + b u + c on the intervals either side of the largest sample
        y0, d0, y1, d1 = _hermite_pieces(h, v, m, j)
        a, b, c = 6 * y0 + 3 * d0 - 6 * y1 + 3 * d1, -6 * y0 - 4 * d0 + 6 * y1 - 2 * d1, d0
        disc = jnp.maximum(b * b - 4 * a * c, 0.0)
        safe_a = jnp.where(jnp.abs(a) > 1e-300, a, 1.0)
        for sgn in (1.0, -1.0):
            quad = jnp.abs(a) > 1e-12 * (jnp.abs(b) + jnp.abs(c))
            u = jnp.where(quad, (-b + sgn * jnp.sqrt(disc)) / (2 * safe_a), -c / jnp.where(b != 0, b, 1.0))
            val = _hermite_at(y0, d0, y1, d1, jnp.clip(u, 0.0, 1.0))[0]
            peak = jnp.maximum(peak, jnp.where((u >= 0) & (u <= 1), val, peak))
    level = threshold * peak
    below = v < level[:, None]
    i_on = jnp.max(jnp.where(below & (idx[None] < i[:, None]), idx[None], 0), axis=1)
    i_off = jnp.min(jnp.where(below & (idx[None] > i[:, None]), idx[None], n - 1), axis=1) - 1

    def root(j):
        """The crossing of ``level`` inside interval ``j``: Newton from the linear estimate."""
        y0, d0, y1, d1 = _hermite_pieces(h, v, m, j)
        u = jnp.clip((level - y0) / jnp.where(y1 != y0, y1 - y0, 1.0), 0.0, 1.0)
        for _ in range(4):
            f, df = _hermite_at(y0, d0, y1, d1, u)
            u = jnp.clip(u - (f - level) / jnp.where(df != 0, df, 1.0), 0.0, 1.0)
        return h * (j + u)

    return root(i_on), root(i_off), peak


def _silverman_weights(bandwidth, h, J):
    """Discrete equivalent kernel of a cubic smoothing spline (Silverman 1984):
    ``K(u) = ½ e^{−|u|/√2} sin(|u|/√2 + π/4)`` at offsets ``j·h``, ``|j| ≤ J``, for bandwidths
    (B,) in the grid's units; normalised to sum 1. (B, 2J + 1)."""
    u = jnp.abs(jnp.arange(-J, J + 1, dtype=float) * h)[None, :] / bandwidth[:, None]
    w = 0.5 * jnp.exp(-u / np.sqrt(2)) * jnp.sin(u / np.sqrt(2) + np.pi / 4)
    return w / jnp.sum(w, axis=1, keepdims=True)


def _smooth(y, w, *, edge):
    """``y`` (B, n, k) convolved with per-item symmetric weights ``w`` (B, 2J + 1); outside the
    grid ``y`` continues as its end values (``edge``) or as zeros. By FFT: a handful of
    operations in the compiled graph whatever ``J`` (shifted sums would add 2J + 1 per call)."""
    J = (w.shape[1] - 1) // 2
    if J == 0:
        return y
    n = y.shape[1]
    lo = jnp.repeat(y[:, :1], J, axis=1) if edge else jnp.zeros_like(y[:, :J])
    hi = jnp.repeat(y[:, -1:], J, axis=1) if edge else jnp.zeros_like(y[:, :J])
    yp = jnp.concatenate([lo, y, hi], axis=1)
    L = 1 << (n + 4 * J).bit_length()
    conv = jnp.fft.irfft(jnp.fft.rfft(yp, n=L, axis=1) * jnp.fft.rfft(w, n=L, axis=1)[:, :, None], n=L, axis=1)
    return conv[:, 2 * J:2 * J + n]  # symmetric kernel: the convolution is the centred moving sum


def spline_bandwidth(lam, rate):
    """Bandwidth [s] of the equivalent kernel of a cubic smoothing spline with parameter ``lam``
    (SciPy's ``make_smoothing_spline`` scale) on samples at ``rate`` [Hz]: ``(λ / rate)^{1/4}``
    (Silverman 1984)."""
    return (np.asarray(lam) / rate) ** 0.25


def _profiles(tr, T, half, bandwidth, *, h, J, threshold, n_samples, radius, joints=True):
    """A batch of normalised-time model movements (``pmpjax._wrist.pointing.normalised_movements``)
    analysed like the data: observed through the smoothing spline of the analysis (its equivalent
    kernel, ``bandwidth`` (B,) in units of T; ``J`` grid steps each side), cut at ``threshold``
    of its peak speed widened by ``half`` (B,) (half a data sample, in units of T: the data's
    sample-level cut lies on average half a sample outside the crossing), then the path, joint
    angles and speed at ``n_samples`` normalised times, the duration [s] and the curvature of the
    cut path (line through its own ends); ``joints``: also the joint angles (``q_path``).

    ``T`` (B,) [s] the time unit of each movement. Differentiable in every array input.
    """
    w = _silverman_weights(bandwidth, h, J)
    x, xdot = _smooth(tr.x, w, edge=True), _smooth(tr.xdot, w, edge=False)
    v = jnp.linalg.norm(xdot, axis=-1) / T[:, None]  # m/s
    s_on, s_off, peak = _crossings(h, v, threshold)
    span = h * (v.shape[1] - 1)
    s_on = jnp.clip(s_on - half, 0.0, span)
    s_off = jnp.clip(s_off + half, 0.0, span)
    u = jnp.linspace(0.0, 1.0, n_samples)
    sq = s_on[:, None] + u[None] * (s_off - s_on)[:, None]
    dense = s_on[:, None] + jnp.linspace(0.0, 1.0, 96)[None] * (s_off - s_on)[:, None]
    xd = _hermite_uniform(h, x, xdot, dense)
    a_sum, a_net = curvature_measures(xd, xd[:, 0], xd[:, -1], scale=radius)
    speed = _hermite_uniform(h, v[..., None], _slopes(h, v)[..., None], sq)[..., 0]
    out = dict(path=_hermite_uniform(h, x, xdot, sq), speed=speed, onset=s_on * T,
               offset=s_off * T, duration=(s_off - s_on) * T, peak=peak, a_sum=a_sum, a_net=a_net)
    if joints:
        out["q_path"] = _hermite_uniform(h, _smooth(tr.q, w, edge=True), _smooth(tr.qdot, w, edge=False), sq)
    return out


def _kernel_halfwidth(bandwidth, h):
    """Static half-width (grid steps) of the kernel: 6 bandwidths (the kernel is < 1e-3 there)."""
    return int(np.ceil(6.0 * float(np.max(bandwidth)) / h))


_profiles_jit = fast_compile_jit(_profiles, static_argnames=("h", "J", "threshold", "n_samples", "radius"))
