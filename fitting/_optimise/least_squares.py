"""The one optimiser loop: Levenberg–Marquardt for nonlinear least squares, jit/vmap friendly.

``least_squares`` is written for one problem; batch it with ``jax.vmap`` (each item keeps its
own damping, step count and convergence flag; finished items are frozen while others go on).
Every fit in ``fitting`` (Donders/NIO, time constants, IK-weight gradient variant, primitives)
goes through it. Jacobians of the residual by forward-mode autodiff (parameters are few).

**Why not optimistix**: on the Donders NIO fit (``benchmarks/least_squares_optimistix.py``: the
same residual, starts and step limit) ``optimistix.least_squares(LevenbergMarquardt)`` reaches the
same optima but compiles 1.8× and runs 2.1× slower (its trust-region steps are shorter than
Nielsen's damping update here, and under ``vmap`` every lane waits for the slowest); its one
advantage, implicit gradients of fitted optima, no fit here needs. No optimistix (nor optax)
dependency.
"""

from __future__ import annotations

import jax
import jax.extend.core
import jax.numpy as jnp
import numpy as np
from jax import lax

from pmpjax import Status
from pmpjax.internal import (
    as_array,
    check_positive,
    check_positive_int,
    forward_jacobians,
    is_concrete,
    pytree_dataclass,
    to_jax,
    warn_without_x64,
)


@pytree_dataclass
class LeastSquaresResult:
    """The result of :func:`least_squares` (one problem; leading axes under ``vmap``).

    **Fields:**

    - ``x``: (p,) solution.
    - ``cost``: ``½|r|²`` at ``x``.
    - ``residual``: (N,) ``r`` at ``x``.
    - ``jac``: (N, p) the Jacobian at ``x``.
    - ``grad_norm``: ``|Jᵀr|_∞``.
    - ``steps``: iterations.
    - ``status``: int :class:`pmpjax.Status`: ``SUCCESSFUL`` (a tolerance was met), ``NONFINITE``
      (the start's residual or Jacobian is not finite), ``MAX_STEPS``.

    ``converged`` = ``status == SUCCESSFUL``.
    """

    x: jax.Array
    cost: jax.Array
    residual: jax.Array
    jac: jax.Array
    grad_norm: jax.Array
    steps: jax.Array
    status: jax.Array

    @property
    def converged(self) -> jax.Array:
        return self.status == Status.SUCCESSFUL


#: With ``approximate=True`` the exact Jacobian takes over once the full Gauss–Newton step would
#: lower the cost by less than this many times the statistical tolerance (``stol``): about where
#: the approximate Jacobian's bias stops the progress on the reaching fits.
APPROXIMATE_UNTIL = 100.0
#: ... or once this many steps in a row were rejected (the damping has then grown 64-fold: the
#: approximate Jacobian, not the step length, is in doubt).
APPROXIMATE_REJECTS = 3


