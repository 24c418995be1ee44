"""Shared problem and independent baselines for the benchmarks (not part of the library).

The Figure 3 wrist problem (Tommasino & Campolo 2017, Eqs 6–9): ``Wrist(d=1)``,
``KJ = diag(0.5, 1.5, 2)`` Nm/rad, ``W = 0.08 KJ``, ``q_rest = (5°, 0, 0)``, Arimoto ``K(t)``
with ``k = 22.5``, ``τ = 0.08 s``; 0.4 s movements from ``q_rest`` to targets on the π/12 circle.

The baselines re-implement the λ0-PMP vector field from the paper's formulas, without pmpjax:

- ``numpy_rhs`` — a straightforward NumPy field for ``scipy.integrate.solve_ivp``,
- ``c_rk4`` — a scalar C loop (classical RK4, fixed step) compiled with ``gcc -O3 -march=native``,
- ``numba_rk4`` — the same scalar loop in numba.

All three use ``q̇ = A (Jᵀ (F + λ0) − τ_el)`` with ``A = W⁻¹``, ``λ0 = (J A Jᵀ)⁻¹ J A τ_el``
(Eq 4, 2×2 closed-form inverse), ``F = K(t) (x_d − x)`` (Eq 8) and the analytic Jacobian of Eq 6.
``check_jacobian`` verifies those closed forms against the generator form ``∂ exp(ê θ)/∂θ =
ê exp(ê θ)`` of Eq 6's rotation product, so the baselines do not just copy pmpjax's algebra.
"""

from __future__ import annotations

import ctypes
import json
import math
import os
import shutil
import subprocess
import tempfile
import time

import numpy as np

D = 1.0
KJ = np.diag([0.5, 1.5, 2.0])  # Nm/rad (Eq 9)
TAU0 = 0.08  # s
W = TAU0 * KJ  # Eq 7/9
Q_REST = np.deg2rad([5.0, 0.0, 0.0])
K_GAIN = 22.5  # N/m (Arimoto k)
TAU = 0.08  # s
DURATION = 0.4  # s
DT = 1e-3  # s
N_STEPS = round(DURATION / DT)
RADIUS = math.pi / 12


def targets(B: int, seed: int = 0) -> np.ndarray:
    """(B, 2) targets on the π/12 circle at uniformly random angles."""
    ang = np.random.default_rng(seed).uniform(0.0, 2.0 * math.pi, B)
    return RADIUS * np.stack([np.cos(ang), np.sin(ang)], axis=-1)


def start_postures(B: int) -> np.ndarray:
    """(B, 3) start postures: all at ``q_rest``."""
    return np.repeat(Q_REST[None], B, axis=0)


def jax_problem():
    """``(model, planner)`` for pmpjax (imports pmpjax lazily)."""
    import jax.numpy as jnp

    import pmpjax as pj

    KJj = jnp.asarray(KJ)
    model = pj.Lambda0PMP(pj.Wrist(D), KJ=KJj, q_rest=jnp.asarray(Q_REST), W=TAU0 * KJj)
    return model, pj.ArimotoPlanner(k=K_GAIN, tau=TAU)


# ----------------------------------------------------------------------------------------------
# NumPy vector field (SciPy baseline and reference solutions)


def fk_jac(q, d=D):
    """Screen point x (2,) and Jacobian J (2, 3) of Eq 6, closed form."""
    sa, ca = math.sin(q[0]), math.cos(q[0])
    sb, cb = math.sin(q[1]), math.cos(q[1])
    sc, cc = math.sin(q[2]), math.cos(q[2])
    x = np.array([-d * (ca * sb * cc - sa * sc), -d * (sa * sb * cc + ca * sc)])
    J = np.array(
        [
            [d * (sa * sb * cc + ca * sc), -d * ca * cb * cc, d * (ca * sb * sc + sa * cc)],
            [d * (sa * sc - ca * sb * cc), -d * sa * cb * cc, d * (sa * sb * sc - ca * cc)],
        ]
    )
    return x, J


def numpy_rhs(t, q, xd, A=None, KJ_=KJ, q_rest=Q_REST, k=K_GAIN, tau=TAU):
    """λ0-PMP joint velocity (3,) at time t [s], posture q (3,), target xd (2,)."""
    A = np.linalg.inv(W) if A is None else A
    x, J = fk_jac(q)
    tau_el = KJ_ @ (q - q_rest)
    AJt = A @ J.T
    B = np.linalg.inv(J @ AJt)
    lam0 = B @ (J @ (A @ tau_el))  # Eq 4
    s = t / tau
    F = k * (1.0 - math.exp(-s) - s * math.exp(-s)) * (xd - x)  # Eq 8
    return AJt @ (F + lam0) - A @ tau_el


