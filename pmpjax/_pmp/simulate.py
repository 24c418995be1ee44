"""``simulate``: batched, differentiable PMP movements and movement sequences."""

from __future__ import annotations

import contextlib
import contextvars
import dataclasses
import functools
import math
import os
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from .._base import (
    Status,
    as_array,
    check_positive_int,
    check_seconds,
    fast_compile_applies,
    fast_compile_jit,
    flatten_batch,
    is_concrete,
    mv,
    on_host,
    positive_float,
    pytree_dataclass,
    replace,
    to_jax,
    to_soa,
    top_level,
    warn_without_x64,
)
from .._chains import manipulability_soa
from .integrate import SOLVERS, integrate_adaptive, integrate_observed
from .models import _PMP
from .planners import Planner
from .redundancy import admittance_terms_soa

OK, NONFINITE, SINGULAR = Status.SUCCESSFUL, Status.NONFINITE, Status.SINGULAR
INACCURATE, INVALID_INPUT, MAX_STEPS = Status.INACCURATE, Status.INVALID_INPUT, Status.MAX_STEPS
NOT_REACHED = Status.NOT_REACHED

#: Default tolerances of ``simulate``'s error estimate: a trajectory is ``INACCURATE`` when its
#: accumulated error estimate exceeds ``ATOL + RTOL·max|q|`` [rad] (at most 0.046° for joint
#: angles within ±π, below the 0.05° that the tests hold every successful trajectory to).
RTOL = 1e-4
ATOL = 5e-4
#: Default ``max_steps`` of adaptive steps (``dt=None``): steps tried per movement.
MAX_ADAPTIVE_STEPS = 4096


@dataclasses.dataclass(frozen=True)
class SaveAt:
    """Where :func:`simulate` saves the state.

    **Arguments:**

    - ``every``: every ``every``-th step (default every step, with t = 0 included), or
    - ``ts``: at given times [s], strictly increasing in [0, duration], or
    - ``final``: only at the end.

    Give one of them. Construction raises ``ValueError`` for more than one, or ``ts`` that are not
    finite, non-negative and strictly increasing.
    """

    every: int | None = None
    ts: tuple[float, ...] | None = None
    final: bool = False

    def __post_init__(self):
        given = (self.every is not None) + (self.ts is not None) + bool(self.final)
        if given > 1:
            raise ValueError("SaveAt takes one of `every`, `ts`, `final`")
        if self.every is not None:
            check_positive_int("SaveAt.every", self.every)
        if self.ts is not None:
            ts = np.asarray(self.ts, dtype=float).reshape(-1)
            if ts.size == 0 or not np.all(np.isfinite(ts)) or np.any(np.diff(ts) <= 0) or ts[0] < 0:
                raise ValueError("`SaveAt.ts` must be finite, non-negative and strictly increasing")
            object.__setattr__(self, "ts", tuple(float(v) for v in ts))


@pytree_dataclass
class Trajectory:
    """Saved states. ``t`` (S,) [s] from the start of each movement; ``q`` (..., S, n) [rad];
    ``x`` (..., S, m); ``qdot`` (..., S, n); ``xdot`` (..., S, m); ``manipulability`` (..., S)
    (``sqrt(det J Jᵀ)``). Sequences add an (M,) axis before S.

    ``error_estimate`` (...,) [rad]: the sum over all steps (of every movement of a sequence) of
    the largest joint component of the solver's embedded local error estimate (RK4: a third-order
    companion, :func:`~pmpjax._pmp.integrate.rk4_fsal_step`; RODAS4: its last stage). It bounds
    the error of the embedded lower-order solution, so it is conservative for the reported
    fourth-order one: 20–1 600× the true error on accurate runs, and about the true error when a
    step is far too coarse (``benchmarks/accuracy.py``).

    ``status`` (...,) int, a :class:`pmpjax.Status` code, by precedence: ``INVALID_INPUT``
    (traced inputs that fail the checks an eager call raises on), ``MAX_STEPS`` (adaptive steps
    ran out), ``NONFINITE``, ``INACCURATE`` (``error_estimate > atol + rtol·max|q|``, ``max|q|``
    the largest joint angle of the start and the saved samples), ``SINGULAR`` (passed within
    ``singular_tol`` of a rank-deficient Jacobian), ``NOT_REACHED`` (only with ``simulate``'s
    ``reach_tol``: the hand ended short of the target) or ``SUCCESSFUL``: finite, non-singular and
    within tolerance (and, with ``reach_tol``, at the target).
    """

    t: jax.Array
    q: jax.Array
    x: jax.Array
    qdot: jax.Array
    xdot: jax.Array
    manipulability: jax.Array
    status: jax.Array
    error_estimate: jax.Array

    @property
    def speed(self):
        """Tangential task speed ``|ẋ|`` (..., S)."""
        if is_concrete(self.xdot):
            return to_jax(np.linalg.norm(np.asarray(self.xdot), axis=-1))
        return jnp.linalg.norm(self.xdot, axis=-1)

    @property
    def ok(self):
        return self.status == OK


@dataclasses.dataclass(frozen=True)
class _Schedule:
    n_steps: int
    t0s: tuple[float, ...]
    hs: tuple[float, ...]
    include_initial: bool
    t: tuple[float, ...]


def _schedule(saveat: SaveAt, duration: float, dt: float) -> _Schedule:
    total = max(1, math.ceil(duration / dt - 1e-9))
    h = duration / total
    if saveat.final:
        return _Schedule(total, (0.0,), (h,), False, (duration,))
    if saveat.ts is None:
        every = saveat.every or 1
        if total % every:
            raise ValueError(
                f"`saveat.every`={every} must divide the number of steps duration/dt = {total}"
            )
        S = total // every
        t0s = tuple(i * every * h for i in range(S))
        return _Schedule(every, t0s, (h,) * S, True, (0.0,) + tuple((i + 1) * every * h for i in range(S)))
    ts = np.asarray(saveat.ts)
    if ts[-1] > duration * (1 + 1e-12):
        raise ValueError(f"`saveat.ts` goes beyond `duration`={duration}")
    include0 = ts[0] == 0.0
    ends = ts[1:] if include0 else ts
    starts = np.concatenate([[0.0], ends[:-1]])
    n_steps = max(1, math.ceil(np.max(ends - starts) / dt - 1e-9)) if ends.size else 1
    return _Schedule(n_steps, tuple(starts), tuple((ends - starts) / n_steps), bool(include0), tuple(ts))


