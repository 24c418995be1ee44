"""NIO fit of Donders' law: per-subject stiffness ``KJ`` (SPD, trace 4) and rest posture ``q_rest``.

For each subject the model posture at each observed pointing position is the equilibrium of
design §3.1 (``pmpjax.equilibrium_posture``, differentiated implicitly), and the parameters
minimise the squared mismatch with the observed postures, by ``fitting.least_squares``
(Levenberg–Marquardt).

**Parameterisation.** ``KJ = t · expm(S) / tr(expm(S))`` with ``S`` symmetric and traceless
(``n(n+1)/2 − 1`` numbers: 5 for the wrist) and ``t`` the trace (4 Nm/rad): every parameter
vector is valid (``fitting._optimise.spd``).

**Residual.** ``residual="torsion"`` (default, wrist only): the signed angle of ``R_obsᵀ R_model``
about the pointing axis [rad], one number per sample. Model and observation point at the same
screen point, so they differ only by a rotation about the pointing axis — the Donders torsion,
which is what the paper's NIO fits; it is free of the joint-angle parameterisation and, for
isotropic orientation noise, has equal variance for every sample, so it is unweighted.
``residual="joint"``: the joint-angle difference ``q_model − q_obs`` (n per sample), for any chain.

Standard errors of the parameters come from the Gauss–Newton covariance (``fitting.covariance``).

**Identifiability in the coefficients of Donders' law.** Every observed posture lies on a surface
whose equation is *linear* in the coefficients ``c = (free entries of KJ, b = KJ q_rest)``
(``fitting._donders.coefficients``). The log-stiffness / ``q_rest`` parameters bend this linear structure:
at 0.5° noise the fit wanders far along the 2–3 directions that ±20° of torsion data cannot pin
down, and the curvature of the map drags even the best-determined parameter combinations 5–35
Gauss–Newton standard errors away from the truth. In ``c`` the residual is nearly linear, so the
singular values, directions, ``identifiable`` flags and standard errors of the report are given
in ``c`` (residual Jacobian ``∂r/∂c = ∂r/∂θ (∂c/∂θ)⁻¹``); there the linearised errors hold at
0.5° noise (tests/test_donders.py checks ``|z| < 3`` along every identifiable direction of the six
Table subjects).
"""

from __future__ import annotations

import dataclasses
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from pmpjax import Chain, Status, Wrist, rotvec_from_joint_angles, torsion_between, wrist_rotation
from pmpjax.internal import (
    as_array,
    bucket,
    check_finite_masked,
    check_positive_int,
    equilibrium_one,
    fast_compile_jit,
    pad_rows,
    replace,
)

from .._optimise import covariance, least_squares, spd_size, stiffness_from_params
from .coefficients import coefficient_names, donders_coefficients, parameter_names

