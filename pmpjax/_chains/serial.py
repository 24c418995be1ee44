"""Site kinematics of a MuJoCo hinge/slide tree as straight-line code on component-leading arrays.

``mjx.kinematics`` (and :func:`pmpjax._chains.mjcf.kinematics`) compute every body's frame as
stacked 3×3 matrices; inside the λ0-PMP's integrator that is a chain of tiny GEMMs per step. Here
the transforms between the world and one site are unrolled at trace time with the model's
constants as Python floats, so products with structural zeros and ones disappear from the graph
and XLA fuses the rest into the integrator's loop, as for the closed-form chains.

The model is ``mj_kinematics`` restricted to that path: each body moves its frame by ``body_pos``
and ``body_quat``; each of its joints (in model order) acts in the frame left by the previous one,
a hinge as ``y ↦ p + R(a, q − qpos0) (y − p)`` about its anchor ``p = jnt_pos`` and axis ``a =
jnt_axis``, a slide as ``y ↦ y + a (q − qpos0)``; the site sits at ``site_pos`` in the last frame.
That composition is rewritten once, in NumPy, as ``C_0 ∘ J_1 ∘ C_1 ∘ … ∘ J_K ∘ C_K`` with constant
rigid transforms ``C_k`` (offsets, orientations, anchors merged) and joints ``J_k`` that are
rotations about a coordinate axis through the origin or translations: a hinge axis ``±e_i`` stays
a plane rotation (four multiplications by its sine and cosine), any other axis ``a`` becomes
``B R_z Bᵀ`` with a constant orthonormal ``B`` (``B e_z = a``) folded into the neighbouring
constants.

Evaluation runs from the site to the world on vectors only, as a closed form is expanded from the
right: ``u = J_k(C_k(…))`` is the site in the frame before joint k, whose Jacobian column there is
``a_k × u`` (hinge) or ``a_k`` (slide) (``mj_jacSite``: ``a × (x − p)`` in the world, rotated back);
every later rotation (towards the world) turns the position and the columns found so far. Each
sine and cosine is computed once (one :func:`sincos` call on the stacked hinge angles); joints off
the path have zero columns.
"""

from __future__ import annotations

import functools

import numpy as np

from .._base import sincos

_SLIDE, _HINGE = 2, 3
_TINY = 1e-14  # constants this close to 0 or ±1 are structural zeros and ones


def _c(v) -> float:
    v = float(v)
    if abs(v) < _TINY:
        return 0.0
    if abs(abs(v) - 1.0) < _TINY:
        return float(np.sign(v))
    return v


class _Signed:
    """A traced value with a pending sign, ``−v`` when ``neg``: negations are carried into the
    next sum as subtractions instead of becoming operations of their own."""

    __slots__ = ("v", "neg")

    def __init__(self, v, neg: bool = False):
        self.v, self.neg = v, neg

    def value(self):
        return -self.v if self.neg else self.v


def _is(v, const) -> bool:
    return isinstance(v, float) and v == const


def _neg(a):
    return -a if isinstance(a, float) else _Signed(a.v, not a.neg)


def _mul(k: float, a):
    """``k * a`` for a Python float ``k``: zeros drop out, ±1 only flips the sign."""
    if k == 0.0 or _is(a, 0.0):
        return 0.0
    if isinstance(a, float):
        return k * a
    if abs(k) == 1.0:
        return a if k == 1.0 else _neg(a)
    return _Signed((-k if a.neg else k) * a.v)


def _tmul(a, b):
    if isinstance(a, float):
        return _mul(a, b)
    if isinstance(b, float):
        return _mul(b, a)
    return _Signed(a.v * b.v, a.neg != b.neg)


def _add(a, b):
    if _is(a, 0.0):
        return b
    if _is(b, 0.0):
        return a
    if isinstance(a, float) and isinstance(b, float):
        return a + b
    if isinstance(a, float):
        a, b = b, a
    if isinstance(b, float):  # a traced
        return _Signed(b - a.v) if a.neg else _Signed(a.v + b)
    if a.neg == b.neg:
        return _Signed(a.v + b.v, a.neg)
    return _Signed(a.v - b.v) if b.neg else _Signed(b.v - a.v)


def _sub(a, b):
    return _add(a, _neg(b))


# --- the path as constants -----------------------------------------------------------------------


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


def _quat_mat(u) -> np.ndarray:
    w, x, y, z = np.asarray(u, float) / np.linalg.norm(u)
    return np.array([[w * w + x * x - y * y - z * z, 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), w * w - x * x + y * y - z * z, 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), w * w - x * x - y * y + z * z]])


def _coordinate_axis(a) -> tuple[int, float] | None:
    """``(i, ±1)`` when the unit vector ``a`` is ``±e_i``, else None."""
    a = [_c(v) for v in a]
    nz = [i for i in range(3) if a[i] != 0.0]
    if len(nz) == 1 and abs(a[nz[0]]) == 1.0:
        return nz[0], a[nz[0]]
    return None


def _basis(a) -> np.ndarray:
    """An orthonormal, right-handed ``B`` with ``B e_z = a`` (unit ``a``)."""
    a = np.asarray(a, float) / np.linalg.norm(a)
    h = np.eye(3)[int(np.argmin(np.abs(a)))]
    e1 = np.cross(h, a)
    e1 /= np.linalg.norm(e1)
    return np.column_stack([e1, np.cross(a, e1), a])


