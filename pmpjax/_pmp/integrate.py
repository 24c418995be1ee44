"""The one ODE integrator: fixed-step classical RK4 or the L-stable Rosenbrock method RODAS4, in
nested ``lax.scan`` loops.

**RK4** (default) was chosen by measurement against diffrax (``benchmarks/integrators.py``): on
0.4 s wrist movements at dt = 1 ms it is 8e-13 rad accurate (fourth order: 1.1e-11 at 2 ms), as
fast per step as diffrax's fixed-step solvers, and compiles faster. Being explicit, it is stable
only for ``|λ| h < 2.78``, and Eq 10's gain makes the λ0-PMP stiff (fastest rate
``cond(J W⁻¹ Jᵀ)/τ0``): anisotropic stiffness needs thousands of steps per movement.

**RODAS4** (Hairer & Wanner, *Solving ODEs II*, IV.7; the coefficients of their ``rodas.f``):
a linearly implicit (Rosenbrock) method of order 4 with six stages, L-stable and stiffly accurate,
so stiff modes are damped at any step size and the step is set by accuracy alone. One step costs
the exact Jacobian ``∂f/∂y`` and ``∂f/∂t`` by forward-mode autodiff (``n + 1`` JVPs of one
linearisation), one LU factorisation with partial pivoting of ``I/(γh) − ∂f/∂y`` per trajectory
(unrolled over the components, batch trailing) and six field evaluations; no Newton iteration,
so the cost of a step is fixed and batches stay in lockstep. Chosen by measurement against
diffrax's Kvaerno5/KenCarp4 and SciPy's Radau/BDF (``benchmarks/stiff.py``).

Fixed steps keep shapes static (a batch moves in lockstep, saves fall on the step grid, cost is
known in advance), forward and reverse mode through ``scan`` give the exact derivative of the
discrete solution, and the core needs no diffrax.

The time axis is cut into ``len(t0s)`` save segments, each integrated with ``n_steps`` equal
steps of size ``hs[i]``. :func:`integrate` records ``save(t, y)`` at the end of every segment as
stacked scan outputs (simple; one extra field evaluation per sample). :func:`integrate_observed`
(``simulate``) lets the field return an observation of the state it is evaluated at and hands the
observations of segment starts, in blocks, to a ``write`` that puts them in place: with one step
per segment they come from the step's first stage at no extra cost. ``stage_loop=True`` evaluates
the stages in a loop (the field traced once; ``simulate`` uses it for derivatives only).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
from jax import lax

from .._base import lu_factor_lists, lu_solve_lists


def rk4_step(f: Callable, t, y, h, args, *, observed: bool = False, stage_loop: bool = False):
    """One classical Runge–Kutta step of ``ẏ = f(t, y, args)`` for pytree ``y``.

    With ``observed=True`` ``f`` returns ``(ẏ, obs)`` and the step returns ``(y_next, obs)``, the
    observation of its first stage, i.e. of ``(t, y)`` (the other stages' are dead code).
    ``stage_loop``: evaluate the four stages in a ``fori_loop`` (``f`` appears once in the graph
    instead of four times: smaller compiled graphs, slower runs at large batches).
    """
    g = f if observed else (lambda t_, y_, a_: (f(t_, y_, a_), None))
    add = lambda a, b, c: jax.tree_util.tree_map(lambda u, v: u + c * v, a, b)  # noqa: E731
    if stage_loop:
        k1, k2, k3, k4, obs = _stages_loop(g, t, y, h, args)
    else:
        k1, obs = g(t, y, args)
        k2 = g(t + 0.5 * h, add(y, k1, 0.5 * h), args)[0]
        k3 = g(t + 0.5 * h, add(y, k2, 0.5 * h), args)[0]
        k4 = g(t + h, add(y, k3, h), args)[0]
    y_next = jax.tree_util.tree_map(
        lambda y_, a, b, c, d: y_ + (h / 6.0) * (a + 2.0 * (b + c) + d), y, k1, k2, k3, k4
    )
    return (y_next, obs) if observed else y_next


def _stages_loop(g, t, y, h, args):
    """The four RK4 stages ``k1..k4`` and stage 1's observation, ``g`` traced once."""
    tm = jax.tree_util.tree_map
    kz = tm(jnp.zeros_like, y)
    obs0 = tm(lambda s: jnp.zeros(s.shape, s.dtype), jax.eval_shape(g, t, y, args)[1])
    ks0 = tm(lambda z: jnp.stack([z] * 4), kz)
    cs = jnp.array([0.0, 0.5, 0.5, 1.0], dtype=jnp.result_type(float))

    def stage(i, carry):
        ks, obs = carry
        c = cs[i] * h
        prev = tm(lambda k: k[jnp.maximum(i - 1, 0)], ks)
        yi = tm(lambda u, v: u + c * v, y, prev)  # stage 1: c = 0 and prev = 0
        k, o = g(t + c, yi, args)
        ks = tm(lambda a, b: a.at[i].set(b), ks, k)
        obs = tm(lambda a, b: jnp.where(i == 0, b, a), obs, o)
        return ks, obs

    ks, obs = lax.fori_loop(0, 4, stage, (ks0, obs0))
    k1, k2, k3, k4 = (tm(lambda k, j=j: k[j], ks) for j in range(4))
    return k1, k2, k3, k4, obs



@dataclasses.dataclass(frozen=True)
class RosenbrockTableau:
    """A Rosenbrock method in the form of Hairer & Wanner (IV.7.25) that needs no products with
    the Jacobian: stage ``i`` solves ``(I/(γh) − ∂f/∂y) U_i = f(t + α_i h, y + Σ_j a_ij U_j) +
    Σ_j (c_ij/h) U_j + d_i h ∂f/∂t`` and ``y_next = y + Σ_i m_i U_i``."""

    name: str
    gamma: float
    alpha: tuple[float, ...]
    d: tuple[float, ...]
    a: tuple[tuple[float, ...], ...]  # row i: a_i0 .. a_i,i-1
    c: tuple[tuple[float, ...], ...]  # row i: c_i0 .. c_i,i-1
    m: tuple[float, ...]


_A5 = (1.221224509226641, 6.019134481288629, 12.53708332932087, -0.6878860361058950)

#: RODAS4 (Hairer & Wanner's ``rodas.f``, METH = 1): order 4, L-stable, stiffly accurate.
RODAS4 = RosenbrockTableau(
    name="rodas4",
    gamma=0.25,
    alpha=(0.0, 0.386, 0.21, 0.63, 1.0, 1.0),
    d=(0.25, -0.1043, 0.1035, -0.3620000000000023e-01, 0.0, 0.0),
    a=((), (1.544,), (0.9466785280815826, 0.2557011698983284),
       (3.314825187068521, 2.896124015972201, 0.9986419139977817), _A5, _A5 + (1.0,)),
    c=((), (-5.6688,), (-2.430093356833875, -0.2063599157091915),
       (-0.1073529058151375, -9.594562251023355, -20.47028614809616),
       (7.496443313967647, -10.24680431464352, -33.99990352819905, 11.70890893206160),
       (8.083246795921522, -7.981132988064893, -31.52159432874371, 16.31930543123136, -6.058818238834054)),
    m=_A5 + (1.0, 1.0),
)

#: Solver names accepted by ``simulate(..., solver=)``.
SOLVERS = ("rk4", "rodas4")


def rosenbrock_step(f: Callable, t, y, h, args, *, observed: bool = False, stage_loop: bool = False,
                    tableau: RosenbrockTableau = RODAS4, frozen=None):
    """One Rosenbrock step of ``ẏ = f(t, y, args)`` for a component-leading array ``y`` (n, ...)
    whose batch elements are independent (``f`` acts elementwise over the trailing axes, as the
    fields of ``simulate`` do), with the exact Jacobian of ``f`` by forward-mode autodiff.

    ``observed``/``stage_loop`` as :func:`rk4_step` (the observation is that of the linearisation
    point ``(t, y)``); with ``observed=True`` returns ``(y_next, obs, err)``, ``err`` the last stage
    increment: the difference to the embedded order-3 solution (Hairer & Wanner's ``rodas.f``).

    ``frozen``: None, or a traced bool; where true, forward-mode derivatives through the step hold
    the field's Jacobian fixed (no second derivatives of ``f``: the derivative of a Rosenbrock-W
    step with RODAS4's coefficients, not of this step; about half the cost of a fit's Jacobian
    through ``simulate``). The step itself is unchanged.
    """
    g = f if observed else (lambda t_, y_, a_: (f(t_, y_, a_), None))
    n = y.shape[0]

    def linearisation():
        f0, lin, obs = jax.linearize(lambda t_, y_: g(t_, y_, args), t, y, has_aux=True)
        # n Jacobian columns (unit tangents of every trajectory's component j) and ∂f/∂t, in one vmap.
        eye = jnp.eye(n + 1, n, dtype=y.dtype).reshape((n + 1, n) + (1,) * (y.ndim - 1))
        t_dir = jnp.zeros((n + 1,) + jnp.shape(t), jnp.result_type(t)).at[n].set(1.0)
        return f0, jax.vmap(lin)(t_dir, jnp.broadcast_to(eye, (n + 1,) + y.shape)), obs

    def held():  # (the held Jacobian's tangents are dead code)
        f0, cols, obs = linearisation()
        return f0, lax.stop_gradient(cols), obs

    f0, cols, obs = linearisation() if frozen is None else lax.cond(frozen, held, linearisation)
    ft = cols[n]
    inv_gh = 1.0 / (tableau.gamma * h)
    lu = lu_factor_lists([[(inv_gh if i == j else 0.0) - cols[j][i] for j in range(n)] for i in range(n)])
    solve = lambda rhs: jnp.stack(lu_solve_lists(lu, [rhs[i] for i in range(n)]))  # noqa: E731
    s = len(tableau.alpha)
    if stage_loop:
        U = _rosenbrock_stages_loop(g, t, y, h, args, f0, ft, solve, tableau)
    else:
        U = []
        hy = _state_step(h)
        for i in range(s):
            fi = f0 if i == 0 else g(t + tableau.alpha[i] * h, y + sum(a * u for a, u in zip(tableau.a[i], U)), args)[0]
            rhs = fi + tableau.d[i] * hy * ft
            for cij, u in zip(tableau.c[i], U):
                rhs = rhs + (cij / hy) * u
            U.append(solve(rhs))
    y_next = y + sum(mi * u for mi, u in zip(tableau.m, U))
    # Stiffly accurate: the embedded solution is the last stage's argument, so U_s is its error.
    return (y_next, obs, U[-1]) if observed else y_next


def _rosenbrock_stages_loop(g, t, y, h, args, f0, ft, solve, tableau):
    """The stage increments ``U_0 .. U_{s−1}`` with stages 1.. in a ``fori_loop`` (``g`` traced once)."""
    s = len(tableau.alpha)
    dt = y.dtype
    lower = lambda rows: jnp.array([list(r) + [0.0] * (s - len(r)) for r in rows], dt)  # noqa: E731
    A, C = lower(tableau.a), lower(tableau.c)
    alpha, d = jnp.array(tableau.alpha, dt), jnp.array(tableau.d, dt)
    hy = _state_step(h)
    U0 = jnp.zeros((s,) + y.shape, dt).at[0].set(solve(f0 + tableau.d[0] * hy * ft))

    def stage(i, U):
        yi = y + jnp.tensordot(A[i], U, axes=1)
        rhs = g(t + alpha[i] * h, yi, args)[0] + jnp.tensordot(C[i], U, axes=1) / hy + d[i] * hy * ft
        return U.at[i].set(solve(rhs))

    U = lax.fori_loop(1, s, stage, U0)
    return [U[i] for i in range(s)]


def step_function(solver: str) -> Callable:
    """The one-step function of a solver name in :data:`SOLVERS`."""
    return {"rk4": rk4_step, "rodas4": rosenbrock_step}[solver]


def integrate(
    f: Callable, y0: Any, t0s, hs, n_steps: int, args: Any, save: Callable, *, unroll: int = 1,
    solver: str = "rk4",
):
    """Integrate ``ẏ = f(t, y, args)`` over consecutive segments and save at their ends.

    **Arguments:** ``t0s`` (S,) segment start times, ``hs`` (S,) step sizes, ``n_steps`` static
    steps per segment, ``save(t, y, args)`` -> pytree. **Returns:** ``(y_final, saved)`` with a
    leading (S,) axis on every saved leaf. ``solver``: one of :data:`SOLVERS` (``"rodas4"`` needs
    a component-leading array ``y``).
    """
    one_step = step_function(solver)

    def segment(y, seg):
        t0, h = seg

        # Rematerialised: reverse mode stores one state per step, not every stage's intermediates.
        @jax.checkpoint
        def step(y, i):
            return one_step(f, t0 + i * h, y, h, args), None

        y, _ = lax.scan(step, y, jnp.arange(n_steps, dtype=jnp.result_type(float)), unroll=unroll)
        return y, save(t0 + n_steps * h, y, args)

    return lax.scan(segment, y0, (t0s, hs))


def rk4_fsal_step(g: Callable, t, y, h, args, k1, *, stage_loop: bool = False):
    """One classical RK4 step of a component-leading array ``y`` whose first stage ``k1 = f(t, y)``
    is given, with an embedded third-order error estimate at no extra field evaluation.

    ``g(t, y, args) -> (ẏ, obs)``. The fifth evaluation ``(k5, obs5) = g(t + h, y_next)`` is the
    next step's first stage (first same as last). With it, ``ŷ = y + h (k1 + 2 k2 + 2 k3 + k5)/6``
    is of order three (weights (1/6, 1/3, 1/3, 0, 1/6) satisfy the four order-3 conditions), so
    ``err = y_next − ŷ = h (k4 − k5)/6`` estimates the local error of the lower-order solution
    (a bound, O(h⁴), on the order-4 step's O(h⁵) error).
    **Returns:** ``(y_next, k5, obs5, err)``.
    """
    if stage_loop:
        return _fsal_stages_loop(g, t, y, h, args, k1)
    hy = _state_step(h)
    k2 = g(t + 0.5 * h, y + (0.5 * hy) * k1, args)[0]
    k3 = g(t + 0.5 * h, y + (0.5 * hy) * k2, args)[0]
    k4 = g(t + h, y + hy * k3, args)[0]
    y_next = y + (hy / 6.0) * (k1 + 2.0 * (k2 + k3) + k4)
    k5, obs5 = g(t + h, y_next, args)
    return y_next, k5, obs5, (hy / 6.0) * (k4 - k5)


def _state_step(h):
    """A step size that multiplies component-leading states: scalar, or a per-trajectory (...)
    array lifted to (1, ...) (adaptive steps)."""
    return h if jnp.ndim(h) == 0 else h[None]


#: Stages 2–5 of :func:`rk4_fsal_step` as rows over ``(k1, k2, k3, k4)``, and their times.
_FSAL_A = ((0.5, 0.0, 0.0, 0.0), (0.0, 0.5, 0.0, 0.0), (0.0, 0.0, 1.0, 0.0), (1 / 6, 1 / 3, 1 / 3, 1 / 6))
_FSAL_C = (0.5, 0.5, 1.0, 1.0)


def _fsal_stages_loop(g, t, y, h, args, k1):
    """:func:`rk4_fsal_step` with stages 2–5 in a ``fori_loop`` (``g`` traced once)."""
    dt = y.dtype
    A, c = jnp.array(_FSAL_A, dt), jnp.array(_FSAL_C, dt)
    obs0 = jax.tree_util.tree_map(lambda s: jnp.zeros(s.shape, s.dtype), jax.eval_shape(g, t, y, args)[1])
    ks0 = jnp.zeros((5,) + y.shape, dt).at[0].set(k1)

    hy = _state_step(h)

    def stage(i, carry):
        ks, _, obs = carry
        yi = y + hy * jnp.tensordot(A[i], ks[:4], axes=1)
        k, o = g(t + c[i] * h, yi, args)
        return ks.at[i + 1].set(k), yi, o

    ks, y_next, obs5 = lax.fori_loop(0, 4, stage, (ks0, y, obs0))
    return y_next, ks[4], obs5, (hy / 6.0) * (ks[3] - ks[4])


def _error_norm(e):
    """Largest component of a component-leading local error ``e`` (n, ...) -> (...)."""
    return jnp.max(jnp.abs(e), axis=0)


def integrate_observed(
    f: Callable, y0: Any, t0s, hs, n_steps: int, args: Any, acc: Any, write: Callable | None, *,
    block: int = 1, unroll: int = 1, stage_loop: bool = False, solver: str = "rk4", frozen=None,
):
    """Integrate ``ẏ = f(t, y, args)[0]`` over consecutive segments, observing their starts, and
    accumulate the solver's embedded local error estimates.

    **Arguments:** ``f(t, y, args) -> (ẏ, obs)`` for a component-leading array ``y0`` (n, ...);
    ``t0s`` (S,) segment start times, ``hs`` (S,) step sizes or one Python float for all (a
    compile-time constant: XLA fuses a step size read per segment into every elementwise loop,
    measured 2× slower with one step per segment), ``n_steps`` static steps per segment;
    ``write(acc, i, obs) -> acc`` receives the observations of the starts of segments
    ``i, ..., i + block − 1`` stacked on a leading ``(block,)`` axis (``block`` divides S);
    ``write=None`` observes nothing. ``solver``: one of :data:`SOLVERS`; ``frozen``: RODAS4's
    (:func:`rosenbrock_step`).

    RK4 carries its first stage from step to step (:func:`rk4_fsal_step`): the observations of
    segment starts and of the end come free. RODAS4 observes its linearisation point: free with
    ``n_steps == 1``, otherwise one extra evaluation per segment, and one at the end.

    **Returns:** ``(y_final, acc, error, obs_end)``: ``error`` (...) the sum over steps of the
    largest component of the embedded local error estimate (RK4: :func:`rk4_fsal_step`; RODAS4:
    the last stage increment, Hairer & Wanner's ``rodas.f``), ``obs_end`` the observation of the
    final state.

    Keep ``write`` linear in ``obs`` (e.g. ``dynamic_update_slice`` into a buffer in ``acc``) so
    that reverse mode stores no per-segment copy of ``acc``.
    """
    t0s = jnp.asarray(t0s)
    S = t0s.shape[0]
    uniform = isinstance(hs, float)
    segs = (t0s,) if uniform else (t0s, jnp.asarray(hs))
    seg_h = (lambda s: (s[0], hs)) if uniform else (lambda s: s)  # noqa: E731
    rk4 = solver == "rk4"
    if solver not in SOLVERS:
        raise ValueError(f"unknown solver {solver!r}")

    # Rematerialised: reverse mode stores one state per step, not every stage's intermediates.
    if rk4:
        @jax.checkpoint
        def step(t, c, h):
            y, (k1, obs), err = c
            y_next, k5, obs5, e = rk4_fsal_step(f, t, y, h, args, k1, stage_loop=stage_loop)
            return (y_next, (k5, obs5), err + lax.stop_gradient(_error_norm(e))), obs
    else:
        @jax.checkpoint
        def step(t, c, h):
            y, _, err = c
            y_next, obs, e = rosenbrock_step(f, t, y, h, args, observed=True, stage_loop=stage_loop,
                                                 frozen=frozen)
            return (y_next, None, err + lax.stop_gradient(_error_norm(e))), obs

    observe = jax.checkpoint(lambda t, y: f(t, y, args)[1])

    def run_steps(c, t0, h):
        def body(c, i):
            return step(t0 + i * h, c, h)[0], None

        return lax.scan(body, c, jnp.arange(n_steps, dtype=jnp.result_type(float)), unroll=unroll)[0]

    err0 = jnp.zeros(y0.shape[1:], y0.dtype)
    c0 = (y0, f(t0s[0], y0, args) if rk4 else None, err0)

    def end(c):
        y, fsal, err = c
        if rk4:
            return y, err, fsal[1]
        t_end = t0s[-1] + n_steps * (hs if uniform else jnp.asarray(hs)[-1])
        return y, err, observe(t_end, y)

    if write is None:
        c = lax.scan(lambda c, s: (run_steps(c, *seg_h(s)), None), c0, segs)[0]
        y, err, obs_end = end(c)
        return y, acc, err, obs_end
    if S % block:
        raise ValueError(f"block={block} must divide the number of segments {S}")

    def segment(c, s):
        t0, h = seg_h(s)
        if n_steps == 1:
            return step(t0, c, h)
        obs = c[1][1] if rk4 else observe(t0, c[0])
        return run_steps(c, t0, h), obs

    def blk(carry, s):
        c, a = carry
        (c, obs) = lax.scan(segment, c, s[1:])
        return (c, write(a, s[0][0], obs)), None

    blocks = tuple(v.reshape(S // block, block) for v in (jnp.arange(S),) + segs)
    c, acc = lax.scan(blk, (c0, acc), blocks)[0]
    y, err, obs_end = end(c)
    return y, acc, err, obs_end


#: PI step-size controller (Hairer & Wanner II, IV.2; Gustafsson): ``h_new = h · safety ·
#: r^(−0.7/k) · r_prev^(0.4/k)`` for the error-per-unit-step ratio ``r`` ∝ h³ of both pairs (k = 3),
#: each factor clipped to [FACTOR_MIN, FACTOR_MAX] (at most 1 after a rejected step).
SAFETY, FACTOR_MIN, FACTOR_MAX = 0.9, 0.2, 10.0
_BETA1, _BETA2 = 0.7 / 3, 0.4 / 3


def integrate_adaptive(
    f: Callable, y0, ts, include_initial: bool, args: Any, acc: Any, write: Callable, *, solver: str,
    rtol: float, atol: float, max_steps: int, span: float, h0: float,
):
    """Integrate ``ẏ = f(t, y, args)[0]`` from ``t = 0`` with adaptive steps, each trajectory of the
    component-leading ``y0`` (n, B) with its own step size, landing on every save time.

    A step is accepted when its embedded local error estimate ``e`` (:func:`rk4_fsal_step`, or
    RODAS4's last stage) meets ``max_i |e_i| / (atol + rtol · max(|y_i|, |y_next_i|)) ≤ h / span``
    (error per unit step: the accepted estimates then sum to at most the tolerance over ``span``);
    step sizes follow a PI controller and are not differentiated (forward-mode derivatives are
    those of the accepted discrete steps). The batch moves in lockstep: a ``while_loop`` runs until
    every trajectory has recorded every save time or ``max_steps`` iterations have run.

    **Arguments:** ``ts`` (S,) increasing save times (a tuple; the integration ends at ``ts[-1]``);
    ``include_initial``: ``ts[0] == 0`` is recorded; ``write(acc, j, obs, mask) -> acc`` records
    the observation ``obs`` (*comp, B) of save time ``j`` (B,) where ``mask`` (B,).
    **Returns:** ``(y_final, acc, error (B,), steps (B,), done (B,))``: ``error`` the sum of the
    accepted steps' estimates [units of y], ``steps`` the steps tried, ``done`` every save time
    recorded (otherwise ``max_steps`` ran out).
    """
    if solver not in SOLVERS:
        raise ValueError(f"unknown solver {solver!r}")
    rk4 = solver == "rk4"
    dt = y0.dtype
    B = y0.shape[1:]
    S = len(ts)
    ts_arr = jnp.asarray(ts, dt)
    t = jnp.zeros(B, dt)
    fsal = f(t, y0, args) if rk4 else None
    h = jnp.full(B, min(h0, ts[0] if ts[0] > 0 else (ts[1] if S > 1 else h0)), dt)
    carry = dict(t=t, y=y0, fsal=fsal, h=h, j=jnp.zeros(B, jnp.int32), pending=jnp.full(B, bool(include_initial)),
                 err=jnp.zeros(B, dt), r_prev=jnp.ones(B, dt), steps=jnp.zeros(B, jnp.int32), it=0, acc=acc)

    def cond(c):
        return jnp.any(c["j"] < S) & (c["it"] < max_steps)

    def body(c):
        t, y, h, j, pending = c["t"], c["y"], c["h"], c["j"], c["pending"]
        j_eff = j + pending.astype(j.dtype)
        active = j_eff < S
        target = ts_arr[jnp.minimum(j_eff, S - 1)]
        gap = target - t
        clipped = h >= gap
        h_eff = lax.stop_gradient(jnp.where(active, jnp.where(clipped, gap, h), h))
        if rk4:
            k1, obs = c["fsal"]
            y_next, k5, obs5, e = rk4_fsal_step(f, t, y, h_eff, args, k1)
        else:
            y_next, obs, e = rosenbrock_step(f, t, y, h_eff, args, observed=True)
        acc = write(c["acc"], j, obs, pending)
        scale = atol + rtol * jnp.maximum(jnp.abs(y), jnp.abs(y_next))
        ratio = lax.stop_gradient(jnp.max(jnp.abs(e) / scale, axis=0) * (span / h_eff))
        ok = jnp.isfinite(ratio) & jnp.all(jnp.isfinite(y_next), axis=0)
        accept = active & ok & (ratio <= 1.0)
        t_next = jnp.where(accept, jnp.where(clipped, target, t + h_eff), t)
        y = jnp.where(accept[None], y_next, y)
        if rk4:
            fsal = jax.tree_util.tree_map(lambda new, old: jnp.where(accept, new, old), (k5, obs5), c["fsal"])
        else:
            fsal = c["fsal"]
        r = jnp.where(ok, jnp.maximum(ratio, 1e-10), 1.0)
        factor = SAFETY * r ** (-_BETA1) * c["r_prev"] ** _BETA2
        factor = jnp.clip(jnp.where(ok, factor, FACTOR_MIN), FACTOR_MIN, jnp.where(accept, FACTOR_MAX, 1.0))
        h_new = h_eff * factor
        h_new = jnp.where(accept & clipped, jnp.maximum(h, h_new), h_new)
        return dict(t=t_next, y=y, fsal=fsal, h=lax.stop_gradient(jnp.where(active, h_new, h)),
                    j=j + pending.astype(j.dtype), pending=accept & clipped,
                    err=c["err"] + jnp.where(accept, lax.stop_gradient(_error_norm(e)), 0.0),
                    r_prev=jnp.where(accept, r, c["r_prev"]), steps=c["steps"] + active.astype(jnp.int32),
                    it=c["it"] + 1, acc=acc)

    c = lax.while_loop(cond, body, carry)
    return c["y"], c["acc"], c["err"], c["steps"], c["j"] >= S
