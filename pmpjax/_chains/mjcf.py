"""``MjcfChain``: a kinematic chain whose ``fk`` is a MuJoCo site position from MJX kinematics.

It lets the λ0-PMP (``pmpjax.simulate``) plan joint trajectories for any MJCF model with hinge
and slide joints, e.g. set-point trajectories for the springy arm (``pmpjax.load_arm``). The
Jacobian is in closed form from one kinematics pass (as ``mj_jacSite``); the MJX model's arrays
are the chain's pytree leaves, so the chain can be passed through ``jax.jit`` like the other
chains.
MuJoCo and MJX are imported on first use (``pmpjax._base.mujoco``), not by ``import pmpjax``.
"""

from __future__ import annotations

import functools
import os
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from .._base import (
    fast_compile_jit,
    import_mjx,
    import_mujoco,
    is_concrete,
    is_mj_model,
    load_mj_model,
    pytree_dataclass,
    row_chunks,
    static_field,
    to_jax,
)
from .kinematics import Chain
from .serial import site_fk_jac_soa, site_path

_SLIDE = 2  # mujoco.mjtJoint.mjJNT_SLIDE
_HINGE = 3  # mujoco.mjtJoint.mjJNT_HINGE


def _mj_model(xml_or_model):
    """An ``MjModel`` from a path (``str`` or ``os.PathLike``), MJCF string, model, or an object
    carrying one as ``mj_model`` (e.g. ``pmpjax.CogArm``)."""
    inner = getattr(xml_or_model, "mj_model", None)
    if is_mj_model(inner):
        return inner
    return load_mj_model(os.fspath(xml_or_model) if isinstance(xml_or_model, os.PathLike) else xml_or_model)


def _source(xml_or_model) -> str:
    """How errors name the model: its file, else the argument."""
    if isinstance(xml_or_model, os.PathLike) or (isinstance(xml_or_model, str)
                                                 and not xml_or_model.lstrip().startswith("<")):
        return os.fspath(xml_or_model)
    return "`xml_or_model`"


@pytree_dataclass
class Kinematics:
    """Frames at one posture (the ``mjx.Data`` fields of the same names): ``xpos`` (nbody, 3),
    ``xmat`` (nbody, 3, 3), ``xipos`` (nbody, 3), ``xanchor`` (njnt, 3), ``xaxis`` (njnt, 3),
    ``site_xpos`` (nsite, 3)."""

    xpos: Any
    xmat: Any
    xipos: Any
    xanchor: Any
    xaxis: Any
    site_xpos: Any


def _quat_mat(u):
    w, x, y, z = u[0], u[1], u[2], u[3]
    return jnp.stack([
        jnp.stack([w * w + x * x - y * y - z * z, 2 * (x * y - w * z), 2 * (x * z + w * y)]),
        jnp.stack([2 * (x * y + w * z), w * w - x * x + y * y - z * z, 2 * (y * z - w * x)]),
        jnp.stack([2 * (x * z - w * y), 2 * (y * z + w * x), w * w - x * x - y * y + z * z]),
    ]) / (u @ u)


def _axis_angle_mat(a, angle):
    """Rotation matrix of ``angle`` about the unit axis ``a`` (Rodrigues)."""
    c, s = jnp.cos(angle), jnp.sin(angle)
    return c * jnp.eye(3, dtype=a.dtype) + s * jnp.cross(jnp.eye(3, dtype=a.dtype), a) + (1 - c) * jnp.outer(a, a)


