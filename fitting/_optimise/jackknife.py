"""Standard errors robust to errors shared within a movement: the delete-one-group jackknife."""

from __future__ import annotations

import numpy as np


def group_jackknife_covariance(jac, residual, groups, n_params: int, *, nuisance_groups=None,
                               rcond: float = 1e-12) -> np.ndarray:
    """Delete-one-group jackknife covariance of a least-squares fit's shared parameters, one
    Gauss–Newton step from the optimum per deleted group (NumPy, on the host).

    Samples of one movement share errors (the noise of its start posture and target, misfit), so
    ``σ² (JᵀJ)⁻¹``, which takes every row as independent, is too small; the jackknife over
    movements is not. For each group ``g``: its rows' Jacobian of the shared parameters ``G_g``,
    projected off the group's own nuisance columns (profiled), the Gauss–Newton step of the problem
    without the group ``Δ_g = −(A − A_g)⁺ (Σ_h G_hᵀ r_h − G_gᵀ r_g)`` with ``A = Σ_g G_gᵀG_g`` (the rows
    in no group, e.g. bounds, included in both sums); then ``(n−1)/n Σ_g (Δ_g − Δ̄)(Δ_g − Δ̄)ᵀ`` over
    the n groups. Non-finite entries count as 0.

    **Arguments:**

    - ``jac`` (N, P), ``residual`` (N,): at the optimum; the first ``n_params`` columns are the
      shared parameters.
    - ``groups`` (N,) int: each row's group (a movement), −1 for rows in none (bounds, padding).
    - ``nuisance_groups`` (P − n_params,) int: the group that owns each remaining column (−1: none);
      ``None`` when there are none.
    - ``rcond``: eigenvalues of ``A − A_g`` below ``rcond`` times the largest are left out (the
      directions the data do not determine get zero variance).

    **Returns:**

    ``cov`` (n_params, n_params); NaN with fewer than two groups.
    """
    J = np.where(np.isfinite(jac), jac, 0.0)
    r = np.where(np.isfinite(residual), residual, 0.0)
    groups = np.asarray(groups)
    p = int(n_params)
    ids = np.unique(groups[groups >= 0])
    if ids.size < 2:
        return np.full((p, p), np.nan)
    rest = groups < 0
    A = J[rest, :p].T @ J[rest, :p]
    blocks, scores = [], []
    for g in ids:
        rows = groups == g
        G = J[rows, :p]
        if nuisance_groups is not None:
            own = p + np.flatnonzero(np.asarray(nuisance_groups) == g)
            if own.size:
                C = J[rows][:, own]
                G = G - C @ np.linalg.lstsq(C, G, rcond=1e-10)[0]
        Ag = G.T @ G
        A = A + Ag
        blocks.append(Ag)
        scores.append(G.T @ r[rows])
    total = J[rest, :p].T @ r[rest] + np.sum(scores, axis=0)  # (≈ 0 at the optimum)
    D = np.stack([np.linalg.pinv(A - Ag, rcond=rcond, hermitian=True) @ (s - total) for Ag, s in zip(blocks, scores)])
    E = D - D.mean(0)
    n = ids.size
    return (n - 1) / n * E.T @ E
