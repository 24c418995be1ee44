"""Donders surfaces: torsion as a quadratic of the pointing components.

Orientations are rotation vectors ``r = (r_x, r_y, r_z)`` [rad] (axis·angle, see
``_orientation``); the surface is

    r_x = c0 + c1 r_y + c2 r_z + c3 r_y² + c4 r_y r_z + c5 r_z²,

fitted by linear least squares (QR). Its *thickness* is the RMS torsion residual [rad]. The
model's surface comes from the equilibrium postures of ``(KJ, q_rest)`` over a grid of
pointing targets.
"""

from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from .._base import as_array, check_positive, check_positive_int, fast_compile_jit, on_host, pytree_dataclass, to_jax
from .._chains import Wrist
from .._pmp import equilibrium_posture
from .orientation import rotvec_from_joint_angles

SCREEN_HALF_ANGLE_DEG = 20.0  # the pointing area of the Donders experiments: ±20°


@pytree_dataclass
class DondersSurface:
    """A Donders surface ``r_x = c0 + c1 r_y + c2 r_z + c3 r_y² + c4 r_y r_z + c5 r_z²``.

    Made by :func:`fit_donders_surface` and :func:`model_donders_surface`.

    **Fields:**

    - ``coef``: (..., 6) ``c0..c5`` [rad, 1, 1, 1/rad, 1/rad, 1/rad].
    - ``stderr``: (..., 6) their standard errors (``σ² (AᵀA)⁻¹``, ``σ² = SSR / (N − 6)``).
    - ``thickness``: (...,) RMS torsion residual [rad].
    - ``n``: (...,) number of samples used.
    """

    coef: jax.Array
    stderr: jax.Array
    thickness: jax.Array
    n: jax.Array

    def __call__(self, r_y, r_z):
        """Torsion ``r_x`` [rad] on the surface at ``(r_y, r_z)`` (broadcast against ``coef[..., 0]``)."""
        return evaluate_surface(self.coef, r_y, r_z)


def _design(r_y, r_z):
    return jnp.stack([jnp.ones_like(r_y), r_y, r_z, r_y**2, r_y * r_z, r_z**2], -1)


def evaluate_surface(coef, r_y, r_z):
    """Torsion ``c0 + c1 r_y + c2 r_z + c3 r_y² + c4 r_y r_z + c5 r_z²`` of a Donders surface.

    **Arguments:**

    - ``coef``: (..., 6) coefficients (``DondersSurface.coef``).
    - ``r_y``, ``r_z``: rotation-vector components [rad], broadcast against ``coef[..., 0]``.

    **Returns:**

    The torsion ``r_x`` [rad], of the broadcast shape.

    **Raises:**

    - ``ValueError`` naming the argument for a wrong trailing shape or NaN/inf.
    """
    coef = to_jax(as_array("coef", coef, tail=(6,)))
    r_y = to_jax(as_array("r_y", r_y), coef.dtype)
    r_z = to_jax(as_array("r_z", r_z), coef.dtype)
    return _evaluate(coef, r_y, r_z)


@fast_compile_jit
def _evaluate(coef, r_y, r_z):
    shape = jnp.broadcast_shapes(coef.shape[:-1], r_y.shape, r_z.shape)
    A = _design(jnp.broadcast_to(r_y, shape), jnp.broadcast_to(r_z, shape))
    return jnp.sum(A * jnp.broadcast_to(coef, shape + (6,)), axis=-1)


def surface_grid(surface_or_coef, *, extent: float = np.deg2rad(20.0), n: int = 21):
    """A Donders surface on an ``n × n`` grid of ``(r_y, r_z) ∈ [−extent, extent]²``.

    **Arguments:**

    - ``surface_or_coef``: a :class:`DondersSurface` or (..., 6) coefficients.
    - ``extent``: half-width of the grid [rad] (default 20°).
    - ``n``: grid points per axis.

    **Returns:**

    ``(r_y, r_z, r_x)``: (n, n), (n, n) and (..., n, n) [rad].

    **Raises:**

    - ``ValueError`` naming the argument for a non-positive ``extent`` or ``n``, or bad coefficients.
    """
    coef = surface_or_coef.coef if isinstance(surface_or_coef, DondersSurface) else surface_or_coef
    coef = to_jax(as_array("surface_or_coef", coef, tail=(6,)))
    check_positive("extent", extent)
    n = check_positive_int("n", n)
    return _surface_grid(coef, extent, n)