def kinematics(mx, q):
    """Forward kinematics at joint positions ``q`` (nq,) for hinge/slide trees, as
    ``mj_kinematics``: a :class:`Kinematics`. Written out body by body (a few dozen small ops),
    because ``mjx.kinematics`` on a full ``mjx.make_data`` makes graphs that take tens of seconds
    to compile. Mocap bodies sit at their model pose."""
    parent, jadr, jnum = (np.asarray(a) for a in (mx.body_parentid, mx.body_jntadr, mx.body_jntnum))
    jtype, qadr = np.asarray(mx.jnt_type), np.asarray(mx.jnt_qposadr)
    if not np.all((jtype == _HINGE) | (jtype == _SLIDE)):
        raise ValueError("kinematics supports hinge and slide joints only")
    q = jnp.asarray(q)
    xpos, xmat = [jnp.zeros(3, q.dtype)], [jnp.eye(3, dtype=q.dtype)]
    anchors, axes = [None] * jtype.size, [None] * jtype.size
    for b in range(1, parent.size):
        p = int(parent[b])
        pos = xpos[p] + xmat[p] @ mx.body_pos[b]
        R = xmat[p] @ _quat_mat(mx.body_quat[b])
        for j in range(int(jadr[b]), int(jadr[b]) + int(jnum[b])):
            anchors[j] = R @ mx.jnt_pos[j] + pos
            axes[j] = R @ mx.jnt_axis[j]
            angle = q[qadr[j]] - mx.qpos0[qadr[j]]
            if jtype[j] == _SLIDE:
                pos = pos + axes[j] * angle
            else:
                R = R @ _axis_angle_mat(mx.jnt_axis[j], angle)
                pos = anchors[j] - R @ mx.jnt_pos[j]
        xpos.append(pos)
        xmat.append(R)
    xpos, xmat = jnp.stack(xpos), jnp.stack(xmat)
    sb = np.asarray(mx.site_bodyid)
    z = jnp.zeros((0, 3), q.dtype)
    return Kinematics(
        xpos=xpos,
        xmat=xmat,
        xipos=xpos + jnp.einsum("bij,bj->bi", xmat, mx.body_ipos),
        xanchor=jnp.stack(anchors) if anchors else z,
        xaxis=jnp.stack(axes) if axes else z,
        site_xpos=xpos[sb] + jnp.einsum("sij,sj->si", xmat[sb], mx.site_pos) if sb.size else z,
    )


def gravity_gradient(mx, q):
    """``∇V(q)`` (nv,) [Nm]: the gravity part of MuJoCo's ``qfrc_bias`` (hinge/slide joints).

    Closed form from MJX kinematics and subtree centres of mass (no autodiff, so cheap to
    compile and differentiate): for a hinge j with world axis ``a_j`` at anchor ``p_j`` carrying
    subtree mass ``M_j`` with centre ``C_j``, ``∂V/∂q_j = −gᵀ (a_j × M_j (C_j − p_j))``; for a
    slide, ``−M_j gᵀ a_j``.
    """
    return gravity_from_kinematics(mx, kinematics(mx, q))


def gravity_from_kinematics(mx, d):
    """``∇V`` (nv,) [Nm] (see :func:`gravity_gradient`) from the kinematics fields (``xipos``,
    ``xanchor``, ``xaxis``) of a :class:`Kinematics` or an ``mjx.Data``, e.g. the one ``mjx.step``
    returns: those fields are for the posture at the start of that step."""
    with jax.numpy_rank_promotion("allow"):
        mass = _subtree_mask(mx) * mx.body_mass[None, :]
        M = jnp.sum(mass, axis=1)[:, None]
        arm = mass @ d.xipos - M * d.xanchor  # M_j (C_j − p_j)
        lever = jnp.where(_is_hinge(mx), jnp.cross(d.xaxis, arm), M * d.xaxis)
        return -(lever @ mx.opt.gravity)


def _subtree_mask(mx) -> np.ndarray:
    """(njnt, nbody) 0/1: body b lies in the subtree moved by joint j (static, from the tree)."""
    body, parent = np.asarray(mx.jnt_bodyid), np.asarray(mx.body_parentid)
    inside = np.zeros((body.size, parent.size))
    for j, bj in enumerate(body):
        for b in range(parent.size):
            a = b
            while a > bj:
                a = parent[a]
            inside[j, b] = float(a == bj)
    return inside


def _is_hinge(mx) -> np.ndarray:
    return np.asarray(mx.jnt_type)[:, None] == _HINGE


def _moves_joint(mx) -> np.ndarray:
    """(njnt, njnt) bool R[i, j]: joint i moves joint j's frame (ancestor, or same body and
    earlier in MuJoCo's joint order, or i == j)."""
    inside = _subtree_mask(mx)
    body = np.asarray(mx.jnt_bodyid)
    idx = np.arange(body.size)
    R = inside[:, body] > 0
    same = body[:, None] == body[None, :]
    return R & (~same | (idx[:, None] <= idx[None, :]))