def scipy_final(q0, xd, *, rtol, atol, method="DOP853", duration=DURATION):
    """Final postures (B, 3) from a per-trajectory ``solve_ivp`` loop, and total evaluations."""
    from scipy.integrate import solve_ivp

    A = np.linalg.inv(W)
    out = np.empty((len(q0), 3))
    nfev = 0
    for i, (q, x) in enumerate(zip(q0, xd)):
        sol = solve_ivp(numpy_rhs, (0.0, duration), q, method=method, rtol=rtol, atol=atol,
                        args=(x, A))
        if not sol.success:
            raise RuntimeError(f"solve_ivp failed on trajectory {i}: {sol.message}")
        out[i] = sol.y[:, -1]
        nfev += sol.nfev
    return out, nfev


def _rot(axis, th):
    c, s = math.cos(th), math.sin(th)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    R = np.eye(3)
    R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
    return R


def _hat(axis):
    e = np.zeros(3)
    e[axis] = 1.0
    return np.array([[0, -e[2], e[1]], [e[2], 0, -e[0]], [-e[1], e[0], 0]])


def check_jacobian(n: int = 20, seed: int = 1) -> float:
    """Max |closed form − generator form| of x and J of Eq 6 over random postures."""
    S = np.array([[0.0, -D, 0.0], [0.0, 0.0, D]])
    ex = np.array([1.0, 0.0, 0.0])
    err = 0.0
    for q in np.random.default_rng(seed).uniform(-1.0, 1.0, (n, 3)):
        Ra, Rb, Rc = _rot(0, -q[0]), _rot(2, q[1]), _rot(1, q[2])
        x_ref = S @ Ra @ Rb @ Rc @ ex
        J_ref = np.stack(
            [S @ (-_hat(0)) @ Ra @ Rb @ Rc @ ex, S @ Ra @ _hat(2) @ Rb @ Rc @ ex,
             S @ Ra @ Rb @ _hat(1) @ Rc @ ex], axis=1)
        x, J = fk_jac(q)
        err = max(err, np.max(np.abs(x - x_ref)), np.max(np.abs(J - J_ref)))
    return float(err)


# ----------------------------------------------------------------------------------------------
# Scalar C loop