def least_squares(
    residual,
    x0,
    args=None,
    *,
    max_steps: int = 100,
    gtol: float = 1e-10,
    ftol: float = 1e-12,
    xtol: float = 1e-12,
    stol: float | None = None,
    damping: float = 1e-3,
    linearise=None,
    approximate: bool = False,
) -> LeastSquaresResult:
    """Minimise ``½ |residual(x, args)|²`` over ``x`` by Levenberg–Marquardt (jit-able, vmappable).

    Marquardt scaling (damping on ``diag(JᵀJ)``) and Nielsen's damping update. Converged when
    ``|Jᵀr|_∞ <= gtol``, or an accepted step changes the cost by ``<= ftol·cost``, or the step is
    ``<= xtol (|x| + xtol)``, or (``stol``, statistical) the full Gauss–Newton step would lower the
    cost by less than ``stol·σ²`` with ``σ² = 2 cost/(N − p)`` (parameters whose Jacobian column is
    exactly zero, held ones, count in neither ``|x|`` nor ``p``): every parameter is then within
    ``√(2 stol)`` standard errors of the optimum (``stol = 1e-4``: 0.014), which is what a fit to
    noisy data can mean by converged, also where the residual is only piecewise smooth (thresholds,
    interpolation) and Levenberg–Marquardt would crawl. Non-finite trial residuals are rejected steps.
    The Jacobian is forward-mode autodiff of ``residual`` unless ``linearise`` is given.

    With ``approximate=True`` the steps come from an approximate Jacobian until a convergence test
    holds: the linearisation is traced inside ``pmpjax.internal.forward_jacobians(frozen=...)``, so
    fixed-step RODAS4 simulations hold their field Jacobian fixed along the tangents (about half
    the cost of a Jacobian through them; a residual may read the flag itself,
    ``pmpjax.internal.frozen_tangents``). The approximate Jacobian moves the stationary point
    (by about 0.1 standard errors on the reaching fits), so when a test holds the exact Jacobian
    is computed at the current point and Levenberg–Marquardt goes on from it: convergence is
    judged, and ``jac`` reported, from the exact Jacobian only (also when ``max_steps`` runs out).
    The exact Jacobian takes over (from the initial damping) when a convergence test holds, the
    statistical one within ``APPROXIMATE_UNTIL`` times ``stol``, after ``APPROXIMATE_REJECTS``
    rejected steps in a row, or at the step limit.

    **Arguments:**

    - ``residual``: a JAX function ``residual(x, args)`` -> (N,) residual vector.
    - ``x0``: (p,) the start.
    - ``args``: a pytree passed to ``residual`` (data; vmap over it to fit many problems at once).
    - ``max_steps``: iterations at most (a traced ``0`` returns the residual and Jacobian at ``x0``).
    - ``gtol``, ``ftol``, ``xtol``: the gradient, cost and step tolerances above (≥ 0).
    - ``stol``: the statistical tolerance above (None: off).
    - ``damping``: the initial Levenberg–Marquardt damping.
    - ``linearise``: optional ``(x, args) -> (r (N,), J (N, p))`` in place of forward-mode autodiff of
      ``residual`` (traced inside ``pmpjax.internal.forward_jacobians``), for Jacobians with known
      structure, e.g. per-item nuisance parameters whose columns one JVP gives together.
    - ``approximate``: steps from an approximate Jacobian until a test holds (above).

    **Returns:**

    A :class:`LeastSquaresResult`.

    **Raises:**

    - ``TypeError`` for a non-callable ``residual`` or ``linearise``; ``ValueError`` naming the
      argument for an ``x0`` that is not 1-D, negative or non-finite tolerances, or a residual that is
      not a 1-D vector.
    """
    if not callable(residual):
        raise TypeError(f"`residual` must be callable residual(x, args), got {type(residual).__name__}")
    if linearise is not None and not callable(linearise):
        raise TypeError(f"`linearise` must be callable linearise(x, args) -> (r, J), got {type(linearise).__name__}")
    warn_without_x64()
    x0 = to_jax(as_array("x0", x0), dtype=jnp.result_type(float))
    if x0.ndim != 1:
        raise ValueError(f"`x0` must be a 1-D parameter vector, got shape {x0.shape}")
    if is_concrete(max_steps):  # (a traced step limit, e.g. per item under lax.map, is the caller's)
        max_steps = check_positive_int("max_steps", max_steps)
    for name, v in (("gtol", gtol), ("ftol", ftol), ("xtol", xtol), ("stol", 0.0 if stol is None else stol)):
        if not (np.isfinite(v) and v >= 0):
            raise ValueError(f"`{name}` must be a finite tolerance >= 0, got {v}")
    check_positive("damping", damping)

    def lin(x, exact):
        # One pass: the residual rides along as jacfwd's aux output (no second primal solve).
        # (simulate's JVP with the tangents folded into its batch: pmpjax.internal.forward_jacobians)
        with forward_jacobians(frozen=jnp.logical_not(exact) if approximate else None):
            if linearise is not None:
                return linearise(x, args)
            J, r = jax.jacfwd(lambda y: (residual(y, args),) * 2, has_aux=True)(x)
        return r, J

    # Traced once: the shapes come from this trace and the loop replays its jaxpr (a separate
    # `eval_shape` of the residual would trace a simulation once more).
    lin_jaxpr, (r_shape, _) = jax.make_jaxpr(lin, return_shape=True)(x0, jnp.asarray(True))
    if r_shape.ndim != 1:
        raise ValueError(f"`residual` must return a 1-D vector, got shape {r_shape.shape}")
    N, p = r_shape.shape[0], x0.shape[0]
    lin = jax.extend.core.jaxpr_as_fun(lin_jaxpr)
    dtype = x0.dtype
    # The initial linearisation is the loop's first pass (`first`), so the residual and its
    # Jacobian appear once in the compiled graph (they dominate compile time for residuals that
    # run a simulation), instead of once before the loop and once inside it.
    state0 = dict(x=x0, r=jnp.zeros((N,), dtype), J=jnp.zeros((N, p), dtype), cost=jnp.asarray(jnp.inf, dtype),
                  lam=jnp.asarray(damping, dtype), nu=jnp.asarray(2.0, dtype), step=jnp.asarray(0),
                  done=jnp.asarray(False), conv=jnp.asarray(False), first=jnp.asarray(True),
                  # (max_steps = 0 asks for the linearisation at x0: the exact one at once)
                  exact=jnp.asarray(not approximate) | (jnp.asarray(max_steps) <= 0), relin=jnp.asarray(False),
                  rejects=jnp.asarray(0))

    def cond(s):  # (the first pass, the linearisation at x0, runs even for a traced max_steps = 0)
        return (~s["done"]) & ((s["step"] < max_steps) | s["first"] | s["relin"])

    def body(s):
        x, r, J, cost, lam, nu, first = s["x"], s["r"], s["J"], s["cost"], s["lam"], s["nu"], s["first"]
        exact, relin = s["exact"], s["relin"]
        again = first | relin  # a pass that linearises at x (no step)
        g = J.T @ r
        H = J.T @ J
        d = jnp.maximum(jnp.diag(H), 1e-12 * jnp.max(jnp.diag(H)) + 1e-300)
        delta = -jnp.linalg.solve(H + lam * jnp.diag(d), g)
        delta = jnp.where(again, 0.0, delta)
        x_new = x + delta
        r_new, J_new = lin(x_new, exact)
        cost_new = 0.5 * jnp.sum(r_new**2)
        pred = -(g @ delta + 0.5 * delta @ (H @ delta))
        ok = jnp.isfinite(cost_new) & jnp.all(jnp.isfinite(J_new))
        rho = jnp.where(ok & (pred > 0), (cost - cost_new) / jnp.where(pred > 0, pred, 1.0), -1.0)
        accept = (rho > 0) | again
        lam_acc = lam * jnp.maximum(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
        active = jnp.any(J != 0, axis=0)  # (a parameter whose column is exactly zero is held, not fitted)
        small_step = ~again & (jnp.linalg.norm(delta) <= xtol * (jnp.linalg.norm(jnp.where(active, x, 0.0)) + xtol))
        small_f = ~again & accept & (jnp.abs(cost - cost_new) <= ftol * cost)
        x, r, J, cost = jax.tree_util.tree_map(
            lambda a, b: jnp.where(accept, a, b), (x_new, r_new, J_new, cost_new), (x, r, J, cost)
        )
        small_g = ~first & (jnp.max(jnp.abs(J.T @ r)) <= gtol)
        conv = small_g | small_f | small_step
        near = conv
        if stol is not None:
            dof = jnp.maximum(N - jnp.sum(active), 1)
            gain = _gauss_newton_gain(J, r) / (stol * 2.0 * cost / dof)
            conv = conv | (~first & (gain <= 1.0))
            near = conv | (~first & (gain <= APPROXIMATE_UNTIL))
        step = s["step"] + jnp.where(again, 0, 1)
        # With an approximate Jacobian a test that holds, the statistical one within
        # APPROXIMATE_UNTIL, rejected steps in a row or the last step send the loop to one more
        # pass at x with the exact Jacobian (from the initial damping), which alone can end it.
        rejects = jnp.where(accept, 0, s["rejects"] + 1)
        to_exact = ~exact & (near | (step >= max_steps) | (rejects >= APPROXIMATE_REJECTS))
        conv = conv & exact
        # A non-finite start stops the loop (reported as not converged).
        done = conv | (first & ~ok)
        lam = jnp.where(again, lam, jnp.where(accept, lam_acc, lam * nu))
        nu = jnp.where(again, nu, jnp.where(accept, 2.0, 2.0 * nu))
        return dict(x=x, r=r, J=J, cost=cost, lam=jnp.where(to_exact, damping, lam).astype(dtype),
                    nu=jnp.where(to_exact, 2.0, nu).astype(dtype), step=step, done=done, conv=conv,
                    first=jnp.asarray(False), exact=exact | to_exact, relin=to_exact & ~done, rejects=rejects)

    s = lax.while_loop(cond, body, state0)
    gn = jnp.max(jnp.abs(s["J"].T @ s["r"]))
    finite = jnp.isfinite(s["cost"]) & jnp.all(jnp.isfinite(s["J"]))
    conv = s["conv"] | (gn <= gtol)
    status = jnp.where(~finite, Status.NONFINITE, jnp.where(conv, Status.SUCCESSFUL, Status.MAX_STEPS))
    return LeastSquaresResult(x=s["x"], cost=s["cost"], residual=s["r"], jac=s["J"], grad_norm=gn,
                              steps=s["step"], status=status)


def _gauss_newton_gain(J, r):
    """Cost decrease ``½ gᵀ (JᵀJ)⁺ g`` (``g = Jᵀr``) that the full Gauss–Newton step predicts.

    From the (p, p) Gauss–Newton matrix with its columns scaled to unit diagonal (an eigenvalue
    decomposition of p × p numbers per iteration, where an SVD of the tall (N, p) Jacobian cost
    about 10 ms per iteration on the reaching fit's N = 32 000): directions whose scaled eigenvalue
    is below ``1e-13`` of the largest (singular values below ~3e-7 of the largest scaled one, at
    the precision of ``JᵀJ``) count as unidentifiable and are left out, as the pseudo-inverse
    leaves out null directions."""
    g = J.T @ r
    H = J.T @ J
    d = jnp.sqrt(jnp.diag(H))
    d = jnp.where(d > 0, d, 1.0)
    w, V = jnp.linalg.eigh(H / d[:, None] / d[None, :])
    z = V.T @ (g / d)
    keep = w > 1e-13 * w[-1]
    return 0.5 * jnp.sum(jnp.where(keep, z**2 / jnp.where(keep, w, 1.0), 0.0))


def covariance(result: LeastSquaresResult, *, rcond: float = 1e-10):
    """Gauss–Newton covariance ``σ² (JᵀJ)⁺`` of a least-squares result, ``σ² = 2 cost / (N − p)``.

    Directions with singular value below ``rcond·s_max`` are unidentifiable (infinite variance is
    replaced by the pseudo-inverse's zero there — check the singular values). Vmappable.

    **Arguments:**

    - ``result``: a :class:`LeastSquaresResult`.
    - ``rcond``: the relative singular-value threshold, in [0, 1).

    **Returns:**

    ``(cov (p, p), stderr (p,), singular_values (p,), right_singular_vectors (p, p))``.

    **Raises:**

    - ``TypeError`` for a non-result; ``ValueError`` for ``rcond`` outside [0, 1).
    """
    if not isinstance(result, LeastSquaresResult):
        raise TypeError(f"`result` must be a LeastSquaresResult, got {type(result).__name__}")
    if not (np.isfinite(rcond) and 0 <= rcond < 1):
        raise ValueError(f"`rcond` must be in [0, 1), got {rcond}")
    J = result.jac
    N, p = J.shape
    U, s, Vt = jnp.linalg.svd(J, full_matrices=False)
    keep = s > rcond * s[0]
    inv_s2 = jnp.where(keep, 1.0 / jnp.where(keep, s, 1.0) ** 2, 0.0)
    sigma2 = 2.0 * result.cost / max(N - p, 1)
    cov = sigma2 * (Vt.T * inv_s2[None, :]) @ Vt
    return cov, jnp.sqrt(jnp.diag(cov)), s, Vt