def _available_memory() -> int:
    """Bytes of memory available to this process (Linux ``MemAvailable``; else physical memory)."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (OSError, ValueError, AttributeError):
        return 1 << 62


def _check_output_size(saveat, duration, dt, movements, floats_per_sample):
    """Refuse (``ValueError`` with the size) a run whose saved trajectory cannot fit in memory."""
    steps = max(1, math.ceil(duration / dt - 1e-9))
    samples = 1 if saveat.final else len(saveat.ts) if saveat.ts is not None else steps // (saveat.every or 1) + 1
    size = float(movements) * samples * floats_per_sample * 8
    avail = _available_memory()
    if size > 0.8 * avail:
        raise ValueError(f"the saved trajectory would take {size / 2**30:.3g} GiB ({movements} movement(s) × "
                         f"{samples} samples; `duration`={duration:g} s, `dt`={dt:g} s) but {avail / 2**30:.3g} GiB "
                         "of memory is available: shorten `duration`, save less often (`saveat`) or simulate fewer "
                         "movements at a time")


@partial(fast_compile_jit, static_argnames=("batch",))
def _rates(model, q0, *, batch):
    """Eigenvalues of ``M = B(q0)⁻¹`` (*batch, m) and the largest |eig| of ``A KJ`` (elastic)."""
    n = model.chain.n
    consts = model.prepare_soa(batch)
    _, J = model.chain.fk_jac_soa(to_soa(jnp.broadcast_to(q0, batch + (n,))))
    M = admittance_terms_soa(J, consts["A"])[1]
    lam = jnp.linalg.eigvalsh(jnp.moveaxis(M, (0, 1), (-2, -1)))
    g = jnp.max(jnp.abs(jnp.linalg.eigvals(jnp.moveaxis(consts["G"], (0, 1), (-2, -1))))) if model.elastic else 0.0
    return lam, g


def check_rk4_stability(model, planner, q0, batch, h):
    """Refuse at once a ``dt`` far outside RK4's stability region (real negative rates need
    |λ h| < 2.78) at the start posture ``q0`` (``h=None``: only check that ``q0`` is not singular).
    The rates along the path can grow beyond those at ``q0``: the trajectory's error estimate
    (``INACCURATE``) catches what this start check cannot.

    Concrete ``model``, ``q0`` inside a caller's ``jit``/``vmap``/``grad`` are evaluated eagerly
    (outside any trace no ``ensure_compile_time_eval``: it would compile each constant op apart)."""
    rates = _rates(model, q0, batch=batch)
    if not is_concrete(rates):
        with jax.ensure_compile_time_eval():
            rates = _rates(model, q0, batch=batch)
    lam, g_null = (np.asarray(v) for v in rates)
    if np.any(lam[..., 0] <= 0):
        raise ValueError("`q0` is at a singular posture: J W⁻¹ Jᵀ is not positive definite")
    if h is None:
        return
    g = planner.max_gain()
    if getattr(planner, "task_velocity", False):
        rate = g
    elif g is None:  # Eq 10: k λ_max(M) = cond(M) / τ0
        rate = np.max(lam[..., -1] / lam[..., 0] / np.asarray(planner.tau0))
    else:
        rate = g * np.max(lam[..., -1])
    rate = max(float(rate), float(g_null))
    if rate * h > 2.5:
        raise ValueError(
            f"`dt`={h:.3g} s is too large for RK4: the fastest time constant at q0 is "
            f"{1 / rate:.3g} s (need dt < {2.5 / rate:.3g} s; or solver='rodas4', L-stable, whose step is "
            "limited by accuracy alone, or adaptive steps with dt=None)"
        )


def simulate_sequence(
    model: _PMP,
    planner: Planner,
    q0,
    targets,
    *,
    duration: float,
    dt: float = 1e-3,
    saveat: SaveAt | None = None,
    singular_tol: float = 1e-4,
    solver: str = "rk4",
    rtol: float = RTOL,
    atol: float = ATOL,
    max_steps: int = MAX_ADAPTIVE_STEPS,
) -> Trajectory:
    """Simulate consecutive movements to ``targets``, each lasting ``duration``.

    Each movement starts where the previous one ended, with the planner's time reset to 0 (and
    Eq 10 gains recomputed at its start posture). Leading axes of ``q0``, ``targets`` and of the
    model's and planner's parameters broadcast together as a batch. Differentiable with respect to
    every array leaf and to ``q0``/``targets``; ``duration``, ``dt``, ``saveat`` and ``solver`` are
    static.

    ``solver="rk4"`` (classical RK4) refuses a ``dt`` far outside its stability region at ``q0``;
    ``"rodas4"`` (L-stable Rosenbrock, order 4) is for stiff movements, e.g. Eq 10's gain with
    anisotropic ``KJ``, where it takes steps 10–100× larger than RK4 could; each step costs about two
    RK4 steps (``pmpjax._pmp.integrate``, ``benchmarks/stiff.py``). Stability is not accuracy: a step
    too coarse for the nonlinear field gives a wrong answer with either solver, which the error
    estimate reports (``INACCURATE``). ``dt=None`` selects adaptive steps: each trajectory's step is
    set by a PI controller so that its local error estimates sum to at most ``atol + rtol·|q|`` over
    the movement, landing on every save time; adaptive runs save at ``saveat.ts``, at the end
    (``final``) or by default at 101 equally spaced times, and support forward-mode derivatives
    (``jax.jvp``, ``jax.jacfwd``) but not ``jax.grad`` (a ``while_loop``). Fixed steps are the
    default: on the benchmark's workloads they are as accurate at a lower cost
    (``benchmarks/accuracy.py``). Inside a caller's ``jit``/``vmap`` the input checks that an eager
    call raises on become per-item ``INVALID_INPUT`` statuses. Saved samples come from the step's
    first stage (no extra field evaluations when saving every step) and are written in place in the
    output layout, so saving costs about the memory it fills (``benchmarks/simulate.py --saves``).

    **Arguments:**

    - ``model``: a :class:`Lambda0PMP`, :class:`PMP1` or :class:`PMP2` (the chain, ``KJ``, ``q_rest``,
      ``W``).
    - ``planner``: a :class:`Planner` (:class:`ArimotoPlanner`, :class:`MinimumJerkPlanner`,
      :class:`ConstantPlanner`).
    - ``q0``: (..., n) start posture [rad].
    - ``targets``: (..., M, m) the M targets in task space (wrist: screen points [m]).
    - ``duration``: length of each movement [s].
    - ``dt``: the fixed step [s] (default 1 ms; each save interval gets equal steps of at most
      ``dt``), or ``None`` for adaptive steps.
    - ``saveat``: a :class:`SaveAt` (default: every step, t = 0 included).
    - ``singular_tol``: ``SINGULAR`` when a movement passes within this of a rank-deficient Jacobian.
    - ``solver``: ``"rk4"`` or ``"rodas4"`` (:data:`SOLVERS`).
    - ``rtol``, ``atol``: relative and absolute tolerance [rad] of the error estimate (defaults
      ``1e-4`` and ``5e-4``: at most 0.046° for joint angles within ±π).
    - ``max_steps``: adaptive steps tried per movement (default 4 096), else ``MAX_STEPS``.

    **Returns:**

    A :class:`Trajectory` with leaves (..., M, S, ·) and a ``status`` per batch item.

    **Raises:**

    - ``TypeError`` for a model or planner of the wrong type; ``ValueError`` naming the argument for
      wrong shapes, NaN/inf, an unknown ``solver``, an RK4 ``dt`` outside its stability region,
      ``saveat`` times beyond ``duration``, a start at a singular posture, or a saved trajectory
      larger than the available memory.
    """
    return _simulate(model, planner, q0, targets, duration, dt, saveat, singular_tol, False, solver, rtol, atol,
                     max_steps)


def check_solver(solver) -> str:
    """``solver`` if it names one of :data:`SOLVERS`, else a ``ValueError`` naming the argument."""
    if not isinstance(solver, str) or solver not in SOLVERS:
        raise ValueError(f"`solver` must be one of {', '.join(map(repr, SOLVERS))}; got {solver!r}")
    return solver


def _simulate(model, planner, q0, targets, duration, dt, saveat, singular_tol, single, solver, rtol, atol,
              max_steps):
    if not isinstance(model, _PMP):
        raise TypeError(f"`model` must be PMP1, PMP2 or Lambda0PMP, got {type(model).__name__}")
    if not isinstance(planner, Planner):
        raise TypeError(f"`planner` must be a pmpjax Planner, got {type(planner).__name__}")
    solver = check_solver(solver)
    rtol, atol = _tolerance("rtol", rtol), _tolerance("atol", atol)
    warn_without_x64()
    chain = model.chain
    n, m = chain.n, chain.m
    q0 = as_array("q0", q0, tail=(n,))
    chain.check_angles("q0", q0)
    q0 = to_jax(q0, float)
    targets = to_jax(as_array("targets", targets, tail=(None, m)), float)
    chain.check_target("targets", targets)
    duration = positive_float("duration", duration)
    check_seconds("duration", duration, kind="duration")
    saveat = saveat or SaveAt()
    batch = tuple(
        np.broadcast_shapes(q0.shape[:-1], targets.shape[:-2], model.batch_shape(), planner.batch_shape())
    )
    concrete = is_concrete(model, planner, q0, targets)
    if dt is None:
        return _simulate_adaptive(model, planner, q0, targets, duration, saveat, singular_tol, single, solver,
                                  rtol, atol, check_positive_int("max_steps", max_steps), batch, concrete)
    dt = positive_float("dt", dt)
    _check_output_size(saveat, duration, dt, math.prod(batch) * targets.shape[-2], 2 * (n + m) + 2)
    sched = _schedule(saveat, duration, dt)
    if is_concrete(model, planner, q0):
        check_rk4_stability(model, planner, q0, batch, max(sched.hs) if solver == "rk4" else None)
    # Equal step sizes (every mode but unequal `ts`) become a compile-time constant.
    h = sched.hs[0] if len(set(sched.hs)) == 1 else None
    kernel = _kernel(h=h, batch=batch, n_steps=sched.n_steps, include_initial=sched.include_initial,
                     singular_tol=float(singular_tol), single=single, solver=solver)
    out = kernel(model, planner, q0, targets, np.asarray(sched.t0s), np.asarray(sched.hs))
    valid = None if concrete else _valid_items(model, planner, q0, targets, batch)
    return replace(out, t=to_jax(np.asarray(sched.t)),
                   status=_judge(out.status, out.error_estimate, out.q, q0, batch, rtol, atol, valid))


#: Samples saved by ``SaveAt()`` with adaptive steps (``dt=None``): equally spaced, ``t = 0`` included.
ADAPTIVE_SAMPLES = 101


def _simulate_adaptive(model, planner, q0, targets, duration, saveat, singular_tol, single, solver, rtol, atol,
                       max_steps, batch, concrete):
    if saveat.every is not None:
        raise ValueError("`saveat.every` counts fixed steps: with adaptive steps (dt=None) save at "
                         "`SaveAt(ts=...)`, `SaveAt(final=True)` or the default (101 equally spaced samples)")
    if saveat.final:
        ts = (duration,)
    elif saveat.ts is not None:
        ts = saveat.ts
        if ts[-1] > duration * (1 + 1e-12):
            raise ValueError(f"`saveat.ts` goes beyond `duration`={duration}")
    else:
        ts = tuple(float(v) for v in np.linspace(0.0, duration, ADAPTIVE_SAMPLES))
    if len(ts) == 1 and ts[0] == 0.0:
        raise ValueError("`saveat.ts` must reach beyond t = 0")
    n, m = model.chain.n, model.chain.m
    size = float(math.prod(batch) * targets.shape[-2]) * len(ts) * (2 * (n + m) + 2) * 8
    if size > 0.8 * _available_memory():
        raise ValueError(f"the saved trajectory would take {size / 2**30:.3g} GiB: save fewer samples or "
                         "simulate fewer movements at a time")
    if is_concrete(model, planner, q0):
        check_rk4_stability(model, planner, q0, batch, None)
    # (the step allowance is a traced loop bound: runs that differ only in it share one compile)
    out = _run_adaptive(model, planner, q0, targets, batch=batch, ts=ts, include_initial=ts[0] == 0.0,
                        singular_tol=float(singular_tol), single=single, solver=solver, rtol=rtol, atol=atol,
                        max_steps=np.int32(min(max_steps, np.iinfo(np.int32).max)))
    valid = None if concrete else _valid_items(model, planner, q0, targets, batch)
    return replace(out, t=to_jax(np.asarray(ts)),
                   status=_judge(out.status, out.error_estimate, out.q, q0, batch, rtol, atol, valid))


def _tolerance(name, v) -> float:
    """A concrete, non-negative, finite tolerance as ``float`` (``ValueError`` naming ``name``)."""
    if not is_concrete(v):
        raise ValueError(f"`{name}` must be a concrete number (it is traced)")
    a = np.asarray(v, dtype=float)
    if a.ndim or not np.isfinite(a) or a < 0:
        raise ValueError(f"`{name}` must be a finite, non-negative number; got {v!r}")
    return float(a)


def _judge(status, error, q, q0, batch, rtol, atol, valid):
    """``status`` with ``INACCURATE`` where the error estimate exceeds ``atol + rtol·max|q|`` (the
    largest joint angle of the start and the saved samples), and ``INVALID_INPUT`` where ``valid``
    (traced inputs, checked in the trace) is False."""
    if valid is None and is_concrete(status, error, q, q0):
        xp, status, error = np, np.asarray(status), np.asarray(error)
        q, q0 = np.asarray(q), np.asarray(q0)
    else:
        xp = jnp
    scale = xp.maximum(xp.max(xp.abs(q.reshape(batch + (-1,))), axis=-1),
                       xp.max(xp.abs(xp.broadcast_to(q0, batch + q0.shape[-1:])), axis=-1))
    inaccurate = ((status == int(OK)) | (status == int(SINGULAR))) & ~(error <= atol + rtol * scale)
    status = xp.where(inaccurate, int(INACCURATE), status)
    if valid is not None:
        status = xp.where(valid, status, int(INVALID_INPUT))
    return to_jax(status) if xp is np else status


#: Largest ``n`` whose positive-definiteness test runs as unrolled LDLᵀ pivots (above: ``eigvalsh``).
_PD_UNROLLED_N = 8


def _positive_definite(M):
    """(...) bool: the symmetric (..., n, n) ``M`` is positive definite (every LDLᵀ pivot > 0).

    Up to :data:`_PD_UNROLLED_N` this is elementwise JAX, not a LAPACK call: under ``vmap`` at
    more than about 1 500 rows jaxlib 0.10's batched LAPACK kernels split the batch over XLA:CPU's
    intra-op thread pool and block a pool thread waiting for the pieces, which deadlocks the
    process when every pool thread does so at once (two such calls, here ``W`` and ``KJ``, on a
    2-core machine; fixed upstream after jax 0.11.0). ``fitting.sweep``'s chunks of the curvature
    sweep hung this way."""
    n = M.shape[-1]
    if n > _PD_UNROLLED_N:
        return jnp.linalg.eigvalsh(M)[..., 0] > 0
    L = [[None] * n for _ in range(n)]
    d = []
    ok = jnp.ones(M.shape[:-2], bool)
    for j in range(n):
        dj = M[..., j, j] - sum((L[j][k] ** 2 * d[k] for k in range(j)), jnp.zeros_like(M[..., j, j]))
        ok &= dj > 0
        d.append(dj)
        safe = jnp.where(dj > 0, dj, 1.0)
        for i in range(j + 1, n):
            L[i][j] = (M[..., i, j] - sum((L[i][k] * L[j][k] * d[k] for k in range(j)),
                                          jnp.zeros_like(M[..., i, j]))) / safe
    return ok


def _valid_items(model, planner, q0, targets, batch):
    """Traced per-item checks (a caller's ``jit``/``vmap``, where the eager ones cannot run): finite
    ``q0``, ``targets``, ``q_rest``; symmetric positive definite ``W`` and ``KJ``; finite, positive
    planner parameters. Returns a (*batch) bool array."""
    ok = jnp.ones(batch, bool)
    fin = lambda a, core: jnp.all(jnp.isfinite(a), axis=tuple(range(-core, 0))) if core else jnp.isfinite(a)  # noqa: E731
    ok &= jnp.broadcast_to(fin(q0, 1), batch) & jnp.broadcast_to(fin(targets, 2), batch)
    for name in ("W", "KJ"):
        M = getattr(model, name)
        if M is None:
            continue
        sym = jnp.max(jnp.abs(M - jnp.swapaxes(M, -1, -2)), axis=(-2, -1)) <= 1e-8 * jnp.max(jnp.abs(M), axis=(-2, -1))
        pd = _positive_definite(jnp.where(fin(M, 2)[..., None, None], 0.5 * (M + jnp.swapaxes(M, -1, -2)),
                                          jnp.eye(M.shape[-1])))
        ok &= jnp.broadcast_to(fin(M, 2) & sym & pd, batch)
    if model.q_rest is not None:
        ok &= jnp.broadcast_to(fin(model.q_rest, 1), batch)
    for leaf in planner._leaves():
        ok &= jnp.broadcast_to(jnp.isfinite(leaf), batch)
    for leaf in planner._positive_leaves():
        ok &= jnp.broadcast_to(leaf > 0, batch)
    return ok


@functools.lru_cache(maxsize=256)
def _kernel(**statics):
    """``_run`` with these static arguments, batched efficiently under a caller's ``jax.vmap``.

    Plain ``vmap`` of ``_run`` adds the mapped axis in front of the component-leading state, so
    every stage reads strided component slices and writes one trajectory at a time. The
    ``custom_vmap`` rule instead folds the mapped axis into the run's own (trailing, contiguous)
    batch. ``custom_vmap`` has no derivative rules, so derivatives go through ``custom_jvp`` with
    ``_run``'s own JVP (linear in the tangents, hence transposable for ``grad``), taken of the
    variant that loops over the four RK4 stages (``stage_loop``): the field and its tangent then
    appear once per step in the graph instead of four times, which cuts the compile time of every
    derivative through ``simulate`` (fits, ``jax.grad``) with the same run time at their sizes
    (benchmarks/compile_times.py). Primal runs: see :func:`_primal_run`.
    """
    run_jvp = partial(_run, **{**statics, "stage_loop": True})

    @jax.custom_batching.custom_vmap
    def batched(*args):
        return _primal_run(statics, traced=True)(*args)

    @batched.def_vmap
    def _rule(axis_size, in_batched, *args):
        return _vmap_rule(statics, axis_size, in_batched, args)

    @jax.custom_jvp
    def kernel(*args):
        return batched(*args)

    @kernel.defjvp
    def _jvp(primals, tangents):
        fold = _FOLD_TANGENTS.get()
        if fold is not None:
            return _kernel_jvp(**statics)(primals, tangents, fold[0] if statics["solver"] == "rodas4" else None)
        return jax.jvp(run_jvp, primals, tangents)

    def call(*args):
        # Outside every trace no rule can apply: run the kernel itself, as a top-level call (JAX
        # evaluates custom_jvp/custom_vmap functions under a trace, which would drop its options).
        return _primal_run(statics)(*args) if top_level() else kernel(*args)

    return call


#: Largest batch (movements) whose primal runs use the compile-light kernel (:func:`_primal_run`):
#: where it compiles with ``FAST_COMPILE`` (top-level calls, a caller's ``pj.fast_compile_jit``), and
#: inside other traces (a caller's ``jax.jit``).
SMALL_BATCH = 1024
TRACED_SMALL_BATCH = 16


def _primal_run(statics, traced=False):
    """``_run`` with these static arguments for primal (underived) runs.

    Up to :data:`SMALL_BATCH` movements, where the first call is mostly compilation, the stages
    run in a loop (``stage_loop``) and top-level calls compile with ``FAST_COMPILE``: about half
    the compilation for 10–25 % more run time; larger batches keep the unrolled stages and XLA's
    defaults. Inside a caller's ``jax.jit`` (``traced``, without ``FAST_COMPILE``) the stage loop
    runs 2–3.5× slower than the unrolled stages from B = 32 on, so there the light kernel serves
    only up to :data:`TRACED_SMALL_BATCH` movements; inside a caller's ``pj.fast_compile_jit``
    (the fits) it keeps :data:`SMALL_BATCH` (``benchmarks/simulate.py``, ``compile_times.py``).
    """
    small = SMALL_BATCH if not traced or fast_compile_applies() else TRACED_SMALL_BATCH
    if math.prod(statics["batch"]) <= small:
        return partial(_run_light, **statics, stage_loop=True)
    return partial(_run, **statics)


#: Set (at trace time) by :func:`forward_jacobians`: None, or ``(frozen,)``.
_FOLD_TANGENTS = contextvars.ContextVar("pmpjax_fold_tangents", default=None)


@contextlib.contextmanager
def forward_jacobians(frozen=None):
    """Trace forward-mode Jacobians (``jax.jacfwd``, also under ``jax.vmap``) through ``simulate``
    with ``_kernel_jvp``'s batching rule: ``jax.jacfwd``'s tangents are batched with the primal
    computed once; a mapped axis of primals and tangents alike (a caller's ``vmap`` of the JVP) is
    folded into the run's own (trailing, contiguous) batch. The result is forward-mode only (no
    ``grad`` or second derivatives of what is traced inside); ``fitting.least_squares`` uses it
    for its Jacobians.

    ``frozen``: None, or a (traced) bool: where true, fixed-step RODAS4 runs hold the field's
    Jacobian fixed along the tangents (``pmpjax._pmp.integrate.rosenbrock_step``): an approximate
    Jacobian at about half the cost (``fitting.least_squares(approximate=True)``). Read by other
    residuals through :func:`frozen_tangents`."""
    token = _FOLD_TANGENTS.set((frozen,))
    try:
        yield
    finally:
        _FOLD_TANGENTS.reset(token)


def frozen_tangents():
    """Inside :func:`forward_jacobians`, its ``frozen`` flag (None when not given); None outside: a
    residual with a cheaper approximate Jacobian of its own may switch to it where it is true."""
    fold = _FOLD_TANGENTS.get()
    return None if fold is None else fold[0]


@functools.lru_cache(maxsize=256)
def _kernel_jvp(**statics):
    """``(primals, tangents) -> jvp of _run`` whose ``vmap`` folds the mapped axis into the batch."""
    run_jvp = partial(_run, **{**statics, "stage_loop": True})

    @jax.custom_batching.custom_vmap
    def jvp(primals, tangents, frozen):
        return jax.jvp(partial(run_jvp, frozen=frozen), primals, tangents)

    @jvp.def_vmap
    def _rule(axis_size, in_batched, primals, tangents, frozen):
        pb, tb, fb = in_batched
        run = partial(run_jvp, frozen=frozen)
        plain = any(jax.tree_util.tree_leaves((pb[0].chain, pb[4:], tb[0].chain, tb[4:], fb)))
        flags = Trajectory(t=False, q=True, x=True, qdot=True, xdot=True, manipulability=True, status=True,
                           error_estimate=True)
        if not plain and not any(jax.tree_util.tree_leaves(pb)):
            # Unmapped primals (jax.jacfwd's basis vmap): plain vmap of the JVP computes the primal
            # once and batches the tangents only (folding repeated the primal per tangent: the
            # reaching fit's Jacobian 1.6x slower with RODAS4, 1.9x with RK4; benchmarks/stiff.py).
            axes = jax.tree_util.tree_map(lambda b: 0 if b else None, (pb, tb))
            oax = jax.tree_util.tree_map(lambda f: 0 if f else None, flags)
            out = jax.vmap(lambda p, t: jax.jvp(run, p, t), in_axes=axes, out_axes=(None, oax))(primals, tangents)
            return out, (jax.tree_util.tree_map(lambda _: False, flags), flags)
        if plain:  # a mapped chain, time grid or frozen flag: plain vmap of the JVP
            axes = jax.tree_util.tree_map(lambda b: 0 if b else None, (pb, tb, fb))
            out = jax.vmap(lambda p, t, fr: jax.jvp(partial(run_jvp, frozen=fr), p, t), in_axes=axes)(
                primals, tangents, frozen)
            return out, jax.tree_util.tree_map(lambda _: True, out)
        batch = statics["batch"]

        def lift(x, b, core):
            if not b:
                return x
            return x.reshape(x.shape[:1] + (1,) * (len(batch) - (x.ndim - 1 - core)) + x.shape[1:])

        def pair(p, t, b_p, b_t, core):
            """Lift both to the new leading axis and broadcast them to one shape."""
            if not (b_p or b_t):
                return p, t
            p, t = lift(p, b_p, core), lift(t, b_t, core)
            shape = (axis_size,) + np.broadcast_shapes(p.shape[1:] if b_p else p.shape,
                                                       t.shape[1:] if b_t else t.shape)
            shape = np.broadcast_shapes(p.shape, t.shape, shape)
            return jnp.broadcast_to(p, shape), jnp.broadcast_to(t, shape)

        (mp, plp, q0p, tgp, t0p, hp), (mt, plt, q0t, tgt, t0t, ht) = primals, tangents
        mods_p, mods_t = {}, {}
        for k, c in (("W", 2), ("KJ", 2), ("q_rest", 1)):
            if getattr(mp, k) is not None:
                mods_p[k], mods_t[k] = pair(getattr(mp, k), getattr(mt, k), getattr(pb[0], k), getattr(tb[0], k), c)
        mp, mt = replace(mp, **mods_p), replace(mt, **mods_t)
        pl = jax.tree_util.tree_map(lambda p, t, bp, bt: pair(p, t, bp, bt, 0), plp, plt, pb[1], tb[1])
        plp = jax.tree_util.tree_map(lambda p, x: x[0], plp, pl)
        plt = jax.tree_util.tree_map(lambda p, x: x[1], plt, pl)
        q0p, q0t = pair(q0p, q0t, pb[2], tb[2], 1)
        tgp, tgt = pair(tgp, tgt, pb[3], tb[3], 2)
        out = _kernel_jvp(**{**statics, "batch": (axis_size,) + batch})(
            (mp, plp, q0p, tgp, t0p, hp), (mt, plt, q0t, tgt, t0t, ht), frozen)
        return out, (flags, flags)

    return jvp


def _vmap_rule(statics, axis_size, in_batched, args):
    """Mapped leaves (axis 0) become a new leading batch axis of ``_run`` (see ``_kernel``)."""
    model, planner, q0, targets, t0s, hs = args
    mb, pb, q0b, tb = in_batched[:4]
    batch = statics["batch"]
    if any(jax.tree_util.tree_leaves((mb.chain, in_batched[4:]))):  # mapped chain: plain vmap
        axes = jax.tree_util.tree_map(lambda b: 0 if b else None, list(in_batched))
        out = jax.vmap(partial(_run, **statics), in_axes=tuple(axes))(*args)
        return out, jax.tree_util.tree_map(lambda _: True, out)

    def lift(x, b, core):
        """(axis_size, *own batch, *core) -> (axis_size, 1, ..., 1, *own batch, *core)."""
        if not b:
            return x
        return x.reshape(x.shape[:1] + (1,) * (len(batch) - (x.ndim - 1 - core)) + x.shape[1:])

    model = replace(model, **{k: lift(getattr(model, k), getattr(mb, k), c)
                              for k, c in (("W", 2), ("KJ", 2), ("q_rest", 1)) if getattr(model, k) is not None})
    planner = jax.tree_util.tree_map(lambda x, b: lift(x, b, 0), planner, pb)
    out = _kernel(**{**statics, "batch": (axis_size,) + batch})(
        model, planner, lift(q0, q0b, 1), lift(targets, tb, 2), t0s, hs)
    return out, Trajectory(t=False, q=True, x=True, qdot=True, xdot=True, manipulability=True, status=True,
                           error_estimate=True)


def simulate(model, planner, q0, target, *, duration, dt=1e-3, saveat=None, singular_tol=1e-4, solver="rk4",
             rtol=RTOL, atol=ATOL, max_steps=MAX_ADAPTIVE_STEPS, reach_tol=None):
    """Simulate one movement (per batch element) from ``q0`` to ``target`` (λ0-PMP, Eqs 1–10).

    As :func:`simulate_sequence` with one target; see it for the solvers, adaptive steps and
    derivatives.

    **Arguments:**

    - ``model``: a :class:`Lambda0PMP`, :class:`PMP1` or :class:`PMP2`.
    - ``planner``: a :class:`Planner`.
    - ``q0``: (..., n) start posture [rad].
    - ``target``: (..., m) the target in task space (wrist: screen point [m]).
    - ``duration``, ``dt``, ``saveat``, ``singular_tol``, ``solver``, ``rtol``, ``atol``,
      ``max_steps``: as :func:`simulate_sequence`.
    - ``reach_tol``: (default None: not judged) a movement whose hand ends farther from its target
      than ``reach_tol`` times its distance at the start (``|x(T) − x_d| > reach_tol·|x(0) − x_d|``)
      has status ``NOT_REACHED`` instead of ``SUCCESSFUL``: it did not reach the target within
      ``duration`` (time constants in milliseconds, a planner too slow for the duration; PMP2, which
      stops short by design). The hand at the end must be saved (every ``saveat`` but ``ts`` that
      end before ``duration``). The command line and sweeps use 0.1.

    **Returns:**

    A :class:`Trajectory` with leaves (..., S, ·): ``t``, ``q``, ``x``, ``qdot``, ``xdot``,
    ``manipulability``, ``error_estimate`` and ``status``.

    **Raises:**

    - As :func:`simulate_sequence`; also ``ValueError`` for a ``q0`` beyond the chain's joint range
      (``Chain.check_angles``: degrees typed as radians), a ``duration`` above 60 s (milliseconds
      typed as seconds; above 10 s runs with a warning), or a ``reach_tol`` whose end is not saved.

    **Compile time:** the first call with a new batch shape, ``duration``/``dt``, ``saveat`` or model
    type compiles the whole scan: ≈ 3 s on a 2-core CPU at the Figure-3 size (8 movements), ≈ 12 s
    for ``jax.grad`` through it (benchmarks/compile_times.py). Later calls reuse it; turn on JAX's
    persistent compilation cache (``jax_compilation_cache_dir``; the command line does) to keep it
    across processes.
    """
    if not isinstance(model, _PMP):
        raise TypeError(f"`model` must be PMP1, PMP2 or Lambda0PMP, got {type(model).__name__}")
    target = as_array("target", target, tail=(model.chain.m,))
    if reach_tol is not None:
        reach_tol = _tolerance("reach_tol", reach_tol)
        if saveat is not None and saveat.ts is not None and saveat.ts[-1] < float(duration) * (1 - 1e-12):
            raise ValueError("`reach_tol` judges the hand at the end of the movement: save it (`saveat.ts` ending "
                             "at `duration`, or another SaveAt)")
    traj = _simulate(model, planner, q0, on_host(target, lambda a: a[..., None, :]), duration, dt, saveat,
                     singular_tol, True, solver, rtol, atol, max_steps)
    if reach_tol is None:
        return traj
    return replace(traj, status=_judge_reach(model.chain, traj, q0, target, reach_tol))


def _judge_reach(chain, traj, q0, target, reach_tol):
    """``traj.status`` with ``NOT_REACHED`` where a ``SUCCESSFUL`` movement's hand ended farther from
    ``target`` than ``reach_tol`` times its start distance (``simulate``'s ``reach_tol``)."""
    x0 = chain.fk(q0)
    if is_concrete(traj.x, traj.status, x0, target):
        xp, x_end, x0, target, status = np, np.asarray(traj.x[..., -1, :]), np.asarray(x0), np.asarray(target), \
            np.asarray(traj.status)
    else:
        xp, x_end, status = jnp, traj.x[..., -1, :], traj.status
    d_end = xp.linalg.norm(x_end - target, axis=-1)
    d0 = xp.linalg.norm(x0 - target, axis=-1)
    short = xp.broadcast_to(d_end > reach_tol * d0 + 1e-12 * (1.0 + d0), status.shape)
    status = xp.where((status == int(OK)) & short, int(NOT_REACHED), status)
    return to_jax(status) if xp is np else status


#: Most consecutive samples written to the trajectory-major outputs at once: one sample per
#: trajectory touches a cache line per trajectory, a block of 16 fills whole lines.
_BLOCK = 16


_RUN_STATICS = ("h", "batch", "n_steps", "include_initial", "singular_tol", "single", "stage_loop", "solver")


def _prepare(model, planner, q0, targets, batch):
    """The flattened batch of a run: ``(chain, consts, planner, q (n, B), targets (M, m, B), field)``
    with ``field(t, q, (planner, target)) -> (q̇, (q, x, q̇, ẋ, manipulability))``."""
    chain = model.chain
    B = math.prod(batch)
    core = {"W": 2, "KJ": 2, "q_rest": 1}
    model = replace(model, **{k: flatten_batch(getattr(model, k), batch, c) for k, c in core.items()
                              if getattr(model, k) is not None})
    consts = model.prepare_soa((B,))
    planner = planner.to_soa(batch)
    q = to_soa(flatten_batch(q0, batch, 1))
    tg = jnp.moveaxis(flatten_batch(targets, batch, 2), 0, -1)  # (M, m, B)

    def field(t, qc, args):
        """``q̇`` and the saved observation ``(q, x, q̇, ẋ, manipulability)`` of ``(t, q)``."""
        pl, target = args
        x, J = chain.fk_jac_soa(qc)
        P, M = admittance_terms_soa(J, consts["A"])
        qd = model.qdot_soa(J, P, M, pl.force_soa(t, x, target, M), qc, consts)
        w = manipulability_soa(J)
        return qd, (qc, x, qd, mv(J, qd), w)

    return chain, consts, planner, q, tg, field


def _movements(model, planner, q0, targets, t0s, hs, *, h, batch, n_steps, include_initial, singular_tol,
               single, stage_loop=False, solver="rk4", frozen=None):
    """``h``: the step size of every segment as a Python float, or None to use ``hs`` (S,);
    ``frozen``: RODAS4's (``integrate.rosenbrock_step``)."""
    chain, consts, planner, q, tg, field = _prepare(model, planner, q0, targets, batch)
    n, m = chain.n, chain.m
    B = math.prod(batch)
    n_mov, n_seg = tg.shape[0], t0s.shape[0]
    # Saved: the start of every segment (the first unless `include_initial`) and the last end.
    S, offset = n_seg + include_initial, 1 - include_initial
    comps = ((n,), (m,), (n,), (m,), ())
    step_h = hs if h is None else h

    def write(acc, j, obs, valid):
        """Samples ``obs`` (K, *comp, B) into rows ``j, ..., j + K − 1`` of the (B, M·S, *comp) outputs."""
        bufs, fin, wmin = acc
        bufs = tuple(lax.dynamic_update_slice_in_dim(b, jnp.moveaxis(o, -1, 0), j, axis=1)
                     for b, o in zip(bufs, obs))
        w = lax.stop_gradient(obs[4])
        fin = fin & (jnp.logical_not(valid) | jnp.all(jnp.isfinite(obs[0]), axis=(0, 1)))
        wmin = jnp.where(valid, jnp.minimum(wmin, jnp.min(jnp.where(jnp.isfinite(w), w, 0.0), axis=0)), wmin)
        return bufs, fin, wmin

    def movement(carry, inp):
        qc, acc, err = carry
        k, target = inp
        _, J0 = chain.fk_jac_soa(qc)
        args = (planner.start(admittance_terms_soa(J0, consts["A"])[1]), target)
        if n_seg > 1 or include_initial:  # segment starts are saved
            # Without `include_initial` segment i's start is row i − 1; segment 0's start is
            # written at row 0 (one sample at a time) and overwritten by segment 1's.
            block = max(k_ for k_ in range(1, _BLOCK + 1) if n_seg % k_ == 0) if include_initial else 1
            wr = lambda a, i, obs: write(a, k * S + jnp.maximum(i - offset, 0), obs, i >= offset)  # noqa: E731
            qc, acc, e, obs = integrate_observed(field, qc, t0s, step_h, n_steps, args, acc, wr, block=block,
                                                 stage_loop=stage_loop, solver=solver, frozen=frozen)
        else:
            qc, acc, e, obs = integrate_observed(field, qc, t0s, step_h, n_steps, args, acc, None,
                                                 stage_loop=stage_loop, solver=solver, frozen=frozen)
        acc = write(acc, k * S + S - 1, jax.tree_util.tree_map(lambda v: v[None], obs), True)  # the end state
        return (qc, acc, err + e), None

    # Distinct fills: XLA would merge equal ones (q and q̇, x and ẋ) and copy them apart (a whole-output
    # copy each); every row is overwritten.
    bufs = tuple(jnp.full((B, n_mov * S) + c, float(i), q.dtype) for i, c in enumerate(comps))
    acc = (bufs, jnp.ones((B,), bool), jnp.full((B,), jnp.inf, q.dtype))
    (qT, (bufs, fin, wmin), err), _ = lax.scan(movement, (q, acc, jnp.zeros((B,), q.dtype)),
                                               (jnp.arange(n_mov), tg))
    fin = fin & jnp.all(jnp.isfinite(qT), axis=0) & jnp.isfinite(err)
    status = jnp.where(~fin, int(NONFINITE), jnp.where(wmin < singular_tol, int(SINGULAR), int(OK)))
    lead = batch if single else batch + (n_mov,)
    q_, x_, qd_, xd_, w_ = (b.reshape(lead + (S,) + c) for b, c in zip(bufs, comps))
    return Trajectory(t=t0s, q=q_, x=x_, qdot=qd_, xdot=xd_, manipulability=w_,
                      status=status.reshape(batch), error_estimate=err.reshape(batch))


def _movements_adaptive(model, planner, q0, targets, *, batch, ts, include_initial, singular_tol, single, solver,
                        rtol, atol, max_steps):
    """The adaptive-step run (``dt=None``): every movement integrated by
    :func:`~pmpjax._pmp.integrate.integrate_adaptive` to the save times ``ts``."""
    chain, consts, planner, q, tg, field = _prepare(model, planner, q0, targets, batch)
    n, m = chain.n, chain.m
    B = math.prod(batch)
    n_mov, S = tg.shape[0], len(ts)
    comps = ((n,), (m,), (n,), (m,), ())
    rows = jnp.arange(B)

    def write(k):
        def wr(acc, j, obs, mask):
            bufs, fin, wmin = acc
            r = k * S + jnp.minimum(j, S - 1)
            bufs = tuple(b.at[rows, r].set(jnp.where(mask.reshape((B,) + (1,) * len(c)), jnp.moveaxis(o, -1, 0),
                                                     b[rows, r]))
                         for b, o, c in zip(bufs, obs, comps))
            w = lax.stop_gradient(obs[4])
            fin = fin & (~mask | jnp.all(jnp.isfinite(obs[0]), axis=0))
            wmin = jnp.where(mask, jnp.minimum(wmin, jnp.where(jnp.isfinite(w), w, 0.0)), wmin)
            return bufs, fin, wmin
        return wr

    def movement(carry, inp):
        qc, acc, err, done = carry
        k, target = inp
        _, J0 = chain.fk_jac_soa(qc)
        args = (planner.start(admittance_terms_soa(J0, consts["A"])[1]), target)
        qc, acc, e, _, ok = integrate_adaptive(field, qc, ts, include_initial, args, acc, write(k), solver=solver,
                                               rtol=rtol, atol=atol, max_steps=max_steps, span=ts[-1],
                                               h0=ts[-1] / 64)
        return (qc, acc, err + e, done & ok), None

    bufs = tuple(jnp.full((B, n_mov * S) + c, jnp.nan, q.dtype) for c in comps)
    acc = (bufs, jnp.ones((B,), bool), jnp.full((B,), jnp.inf, q.dtype))
    init = (q, acc, jnp.zeros((B,), q.dtype), jnp.ones((B,), bool))
    (qT, (bufs, fin, wmin), err, done), _ = lax.scan(movement, init, (jnp.arange(n_mov), tg))
    fin = fin & jnp.all(jnp.isfinite(qT), axis=0) & jnp.isfinite(err)
    status = jnp.where(~done, int(MAX_STEPS), jnp.where(~fin, int(NONFINITE),
                                                        jnp.where(wmin < singular_tol, int(SINGULAR), int(OK))))
    lead = batch if single else batch + (n_mov,)
    q_, x_, qd_, xd_, w_ = (b.reshape(lead + (S,) + c) for b, c in zip(bufs, comps))
    return Trajectory(t=jnp.asarray(ts), q=q_, x=x_, qdot=qd_, xdot=xd_, manipulability=w_,
                      status=status.reshape(batch), error_estimate=err.reshape(batch))


_run_adaptive = jax.jit(_movements_adaptive, static_argnames=(
    "batch", "ts", "include_initial", "singular_tol", "single", "solver", "rtol", "atol"))


#: The kernel, and the compile-light kernel for small batches (:func:`_primal_run`).
_run = jax.jit(_movements, static_argnames=_RUN_STATICS)
_run_light = fast_compile_jit(_movements, static_argnames=_RUN_STATICS)