C_SOURCE = r"""
#include <math.h>

/* λ0-PMP wrist field: qd = P (F + lam0) - g, P = A J^T, g = A KJ (q - q_rest) = G (q - q_rest),
   lam0 = (J P)^{-1} J g (2x2 closed form), F = K(t) (xd - x). */
static inline void field(double t, const double *q, double *qd, const double *A,
                         const double *G, const double *qr, double d, double k, double tau,
                         double xd1, double xd2) {
    double sa = sin(q[0]), ca = cos(q[0]), sb = sin(q[1]), cb = cos(q[1]);
    double sc = sin(q[2]), cc = cos(q[2]);
    double x1 = -d * (ca * sb * cc - sa * sc), x2 = -d * (sa * sb * cc + ca * sc);
    double J[2][3] = {{d * (sa * sb * cc + ca * sc), -d * ca * cb * cc, d * (ca * sb * sc + sa * cc)},
                      {d * (sa * sc - ca * sb * cc), -d * sa * cb * cc, d * (sa * sb * sc - ca * cc)}};
    double P[3][2], g[3], e[3] = {q[0] - qr[0], q[1] - qr[1], q[2] - qr[2]};
    for (int i = 0; i < 3; i++) {
        for (int j = 0; j < 2; j++)
            P[i][j] = A[3 * i] * J[j][0] + A[3 * i + 1] * J[j][1] + A[3 * i + 2] * J[j][2];
        g[i] = G[3 * i] * e[0] + G[3 * i + 1] * e[1] + G[3 * i + 2] * e[2];
    }
    double m00 = J[0][0] * P[0][0] + J[0][1] * P[1][0] + J[0][2] * P[2][0];
    double m01 = J[0][0] * P[0][1] + J[0][1] * P[1][1] + J[0][2] * P[2][1];
    double m11 = J[1][0] * P[0][1] + J[1][1] * P[1][1] + J[1][2] * P[2][1];
    double v1 = J[0][0] * g[0] + J[0][1] * g[1] + J[0][2] * g[2];
    double v2 = J[1][0] * g[0] + J[1][1] * g[1] + J[1][2] * g[2];
    double idet = 1.0 / (m00 * m11 - m01 * m01);
    double s = t / tau, es = exp(-s), K = k * (1.0 - es - s * es);
    double F1 = K * (xd1 - x1) + (m11 * v1 - m01 * v2) * idet;
    double F2 = K * (xd2 - x2) + (m00 * v2 - m01 * v1) * idet;
    for (int i = 0; i < 3; i++) qd[i] = P[i][0] * F1 + P[i][1] * F2 - g[i];
}

void lambda0_rk4(long B, long steps, double h, const double *A, const double *G,
                 const double *qr, double d, double k, double tau, const double *q0,
                 const double *xd, double *qT) {
    for (long b = 0; b < B; b++) {
        double q[3] = {q0[3 * b], q0[3 * b + 1], q0[3 * b + 2]}, y[3];
        double k1[3], k2[3], k3[3], k4[3];
        double xd1 = xd[2 * b], xd2 = xd[2 * b + 1];
        for (long i = 0; i < steps; i++) {
            double t = i * h;
            field(t, q, k1, A, G, qr, d, k, tau, xd1, xd2);
            for (int j = 0; j < 3; j++) y[j] = q[j] + 0.5 * h * k1[j];
            field(t + 0.5 * h, y, k2, A, G, qr, d, k, tau, xd1, xd2);
            for (int j = 0; j < 3; j++) y[j] = q[j] + 0.5 * h * k2[j];
            field(t + 0.5 * h, y, k3, A, G, qr, d, k, tau, xd1, xd2);
            for (int j = 0; j < 3; j++) y[j] = q[j] + h * k3[j];
            field(t + h, y, k4, A, G, qr, d, k, tau, xd1, xd2);
            for (int j = 0; j < 3; j++) q[j] += (h / 6.0) * (k1[j] + 2.0 * (k2[j] + k3[j]) + k4[j]);
        }
        qT[3 * b] = q[0]; qT[3 * b + 1] = q[1]; qT[3 * b + 2] = q[2];
    }
}
"""

C_FLAGS = ["-O3", "-march=native", "-shared", "-fPIC"]


def build_c():
    """Compile ``C_SOURCE`` into a temp dir; returns a callable ``c_rk4`` or None without gcc."""
    gcc = shutil.which("gcc")
    if gcc is None:
        return None
    tmp = tempfile.mkdtemp(prefix="pmpjax_bench_")
    src, lib = os.path.join(tmp, "rk4.c"), os.path.join(tmp, "rk4.so")
    with open(src, "w") as f:
        f.write(C_SOURCE)
    subprocess.run([gcc, *C_FLAGS, src, "-o", lib, "-lm"], check=True, capture_output=True)
    dll = ctypes.CDLL(lib)
    arr = np.ctypeslib.ndpointer(dtype=np.float64, flags="C_CONTIGUOUS")
    fn = dll.lambda0_rk4
    fn.restype = None
    fn.argtypes = [ctypes.c_long, ctypes.c_long, ctypes.c_double, arr, arr, arr, ctypes.c_double,
                   ctypes.c_double, ctypes.c_double, arr, arr, arr]

    def c_rk4(q0, xd, steps=N_STEPS, h=DT):
        q0 = np.ascontiguousarray(q0, dtype=np.float64)
        xd = np.ascontiguousarray(xd, dtype=np.float64)
        A = np.linalg.inv(W)
        G = np.ascontiguousarray(A @ KJ)
        out = np.empty_like(q0)
        fn(len(q0), steps, h, np.ascontiguousarray(A), G, np.ascontiguousarray(Q_REST), D, K_GAIN,
           TAU, q0, xd, out)
        return out

    c_rk4.flags = " ".join([gcc.split("/")[-1], *C_FLAGS[:2]])
    return c_rk4


# ----------------------------------------------------------------------------------------------
# numba scalar loop (same algorithm as the C one)


