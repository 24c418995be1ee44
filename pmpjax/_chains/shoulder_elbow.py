"""``ShoulderElbowArm``: the 4-DoF shoulder–elbow arm of the HuG-MP recordings
(also the 4-DoF chain of the IK paper's Experiment 1).

Shoulder-centred frame: x forward, y to the subject's left, z up; zero pose = arm hanging down,
elbow straight. ``p(q) = Rx(q1) Ry(q2) Rz(−q3) ([0, 0, −L1] + Ry(−q4) [0, 0, −L2])`` [m], angles
[rad]: q1 < 0 abduction, q2 < 0 forward flexion, q3 < 0 internal rotation, q4 > 0 elbow flexion.
This chain was inferred from the HuG-MP recordings (see ``pmpjax/data/hugmp/README.md``); it is
the best available reading, not a published formula.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from .._base import (
    add_const,
    as_array,
    check_positive,
    matmul_rows,
    mul_const,
    pytree_dataclass,
    rotation_rows,
    sincos,
    static_field,
)
from .kinematics import Chain


def _cross(a, b):
    """``a × b`` of 3-lists whose entries may be the Python floats 0.0 / 1.0 (skipped)."""
    def sub(u, v):
        return add_const(u, mul_const(-1.0, v)) if not isinstance(v, float) else add_const(u, -v)

    return [sub(mul_const(a[1], b[2]), mul_const(a[2], b[1])), sub(mul_const(a[2], b[0]), mul_const(a[0], b[2])),
            sub(mul_const(a[0], b[1]), mul_const(a[1], b[0]))]


@pytree_dataclass
class ShoulderElbowArm(Chain):
    """Shoulder (3 rotations) + elbow chain, hand position ``x`` (3,) [m] relative to the shoulder.

    The 4-DoF arm of the HuG-MP recordings.

    ``L1`` upper-arm and ``L2`` forearm-to-hand lengths [m] are array leaves (differentiable,
    vmappable). Analytic Jacobian: column i is ``a_i × (p − o_i)`` with the joint axes
    ``a1 = x̂``, ``a2 = Rx ŷ``, ``a3 = −Rx Ry ẑ``, ``a4 = −Rx Ry Rz ŷ`` and ``o_4`` the elbow.
    The Jacobian loses rank with the elbow straight (q4 = 0). Joint angles beyond ±π (180°, past
    the human range of every joint of the arm) run with a warning, beyond ±2π they are refused
    (``angle_limit``, ``angle_error``: degrees typed as radians).

    **Fields:** ``L1``, ``L2`` [m]; ``n`` = 4 joints and ``m`` = 3 task dimensions (fixed).
    """

    angle_limit = float(np.pi)

    #: Plot labels of q1..q4 with the sign of each movement (class attribute, not a field).
    joint_names = ("q1 shoulder abd.(−)/add.(+)", "q2 shoulder flex.(−)/ext.(+)",
                   "q3 shoulder int.(−)/ext.(+) rot.", "q4 elbow flexion (+)")

    L1: jax.Array = 0.30
    L2: jax.Array = 0.33
    n: int = static_field(default=4)
    m: int = static_field(default=3)

    def __post_init__(self):
        for name in ("L1", "L2"):
            v = as_array(name, getattr(self, name))
            check_positive(name, v)
            object.__setattr__(self, name, jnp.asarray(v, dtype=float))

    def fk_jac_soa(self, qc):
        s, c = sincos(qc)
        R1 = rotation_rows(0, sin_cos=(s[0], c[0]))
        R12 = matmul_rows(R1, rotation_rows(1, sin_cos=(s[1], c[1])))
        R123 = matmul_rows(R12, rotation_rows(2, sin_cos=(-s[2], c[2])))
        R1234 = matmul_rows(R123, rotation_rows(1, sin_cos=(-s[3], c[3])))
        L1, L2 = self.L1, self.L2
        elbow = [-L1 * R123[i][2] for i in range(3)]
        p = [elbow[i] - L2 * R1234[i][2] for i in range(3)]
        a1 = [1.0, 0.0, 0.0]
        a2 = [R1[i][1] for i in range(3)]
        a3 = [-R12[i][2] for i in range(3)]
        a4 = [-R123[i][1] for i in range(3)]
        fore = [p[i] - elbow[i] for i in range(3)]
        cols = [_cross(a1, p), _cross(a2, p), _cross(a3, p), _cross(a4, fore)]
        full = lambda v: jnp.zeros_like(qc[0]) + v if isinstance(v, float) else v  # noqa: E731
        J = jnp.stack([jnp.stack([full(cols[j][i]) for j in range(4)]) for i in range(3)])
        return jnp.stack([full(v) for v in p]), J

    def reachable(self, x):
        r = np.linalg.norm(np.asarray(x, dtype=float), axis=-1)
        L1, L2 = float(self.L1), float(self.L2)
        return (r <= 0.999 * (L1 + L2)) & (r >= abs(L1 - L2) + 1e-3 * (L1 + L2))

    def workspace_description(self):
        L1, L2 = float(self.L1), float(self.L2)
        return f"shell {abs(L1 - L2):.3g} m < |x| < {L1 + L2:.3g} m"