def gravity_terms(mx, q):
    """``(∇V (nv,), ∇²V (nv, nv), d)`` at ``q`` from one kinematics pass (hinge joints only);
    ``d`` the :class:`Kinematics` (for site positions).

    With ``m_j = M_j (C_j − p_j)`` (subtree mass moment about joint j) and ``G_ij =
    −gᵀ (a_i × (a_j × m_j))``: ``∂²V/∂q_j∂q_i = G_ij`` when joint i moves joint j (rotating the
    whole of ``a_j × m_j``), ``G_ji`` when j moves i, else 0 (the Jacobi identity gives symmetry).
    """
    if not np.all(_is_hinge(mx)):
        raise ValueError("gravity_terms supports hinge joints only")
    with jax.numpy_rank_promotion("allow"):
        d = kinematics(mx, q)
        mass = _subtree_mask(mx) * mx.body_mass[None, :]
        arm = mass @ d.xipos - jnp.sum(mass, axis=1)[:, None] * d.xanchor
        inner = jnp.cross(d.xaxis, arm)  # a_j × m_j
        G = -(jnp.cross(d.xaxis[:, None, :], inner[None, :, :]) @ mx.opt.gravity)  # G[i, j]
        R = _moves_joint(mx)
        return -(inner @ mx.opt.gravity), jnp.where(R.T, G.T, jnp.where(R, G, 0.0)), d


def site_jacobian(mx, site_id: int, q):
    """Site position ``x`` (3,) and translational Jacobian ``J`` (3, nv) at ``q`` from one MJX
    kinematics pass (as ``mj_jacSite``): column j is ``a_j × (x − p_j)`` for a hinge moving the
    site, ``a_j`` for a slide, 0 otherwise. Differentiable in ``q`` by a closed-form JVP (below),
    so derivatives never trace MJX kinematics (small compile times)."""
    return _site_jac(int(site_id), mx, q)


def _site_jac_terms(mx, site_id: int, q):
    with jax.numpy_rank_promotion("allow"):
        d = kinematics(mx, q)
        x = d.site_xpos[site_id]
        moves = _subtree_mask(mx)[:, int(np.asarray(mx.site_bodyid)[site_id])][:, None]
        cols = jnp.where(_is_hinge(mx), jnp.cross(d.xaxis, x[None, :] - d.xanchor), d.xaxis)
        return x, moves, cols, d


@functools.partial(jax.custom_jvp, nondiff_argnums=(0,))
def _site_jac(site_id, mx, q):
    x, moves, cols, _ = _site_jac_terms(mx, site_id, q)
    return x, (moves * cols).T


@_site_jac.defjvp
def _site_jac_jvp(site_id, primals, tangents):
    # Rigid-body velocities of the frames for joint rates dq (the model's tangents are ignored):
    # frame j turns at ω_j = Σ_i R_ij h_i a_i dq_i (R_ij: joint i moves joint j; h_i: hinge), a
    # point y on it moves at Σ_i R_ij (h_i a_i × (y − p_i) + (1 − h_i) a_i) dq_i. Then
    # d(a_j × (x − p_j)) = (ω_j × a_j) × (x − p_j) + a_j × (dx − dp_j) and d(a_j) = ω_j × a_j.
    mx, q = primals
    dq = tangents[1]
    x, moves, cols, d = _site_jac_terms(mx, site_id, q)
    with jax.numpy_rank_promotion("allow"):
        A, Pn = d.xaxis, d.xanchor
        h = jnp.asarray(_is_hinge(mx)[:, 0], A.dtype)
        Rt = jnp.asarray(_moves_joint(mx).T, A.dtype)  # Rt[j, i] = R[i, j]
        dx = (moves[:, 0] * dq) @ cols
        omega = Rt @ ((h * dq)[:, None] * A)
        dp = jnp.cross(omega, Pn) - Rt @ ((h * dq)[:, None] * jnp.cross(A, Pn)) + Rt @ (((1 - h) * dq)[:, None] * A)
        da = jnp.cross(omega, A)
        dcols = jnp.where(h[:, None] > 0, jnp.cross(da, x[None, :] - Pn) + jnp.cross(A, dx[None, :] - dp), da)
        return (x, (moves * cols).T), (dx, (moves * dcols).T)