def build_numba():
    """Returns a jitted ``numba_rk4(q0, xd)`` or None without numba (compiles on first call)."""
    try:
        import numba
    except ImportError:
        return None

    @numba.njit(cache=False)
    def field(t, q0, q1, q2, A, G, qr, d, k, tau, xd1, xd2):
        sa, ca = math.sin(q0), math.cos(q0)
        sb, cb = math.sin(q1), math.cos(q1)
        sc, cc = math.sin(q2), math.cos(q2)
        x1 = -d * (ca * sb * cc - sa * sc)
        x2 = -d * (sa * sb * cc + ca * sc)
        J00, J01, J02 = d * (sa * sb * cc + ca * sc), -d * ca * cb * cc, d * (ca * sb * sc + sa * cc)
        J10, J11, J12 = d * (sa * sc - ca * sb * cc), -d * sa * cb * cc, d * (sa * sb * sc - ca * cc)
        e0, e1, e2 = q0 - qr[0], q1 - qr[1], q2 - qr[2]
        P00 = A[0, 0] * J00 + A[0, 1] * J01 + A[0, 2] * J02
        P10 = A[1, 0] * J00 + A[1, 1] * J01 + A[1, 2] * J02
        P20 = A[2, 0] * J00 + A[2, 1] * J01 + A[2, 2] * J02
        P01 = A[0, 0] * J10 + A[0, 1] * J11 + A[0, 2] * J12
        P11 = A[1, 0] * J10 + A[1, 1] * J11 + A[1, 2] * J12
        P21 = A[2, 0] * J10 + A[2, 1] * J11 + A[2, 2] * J12
        g0 = G[0, 0] * e0 + G[0, 1] * e1 + G[0, 2] * e2
        g1 = G[1, 0] * e0 + G[1, 1] * e1 + G[1, 2] * e2
        g2 = G[2, 0] * e0 + G[2, 1] * e1 + G[2, 2] * e2
        m00 = J00 * P00 + J01 * P10 + J02 * P20
        m01 = J00 * P01 + J01 * P11 + J02 * P21
        m11 = J10 * P01 + J11 * P11 + J12 * P21
        v1 = J00 * g0 + J01 * g1 + J02 * g2
        v2 = J10 * g0 + J11 * g1 + J12 * g2
        idet = 1.0 / (m00 * m11 - m01 * m01)
        s = t / tau
        es = math.exp(-s)
        K = k * (1.0 - es - s * es)
        F1 = K * (xd1 - x1) + (m11 * v1 - m01 * v2) * idet
        F2 = K * (xd2 - x2) + (m00 * v2 - m01 * v1) * idet
        return P00 * F1 + P01 * F2 - g0, P10 * F1 + P11 * F2 - g1, P20 * F1 + P21 * F2 - g2

    @numba.njit(cache=False)
    def run(q0, xd, steps, h, A, G, qr, d, k, tau):
        out = np.empty_like(q0)
        for b in range(q0.shape[0]):
            y0, y1, y2 = q0[b, 0], q0[b, 1], q0[b, 2]
            a, c = xd[b, 0], xd[b, 1]
            for i in range(steps):
                t = i * h
                a0, a1, a2 = field(t, y0, y1, y2, A, G, qr, d, k, tau, a, c)
                b0, b1, b2 = field(t + 0.5 * h, y0 + 0.5 * h * a0, y1 + 0.5 * h * a1, y2 + 0.5 * h * a2,
                                   A, G, qr, d, k, tau, a, c)
                c0, c1, c2 = field(t + 0.5 * h, y0 + 0.5 * h * b0, y1 + 0.5 * h * b1, y2 + 0.5 * h * b2,
                                   A, G, qr, d, k, tau, a, c)
                d0, d1, d2 = field(t + h, y0 + h * c0, y1 + h * c1, y2 + h * c2, A, G, qr, d, k, tau, a, c)
                y0 += (h / 6.0) * (a0 + 2.0 * (b0 + c0) + d0)
                y1 += (h / 6.0) * (a1 + 2.0 * (b1 + c1) + d1)
                y2 += (h / 6.0) * (a2 + 2.0 * (b2 + c2) + d2)
            out[b, 0], out[b, 1], out[b, 2] = y0, y1, y2
        return out

    A = np.linalg.inv(W)
    G = A @ KJ

    def numba_rk4(q0, xd, steps=N_STEPS, h=DT):
        return run(np.ascontiguousarray(q0, dtype=np.float64), np.ascontiguousarray(xd, dtype=np.float64),
                   steps, h, A, G, Q_REST, D, K_GAIN, TAU)

    return numba_rk4


# ----------------------------------------------------------------------------------------------
# timing