# --- result -------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class DondersFit:
    """Per-subject NIO results (leading axis S = subjects; p parameters; numpy arrays).

    ``KJ`` (S, n, n) [Nm/rad], ``q_rest`` (S, n) [rad]; ``params`` (S, p) named by
    ``param_names`` (:func:`parameter_names`); ``loss`` (S,) ½ Σ r²; ``rms`` (S,) RMS residual [rad];
    ``steps`` (S,) LM iterations of the best start; ``status`` (S,) int :class:`pmpjax.Status`
    (``SUCCESSFUL``, ``MAX_STEPS``, ``NONFINITE``: no start had a finite loss or every equilibrium
    failed, ``TOO_FEW_DATA``: no more valid samples than parameters); ``converged`` (S,) bool
    = ``status == SUCCESSFUL``; ``n_samples`` (S,); ``stderr`` (S, p), ``cov`` (S, p, p); ``KJ_stderr``
    (S, n, n), ``q_rest_stderr`` (S, n) (delta method); ``coefficients`` (S, p) of Donders' law
    (:func:`donders_coefficients`) named by ``coef_names``, ``coefficient_stderr`` (S, p),
    ``coefficient_cov`` (S, p, p);
    ``singular_values`` (S, p) of the residual Jacobian with respect to the coefficients;
    ``directions`` (S, p, p), row k = the combination of coefficients of singular value k;
    ``identifiable`` (S, p) bool per direction (``s_k > rcond s_max``); ``direction_stderr``
    (S, p) standard error along each direction; ``start_loss``, ``start_steps`` (S, n_starts).
    """

    KJ: np.ndarray
    q_rest: np.ndarray
    params: np.ndarray
    loss: np.ndarray
    rms: np.ndarray
    steps: np.ndarray
    status: np.ndarray
    n_samples: np.ndarray
    stderr: np.ndarray
    cov: np.ndarray
    KJ_stderr: np.ndarray
    q_rest_stderr: np.ndarray
    coefficients: np.ndarray
    coefficient_stderr: np.ndarray
    coefficient_cov: np.ndarray
    singular_values: np.ndarray
    directions: np.ndarray
    identifiable: np.ndarray
    direction_stderr: np.ndarray
    start_loss: np.ndarray
    start_steps: np.ndarray
    param_names: tuple[str, ...]
    coef_names: tuple[str, ...]

    @property
    def converged(self) -> np.ndarray:
        return self.status == Status.SUCCESSFUL

    def report(self, i: int = 0) -> str:
        """Human-readable identifiability report of one subject: which combinations of Donders'
        coefficients the data determine, with their standard errors.

        **Arguments:**

        - ``i``: the subject's index.

        **Returns:**

        The report (str).
        """
        lines = [
            f"subject {i}: {Status(int(self.status[i])).message}, {int(self.steps[i])} LM steps, "
            f"RMS residual {np.rad2deg(self.rms[i]):.3g} deg, n = {int(self.n_samples[i])}"
        ]
        lines.append("singular values of the residual Jacobian and their combinations of the coefficients "
                     "of Donders' law (b = KJ q_rest):")
        for k, s in enumerate(self.singular_values[i]):
            v = self.directions[i, k]
            top = np.argsort(-np.abs(v))[:3]
            combo = " ".join(f"{v[j]:+.2f}·{self.coef_names[j]}" for j in top)
            tag = "" if self.identifiable[i, k] else "  <- UNIDENTIFIABLE"
            lines.append(f"  s={s:.3g}  se={self.direction_stderr[i, k]:.3g}  {combo}{tag}")
        return "\n".join(lines)


# --- the fit ------------------------------------------------------------------------------


def nio_residual(chain, n_k, trace, kind, tol):
    """The NIO residual ``residual(theta, (x, q_obs, w))`` of one subject (module docstring):
    ``theta`` = ``n_k`` log-stiffness parameters then ``q_rest``; ``kind`` "torsion" or "joint";
    ``tol`` the equilibrium Newton tolerance."""
    n = chain.n

    def residual(theta, data):
        x, q_obs, w = data
        KJ = stiffness_from_params(theta[:n_k], n, trace)
        qr = theta[n_k:]
        q, _, status, _, _ = jax.vmap(
            lambda xx, q0: equilibrium_one(chain, KJ, qr, xx, q0, tol=tol, check_minimum=False)
        )(x, q_obs)
        ok = status == Status.SUCCESSFUL
        if kind == "torsion":
            r = torsion_between(wrist_rotation(q_obs), wrist_rotation(q))
            bad = ~ok
        else:
            r = q - q_obs
            bad = ~ok[:, None]
            w = w[:, None]
        # A failed equilibrium makes the residual non-finite: LM rejects the step (and a start
        # whose own residual fails is reported as not converged).
        return jnp.where(bad & (w > 0), jnp.nan, r * w).reshape(-1)

    return residual


