"""Site kinematics of a MuJoCo hinge/slide tree as straight-line code on component-leading arrays.

``mjx.kinematics`` (and :func:`pmpjax._chains.mjcf.kinematics`) compute every body's frame as
stacked 3×3 matrices; inside the λ0-PMP's integrator that is a chain of tiny GEMMs per step. Here
the bodies between the world and one site are unrolled at trace time with the model's constants
as Python floats, so products with structural zeros and ones disappear from the graph (a hinge
about a coordinate axis leaves 4 of 9 entries moving) and XLA fuses the rest into the
integrator's loop, as for the closed-form chains.

The algorithm is ``mj_kinematics`` restricted to that path: for each body, ``pos = pos_parent +
R_parent body_pos``, ``R = R_parent R(body_quat)``; for each of its joints (in model order) the
anchor ``p_j = R jnt_pos + pos`` and axis ``a_j = R jnt_axis``; a slide moves ``pos += a_j (q −
qpos0)``, a hinge turns ``R ← R R(jnt_axis, q − qpos0)`` about its anchor, ``pos = p_j − R
jnt_pos``. The site sits at ``pos + R site_pos``; the Jacobian's column j is ``a_j × (x − p_j)``
for a hinge on the path, ``a_j`` for a slide, 0 for a joint elsewhere (``mj_jacSite``).
"""

from __future__ import annotations

import numpy as np

from .._base import add_const, matmul_rows, mul_const, sincos

_SLIDE, _HINGE = 2, 3
_TINY = 1e-14  # constants smaller than this are structural zeros


def _c(v) -> float:
    v = float(v)
    return 0.0 if abs(v) < _TINY else (1.0 if abs(v - 1.0) < _TINY else v)


def _add(*terms):
    out = 0.0
    for t in terms:
        out = add_const(out, t)
    return out


def _sub(a, b):
    return _add(a, -b)


def _matvec(A, v):
    return [_add(*(mul_const(A[i][k], v[k]) for k in range(3))) for i in range(3)]


def _cross(a, b):
    return [_sub(mul_const(a[1], b[2]), mul_const(a[2], b[1])), _sub(mul_const(a[2], b[0]), mul_const(a[0], b[2])),
            _sub(mul_const(a[0], b[1]), mul_const(a[1], b[0]))]


def _quat_mat(u) -> list:
    w, x, y, z = (float(a) for a in np.asarray(u) / np.linalg.norm(u))
    R = [[w * w + x * x - y * y - z * z, 2 * (x * y - w * z), 2 * (x * z + w * y)],
         [2 * (x * y + w * z), w * w - x * x + y * y - z * z, 2 * (y * z - w * x)],
         [2 * (x * z - w * y), 2 * (y * z + w * x), w * w - x * x - y * y + z * z]]
    return [[_c(v) for v in row] for row in R]


def _axis_angle(a, s, c):
    """Rodrigues ``c I + s [a]× + (1 − c) a aᵀ`` for a constant unit axis ``a``."""
    K = [[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]]
    out = []
    for i in range(3):
        row = []
        for j in range(3):
            aa = _c(a[i] * a[j])
            diag = 1.0 if i == j else 0.0
            cos_coef = _c(diag - aa)
            row.append(_add(mul_const(cos_coef, c), mul_const(_c(K[i][j]), s), aa))
        out.append(row)
    return out


def site_path(m, site_id: int) -> tuple:
    """The constants of the bodies between the world and ``site_id``'s body of ``MjModel`` ``m``:
    a hashable tuple ``(bodies, site_pos)``, each body ``(pos, quat, joints)`` and each joint
    ``(type, axis, pos, qposadr, qpos0)``."""
    path, b = [], int(m.site_bodyid[site_id])
    while b > 0:
        path.append(b)
        b = int(m.body_parentid[b])
    bodies = []
    for b in reversed(path):
        joints = tuple(
            (int(m.jnt_type[j]), tuple(map(float, m.jnt_axis[j])), tuple(map(float, m.jnt_pos[j])),
             int(m.jnt_qposadr[j]), float(m.qpos0[m.jnt_qposadr[j]]))
            for j in range(int(m.body_jntadr[b]), int(m.body_jntadr[b]) + int(m.body_jntnum[b])))
        bodies.append((tuple(map(float, m.body_pos[b])), tuple(map(float, m.body_quat[b])), joints))
    return tuple(bodies), tuple(map(float, m.site_pos[site_id]))


def site_fk_jac_soa(path: tuple, n: int, qc):
    """Site position ``x`` (3, ...) and Jacobian ``J`` (3, n, ...) at joint positions ``qc``
    (n, ...), component-leading (the chain's ``fk_jac_soa``), from :func:`site_path`'s constants."""
    import jax.numpy as jnp

    bodies, site_pos = path
    batch = qc.shape[1:]
    pos = [0.0, 0.0, 0.0]
    R = [[1.0 if i == j else 0.0 for j in range(3)] for i in range(3)]
    cols: dict[int, tuple] = {}
    for body_pos, body_quat, joints in bodies:
        pos = [_add(pos[i], v) for i, v in enumerate(_matvec(R, [_c(v) for v in body_pos]))]
        R = matmul_rows(R, _quat_mat(body_quat))
        for jtype, axis, jpos, adr, qpos0 in joints:
            jpos = [_c(v) for v in jpos]
            anchor = [_add(a, p) for a, p in zip(_matvec(R, jpos), pos)]
            world_axis = _matvec(R, [_c(v) for v in axis])
            angle = qc[adr] if qpos0 == 0.0 else qc[adr] - qpos0
            if jtype == _SLIDE:
                pos = [_add(p, mul_const(a, angle)) for p, a in zip(pos, world_axis)]
                cols[adr] = (_SLIDE, world_axis, None)
            else:
                s, c = sincos(angle)
                R = matmul_rows(R, _axis_angle([_c(v) for v in axis], s, c))
                pos = [_sub(a, r) for a, r in zip(anchor, _matvec(R, jpos))]
                cols[adr] = (_HINGE, world_axis, anchor)
    x = [_add(p, r) for p, r in zip(pos, _matvec(R, [_c(v) for v in site_pos]))]
    zero = jnp.zeros(batch, qc.dtype)
    full = lambda v: v + zero if isinstance(v, float) else v  # noqa: E731
    J = []
    for k in range(n):
        if k not in cols:
            J.append([zero] * 3)
            continue
        jtype, a, anchor = cols[k]
        col = a if jtype == _SLIDE else _cross(a, [_sub(xi, pi) for xi, pi in zip(x, anchor)])
        J.append([full(v) for v in col])
    return jnp.stack([full(v) for v in x]), jnp.stack([jnp.stack([J[k][i] for k in range(n)]) for i in range(3)])