@partial(fast_compile_jit, static_argnums=2)
def _surface_grid(coef, extent, n):
    g = jnp.linspace(-extent, extent, n)
    ry, rz = jnp.meshgrid(g, g, indexing="ij")
    return ry, rz, _evaluate(coef[..., None, None, :], ry, rz)


@fast_compile_jit
def _fit(r, w):
    A = _design(r[..., 1], r[..., 2]) * w[..., None]
    b = r[..., 0] * w
    Q, R = jnp.linalg.qr(A)
    coef = jax.scipy.linalg.solve_triangular(R, jnp.einsum("...ni,...n->...i", Q, b)[..., None])[..., 0]
    resid = (b - jnp.einsum("...ni,...i->...n", A, coef)) * w
    n = jnp.sum(w, axis=-1)
    ssr = jnp.sum(resid**2, axis=-1)
    Rinv = jax.scipy.linalg.solve_triangular(R, jnp.broadcast_to(jnp.eye(6), R.shape))
    var = jnp.sum(Rinv**2, axis=-1)  # diag((RᵀR)⁻¹) = row norms² of R⁻¹
    sigma2 = ssr / jnp.maximum(n - 6, 1)
    return DondersSurface(
        coef=coef, stderr=jnp.sqrt(sigma2[..., None] * var), thickness=jnp.sqrt(ssr / n), n=n
    )


def fit_donders_surface(r, mask=None) -> DondersSurface:
    """Least-squares Donders surface of rotation vectors (QR).

    Leading axes are fitted independently.

    **Arguments:**

    - ``r``: (..., N, 3) rotation vectors ``(r_x, r_y, r_z)`` [rad] (:func:`rotvec_from_quat`).
    - ``mask``: optional (..., N) bool selecting samples (ragged subjects).

    **Returns:**

    A :class:`DondersSurface` with leading axes ``(...)``.

    **Raises:**

    - ``ValueError`` naming the argument for NaN/inf, wrong shapes, or fewer than 7 samples.
    """
    r = as_array("r", r, tail=(None, 3))
    r = jnp.asarray(r, jnp.result_type(float))
    if mask is None:
        w = np.ones(r.shape[:-1], r.dtype)  # concrete even under jit (the sample count check below)
    else:
        mask = np.asarray(mask)
        if mask.shape != tuple(r.shape[:-1]):
            raise ValueError(f"`mask` must have shape {tuple(r.shape[:-1])}, got {mask.shape}")
        w = mask.astype(r.dtype)
    n = np.sum(w, axis=-1)
    if np.any(n < 7):
        raise ValueError(f"`r` needs at least 7 (unmasked) samples per surface, got {int(n.min())}")
    return _fit(r, jnp.asarray(w))


def screen_grid(n: int = 9, *, half_angle_deg: float = SCREEN_HALF_ANGLE_DEG, d: float = 1.0):
    """A grid of pointing targets covering the screen area of the Donders experiments.

    **Arguments:**

    - ``n``: targets per axis.
    - ``half_angle_deg``: the area's half-angle [deg], in (0, 90): ``|x_i| ≤ d sin(half_angle)``.
    - ``d``: screen distance [m] (Eq 6).

    **Returns:**

    (n², 2) screen points [m].

    **Raises:**

    - ``ValueError`` naming the argument for a non-positive ``n`` or ``d``, or a half-angle outside
      (0, 90).
    """
    n = check_positive_int("n", n)
    check_positive("d", d)
    if not (np.isfinite(half_angle_deg) and 0 < half_angle_deg < 90):
        raise ValueError(f"`half_angle_deg` must be in (0, 90), got {half_angle_deg}")
    h = d * np.sin(np.deg2rad(half_angle_deg))
    g = np.linspace(-h, h, n)
    return np.stack(np.meshgrid(g, g, indexing="ij"), -1).reshape(-1, 2)