@partial(fast_compile_jit, static_argnames=("n_k", "trace", "kind", "tol", "max_steps"))
def fit_nio_batch(chain, theta0, x, q_obs, w, *, n_k, trace, kind, tol, max_steps, rcond):
    """The compiled fit behind :func:`fit_donders`: subjects (leading axis) × starts ``theta0``
    (S, n_starts, p), data ``x`` (S, N, m), ``q_obs`` (S, N, n), weights ``w`` (S, N); a dict of
    per-subject arrays (best start, standard errors, identifiability in the coefficients)."""
    residual = nio_residual(chain, n_k, trace, kind, tol)
    n = chain.n
    p = theta0.shape[-1]

    def one_subject(th0, x, q_obs, w):
        res = jax.vmap(lambda t: least_squares(residual, t, (x, q_obs, w), max_steps=max_steps))(th0)
        finite = jnp.isfinite(res.cost)
        best = jnp.argmin(jnp.where(finite, res.cost, jnp.inf))
        r = jax.tree_util.tree_map(lambda a: a[best], res)
        n_valid = jnp.sum(w > 0) * (1 if kind == "torsion" else n)
        nv = n_valid.astype(r.cost.dtype)  # float counts: no implicit int→float promotion
        N = r.residual.shape[0]
        cov, se, _, _ = covariance(r, rcond=1e-12)
        # the same in the coefficients c of Donders' law (module docstring): ∂r/∂c = ∂r/∂θ (∂c/∂θ)⁻¹
        dc = jax.jacfwd(lambda t: donders_coefficients(t, n, trace))(r.x)
        r_c = replace(r, jac=jnp.linalg.solve(dc.T, r.jac.T).T)
        cov_c, se_c, s, Vt = covariance(r_c, rcond=1e-12)
        # `covariance` divides by N − p; masked samples are not data: rescale to n_valid − p.
        fix = (N - p) / jnp.maximum(nv - p, 1.0)
        cov, se, cov_c, se_c = cov * fix, se * jnp.sqrt(fix), cov_c * fix, se_c * jnp.sqrt(fix)
        sigma = jnp.sqrt(2.0 * r.cost / jnp.maximum(nv - p, 1.0))
        dse = sigma / jnp.where(s > 0, s, jnp.inf)
        ident = s > rcond * s[0]
        dK = jax.jacfwd(lambda t: stiffness_from_params(t, n, trace))(r.x[:n_k])  # (n, n, n_k)
        covK = jnp.einsum("ija,ab,ijb->ij", dK, cov[:n_k, :n_k], dK)
        enough = n_valid > p
        status = jnp.where(~enough, Status.TOO_FEW_DATA,
                           jnp.where(~finite[best], Status.NONFINITE, r.status))
        return dict(
            x=r.x,
            KJ=stiffness_from_params(r.x[:n_k], n, trace),
            cost=r.cost,
            rms=jnp.sqrt(2.0 * r.cost / jnp.maximum(nv, 1.0)),
            steps=r.steps,
            status=status,
            n=n_valid,
            se=se,
            cov=cov,
            KJ_se=jnp.sqrt(jnp.maximum(covK, 0.0)),
            c=donders_coefficients(r.x, n, trace),
            se_c=se_c,
            cov_c=cov_c,
            s=s,
            Vt=Vt,
            ident=ident,
            dse=dse,
            start_cost=jnp.where(finite, res.cost, jnp.inf),
            start_steps=res.steps,
        )

    return jax.vmap(one_subject)(theta0, x, q_obs, w)


def nio_starts(q_mean, n_k, n, n_starts, seed):
    """Start 0: isotropic KJ, q_rest = mean observed posture; others: random log-stiffness
    (component sd 0.3, i.e. eigenvalue ratios up to ~2) and q_rest offsets (sd 0.1 rad)."""
    rng = np.random.default_rng(seed)
    dk = rng.normal(scale=0.3, size=(n_starts, n_k))
    dq = rng.normal(scale=0.1, size=(n_starts, n))
    dk[0], dq[0] = 0.0, 0.0
    return np.concatenate(
        [np.broadcast_to(dk, q_mean.shape[:1] + dk.shape), q_mean[:, None, :] + dq[None]], -1
    )


