"""Wrist orientations: rotation matrices (Eq 6), quaternions, rotation vectors, and back to joints.

Conventions (all functions take leading batch axes and are differentiable):

- Quaternions are **scalar-first** ``(w, x, y, z)``, unit norm, sign chosen with ``w >= 0``
  (SciPy's ``Rotation.as_quat`` is scalar-last: reorder with ``quat[..., [3, 0, 1, 2]]``).
- Rotation vectors are axis·angle ``r = θ n`` [rad], ``θ ∈ [0, π]``, ``R = exp(r̂)``
  (``convention="rodrigues"`` gives Haslwanter's ``tan(θ/2) n`` instead).
- ``R`` maps hand-frame to world-frame coordinates; the hand points along ``R e_x``.
- Joint angles ``q = (q_PS, q_FE, q_RUD)`` with ``R(q) = Rx(−q_PS) Rz(q_FE) Ry(q_RUD)`` (Eq 6).
  The inverse picks the branch ``|q_FE| < π/2`` (``cos q_FE > 0``) with ``q_PS, q_RUD ∈ (−π, π]``;
  every orientation with ``R[0, 1] ≠ ±1`` has exactly one such triple. The other branch
  ``(q_PS + π, π − q_FE, q_RUD + π)`` gives the same ``R`` and is never returned.

Inputs are checked before tracing (``ValueError`` naming the argument for a wrong trailing shape,
or NaN/inf when concrete; a zero quaternion is rejected); each function then makes one jitted call,
on rows padded to 64 or in chunks of 1024 when eager (``eager_rows``: two compilations for every
batch shape, not one per ``jnp`` op and shape).
"""

from __future__ import annotations

from functools import partial

import jax.numpy as jnp
import numpy as np

from .._base import as_array, eager_rows, fast_compile_jit, is_concrete, to_jax
from .._chains import Wrist

_WRIST = Wrist()


def _arr(name, x, tail):
    return to_jax(as_array(name, x, tail=tail))


def _quat(name, quat):
    quat = _arr(name, quat, (4,))
    if is_concrete(quat) and np.any(np.linalg.norm(np.asarray(quat), axis=-1) == 0):
        raise ValueError(f"`{name}` contains a zero quaternion (no rotation)")
    return quat


def _convention(convention):
    if convention not in ("axis_angle", "rodrigues"):
        raise ValueError(f"`convention` must be 'axis_angle' or 'rodrigues', got {convention!r}")


def wrist_rotation(q):
    """Hand orientation ``R(q)`` of wrist joint angles (Eq 6).

    ``R(q) = exp(−ê_x q_PS) exp(ê_z q_FE) exp(ê_y q_RUD)``: rotations about x, z and y, in that order.

    **Arguments:**

    - ``q``: (..., 3) joint angles ``(q_PS, q_FE, q_RUD)`` [rad].

    **Returns:**

    (..., 3, 3) rotation matrices.

    **Raises:**

    - ``ValueError`` naming the argument for a wrong trailing shape or NaN/inf.
    """
    return eager_rows(_rotation, _arr("q", q, (3,)), 1)


@fast_compile_jit
def _rotation(q):
    return _WRIST.rotation(q)


def _hat(r):
    z = jnp.zeros_like(r[..., 0])
    x, y, w = r[..., 0], r[..., 1], r[..., 2]
    return jnp.stack([jnp.stack([z, -w, y], -1), jnp.stack([w, z, -x], -1), jnp.stack([-y, x, z], -1)], -2)


def quat_from_matrix(R):
    """Unit quaternions of rotation matrices.

    Shepperd's method: the largest of ``(w², x², y², z²)`` is computed from the diagonal and the
    others from off-diagonal sums, so the result is accurate for every rotation.

    **Arguments:**

    - ``R``: (..., 3, 3) rotation matrices.

    **Returns:**

    (..., 4) unit quaternions ``(w, x, y, z)``, scalar first, with ``w >= 0``.

    **Raises:**

    - ``ValueError`` naming the argument for a wrong trailing shape or NaN/inf.
    """
    return eager_rows(_quat_from_matrix, _arr("R", R, (3, 3)), 2)


@fast_compile_jit
def _quat_from_matrix(R):
    m00, m11, m22 = R[..., 0, 0], R[..., 1, 1], R[..., 2, 2]
    tr = m00 + m11 + m22
    d = jnp.stack([tr, m00 - m11 - m22, -m00 + m11 - m22, -m00 - m11 + m22], -1)
    k = jnp.argmax(d, axis=-1)
    s21, s12 = R[..., 2, 1], R[..., 1, 2]
    s02, s20 = R[..., 0, 2], R[..., 2, 0]
    s10, s01 = R[..., 1, 0], R[..., 0, 1]
    # 4·(largest component) times each component, for each choice of the largest.
    cands = jnp.stack(
        [
            jnp.stack([1 + tr, s21 - s12, s02 - s20, s10 - s01], -1),
            jnp.stack([s21 - s12, 1 + m00 - m11 - m22, s01 + s10, s02 + s20], -1),
            jnp.stack([s02 - s20, s01 + s10, 1 - m00 + m11 - m22, s12 + s21], -1),
            jnp.stack([s10 - s01, s02 + s20, s12 + s21, 1 - m00 - m11 + m22], -1),
        ],
        -2,
    )
    v = jnp.take_along_axis(cands, k[..., None, None], axis=-2)[..., 0, :]
    v = v / jnp.linalg.norm(v, axis=-1, keepdims=True)
    return jnp.where(v[..., :1] < 0, -v, v)