def model_donders_surface(KJ, q_rest, pointing=None, *, chain: Wrist | None = None):
    """The λ0-PMP's Donders surface: its equilibrium postures over a grid of pointing targets.

    The equilibria (:func:`equilibrium_posture`) of ``(KJ, q_rest)`` at ``pointing``, their rotation
    vectors, and the surface fitted to them. Differentiable in ``KJ`` and ``q_rest``.

    **Arguments:**

    - ``KJ``: (..., 3, 3) SPD joint stiffness [Nm/rad].
    - ``q_rest``: (..., 3) rest posture [rad].
    - ``pointing``: (P, 2) screen targets [m] (default a 9 × 9 grid over ±20°, :func:`screen_grid`).
    - ``chain``: the :class:`Wrist` (default ``Wrist(d=1.0)``).

    **Returns:**

    ``(surface, r, q)``: the :class:`DondersSurface`, (..., P, 3) rotation vectors [rad] and
    (..., P, 3) postures [rad].

    **Raises:**

    - ``TypeError`` for a chain that is not a ``Wrist``; ``ValueError`` naming the argument for wrong
      shapes, non-SPD ``KJ`` or unreachable ``pointing``.
    """
    chain = Wrist() if chain is None else chain
    if not isinstance(chain, Wrist):
        raise TypeError(f"`chain` must be a pmpjax.Wrist (Donders surfaces are of wrist postures), got {chain!r}")
    pointing = screen_grid() if pointing is None else as_array("pointing", pointing, tail=(None, 2))
    if np.ndim(pointing) != 2:
        raise ValueError(f"`pointing` must have shape (P, 2), got {np.shape(pointing)}")
    chain.check_target("pointing", pointing)
    KJ = to_jax(as_array("KJ", KJ, tail=(3, 3)))
    q_rest = to_jax(as_array("q_rest", q_rest, tail=(3,)))
    KJ, q_rest = on_host(KJ, lambda a: a[..., None, :, :]), on_host(q_rest, lambda a: a[..., None, :])
    q = equilibrium_posture(chain, KJ, q_rest, pointing).q
    r = rotvec_from_joint_angles(q)
    return fit_donders_surface(r), r, q


def plot_donders(r=None, surfaces=(), *, labels=None, ax=None, extent=np.deg2rad(20.0), n=15):
    """3-D plot of rotation-vector samples and Donders surfaces (degrees on all axes).

    Axes: ``r_y`` and ``r_z`` horizontal, torsion ``r_x`` vertical.

    **Arguments:**

    - ``r``: optional (N, 3) rotation vectors [rad] drawn as points.
    - ``surfaces``: a sequence of :class:`DondersSurface` or (6,) coefficient vectors.
    - ``labels``: legend labels, one per surface.
    - ``ax``: a matplotlib 3-D ``Axes`` to draw into (default a new figure).
    - ``extent``: half-width of the drawn surfaces [rad].
    - ``n``: grid points per axis of each surface.

    **Returns:**

    The matplotlib ``Axes``.
    """
    import matplotlib.pyplot as plt

    if r is not None:
        r = as_array("r", r, tail=(3,))
    if ax is None:
        ax = plt.figure(figsize=(6, 5)).add_subplot(projection="3d")
    deg = np.rad2deg
    if r is not None:
        r = np.asarray(r)
        ax.scatter(deg(r[..., 1]), deg(r[..., 2]), deg(r[..., 0]), s=4, alpha=0.5, label="data")
    if isinstance(surfaces, DondersSurface) or (
        not isinstance(surfaces, list | tuple) and np.ndim(surfaces) == 1
    ):
        surfaces = [surfaces]
    for i, s in enumerate(surfaces):
        ry, rz, rx = (np.asarray(a) for a in surface_grid(s, extent=extent, n=n))
        lab = labels[i] if labels is not None else None
        ax.plot_wireframe(deg(ry), deg(rz), deg(rx), color=f"C{i + 1}", linewidth=0.6, label=lab)
    ax.set_xlabel("r_y [deg]")
    ax.set_ylabel("r_z [deg]")
    ax.set_zlabel("torsion r_x [deg]")
    if r is not None or labels is not None:
        ax.legend(loc="upper left", fontsize="small")
    return ax