def fit_donders(
    chain: Chain,
    pointing,
    postures,
    *,
    mask=None,
    n_starts: int = 4,
    seed: int = 0,
    residual: str | None = None,
    trace: float = 4.0,
    max_steps: int = 100,
    rcond: float = 1e-2,
    chunk_size: int | None = None,
    tol: float = 1e-10,
    callback=None,
) -> DondersFit:
    """Fit ``KJ`` (SPD, trace ``trace``) and ``q_rest`` per subject to steady postures (NIO).

    **Arguments:**

    - ``chain``: the chain (``pmpjax.Wrist()`` for Donders' law of the wrist).
    - ``pointing``: (S, N, m) or (N, m) observed task positions (screen points [m]).
    - ``postures``: (S, N, n) or (N, n) observed joint angles [rad] (from quaternions with
      ``pmpjax.joint_angles_from_quat``).
    - ``mask``: optional (S, N) bool of valid samples (ragged subjects; padded entries ignored).
    - ``n_starts``: LM starts per subject (start 0 isotropic at the mean posture; the rest
      random perturbations drawn with ``seed``); the lowest finite loss wins.
    - ``seed``: seed of the random starts.
    - ``residual``: "torsion" (wrist default) or "joint" (any chain) — see module docstring.
    - ``trace``: the fixed trace of ``KJ`` [Nm/rad] (only the eigenvalue ratios shape Donders' law).
    - ``max_steps``: LM iterations per start; ``rcond``: identifiability threshold on singular
      values relative to the largest; ``tol``: equilibrium Newton tolerance.
    - ``chunk_size``: subjects per compiled call (default: 8 for up to 8 subjects, else 16 —
      a vmapped LM runs every lane until the chunk's slowest start has finished, so small chunks
      are faster per subject; see benchmarks/donders_fit.py); chunks reuse one compilation, and
      ``callback(start, partial_fit)`` is called after each chunk (write results as they go).

    All subjects of a chunk, and all their starts, run in one ``jit``+``vmap`` call. A subject
    whose fit fails is reported with ``converged = False`` and a ``status`` code; the others are
    unaffected.

    **Returns:**

    A :class:`DondersFit`.

    **Raises:**

    ``TypeError``/``ValueError`` naming the argument for a non-chain, wrong shapes,
    NaN/inf among the valid samples, unreachable pointing, bad options.

    **Compile time:** ≈ 13 s on first use (the NIO residual, its forward-mode Jacobian through the
    equilibria and the LM loop, compiled once for every subject in the batch; subject counts are
    bucketed); ≈ 2 s to run the six Table subjects × 500 postures (benchmarks/compile_times.py).
    """
    if not isinstance(chain, Chain):
        raise TypeError(f"`chain` must be a pmpjax Chain, got {type(chain).__name__}")
    n, m = chain.n, chain.m
    kind = residual or ("torsion" if isinstance(chain, Wrist) else "joint")
    if kind not in ("torsion", "joint"):
        raise ValueError(f"`residual` must be 'torsion' or 'joint', got {residual!r}")
    if kind == "torsion" and not isinstance(chain, Wrist):
        raise ValueError("`residual='torsion'` needs a pmpjax.Wrist chain; use residual='joint'")
    pointing = np.asarray(as_array("pointing", pointing, tail=(None, m), finite=False), dtype=float)
    postures = np.asarray(as_array("postures", postures, tail=(None, n), finite=False), dtype=float)
    if pointing.ndim == 2:
        pointing, postures = pointing[None], postures[None]
        mask = None if mask is None else np.asarray(mask)[None]
    if pointing.ndim != 3 or postures.shape[:2] != pointing.shape[:2]:
        raise ValueError(
            f"`pointing` (S, N, {m}) and `postures` (S, N, {n}) must agree in (S, N); got "
            f"{pointing.shape} and {postures.shape}"
        )
    S, N = pointing.shape[:2]
    if S == 0 or N == 0:
        raise ValueError(f"need at least one subject and one sample, got (S, N) = ({S}, {N})")
    mask = np.ones((S, N), bool) if mask is None else np.asarray(mask)
    if mask.shape != (S, N) or mask.dtype != bool:
        raise ValueError(f"`mask` must be a bool array of shape {(S, N)}, got {mask.dtype} {mask.shape}")
    for name, a in (("pointing", pointing), ("postures", postures)):
        check_finite_masked(name, a, mask)
    chain.check_target("pointing", pointing[mask])
    check_positive_int("n_starts", n_starts)
    check_positive_int("max_steps", max_steps)
    if not (np.isfinite(trace) and trace > 0):
        raise ValueError(f"`trace` must be positive, got {trace}")
    if chunk_size is not None:
        check_positive_int("chunk_size", chunk_size)
    # Compiled shapes are bucketed (subjects per call: 8 or 16 unless `chunk_size` is given;
    # samples: power of two >= 64, padding masked out) so similar problems share a compile.
    chunk = int(chunk_size) if chunk_size is not None else (8 if S <= 8 else 16)
    Np = bucket(N, minimum=64)
    pointing, postures, mask = (pad_rows(a, Np, axis=1, fill="zeros") for a in (pointing, postures, mask))

    n_k = spd_size(n)
    w = mask.astype(float)
    x = np.where(mask[..., None], pointing, 0.0)
    q_obs = np.where(mask[..., None], postures, 0.0)
    q_mean = (q_obs * w[..., None]).sum(1) / np.maximum(w.sum(1), 1)[:, None]
    theta0 = nio_starts(q_mean, n_k, n, int(n_starts), seed)
    opts = dict(
        n_k=n_k, trace=float(trace), kind=kind, tol=float(tol), max_steps=int(max_steps), rcond=float(rcond)
    )
    outs = []
    for start in range(0, S, chunk):
        sl = slice(start, min(start + chunk, S))
        # padded subjects repeat the last one; dropped below
        args = [pad_rows(a[sl], chunk) for a in (theta0, x, q_obs, w)]
        out = jax.device_get(fit_nio_batch(chain, *args, **opts))
        out = {k: v[: sl.stop - sl.start] for k, v in out.items()}
        outs.append(out)
        if callback is not None:
            callback(start, _to_fit(outs, n_k, chain))
    return _to_fit(outs, n_k, chain)