def matrix_from_quat(quat):
    """Rotation matrices of quaternions.

    **Arguments:**

    - ``quat``: (..., 4) quaternions ``(w, x, y, z)``, scalar first (normalised first).

    **Returns:**

    (..., 3, 3) rotation matrices.

    **Raises:**

    - ``ValueError`` naming ``quat`` for a wrong trailing shape, NaN/inf or a zero quaternion.
    """
    return eager_rows(_matrix_from_quat, _quat("quat", quat), 1)


@fast_compile_jit
def _matrix_from_quat(quat):
    quat = quat / jnp.linalg.norm(quat, axis=-1, keepdims=True)
    w, x, y, z = (quat[..., i] for i in range(4))
    return jnp.stack(
        [
            jnp.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            jnp.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            jnp.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def rotvec_from_quat(quat, *, convention: str = "axis_angle"):
    """Rotation vectors of quaternions.

    **Arguments:**

    - ``quat``: (..., 4) quaternions ``(w, x, y, z)``, scalar first.
    - ``convention``: ``"axis_angle"`` (``θ n``, θ in rad) or ``"rodrigues"`` (``tan(θ/2) n``).

    **Returns:**

    (..., 3) rotation vectors.

    **Raises:**

    - ``ValueError`` naming the argument for a wrong trailing shape, NaN/inf, a zero quaternion or an
      unknown ``convention``.
    """
    _convention(convention)
    return eager_rows(lambda q: _rotvec_from_quat(q, convention), _quat("quat", quat), 1)


@partial(fast_compile_jit, static_argnums=1)
def _rotvec_from_quat(quat, convention):
    quat = quat / jnp.linalg.norm(quat, axis=-1, keepdims=True)
    quat = jnp.where(quat[..., :1] < 0, -quat, quat)
    w, v = quat[..., 0], quat[..., 1:]
    if convention == "rodrigues":
        return v / w[..., None]
    s2 = jnp.sum(v * v, axis=-1)
    small = s2 < 1e-12
    s = jnp.sqrt(jnp.where(small, 1.0, s2))
    # r = θ v / |v| with θ = 2 atan2(|v|, w); series 2/w − 2|v|²/(3w³) near 0 keeps it smooth.
    factor = jnp.where(small, 2.0 / w - 2.0 * s2 / (3.0 * w**3), 2.0 * jnp.arctan2(s, w) / s)
    return factor[..., None] * v


def quat_from_rotvec(r):
    """Quaternions of axis·angle rotation vectors.

    **Arguments:**

    - ``r``: (..., 3) rotation vectors ``θ n`` [rad].

    **Returns:**

    (..., 4) unit quaternions ``(w, x, y, z)``, scalar first.

    **Raises:**

    - ``ValueError`` naming the argument for a wrong trailing shape or NaN/inf.
    """
    return eager_rows(_quat_from_rotvec, _arr("r", r, (3,)), 1)


@fast_compile_jit
def _quat_from_rotvec(r):
    t2 = jnp.sum(r * r, axis=-1)
    small = t2 < 1e-8
    t = jnp.sqrt(jnp.where(small, 1.0, t2))
    half_sinc = jnp.where(small, 0.5 - t2 / 48.0, jnp.sin(0.5 * t) / t)
    w = jnp.where(small, 1.0 - t2 / 8.0, jnp.cos(0.5 * t))
    q = jnp.concatenate([w[..., None], half_sinc[..., None] * r], -1)
    return jnp.where(q[..., :1] < 0, -q, q)


def rotvec_from_matrix(R, *, convention: str = "axis_angle"):
    """Rotation vectors of rotation matrices (as :func:`rotvec_from_quat`).

    **Arguments:**

    - ``R``: (..., 3, 3) rotation matrices.
    - ``convention``: ``"axis_angle"`` (``θ n``, θ in rad) or ``"rodrigues"`` (``tan(θ/2) n``).

    **Returns:**

    (..., 3) rotation vectors.

    **Raises:**

    - ``ValueError`` naming the argument for a wrong trailing shape, NaN/inf or an unknown
      ``convention``.
    """
    _convention(convention)
    return rotvec_from_quat(quat_from_matrix(R), convention=convention)


def matrix_from_rotvec(r):
    """Rotation matrices ``exp(r̂)`` of rotation vectors.

    **Arguments:**

    - ``r``: (..., 3) rotation vectors ``θ n`` [rad].

    **Returns:**

    (..., 3, 3) rotation matrices.

    **Raises:**

    - ``ValueError`` naming the argument for a wrong trailing shape or NaN/inf.
    """
    return matrix_from_quat(quat_from_rotvec(_arr("r", r, (3,))))


def joint_angles_from_matrix(R):
    """Wrist joint angles with ``R(q) = R`` (the inverse of Eq 6).

    From ``R = Rx(−a) Rz(b) Ry(c)``: ``R[0,1] = −sin b``, ``(R[0,0], R[0,2]) = cos b (cos c, sin c)``,
    ``(R[1,1], R[2,1]) = cos b (cos a, −sin a)``. Branch ``|q_FE| < π/2``; undefined at gimbal lock
    ``|q_FE| = π/2`` (the wrist points along the screen, outside every reachable target).

    **Arguments:**

    - ``R``: (..., 3, 3) rotation matrices (hand to world).

    **Returns:**

    (..., 3) joint angles ``(q_PS, q_FE, q_RUD)`` [rad].

    **Raises:**

    - ``ValueError`` naming the argument for a wrong trailing shape or NaN/inf.
    """
    return eager_rows(_joint_angles_from_matrix, _arr("R", R, (3, 3)), 2)


@fast_compile_jit
def _joint_angles_from_matrix(R):
    b = jnp.arctan2(-R[..., 0, 1], jnp.hypot(R[..., 0, 0], R[..., 0, 2]))
    c = jnp.arctan2(R[..., 0, 2], R[..., 0, 0])
    a = jnp.arctan2(-R[..., 2, 1], R[..., 1, 1])
    return jnp.stack([a, b, c], -1)


def joint_angles_from_quat(quat):
    """Wrist joint angles of quaternions (the inverse of Eq 6).

    **Arguments:**

    - ``quat``: (..., 4) hand-to-world quaternions ``(w, x, y, z)``, scalar first.

    **Returns:**

    (..., 3) joint angles ``(q_PS, q_FE, q_RUD)`` [rad].

    **Raises:**

    - ``ValueError`` naming ``quat`` for a wrong trailing shape, NaN/inf or a zero quaternion.
    """
    return joint_angles_from_matrix(matrix_from_quat(_quat("quat", quat)))


def quat_from_joint_angles(q):
    """Quaternions of wrist joint angles (Eq 6).

    **Arguments:**

    - ``q``: (..., 3) joint angles ``(q_PS, q_FE, q_RUD)`` [rad].

    **Returns:**

    (..., 4) unit quaternions ``(w, x, y, z)``, scalar first.

    **Raises:**

    - ``ValueError`` naming the argument for a wrong trailing shape or NaN/inf.
    """
    return quat_from_matrix(wrist_rotation(_arr("q", q, (3,))))


def rotvec_from_joint_angles(q, *, convention: str = "axis_angle"):
    """Rotation vectors of wrist postures (the coordinates of Donders surfaces).

    **Arguments:**

    - ``q``: (..., 3) joint angles ``(q_PS, q_FE, q_RUD)`` [rad].
    - ``convention``: ``"axis_angle"`` (``θ n``, θ in rad) or ``"rodrigues"`` (``tan(θ/2) n``).

    **Returns:**

    (..., 3) rotation vectors ``r``.

    **Raises:**

    - ``ValueError`` naming the argument for a wrong trailing shape, NaN/inf or an unknown
      ``convention``.
    """
    _convention(convention)
    return rotvec_from_matrix(wrist_rotation(_arr("q", q, (3,))), convention=convention)


def torsion_between(R_ref, R):
    """Signed torsion of ``R`` relative to ``R_ref`` about the hand's pointing axis ``e_x``.

    For two postures pointing the same way, ``R_refᵀ R`` is a pure rotation about ``e_x`` and this
    is exactly its angle; otherwise it is the torsional component ``atan2(M21 − M12, M11 + M22)`` of
    ``M = R_refᵀ R``.

    **Arguments:**

    - ``R_ref``: (..., 3, 3) reference orientations.
    - ``R``: (..., 3, 3) orientations (leading axes broadcast with ``R_ref``'s).

    **Returns:**

    (...,) angles [rad].

    **Raises:**

    - ``ValueError`` naming the argument for a wrong trailing shape or NaN/inf.
    """
    return _torsion_between(_arr("R_ref", R_ref, (3, 3)), _arr("R", R, (3, 3)))


@fast_compile_jit
def _torsion_between(R_ref, R):
    M = jnp.swapaxes(R_ref, -1, -2) @ R
    return jnp.arctan2(M[..., 2, 1] - M[..., 1, 2], M[..., 1, 1] + M[..., 2, 2])