def lambda0_rhs(fk_jac, q0, target, KJ, q_rest, tau, tau0):
    """A careful SciPy user's λ0-PMP field ``rhs(t, q)`` (``W = τ0 KJ``, Arimoto's gain with Eq 10's
    ``k = b_max/τ0`` at ``q0``) for a closed-form ``fk_jac(q) -> (x, J)``. With ``A = W⁻¹``,
    ``g = A τ_el = (q − q_rest)/τ0`` and ``P = A Jᵀ``: ``q̇ = P (F + λ0) − g``, ``λ0 = (J P)⁻¹ J g``
    (one m×m solve), ``F = K(t) (x_d − x)``."""
    import math

    A = np.linalg.inv(tau0 * KJ)  # once per movement
    _, J0 = fk_jac(q0)
    k = 1.0 / (np.linalg.eigvalsh(J0 @ A @ J0.T)[0] * tau0)
    itau, itau0, exp = 1.0 / tau, 1.0 / tau0, math.exp

    def rhs(t, q):
        x, J = fk_jac(q)
        s = t * itau
        g = (q - q_rest) * itau0
        P = A @ J.T
        lam0 = np.linalg.solve(J @ P, J @ g)
        return P @ ((k * (1.0 - (1.0 + s) * exp(-s))) * (target - x) + lam0) - g

    return rhs


def per_call_us(fn, *args, number=2000, repeats=7):
    """Minimum over ``repeats`` of the mean µs per call of ``fn(*args)`` in ``number`` calls."""
    import time

    best = float("inf")
    for _ in range(repeats):
        t = time.perf_counter()
        for _ in range(number):
            fn(*args)
        best = min(best, (time.perf_counter() - t) / number)
    return 1e6 * best


def best_of(fn, repeats: int, min_total: float = 0.0):
    """Minimum wall time [s] of ``fn()`` over ``repeats`` calls (more if ``min_total`` not reached)."""
    times = []
    while len(times) < repeats or sum(times) < min_total:
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
        if len(times) >= 50:
            break
    return min(times)


def _thread_ticks() -> dict:
    """CPU clock ticks (user + system) of every thread of this process, by thread id (Linux)."""
    out = {}
    try:
        for tid in os.listdir("/proc/self/task"):
            try:
                with open(f"/proc/self/task/{tid}/stat") as f:
                    fields = f.read().rsplit(")", 1)[1].split()
                out[tid] = int(fields[11]) + int(fields[12])  # utime, stime
            except (OSError, IndexError, ValueError):
                pass
    except OSError:
        pass
    return out


class CpuClock:
    """Wall and process CPU time (every thread of this process) of a ``with`` block; ``cores`` =
    CPU / wall, the mean number of cores the block kept busy (on an idle machine; other load
    lowers it); ``thread_cpu``: CPU time of the calling thread alone; ``threads``: how many
    threads did at least 5 % of the block's CPU work (from ``/proc``, whatever the load)."""

    def __enter__(self):
        self._ticks = _thread_ticks()
        self.wall, self.cpu, self.thread_cpu = time.perf_counter(), time.process_time(), time.thread_time()
        return self

    def __exit__(self, *exc):
        self.wall, self.cpu = time.perf_counter() - self.wall, time.process_time() - self.cpu
        self.thread_cpu = time.thread_time() - self.thread_cpu  # the calling thread alone
        self.cores = self.cpu / self.wall if self.wall > 0 else float("nan")
        after = _thread_ticks()
        d = [after[t] - self._ticks.get(t, 0) for t in after]
        total = sum(d)
        self.threads = sum(1 for v in d if total > 0 and v >= 0.05 * total)
        return False


def _openblas_threads() -> dict:
    """Thread count of every OpenBLAS loaded in this process (NumPy's and SciPy's), through its
    ``*_get_num_threads`` symbol (what ``threadpoolctl`` reads)."""
    import ctypes

    out = {}
    try:
        with open("/proc/self/maps") as f:
            libs = sorted({line.split()[-1] for line in f if "openblas" in line.lower() and "/" in line})
    except OSError:
        return out
    for path in libs:
        lib = ctypes.CDLL(path)
        for sym in ("scipy_openblas_get_num_threads64_", "scipy_openblas_get_num_threads",
                    "openblas_get_num_threads64_", "openblas_get_num_threads"):
            if hasattr(lib, sym):
                out[os.path.basename(path)] = int(getattr(lib, sym)())
                break
    return out


