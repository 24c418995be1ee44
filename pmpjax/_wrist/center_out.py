"""Center-out protocol (design §3.2): 9 named targets and seeded pseudo-random trial orders.

**Target radius.** The paper places the 8 peripheral targets "on a circle with a radius of 15°"
and normalises curvature areas by the "nominal target-to-target distance" ``(π/12)² m²``: it
equates the 15° visual angle with the arc length ``π/12 = 0.2618 m`` at ``d = 1 m``. Through
Eq 6, however, a hand direction 15° from the screen normal lands at ``d·sin 15° = 0.2588 m``
(1.1 % closer). The default here is the paper's nominal ``TARGET_RADIUS = π/12`` m (so
Figure 3 and the normalisation of ``A_sum``/``A_net`` are the paper's); pass ``radius`` [m] to
choose another, or ``angle_deg`` (with the screen distance ``d``) for targets at a true visual
angle, ``radius = d·sin(angle)``.
"""

from __future__ import annotations

import numpy as np

from .._base import check_positive_int

#: Peripheral target names in compass order; E = +x1 (right), N = +x2 (up).
DIRECTIONS = ("N", "NE", "E", "SE", "S", "SW", "W", "NW")
_ANGLE = {name: np.deg2rad(90.0 - 45.0 * i) for i, name in enumerate(DIRECTIONS)}

#: The paper's nominal target distance [m] (15° as arc length at d = 1 m); see module docstring.
TARGET_RADIUS = float(np.pi / 12)


def target_radius(radius: float | None = None, *, angle_deg: float | None = None, d: float = 1.0) -> float:
    """The distance of the center-out targets from the centre.

    **Arguments:**

    - ``radius``: the distance [m], if given.
    - ``angle_deg``: else a true visual angle [deg] in (0, 80] at screen distance ``d``: ``r = d sin angle``.
    - ``d``: screen distance [m].

    **Returns:**

    The radius [m]: ``radius``, ``d·sin(angle_deg)``, or :data:`TARGET_RADIUS` (π/12, the paper's
    nominal distance) when neither is given.

    **Raises:**

    - ``ValueError`` naming the argument for both given, non-positive values or an angle outside
      (0°, 80°].
    """
    if radius is not None and angle_deg is not None:
        raise ValueError("give at most one of `radius` [m] and `angle_deg` [deg]")
    if not (np.isfinite(d) and d > 0):
        raise ValueError(f"`d` must be a positive screen distance [m], got {d}")
    if angle_deg is not None:
        if not (np.isfinite(angle_deg) and 0.0 < angle_deg <= 80.0):
            raise ValueError(f"`angle_deg` must lie in (0, 80] degrees, got {angle_deg}")
        return float(d * np.sin(np.deg2rad(angle_deg)))
    if radius is None:
        return TARGET_RADIUS
    if not (np.isfinite(radius) and radius > 0):
        raise ValueError(f"`radius` must be positive, got {radius}")
    return float(radius)


def center_out_targets(radius: float | None = None, *, angle_deg: float | None = None,
                       d: float = 1.0) -> dict[str, np.ndarray]:
    """The nine targets of the center-out task: the centre and eight on a circle.

    **Arguments:**

    - ``radius``, ``angle_deg``, ``d``: the circle's radius as in :func:`target_radius` (default π/12 m).

    **Returns:**

    ``{"C": (0, 0), "N": (0, r), "NE": ..., ...}``: (2,) screen positions [m] by name (``E`` = +x1,
    ``N`` = +x2).

    **Raises:**

    - ``ValueError`` as :func:`target_radius`.
    """
    r = target_radius(radius, angle_deg=angle_deg, d=d)
    out = {"C": np.zeros(2)}
    for name in DIRECTIONS:
        a = _ANGLE[name]
        out[name] = r * np.array([np.cos(a), np.sin(a)])
    return out


def center_out_trials(n_trials: int, *, seed: int = 0, radius: float | None = None,
                      angle_deg: float | None = None, d: float = 1.0):
    """Seeded trial orders of the center-out task.

    Each trial visits the 8 peripheral targets once in a random order, each outbound movement
    followed by the inbound one.

    **Arguments:**

    - ``n_trials``: number of trials.
    - ``seed``: seed of the random orders.
    - ``radius``, ``angle_deg``, ``d``: the targets' radius as in :func:`target_radius`.

    **Returns:**

    ``(order, targets)``: ``order`` (n_trials, 8) direction names; ``targets`` (n_trials, 16, 2) the
    movement end points ``[P1, C, P2, C, ...]`` [m].

    **Raises:**

    - ``ValueError`` naming the argument for a non-positive ``n_trials`` or as :func:`target_radius`.
    """
    check_positive_int("n_trials", n_trials)
    rng = np.random.default_rng(seed)
    tg = center_out_targets(radius, angle_deg=angle_deg, d=d)
    order = np.array([[DIRECTIONS[i] for i in rng.permutation(8)] for _ in range(int(n_trials))])
    seq = np.stack([np.stack([tg[name] if k == 0 else tg["C"] for name in row for k in (0, 1)])
                    for row in order])
    return order, seq
