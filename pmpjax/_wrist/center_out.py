"""Center-out protocol (design §3.2): 9 named targets and seeded pseudo-random trial orders."""

from __future__ import annotations

import numpy as np

from .._base.validate import check_positive_int

#: Peripheral target names in compass order; E = +x1 (right), N = +x2 (up).
DIRECTIONS = ("N", "NE", "E", "SE", "S", "SW", "W", "NW")
_ANGLE = {name: np.deg2rad(90.0 - 45.0 * i) for i, name in enumerate(DIRECTIONS)}


def center_out_targets(radius: float = np.pi / 12) -> dict[str, np.ndarray]:
    """``{"C": (0, 0), "N": (0, r), "NE": ..., ...}`` screen positions (2,) [m at d = 1]."""
    if not np.isfinite(radius) or radius <= 0:
        raise ValueError(f"`radius` must be positive, got {radius}")
    out = {"C": np.zeros(2)}
    for name in DIRECTIONS:
        a = _ANGLE[name]
        out[name] = radius * np.array([np.cos(a), np.sin(a)])
    return out


def center_out_trials(n_trials: int, *, seed: int = 0, radius: float = np.pi / 12):
    """Seeded trial orders: each trial visits the 8 peripheral targets once in a random order,
    each outbound movement followed by the inbound one.

    Returns ``(order, targets)``: ``order`` (n_trials, 8) direction names, ``targets``
    (n_trials, 16, 2) the movement end points ``[P1, C, P2, C, ...]``.
    """
    check_positive_int("n_trials", n_trials)
    rng = np.random.default_rng(seed)
    tg = center_out_targets(radius)
    order = np.array([[DIRECTIONS[i] for i in rng.permutation(8)] for _ in range(int(n_trials))])
    seq = np.stack([np.stack([tg[name] if k == 0 else tg["C"] for name in row for k in (0, 1)])
                    for row in order])
    return order, seq
