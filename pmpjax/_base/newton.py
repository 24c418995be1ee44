"""The one Newton solver: a damped Newton loop for ``F(y, θ) = 0`` with implicit gradients.

Used by the λ0-PMP equilibria (``pmpjax._pmp.equilibria``: ``y = (q, λ)``, the KKT system with its
augmented-Lagrangian solve) and by the springy arm's equilibrium under gravity
(``pmpjax._springy_arm.primitives``: ``y = θ``, ``K (θ − θ_set) + ∇V(θ) = 0``). A problem
supplies its residual ``F`` and a solver of its Newton system ``(∂F/∂y) δ = rhs``; the loop, the
step cap and the differentiation rule are here.

**Loop.** ``δ = solve(y, −F(y))``; the step is scaled so that ``max |measure(δ)| <= step_cap``
(a far start cannot jump across the workspace; ``measure`` picks the part of ``y`` the cap and the
stopping test look at, e.g. the joint angles of ``(q, λ)``). It stops when
``max |measure(δ)| <= tol (1 + max |measure(y)|)`` or after ``max_steps`` steps (a ``while_loop``:
under ``vmap`` every lane runs until the slowest has stopped; finished lanes take zero steps). A
NaN step stops the loop (the iterate stays non-finite and the caller's status says so).

**Gradients** by the implicit function theorem (as optimistix ``ImplicitAdjoint``), never by
stepping back through the iterations: with ``F(y*(θ), θ) = 0``,
``(∂F/∂y) ẏ = −(∂F/∂θ) θ̇`` — one more call of the same ``solve`` per tangent (``jax.custom_jvp``;
reverse mode by JAX's transposition of the JVP, so ``solve`` must be linear in ``rhs``). Tangents of
``y0`` (the solution does not depend on the start) and of ``consts`` (data the caller declares
constant, e.g. a MuJoCo model whose derivatives would cost minutes of compile time) are ignored.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import partial
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

Residual = Callable[[Any, Any, Any], Any]
"""``F(y, params, consts)`` -> a pytree like ``y``."""
LinearSolve = Callable[[Any, Any, Any, Any], Any]
"""``solve(y, params, consts, rhs)`` -> ``δ`` with ``(∂F/∂y)(y) δ = rhs`` (``rhs``, ``δ`` like ``y``)."""


def _max_abs(tree):
    return jnp.max(jnp.stack([jnp.max(jnp.abs(a)) for a in jax.tree_util.tree_leaves(tree)]))


def _identity(y):
    return y


def newton_solve(
    residual: Residual,
    solve: LinearSolve,
    y0,
    params,
    consts=None,
    *,
    max_steps: int,
    tol: float = 0.0,
    step_cap: float | None = None,
    measure: Callable[[Any], Any] = _identity,
):
    """Solve ``residual(y, params, consts) = 0`` for ``y`` by damped Newton from ``y0``.

    **Arguments:** ``residual`` and ``solve`` as in the module docstring; ``y0`` a pytree of arrays;
    ``params`` a pytree differentiated implicitly; ``consts`` a pytree whose tangents are ignored;
    ``max_steps`` the step limit; ``tol`` the relative step tolerance (0: run ``max_steps`` steps
    unless a step is exactly zero); ``step_cap`` the largest ``max |measure(δ)|`` of a step (None:
    no cap); ``measure`` the part of ``y`` (and ``δ``) the cap and the test look at.

    Returns ``(y, steps)``: the solution (differentiable in ``params``) and the number of steps
    taken (int; ``steps == max_steps`` with a large residual means the limit was hit).
    """
    return _solve(residual, solve, measure, int(max_steps), float(tol), step_cap, y0, params, consts)


@partial(jax.custom_jvp, nondiff_argnums=(0, 1, 2, 3, 4, 5))
def _solve(residual, solve, measure, max_steps, tol, step_cap, y0, params, consts):
    def cond(s):
        y, big, it = s
        return (it < max_steps) & (big > tol * (1.0 + _max_abs(measure(y))))

    def body(s):
        y, _, it = s
        F = residual(y, params, consts)
        d = solve(y, params, consts, jax.tree_util.tree_map(jnp.negative, F))
        big = _max_abs(measure(d))
        # (a zero step in the measured part keeps alpha = 1: the rest of y still takes its full step)
        alpha = 1.0 if step_cap is None else jnp.where(big > step_cap, step_cap / jnp.where(big > 0, big, 1.0), 1.0)
        y = jax.tree_util.tree_map(lambda a, b: a + alpha * b, y, d)
        return y, jnp.where(jnp.isnan(big), 0.0, big), it + 1

    leaf = jax.tree_util.tree_leaves(y0)[0]
    init = (y0, jnp.asarray(jnp.inf, leaf.dtype), jnp.asarray(0))
    y, _, steps = jax.lax.while_loop(cond, body, init)
    return y, steps


@_solve.defjvp
def _solve_jvp(residual, solve, measure, max_steps, tol, step_cap, primals, tangents):
    y0, params, consts = primals
    _, dparams, _ = tangents
    y, steps = _solve(residual, solve, measure, max_steps, tol, step_cap, y0, params, consts)
    # Implicit function theorem: (∂F/∂y) ẏ = −(∂F/∂θ) θ̇ at the solution.
    _, dF = jax.jvp(lambda p: residual(y, p, consts), (params,), (dparams,))
    dy = solve(y, params, consts, jax.tree_util.tree_map(jnp.negative, dF))
    return (y, steps), (dy, np.zeros(np.shape(steps), dtype=jax.dtypes.float0))