@functools.lru_cache(maxsize=64)
def _program(path: tuple) -> tuple:
    """``path`` (:func:`site_path`) as ``(steps, hinges)``: ``steps`` from the world to the site,
    each ``("C", R, t)`` (a constant ``y ↦ R y + t``, ``R`` None for the identity; Python floats
    with exact structural zeros and ones), ``("H", i, sign, k)`` (rotation about ``sign · e_i``
    by hinge angle k) or ``("S", a, adr, qpos0)``; ``hinges`` the ``(qposadr, qpos0)`` of hinge
    angle k = 0, 1, …"""
    raw: list = []  # C as (R ndarray, t ndarray)
    hinges: list = []

    def const(R, t):
        if raw and raw[-1][0] == "C":  # y ↦ R1 (R y + t) + t1
            _, R1, t1 = raw.pop()
            R, t = R1 @ R, R1 @ t + t1
        raw.append(("C", R, t))

    eye, zero = np.eye(3), np.zeros(3)
    bodies, site_pos = path
    for body_pos, body_quat, joints in bodies:
        const(_quat_mat(body_quat), np.asarray(body_pos, float))
        for jtype, axis, jpos, adr, qpos0 in joints:
            if jtype == _SLIDE:
                raw.append(("S", axis, adr, qpos0))
                continue
            jpos = np.asarray(jpos, float)
            hinges.append((adr, qpos0))
            k = len(hinges) - 1
            coord = _coordinate_axis(axis)
            const(eye, jpos)
            if coord is not None:
                raw.append(("H", coord[0], coord[1], k))
            else:
                B = _basis(axis)
                const(B, zero)
                raw.append(("H", 2, 1.0, k))
                const(B.T, zero)
            const(eye, -jpos)
    const(eye, np.asarray(site_pos, float))
    steps = []
    for step in raw:
        if step[0] == "C":
            R = [[_c(v) for v in row] for row in step[1]]
            identity = all(R[i][j] == (1.0 if i == j else 0.0) for i in range(3) for j in range(3))
            steps.append(("C", None if identity else tuple(map(tuple, R)), tuple(_c(v) for v in step[2])))
        elif step[0] == "S":
            a = np.asarray(step[1], float)
            steps.append(("S", tuple(_c(v) for v in a / np.linalg.norm(a)), step[2], step[3]))
        else:
            steps.append(step)
    return tuple(steps), tuple(hinges)


# --- evaluation ----------------------------------------------------------------------------------


def _rotate_const(R, v):
    if R is None:
        return list(v)
    out = []
    for i in range(3):
        acc = 0.0
        for j in range(3):
            acc = _add(acc, _mul(R[i][j], v[j]))
        out.append(acc)
    return out


def _rotate_plane(i, sign, s, c, v):
    """``R(sign · e_i, θ) v`` from ``s = sin θ``, ``c = cos θ``: only the two components in the
    plane normal to ``e_i`` change."""
    j, k = (i + 1) % 3, (i + 2) % 3
    out = list(v)
    if sign > 0:
        out[j] = _sub(_tmul(c, v[j]), _tmul(s, v[k]))
        out[k] = _add(_tmul(s, v[j]), _tmul(c, v[k]))
    else:
        out[j] = _add(_tmul(c, v[j]), _tmul(s, v[k]))
        out[k] = _sub(_tmul(c, v[k]), _tmul(s, v[j]))
    return out


def _cross_axis(i, sign, u):
    """``(sign · e_i) × u``."""
    j, k = (i + 1) % 3, (i + 2) % 3
    out = [0.0, 0.0, 0.0]
    out[j], out[k] = _mul(-sign, u[k]), _mul(sign, u[j])
    return out


def site_fk_jac_soa(path: tuple, n: int, qc):
    """Site position ``x`` (3, ...) and Jacobian ``J`` (3, n, ...) at joint positions ``qc``
    (n, ...), component-leading (the chain's ``fk_jac_soa``), from :func:`site_path`'s constants."""
    import jax.numpy as jnp

    steps, hinges = _program(path)
    if hinges:
        adrs = [a for a, _ in hinges]
        if adrs == list(range(n)) and all(q0 == 0.0 for _, q0 in hinges):
            angles = qc
        else:
            angles = jnp.stack([qc[a] if q0 == 0.0 else qc[a] - q0 for a, q0 in hinges])
        s, c = sincos(angles)
    pos = [0.0, 0.0, 0.0]
    cols: dict[int, list] = {}
    for step in reversed(steps):
        kind = step[0]
        if kind == "C":
            _, R, t = step
            pos = [_add(p, ti) for p, ti in zip(_rotate_const(R, pos), t)]
            if R is not None:
                cols = {a: _rotate_const(R, v) for a, v in cols.items()}
        elif kind == "H":
            _, i, sign, k = step
            sk, ck = _Signed(s[k]), _Signed(c[k])
            pos = _rotate_plane(i, sign, sk, ck, pos)
            cols = {a: _rotate_plane(i, sign, sk, ck, v) for a, v in cols.items()}
            cols[hinges[k][0]] = _cross_axis(i, sign, pos)
        else:
            _, a, adr, qpos0 = step
            d = _Signed(qc[adr] if qpos0 == 0.0 else qc[adr] - qpos0)
            pos = [_add(p, _mul(ai, d)) for p, ai in zip(pos, a)]
            cols[adr] = list(a)
    zero = jnp.zeros(qc.shape[1:], qc.dtype)
    full = lambda v: v + zero if isinstance(v, float) else v.value()  # noqa: E731
    J = [[full(v) for v in cols[k]] if k in cols else [zero] * 3 for k in range(n)]
    return jnp.stack([full(v) for v in pos]), jnp.stack([jnp.stack([J[k][i] for k in range(n)]) for i in range(3)])