def threads_report() -> dict:
    """The thread pools either side may use: cores available to this process, BLAS (threadpoolctl
    if installed, else NumPy's build configuration and the OpenBLAS thread counts), the thread
    environment variables, and XLA's CPU devices."""
    import numpy

    rep = {"cpu_count": os.cpu_count(), "affinity": len(os.sched_getaffinity(0)),
           "env": {k: os.environ[k] for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                                               "XLA_FLAGS") if k in os.environ}}
    try:
        from threadpoolctl import threadpool_info

        rep["blas"] = [{k: d.get(k) for k in ("internal_api", "version", "num_threads", "filepath")}
                       for d in threadpool_info()]
    except ImportError:
        blas = numpy.show_config(mode="dicts")["Build Dependencies"]["blas"]
        rep["blas"] = {"numpy_blas": f"{blas.get('name')} {blas.get('version')}",
                       "openblas_configuration": blas.get("openblas configuration"),
                       "openblas_threads": _openblas_threads(), "threadpoolctl": "not installed"}
    try:
        import jax

        rep["xla"] = {"devices": [str(d) for d in jax.devices()], "backend": jax.default_backend()}
    except ImportError:
        pass
    return rep


_COMPILE_EVENTS = ("/jax/core/compile/jaxpr_trace_duration", "/jax/core/compile/jaxpr_to_mlir_module_duration",
                   "/jax/core/compile/backend_compile_duration")
_SPANS: list = []


def _span_listener(event, start, end, **_):
    if event in _COMPILE_EVENTS:
        _SPANS.append((start, end))


def watch_compiles() -> None:
    """Record JAX's tracing, lowering and XLA compilation time spans (``jax.monitoring``), once."""
    import jax

    if not getattr(watch_compiles, "done", False):
        jax.monitoring.register_event_time_span_listener(_span_listener)
        watch_compiles.done = True


def compile_seconds(since: float) -> float:
    """Union of the tracing/lowering/compilation time spans that started after ``since``
    (``time.time()``; nested traces counted once). Needs :func:`watch_compiles` first."""
    spans = sorted(s for s in _SPANS if s[0] >= since)
    total, cur = 0.0, None
    for a, b in spans:
        if cur is None or a > cur[1]:
            total += 0.0 if cur is None else cur[1] - cur[0]
            cur = [a, b]
        else:
            cur[1] = max(cur[1], b)
    return total + (0.0 if cur is None else cur[1] - cur[0])


def machine() -> str:
    try:
        with open("/proc/cpuinfo") as f:
            model = next(line.split(":", 1)[1].strip() for line in f if line.startswith("model name"))
    except (OSError, StopIteration):
        model = "unknown CPU"
    return f"{os.cpu_count()}-core {model} (KVM), no GPU"


def versions(*extra: str) -> dict:
    """Versions of Python and of the packages a benchmark's figures depend on (``None`` when one
    is not installed); ``extra`` names further distributions (e.g. ``"diffrax"``)."""
    import platform
    from importlib import metadata

    out = {"python": platform.python_version()}
    for name in ("jax", "jaxlib", "numpy", "scipy", "mujoco", *extra):
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = None
    return out


def header(parameters: dict, *extra: str) -> dict:
    """The common head of a ``results/<name>.json``: date (UTC), machine, CPU count, versions,
    the 1-, 5- and 15-minute load averages at the start, and the run's parameters. The caller adds
    its data, ``tables`` (the printed tables) and ``load_end`` (:func:`load_average`)."""
    return {"date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "machine": machine(),
            "cpu_count": os.cpu_count(), "versions": versions(*extra), "load_start": load_average(),
            "parameters": parameters}


def load_average() -> list[float]:
    """The 1-, 5- and 15-minute load averages, rounded to 0.01."""
    return [round(v, 2) for v in os.getloadavg()]


def write_results(name: str, res: dict) -> str:
    """Write ``res`` to ``<results>/<name>.json``; returns the path. ``<results>`` is
    ``$PMPJAX_BENCH_RESULTS`` (set by ``python -m benchmarks``) or ``benchmarks/results``."""
    default = os.path.join(os.path.dirname(os.path.abspath(__file__)), "results")
    path = os.path.join(os.environ.get("PMPJAX_BENCH_RESULTS") or default, f"{name}.json")
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "w") as f:
        json.dump(res, f, indent=1)
    return path