@functools.partial(jax.custom_jvp, nondiff_argnums=(0,))
def _site_pos(site_id, mx, q):
    return kinematics(mx, q).site_xpos[site_id]


@_site_pos.defjvp
def _site_pos_jvp(site_id, primals, tangents):
    mx, q = primals
    x, J = site_jacobian(mx, site_id, q)
    return x, J @ tangents[1]


def site_position(mx, site_id: int, q):
    """Site position (3,) at ``q``, differentiable with the analytic Jacobian (``custom_jvp``):
    derivatives never trace MJX kinematics, which keeps compile times small."""
    return _site_pos(int(site_id), mx, q)


_EAGER_CHUNK = 64


def _map_rows(kernel, mx, q):
    """``kernel(mx, q (B, n))`` (a jitted, vmapped function) over rows of ``q``. Concrete (eager)
    calls run it on chunks of 64 rows, so every batch size shares one compile; traced calls
    (inside ``jit``/``grad``/``vmap``) run it once on the whole batch (inlined)."""
    if not is_concrete(q):
        return kernel(mx, q)
    out = row_chunks(lambda r: kernel(mx, r), q, small=_EAGER_CHUNK, chunk=_EAGER_CHUNK)
    return jax.tree_util.tree_map(to_jax, out)


@functools.partial(fast_compile_jit, static_argnames=("site_id",))
def _site_jacobians_kernel(mx, q, *, site_id: int):
    return jax.vmap(lambda qq: site_jacobian(mx, site_id, qq))(q)


@fast_compile_jit
def _gravity_kernel(mx, q):
    return jax.vmap(lambda qq: gravity_gradient(mx, qq))(q)


def site_jacobians(mx, site_id: int, q):
    """Site positions (B, 3) and Jacobians (B, 3, nv) at postures ``q`` (B, nv) (see
    :func:`_map_rows`: one compile for every eager batch size)."""
    return _map_rows(functools.partial(_site_jacobians_kernel, site_id=int(site_id)), mx, q)


def gravity_gradients(mx, q):
    """``∇V`` (B, nv) at postures ``q`` (B, nv) (see :func:`gravity_gradient`, :func:`_map_rows`)."""
    return _map_rows(_gravity_kernel, mx, q)


#: One treedef object per distinct MJX model structure. The chain holds the model as its flat
#: leaves and this treedef (static): flattening an ``mjx.Model`` node by node costs ≈ 0.4 ms in
#: every jitted call that takes the chain, a tuple of its leaves ≈ 0.03 ms; and equal treedefs
#: compare in ≈ 1 ms, the same object at once (chains built from the same file share it).
_TREEDEFS: dict = {}