def _to_fit(outs, n_k, chain) -> DondersFit:
    o = {k: np.concatenate([d[k] for d in outs]) for k in outs[0]}
    return DondersFit(
        KJ=o["KJ"],
        q_rest=o["x"][:, n_k:],
        params=o["x"],
        loss=o["cost"],
        rms=o["rms"],
        steps=o["steps"],
        status=o["status"],
        n_samples=o["n"],
        stderr=o["se"],
        cov=o["cov"],
        KJ_stderr=o["KJ_se"],
        q_rest_stderr=o["se"][:, n_k:],
        coefficients=o["c"],
        coefficient_stderr=o["se_c"],
        coefficient_cov=o["cov_c"],
        singular_values=o["s"],
        directions=o["Vt"],
        identifiable=o["ident"],
        direction_stderr=o["dse"],
        start_loss=o["start_cost"],
        start_steps=o["start_steps"],
        param_names=parameter_names(chain),
        coef_names=coefficient_names(chain),
    )


def fit_average_donders(chain: Wrist, pointing, postures, *, mask=None, grid: int = 17, **options) -> DondersFit:
    """The paper's own route to ``KJ`` and ``q_rest`` (Tommasino & Campolo 2016, 2017 Section 2):
    NIO on the subject's *average* Donders surface instead of on every sample.

    Per subject the quadratic Donders surface (``pmpjax.fit_donders_surface``) is
    fitted to the rotation vectors of the observed postures ("an extreme down-sampling of
    experimental data"); ``grid × grid`` postures on that surface, spanning the observed range of
    ``(r_y, r_z)``, then go to :func:`fit_donders`.

    The surface postures are noise-free, so the returned ``loss``/``rms`` measure how far the
    λ0-PMP's own surface is from a quadratic, and its standard errors do not describe the data:
    use :func:`fit_donders` on the samples for uncertainty. A quadratic surface has 6 coefficients
    and ``(KJ, q_rest)`` 8 parameters (trace fixed): the fit determines Donders' law (torsion over
    the observed range) but drifts along the remaining flat directions of the parameters, often
    until ``max_steps`` (status MAX_STEPS), and may end with ``q_rest`` far from the postures: the
    samples route (:func:`fit_donders`), where noise and the data's spread pin the parameters
    down, is the better-posed of the two (tests/test_pointing.py compares them).

    **Arguments:**

    - ``chain``: the :class:`pmpjax.Wrist`.
    - ``pointing``: (S, N, 2) observed screen points [m].
    - ``postures``: (S, N, 3) observed joint angles [rad].
    - ``mask``: optional (S, N) bool valid samples.
    - ``grid``: surface postures per axis (``grid × grid`` per subject).
    - ``options``: passed on to :func:`fit_donders` (``n_starts``, ``max_steps``, ...).

    **Returns:**

    A :class:`DondersFit`.

    **Raises:**

    ``TypeError`` for a chain that is not a ``Wrist``; ``ValueError`` for ``grid < 3``; otherwise as
    :func:`fit_donders`.
    """
    from pmpjax import evaluate_surface, fit_donders_surface, joint_angles_from_matrix, matrix_from_rotvec

    if not isinstance(chain, Wrist):
        raise TypeError(f"`chain` must be a pmpjax.Wrist (Donders surfaces are of wrist orientations), got "
                        f"{type(chain).__name__}")
    grid = check_positive_int("grid", grid, minimum=3)  # (a quadratic surface)
    pointing = np.asarray(as_array("pointing", pointing, tail=(None, 2), finite=False), dtype=float)
    postures = np.asarray(as_array("postures", postures, tail=(None, 3), finite=False), dtype=float)
    if postures.ndim == 2:
        pointing, postures = pointing[None], postures[None]
        mask = None if mask is None else np.asarray(mask)[None]
    if postures.ndim != 3 or pointing.shape[:2] != postures.shape[:2]:
        raise ValueError(f"`pointing` (S, N, 2) and `postures` (S, N, 3) must agree in (S, N); got "
                         f"{pointing.shape} and {postures.shape}")
    S, N = postures.shape[:2]
    mask = np.ones((S, N), bool) if mask is None else np.asarray(mask)
    if mask.shape != (S, N) or mask.dtype != bool:
        raise ValueError(f"`mask` must be a bool array of shape {(S, N)}, got {mask.dtype} {mask.shape}")
    check_finite_masked("postures", postures, mask)
    r = np.asarray(rotvec_from_joint_angles(np.where(mask[..., None], postures, 0.0)))
    surface = fit_donders_surface(r, mask=mask)
    u = np.linspace(0.0, 1.0, grid)
    ry_lo, rz_lo = (np.where(mask, r[..., i], np.inf).min(axis=1) for i in (1, 2))
    ry_hi, rz_hi = (np.where(mask, r[..., i], -np.inf).max(axis=1) for i in (1, 2))
    ry = ry_lo[:, None, None] + (ry_hi - ry_lo)[:, None, None] * u[None, :, None]
    rz = rz_lo[:, None, None] + (rz_hi - rz_lo)[:, None, None] * u[None, None, :]
    ry, rz = np.broadcast_arrays(ry, rz)
    rx = np.asarray(evaluate_surface(surface.coef[:, None, :], ry.reshape(S, -1), rz.reshape(S, -1)))
    R = np.asarray(matrix_from_rotvec(np.stack([rx, ry.reshape(S, -1), rz.reshape(S, -1)], -1)))
    q = np.asarray(joint_angles_from_matrix(R))
    x = float(chain.d) * np.stack([-R[..., 1, 0], R[..., 2, 0]], -1)
    return fit_donders(chain, x, q, **options)
