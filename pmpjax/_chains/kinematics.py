"""Kinematic chains ``x = fk(q)``: the wrist of Eq 6, planar n-link arms, user FK functions.

Every chain exposes ``n`` (joints), ``m`` (task dimensions), ``fk(q)`` (..., n) -> (..., m) and
``jacobian(q)`` (..., n) -> (..., m, n), plus the component-leading kernel ``fk_jac_soa`` used
inside integrators (see ``_base.linalg``). Chains are pytrees: lengths are leaves, sizes are
static. How to write your own chain: see :class:`Chain`.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from .._base import (
    MAX_JOINT_ANGLE,
    as_array,
    check_joint_angles,
    check_positive,
    det_lists,
    elements,
    fast_compile_jit,
    from_soa,
    is_concrete,
    on_host,
    pytree_dataclass,
    register_pytree_class,
    rotation_matrix,
    sincos,
    static_field,
    to_jax,
    to_soa,
)


class Chain:
    """Base class of kinematic chains ``x = fk(q)``, ``q`` (n,) joint angles, ``x`` (m,) task point.

    **Writing a chain (the extension contract).** Subclass ``Chain``, give ``n`` and ``m`` (class
    attributes or fields) and implement, in JAX, for **one** posture:

    - ``fk(self, q)``: ``q`` (n,) -> ``x`` (m,) (required);
    - ``jacobian(self, q)``: ``q`` (n,) -> ``J = ∂fk/∂q`` (m, n) (optional; default ``jax.jacfwd``
      of ``fk``).

    The base class vectorises them: on every chain the public ``fk``/``jacobian`` accept leading
    batch axes (..., n), and every pmpjax function (``simulate``, ``equilibrium_posture``, fits)
    works with the chain. Optionally override ``reachable(x)`` and ``workspace_description()``
    so that unreachable targets are rejected by name. A subclass is registered as a pytree when
    it is defined: a ``pmpjax`` pytree dataclass keeps its array fields as leaves (differentiable,
    vmappable: e.g. link lengths), any other class is a static object (hashed by identity).

    **Optional fast path.** Instead of ``fk``, a chain may implement the component-leading kernel
    ``fk_jac_soa(qc)``: ``qc`` (n, ...) -> ``(x (m, ...), J (m, n, ...))`` with the small axes
    leading and the batch trailing (see ``pmpjax._base.linalg``), which XLA fuses into the RK4
    loop; ``Wrist``, ``PlanarArm`` and ``ShoulderElbowArm`` do. Without it the base class builds that kernel
    from ``fk`` (and ``jacobian``) by ``jax.vmap``, as :class:`FunctionChain` does for a plain
    function.

    **Joint-angle ranges.** ``angle_error`` [rad] (class attribute, default ``2π``): ``simulate``'s
    ``q0`` and the models' ``q_rest`` beyond it are refused as degrees typed as radians;
    ``angle_limit`` [rad] (default None): beyond it they run with a warning (a chain with a human
    range sets it).
    """

    n: int
    m: int
    angle_error = MAX_JOINT_ANGLE
    angle_limit = None

    def check_angles(self, name: str, q) -> None:
        """Refuse joint angles beyond ``angle_error`` and warn beyond ``angle_limit`` (degrees typed
        as radians, most likely).

        **Arguments:**

        - ``name``: the argument's name, for the message.
        - ``q``: (..., n) joint angles [rad].

        **Raises:**

        - ``ValueError`` naming ``name`` for angles beyond ``angle_error``.
        """
        check_joint_angles(name, q, self)

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        # Per-item methods written by the subclass become the kernels; the public names get the
        # batched (validated, vectorised) versions below.
        for name in ("fk", "jacobian"):
            f = cls.__dict__.get(name)
            if f is not None and not getattr(f, "_batched", False):
                setattr(cls, f"_{name}_one", f)
                setattr(cls, name, getattr(Chain, name))
        register_pytree_class(cls)

    def _fk_jac_one(self):
        fk_one = getattr(type(self), "_fk_one", None)
        if fk_one is None:
            raise NotImplementedError(
                f"{type(self).__name__} must implement fk(q) for one posture q (n,) -> x (m,) "
                "(or the fast path fk_jac_soa)"
            )
        jac_one = getattr(type(self), "_jacobian_one", None)
        fk = lambda q: fk_one(self, q)  # noqa: E731
        return fk, (jax.jacfwd(fk) if jac_one is None else (lambda q: jac_one(self, q)))

    def fk_jac_soa(self, qc):
        """Task positions and Jacobians of component-leading postures (the kernel integrators use).

        Default: ``vmap`` of the per-item ``fk`` and ``jacobian``; closed-form chains override it.

        **Arguments:**

        - ``qc``: (n, ...) joint angles [rad], components leading, the batch trailing.

        **Returns:**

        ``(x, J)``: (m, ...) task positions and (m, n, ...) Jacobians.
        """
        fk, jac = self._fk_jac_one()
        batch = qc.shape[1:]
        flat = qc.reshape(self.n, -1).T
        x, J = jax.vmap(fk)(flat), jax.vmap(jac)(flat)
        return x.T.reshape((self.m,) + batch), jnp.moveaxis(J, 0, -1).reshape((self.m, self.n) + batch)

    #: ``fk``/``jacobian`` of concrete postures in one jitted call (False: chains whose
    #: ``fk_jac_soa`` runs its own eager chunks, e.g. :class:`pmpjax.MjcfChain`).
    _jit_eager = True

    def _per_item(self, which: int, q):
        if getattr(type(self), "_fk_one", None) is None:
            out = self.fk_jac_soa(on_host(q, to_soa))[which]
            return on_host(out, lambda a: from_soa(a, which + 1))
        f = self._fk_jac_one()[which]
        flat = q.reshape(-1, self.n)
        out = jax.vmap(f)(flat)
        return out.reshape(q.shape[:-1] + out.shape[1:])

    def fk(self, q):
        """Task positions of joint angles (forward kinematics, batched).

        **Arguments:**

        - ``q``: (..., n) joint angles [rad].

        **Returns:**

        (..., m) task positions (wrist: screen points [m]).

        **Raises:**

        - ``ValueError`` naming ``q`` for a wrong trailing shape or NaN/inf.
        """
        q = as_array("q", q, tail=(self.n,))
        return (_per_item if self._jit_eager else Chain._per_item)(self, 0, to_jax(q))

    fk._batched = True

    def jacobian(self, q):
        """Task Jacobians ``∂fk/∂q`` (Eq 2, batched).

        **Arguments:**

        - ``q``: (..., n) joint angles [rad].

        **Returns:**

        (..., m, n) Jacobians.

        **Raises:**

        - ``ValueError`` naming ``q`` for a wrong trailing shape or NaN/inf.
        """
        q = as_array("q", q, tail=(self.n,))
        return (_per_item if self._jit_eager else Chain._per_item)(self, 1, to_jax(q))

    jacobian._batched = True

    def reachable(self, x) -> np.ndarray:
        """Which task points lie inside the reachable workspace (every point for the base class).

        **Arguments:**

        - ``x``: (..., m) task points.

        **Returns:**

        (...,) bool mask.
        """
        return np.ones(np.shape(x)[:-1], dtype=bool)

    def check_target(self, name: str, x) -> None:
        """Refuse unreachable targets (concrete values only; traced ones pass).

        **Arguments:**

        - ``name``: the argument's name, for the message.
        - ``x``: (..., m) task points.

        **Raises:**

        - ``ValueError`` naming ``name`` and the first unreachable point.
        """
        if is_concrete(x):
            ok = self.reachable(np.asarray(x, dtype=float))
            if not np.all(ok):
                bad = np.asarray(x, dtype=float).reshape(-1, self.m)[~ok.reshape(-1)][0]
                raise ValueError(
                    f"`{name}` has {int((~ok).sum())} point(s) outside the reachable workspace "
                    f"of {type(self).__name__} ({self.workspace_description()}); first: {bad}"
                )

    def workspace_description(self) -> str:
        """The reachable workspace in words, for error messages.

        **Returns:**

        A short description (``"unbounded"`` for the base class).
        """
        return "unbounded"


def manipulability(chain: Chain, q):
    """Yoshikawa manipulability ``sqrt(det(J Jᵀ))`` of a chain at postures ``q``.

    It falls to zero where the Jacobian loses rank (wrist: pointing at the rim of the screen
    hemisphere, which includes gimbal lock FE = ±90°), so it is the detector for singular postures.

    **Arguments:**

    - ``chain``: a :class:`Chain`.
    - ``q``: (..., n) postures [rad].

    **Returns:**

    (...,) manipulability (units of ``x`` per radian to the power m).

    **Raises:**

    - ``TypeError`` for a non-chain; ``ValueError`` naming ``q`` for a wrong trailing shape or NaN/inf.
    """
    if not isinstance(chain, Chain):
        raise TypeError(f"`chain` must be a pmpjax Chain, got {type(chain).__name__}")
    q = as_array("q", q, tail=(chain.n,))
    return manipulability_soa(chain.fk_jac_soa(to_soa(jnp.asarray(q)))[1])


@partial(fast_compile_jit, static_argnums=1)
def _per_item(chain, which: int, q):
    """``fk`` (``which`` 0) or ``jacobian`` (1) of ``q`` (..., n) in one compiled call."""
    return chain._per_item(which, q)


def manipulability_soa(J):
    """``sqrt(det(J Jᵀ))`` (...) of a component-leading Jacobian ``J`` (m, n, ...) (the kernel of
    :func:`manipulability`, for integrators)."""
    m, n = J.shape[:2]
    # J Jᵀ as element lists: a stacked Gram matrix is an extra fused loop per call (per RK4 step
    # when simulate saves it).
    r = elements(J)
    gram = [[sum(r[i][k] * r[j][k] for k in range(n)) for j in range(m)] for i in range(m)]
    return jnp.sqrt(jnp.maximum(det_lists(gram), 0.0))


@pytree_dataclass
class Wrist(Chain):
    """Wrist pointing on a screen at distance ``d`` [m] (Eq 6).

    ``q = (q_PS, q_FE, q_RUD)`` [rad]; ``R(q) = exp(−ê_x q_PS) exp(ê_z q_FE) exp(ê_y q_RUD)``;
    ``x = [[0, −d, 0], [0, 0, d]] R(q) e_x`` [m]: ``x1`` to the right (East), ``x2`` up (North).

    The Jacobian is analytic. It loses rank where the pointing axis ``R e_x`` lies in the screen
    plane (``|x| = d``), which includes gimbal lock at ``q_FE = ±π/2``; ``reachable`` accepts
    ``|x| ≤ d·sin(max_angle)`` (default 80°) to stay clear of that rim.

    Joint angles beyond ±π (180°: no wrist joint turns that far from neutral) are refused as
    degrees typed as radians, and beyond ±π/2 (90°, the end of the human range of pronation)
    they run with a warning (``angle_error``, ``angle_limit``).

    **Fields:** ``d`` screen distance [m] (array leaf: differentiable, vmappable); ``max_angle``
    [rad] the largest pointing angle ``reachable`` accepts; ``n`` = 3 joints and ``m`` = 2 task
    dimensions (fixed).
    """

    angle_error = float(np.pi)
    angle_limit = float(np.pi / 2)

    d: jax.Array = 1.0  # array leaf [m] (differentiable, vmappable)
    max_angle: float = static_field(default=float(np.deg2rad(80.0)))
    n: int = static_field(default=3)
    m: int = static_field(default=2)

    def __post_init__(self):
        check_positive("d", self.d)

    def fk_jac_soa(self, qc):
        d = self.d
        s, c = sincos(qc)
        (sa, sb, sc), (ca, cb, cc) = (s[0], s[1], s[2]), (c[0], c[1], c[2])
        sbcc = sb * cc
        # Pointing axis u = R e_x = (cb cc, ca sb cc − sa sc, −sa sb cc − ca sc); x = d (−u2, u3).
        x1 = -d * (ca * sbcc - sa * sc)
        x2 = -d * (sa * sbcc + ca * sc)
        dcbcc = d * cb * cc
        J = jnp.stack(
            [
                jnp.stack([-x2, -ca * dcbcc, d * (ca * sb * sc + sa * cc)]),
                jnp.stack([x1, -sa * dcbcc, d * (sa * sb * sc - ca * cc)]),
            ]
        )
        return jnp.stack([x1, x2]), J

    def reachable(self, x):
        r = np.linalg.norm(np.asarray(x, dtype=float), axis=-1)
        return r <= float(np.asarray(self.d)) * np.sin(self.max_angle)

    def workspace_description(self):
        d = float(np.asarray(self.d))
        return f"|x| <= d*sin({np.rad2deg(self.max_angle):.0f}°) = {d * np.sin(self.max_angle):.4g} m"

    def rotation(self, q):
        """Hand orientations ``R(q)`` of Eq 6 (as :func:`pmpjax.wrist_rotation`).

        **Arguments:**

        - ``q``: (..., 3) joint angles ``(q_PS, q_FE, q_RUD)`` [rad].

        **Returns:**

        (..., 3, 3) rotation matrices.
        """
        q = jnp.asarray(q)
        a, b, c = q[..., 0], q[..., 1], q[..., 2]
        return rotation_matrix(0, -a) @ rotation_matrix(2, b) @ rotation_matrix(1, c)


@pytree_dataclass
class PlanarArm(Chain):
    """Planar n-link arm with hand position ``x`` (2,) [m]; ``lengths`` (n,) [m], joints relative."""

    lengths: jax.Array
    n: int = static_field(default=0)
    m: int = static_field(default=2)

    def __init__(self, lengths):
        lengths = as_array("lengths", lengths, tail=(None,))
        if np.ndim(lengths) != 1 or np.shape(lengths)[0] < 2:
            raise ValueError(f"`lengths` must be a 1-D array of >= 2 link lengths, got {np.shape(lengths)}")
        check_positive("lengths", lengths)
        object.__setattr__(self, "lengths", jnp.asarray(lengths, dtype=float))
        object.__setattr__(self, "n", int(np.shape(lengths)[0]))
        object.__setattr__(self, "m", 2)

    def fk_jac_soa(self, qc):
        phi = jnp.cumsum(qc, axis=0)
        L = self.lengths.reshape((self.n,) + (1,) * (qc.ndim - 1))
        s, c = sincos(phi)
        lc, ls = L * c, L * s
        x = jnp.stack([lc.sum(0), ls.sum(0)])
        # Column j moves every link from j outward: reverse cumulative sums.
        tail_c = jnp.flip(jnp.cumsum(jnp.flip(lc, 0), 0), 0)
        tail_s = jnp.flip(jnp.cumsum(jnp.flip(ls, 0), 0), 0)
        return x, jnp.stack([-tail_s, tail_c])

    def reachable(self, x):
        L = np.asarray(self.lengths)
        r = np.linalg.norm(np.asarray(x, dtype=float), axis=-1)
        inner = max(0.0, 2 * L.max() - L.sum())
        return (r <= 0.999 * L.sum()) & (r >= inner + 1e-3 * L.sum())

    def workspace_description(self):
        L = np.asarray(self.lengths)
        return f"annulus {max(0.0, 2 * L.max() - L.sum()):.3g} m < |x| < {L.sum():.3g} m"


@pytree_dataclass
class FunctionChain(Chain):
    """Chain from a user JAX function ``fk(q)`` (n,) -> (m,); Jacobian by ``jax.jacfwd``.

    **Arguments:**

    - ``fn``: the forward kinematics, a JAX function of one posture ``q`` (n,) [rad] returning the
      task point (m,).
    - ``n``: number of joints.
    - ``m``: task dimensions.
    - ``reach``: optional function mapping task points (..., m) to a boolean mask of reachable
      points (targets outside it are refused by name).

    Construction raises ``TypeError`` for a non-callable ``fn`` and ``ValueError`` when ``fn`` does
    not map (n,) to (m,).
    """

    fn: Callable = static_field()
    n: int = static_field()
    m: int = static_field()
    reach: Callable | None = static_field(default=None)

    def __post_init__(self):
        if not callable(self.fn):
            raise TypeError("`fn` must be callable: fk(q) with q of shape (n,)")
        out = jax.eval_shape(self.fn, jax.ShapeDtypeStruct((self.n,), jnp.float64))
        if out.shape != (self.m,):
            raise ValueError(f"`fn` must map (n,)=({self.n},) to (m,)=({self.m},), got {out.shape}")

    def fk(self, q):
        return self.fn(q)

    def reachable(self, x):
        if self.reach is None:
            return super().reachable(x)
        return np.asarray(self.reach(np.asarray(x)), dtype=bool)
