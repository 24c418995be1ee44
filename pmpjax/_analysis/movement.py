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
from scipy.interpolate import make_smoothing_spline

from .._base.validate import as_array


@dataclasses.dataclass(frozen=True)
class SmoothedPath:
    """A smoothing spline through samples ``x`` (N, m) at times ``t`` (N,) [s].

    ``x`` (N, m) smoothed positions, ``xdot`` (N, m) velocities [units/s], ``speed`` (N,) the
    tangential speed ``|ẋ|``; ``lam`` the smoothing parameter (None: chosen by GCV per component).
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
    """Smoothing spline of a sampled path (cubic, penalised second derivative).

    ``t`` (N,) strictly increasing [s]; ``x`` (N, m). ``lam=None`` picks the smoothing of each
    component by generalised cross-validation; a given ``lam`` is used for all components.
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
    if lam is None:  # GCV per component (SciPy's choice, as the paper's Dohrmann filter)
        spline = _ComponentSplines([make_smoothing_spline(t, x[:, j]) for j in range(x.shape[1])])
    else:
        spline = make_smoothing_spline(t, x, lam=float(lam), axis=0)
    xs = spline(t)
    xd = spline(t, nu=1)
    return SmoothedPath(t=t, x=xs, xdot=xd, speed=np.linalg.norm(xd, axis=-1), lam=lam, spline=spline)


class _ComponentSplines:
    def __init__(self, splines):
        self.splines = splines

    def __call__(self, t, nu: int = 0):
        return np.stack([s(t, nu=nu) for s in self.splines], axis=-1)


def segment_by_speed(speed, *, threshold: float = 0.2):
    """Movement onset and offset from a tangential speed profile (paper Section 2).

    ``speed`` (N,); the peak is the global maximum. Start = the first sample before the peak
    (searching back from it) whose speed is below ``threshold·peak``; end = the first sample after
    the peak below it. Returns ``(start, end)`` sample indices, or ``None`` for a side where the
    speed never drops below the threshold (the movement was cut by the recording).
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


def normalised_samples(t0: float, t1: float, n: int) -> np.ndarray:
    """``n`` equally spaced times from ``t0`` to ``t1`` inclusive (normalised time 0..1)."""
    if not t1 > t0:
        raise ValueError(f"the segment must have positive duration; got t0={t0}, t1={t1}")
    return np.linspace(t0, t1, n)
