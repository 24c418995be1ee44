"""Shared test problems (typed from the papers, not from pmpjax), used across the test files.

- Figure 3 of Tommasino & Campolo (2017): ``KJ = diag(0.5, 1.5, 2)`` Nm/rad, ``W = 0.08 KJ``,
  ``q_rest = (5°, 0, 0)``, Arimoto ``k = 22.5``, ``τ = τ0 = 0.08 s``, 0.4 s movements to the
  π/12 circle.
- Tables 1–2 (six subjects' ``KJ`` as printed and ``q_rest``).
- A 3-link planar arm (design §3.1's example chain) with a coupled stiffness.
"""

import numpy as np

# Figure 3 (Eq 9)
FIG3_KJ = np.diag([0.5, 1.5, 2.0])
FIG3_Q_REST = np.deg2rad([5.0, 0.0, 0.0])
FIG3_TAU0 = 0.08
FIG3_TAU = 0.08
FIG3_K = 22.5
FIG3_T = 0.4
RADIUS = np.pi / 12

# Tables 1–2 as printed: K11 K12 K13 K22 K23 K33 [Nm/rad], q_rest (PS, FE, RUD) [rad]
TABLE1 = np.array(
    [
        [1.22, 0.07, 0.08, 1.68, 0.03, 1.09],
        [1.20, 0.04, -0.12, 1.47, 0.26, 1.33],
        [1.25, -0.08, 0.00, 1.63, 0.11, 1.12],
        [1.21, 0.10, -0.15, 1.24, 0.29, 1.54],
        [1.26, 0.00, -0.08, 1.21, 0.16, 1.52],
        [1.30, -0.01, -0.04, 1.42, -0.05, 1.27],
    ]
)
TABLE2 = np.array(
    [
        [0.26, 0.51, 0.06, 0.36, 0.35, 0.23],
        [-0.08, 0.11, 0.04, 0.25, 0.12, 0.03],
        [0.13, -0.11, -0.19, -0.09, -0.07, -0.04],
    ]
).T


def table_kj(i, *, normalize=False):
    k11, k12, k13, k22, k23, k33 = TABLE1[i]
    K = np.array([[k11, k12, k13], [k12, k22, k23], [k13, k23, k33]])
    return K * (4.0 / np.trace(K)) if normalize else K


KJ_S1, QREST_S1 = table_kj(0), TABLE2[0]
KJ_S2, QREST_S2 = table_kj(1), TABLE2[1]

# 3-link planar arm
PLANAR_L = np.array([0.3, 0.25, 0.15])
PLANAR_KJ = np.array([[2.0, 0.3, 0.0], [0.3, 1.0, 0.1], [0.0, 0.1, 0.5]])
PLANAR_Q_REST = np.array([0.3, 0.8, 0.4])
PLANAR_TARGETS = np.array([[0.35, 0.3], [0.1, 0.45]])