@pytree_dataclass
class MjcfChain(Chain):
    """Hand/site position ``x`` (3,) [m] of a MuJoCo model, ``q`` (nq,) joint positions.

    **Arguments:**

    - ``xml_or_model``: a path, MJCF string, ``mujoco.MjModel`` or an object holding one as
      ``mj_model`` (:class:`pmpjax.CogArm`).
    - ``site``: the name of the site that plays the hand.

    Only hinge and slide joints (``nq == nv``). ``joint_names`` (n,) the model's joint names in
    ``qpos`` order (None when a joint is unnamed), so ``pmpjax.read_joint_angles(path,
    joints=chain)`` picks a recording's columns by name.
    ``reachable`` accepts points closer to the first joint than 0.99 × the summed link offsets.
    ``mjx_model`` the MJX model; its arrays (``mjx_leaves``) are the chain's pytree leaves.
    """

    mjx_leaves: tuple
    mjx_treedef: Any = static_field(default=None)
    site_id: int = static_field(default=0)
    n: int = static_field(default=0)
    m: int = static_field(default=3)
    center: tuple = static_field(default=(0.0, 0.0, 0.0))
    reach: float = static_field(default=np.inf)
    joint_names: tuple[str, ...] | None = static_field(default=None)
    path: tuple = static_field(default=())

    def __init__(self, xml_or_model, site: str):
        mujoco = import_mujoco()
        m = _mj_model(xml_or_model)
        source = _source(xml_or_model)
        if not isinstance(site, str):
            raise TypeError(f"`site` must be a site name (str), got {type(site).__name__}")
        sid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, site)
        if sid < 0:
            names = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_SITE, i) for i in range(m.nsite)]
            raise ValueError(f"{source}: `site` '{site}' is not a site of the model; its sites: {names}")
        kinds = {int(mujoco.mjtJoint.mjJNT_FREE): "free", int(mujoco.mjtJoint.mjJNT_BALL): "ball"}
        other = [f"'{mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j) or j}' ({kinds[int(t)]})"
                 for j, t in enumerate(m.jnt_type) if int(t) in kinds]
        if other or m.nq == 0:
            raise ValueError(f"{source}: an MjcfChain takes hinge and slide joints only; the model has "
                             + (f"the joint(s) {', '.join(other)}" if other else "no joints"))
        # Reach: summed offsets from the outermost jointed body (its first joint) out to the site.
        path, b = [], int(m.site_bodyid[sid])
        while b > 0:
            path.append(b)
            b = int(m.body_parentid[b])
        jointed = [b for b in path if m.body_jntnum[b] > 0]
        if not jointed:
            raise ValueError(f"{source}: `site` '{site}' is not moved by any joint")
        root = jointed[-1]
        reach = float(np.linalg.norm(m.site_pos[sid])) + float(np.linalg.norm(m.jnt_pos[m.body_jntadr[root]]))
        reach += sum(float(np.linalg.norm(m.body_pos[b])) for b in path[: path.index(root)])
        d = mujoco.MjData(m)
        mujoco.mj_kinematics(m, d)
        center = d.xanchor[m.body_jntadr[root]]
        with jax.numpy_rank_promotion("allow"):
            mx = import_mjx().put_model(m)
        leaves, treedef = jax.tree_util.tree_flatten(mx)
        object.__setattr__(self, "mjx_leaves", tuple(leaves))
        object.__setattr__(self, "mjx_treedef", _TREEDEFS.setdefault(treedef, treedef))
        object.__setattr__(self, "site_id", int(sid))
        object.__setattr__(self, "n", int(m.nq))
        object.__setattr__(self, "m", 3)
        object.__setattr__(self, "center", tuple(float(v) for v in center))
        object.__setattr__(self, "reach", float(reach))
        names = tuple(mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j) for j in np.argsort(m.jnt_qposadr))
        object.__setattr__(self, "joint_names", names if all(names) else None)
        object.__setattr__(self, "path", site_path(m, int(sid)))

    @property
    def mjx_model(self):
        """The MJX model (``mujoco.mjx.Model``), rebuilt from the chain's leaves."""
        return jax.tree_util.tree_unflatten(self.mjx_treedef, self.mjx_leaves)

    def site_position(self, q):
        """Site position for one posture (MJX kinematics, differentiable).

        **Arguments:**

        - ``q``: (n,) joint positions.

        **Returns:**

        (3,) the site's position [m].
        """
        return site_position(self.mjx_model, self.site_id, q)

    def fk_jac_soa(self, qc):
        """Site positions and Jacobians of component-leading postures: the bodies from the world to the
        site unrolled with the model's constants (``pmpjax._chains.serial``), fused into the caller's
        loop like a closed-form chain.

        **Arguments:**

        - ``qc``: (n, ...) joint positions, components leading.

        **Returns:**

        ``(x, J)``: (3, ...) positions [m] and (3, n, ...) Jacobians.
        """
        return site_fk_jac_soa(self.path, self.n, qc)

    def reachable(self, x):
        """Task points within 0.99 × the summed link offsets of the first joint.

        **Arguments:**

        - ``x``: (..., 3) points [m].

        **Returns:**

        (...,) bool mask.
        """
        r = np.linalg.norm(np.asarray(x, dtype=float) - np.asarray(self.center), axis=-1)
        return r <= 0.99 * self.reach

    def workspace_description(self):
        """The reachable ball in words, for error messages.

        **Returns:**

        ``|x - centre| <= radius m``.
        """
        return f"|x - {np.round(self.center, 3).tolist()}| <= {0.99 * self.reach:.3g} m"
