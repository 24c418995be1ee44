"""Movement analysis of recorded paths (Tommasino & Campolo 2017, Section 2 "Data Analysis").

Smoothing-spline filtering, tangential speed, segmentation at a fraction of peak speed and
time normalisation. These run on measured, ragged data on the host (NumPy/SciPy), not inside
``jit``: SciPy's ``make_smoothing_spline`` chooses the smoothing by generalised
cross-validation (GCV), as the paper's Dohrmann filter does, and a hand-written JAX version
would buy nothing for data read from files.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .._base import as_array


@dataclasses.dataclass(frozen=True)
class SmoothedPath:
    """A smoothing spline through samples ``x`` (N, m) at times ``t`` (N,) [s] (made by
    :func:`smooth_path`).

    **Fields:**

    - ``t``: (N,) sample times [s].
    - ``x``: (N, m) smoothed positions.
    - ``xdot``: (N, m) velocities [units/s].
    - ``speed``: (N,) the tangential speed ``|ẋ|``.
    - ``lam``: the smoothing parameter (None: chosen by GCV per component).
    - ``spline``: the fitted SciPy spline; ``path(t, nu)`` evaluates it (``nu``-th derivative).
    """

    t: np.ndarray
    x: np.ndarray
    xdot: np.ndarray
    speed: np.ndarray
    lam: float | None
    spline: object

    def __call__(self, t, nu: int = 0) -> np.ndarray:
        """Evaluate the spline (``nu``-th derivative) at times ``t``: (..., m)."""
        return self.spline(np.asarray(t, dtype=float), nu=nu)


def smooth_path(t, x, *, lam: float | None = None) -> SmoothedPath:
    """Smoothing spline of a sampled path (cubic, penalised second derivative; paper Section 2).

    **Arguments:**

    - ``t``: (N,) strictly increasing sample times [s], N ≥ 5.
    - ``x``: (N, m) positions.
    - ``lam``: the smoothing parameter for all components; ``None`` picks each component's by
      generalised cross-validation (:func:`gcv_lambda`).

    **Returns:**

    A :class:`SmoothedPath`.

    **Raises:**

    - ``ValueError`` naming the argument for wrong shapes, fewer than 5 samples, NaN/inf or times
      that do not increase.
    """
    t = np.asarray(as_array("t", t), dtype=float)
    if t.ndim != 1:
        raise ValueError(f"`t` must be 1-D; got shape {t.shape}")
    x = np.asarray(x, dtype=float)
    if x.ndim == 1:
        x = x[:, None]
    if x.ndim != 2 or x.shape[0] != t.shape[0]:
        raise ValueError(f"`x` must have shape (N, m) with N = len(t) = {t.shape[0]}; got {x.shape}")
    if t.shape[0] < 5:
        raise ValueError(f"`t` needs at least 5 samples to fit a smoothing spline; got {t.shape[0]}")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(x))):
        raise ValueError("`x` contains NaN or inf")
    if np.any(np.diff(t) <= 0):
        raise ValueError("`t` must be strictly increasing")
    from scipy.interpolate import make_smoothing_spline  # (imported here: 0.7 s at `import pmpjax`)

    if lam is None:  # GCV per component (SciPy's choice, as the paper's Dohrmann filter)
        spline = _ComponentSplines([make_smoothing_spline(t, x[:, j]) for j in range(x.shape[1])])
    else:
        spline = make_smoothing_spline(t, x, lam=float(lam), axis=0)
    xs = spline(t)
    xd = spline(t, nu=1)
    return SmoothedPath(t=t, x=xs, xdot=xd, speed=np.linalg.norm(xd, axis=-1), lam=lam, spline=spline)


def gcv_lambda(t, y, *, joint: bool = False, log10_bounds: tuple[float, float] = (-16.0, 4.0)) -> np.ndarray:
    """Smoothing parameter of a cubic smoothing spline chosen by generalised cross-validation.

    Minimises ``GCV(λ) = N |(I − A_λ) y|² / (N − tr A_λ)²`` for the spline that minimises
    ``Σ (y_i − f(t_i))² + λ ∫ f''²`` — the criterion and the λ of SciPy's
    ``make_smoothing_spline`` (whose own GCV search is pure Python and costs ≈ 4 ms per sample; pass
    the result as ``lam``). Here the influence matrix is diagonalised once (Demmler–Reinsch:
    ``A_λ = (I + λ K)⁻¹``, ``K = Q R⁻¹ Qᵀ`` of Green & Silverman 1994, §2.1), so every λ costs
    O(N); N³ work for the eigendecomposition, so use windows of up to ~10³ samples.

    **Arguments:**

    - ``t``: (N,) strictly increasing sample times, N ≥ 5.
    - ``y``: (N,) or (N, m) samples.
    - ``joint``: one λ for all components, minimising the sum of their GCV scores: right for a path
      whose components share one noise level, where a component that barely moves would otherwise
      ask for a much larger λ.
    - ``log10_bounds``: the search interval of ``log10 λ``.

    **Returns:**

    λ (m,), or a scalar for 1-D ``y`` or with ``joint=True``.

    **Raises:**

    - ``ValueError`` naming the argument for shapes that do not agree, fewer than 5 samples, times
      that do not increase or bounds that do not increase.
    """
    t = np.asarray(as_array("t", t), dtype=float)
    y = np.asarray(as_array("y", y), dtype=float)
    one = y.ndim == 1
    y = y[:, None] if one else y
    if t.ndim != 1 or y.ndim != 2 or y.shape[0] != t.shape[0]:
        raise ValueError(f"`t` (N,) and `y` (N,) or (N, m) must agree; got {t.shape} and {y.shape}")
    n = t.shape[0]
    if n < 5:
        raise ValueError(f"`t` needs at least 5 samples for GCV; got {n}")
    h = np.diff(t)
    if np.any(h <= 0):
        raise ValueError("`t` must be strictly increasing")
    lo, hi = log10_bounds
    if not lo < hi:
        raise ValueError(f"`log10_bounds` must be increasing, got {log10_bounds}")
    j = np.arange(n - 2)
    Q = np.zeros((n, n - 2))
    Q[j, j], Q[j + 1, j], Q[j + 2, j] = 1 / h[:-1], -1 / h[:-1] - 1 / h[1:], 1 / h[1:]
    R = np.diag((h[:-1] + h[1:]) / 3) + np.diag(h[1:-1] / 6, 1) + np.diag(h[1:-1] / 6, -1)
    Kmat = Q @ np.linalg.solve(R, Q.T)
    kappa, U = np.linalg.eigh(0.5 * (Kmat + Kmat.T))
    kappa = np.maximum(kappa, 0.0)
    z2 = (U.T @ y) ** 2  # (n, m)

    if joint:
        z2 = z2.sum(axis=1, keepdims=True)

    def gcv(log_lam):
        lk = 10.0 ** log_lam[:, None] * kappa[None, :]  # (G, n)
        shrink = lk / (1 + lk)
        rss = shrink**2 @ z2  # (G, m)
        dof = n - np.sum(1 / (1 + lk), axis=1)
        return n * rss / dof[:, None] ** 2

    grid = np.linspace(lo, hi, int(8 * (hi - lo)) + 1)
    best = grid[np.argmin(gcv(grid), axis=0)]  # (m,)
    out = np.empty(z2.shape[1])
    step = grid[1] - grid[0]
    for c in range(z2.shape[1]):  # golden-section refinement around the grid minimum
        a, b = best[c] - step, best[c] + step
        g = (np.sqrt(5) - 1) / 2
        for _ in range(40):
            x1, x2 = b - g * (b - a), a + g * (b - a)
            f1, f2 = gcv(np.array([x1, x2]))[:, c]
            a, b = (a, x2) if f1 < f2 else (x1, b)
        out[c] = 10.0 ** ((a + b) / 2)
    return out[0] if one or joint else out


class _ComponentSplines:
    def __init__(self, splines):
        self.splines = splines

    def __call__(self, t, nu: int = 0):
        return np.stack([s(t, nu=nu) for s in self.splines], axis=-1)


def segment_by_speed(speed, *, threshold: float = 0.2):
    """Movement onset and offset from a tangential speed profile (paper Section 2).

    The peak is the global maximum. Start = the first sample before the peak (searching back from
    it) whose speed is below ``threshold·peak``; end = the first sample after the peak below it.

    **Arguments:**

    - ``speed``: (N,) tangential speed, N ≥ 3.
    - ``threshold``: the level as a fraction of the peak, in (0, 1) (paper: 20 %).

    **Returns:**

    ``(start, end)`` sample indices, each ``None`` for a side where the speed never drops below the
    threshold (the movement was cut by the recording).

    **Raises:**

    - ``ValueError`` naming the argument for a wrong shape, NaN/inf or a threshold outside (0, 1).
    """
    speed = np.asarray(speed, dtype=float)
    if speed.ndim != 1 or speed.shape[0] < 3:
        raise ValueError(f"`speed` must be a 1-D array of at least 3 samples; got shape {speed.shape}")
    if not np.all(np.isfinite(speed)):
        raise ValueError("`speed` contains NaN or inf")
    if not 0.0 < threshold < 1.0:
        raise ValueError(f"`threshold` must lie in (0, 1); got {threshold}")
    peak = int(np.argmax(speed))
    level = threshold * speed[peak]
    below_before = np.nonzero(speed[:peak] < level)[0]
    below_after = np.nonzero(speed[peak + 1 :] < level)[0]
    start = int(below_before[-1]) if below_before.size else None
    end = int(peak + 1 + below_after[0]) if below_after.size else None
    return start, end
