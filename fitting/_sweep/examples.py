"""Sweep kernels of the examples (main job, benchmark, notebook): one parameter row each.

- :func:`curvature_row`: λ0-PMP center-out movements of the wrist (Figure 3 set-up, design §3.2-3.5)
  from the centre to the 8 targets for one stiffness anisotropy and rest posture; ``A_net``,
  ``A_sum`` per target (``pmpjax.curvature_measures``) and a per-movement status.
- :func:`donders_power_row`: one synthetic subject's Donders NIO fit (``fitting._donders``'s
  compiled fit ``fit_nio_batch``, the one behind ``fitting.fit_donders``) from ``n`` noisy steady
  postures; the error of the fitted ``KJ``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

import pmpjax as pj

#: Eigenvalues of KJ (PS, FE, RUD) before the trace normalisation: Figure 3's (0.5, 1.5, 2) has
#: anisotropy K_RUD / K_FE = 4/3.
K_PS, K_FE = 0.5, 1.5
TARGETS = np.stack([pj.center_out_targets()[name] for name in pj.DIRECTIONS])  # (8, 2) [m at d = 1]


def curvature_row(p, *, duration: float = 0.4, dt: float = 1e-3, tau: float = 0.08, k: float = 22.5):
    """Outbound movements centre -> each of the 8 targets for one row ``p``:

    - ``p["anisotropy"]``: ``K_RUD / K_FE``, with ``KJ = normalize_trace(diag(0.5, 1.5, 1.5 ρ))``
      (trace 4 Nm/rad; ρ = 4/3 is Figure 3's ``diag(0.5, 1.5, 2)``);
    - ``p["rest_ps_deg"]``: the pronation-supination angle of ``q_rest = (ps, 0, 0)`` [deg]
      (it points at the centre, where every movement starts).

    ``W = τ KJ`` (Eq 7, τ0 = τ), Arimoto planner ``k``, ``τ`` (Eq 8). Returns ``A_net``, ``A_sum``
    (8,) normalised by (π/12)² and ``status`` (8,) Status codes of the movements.
    """
    rho = jnp.asarray(p["anisotropy"], float)
    KJ = pj.normalize_trace(jnp.diag(jnp.stack([K_PS + 0.0 * rho, K_FE + 0.0 * rho, K_FE * rho])))
    q_rest = jnp.stack([jnp.deg2rad(p["rest_ps_deg"]), 0.0, 0.0])
    model = pj.Lambda0PMP(pj.Wrist(), KJ=KJ, q_rest=q_rest, W=pj.damping_from_stiffness(KJ, tau))
    tr = pj.simulate(model, pj.ArimotoPlanner(k=k, tau=tau), jnp.broadcast_to(q_rest, (8, 3)), TARGETS,
                     duration=duration, dt=dt)
    a_sum, a_net = pj.curvature_measures(tr.x, np.zeros((8, 2)), TARGETS)
    # simulate's codes: 0 ok, 1 non-finite, else singular (mapped onto the Status vocabulary)
    status = tr.status  # already pmpjax.Status codes
    return {"A_net": a_net, "A_sum": a_sum, "status": status}


def plot_curvature_map(anisotropy, rest_ps_deg, a_net, *, fig=None):
    """``A_net`` (n_anisotropy, n_rest, 8) as one heat map per target, in compass layout."""
    import matplotlib.pyplot as plt

    fig = fig or plt.figure(figsize=(10, 9))
    axes = fig.subplots(3, 3)
    where = {"NW": (0, 0), "N": (0, 1), "NE": (0, 2), "W": (1, 0), "E": (1, 2), "SW": (2, 0), "S": (2, 1),
             "SE": (2, 2)}
    lim = float(np.nanmax(np.abs(a_net))) or 1.0
    for i, name in enumerate(pj.DIRECTIONS):
        ax = axes[where[name]]
        im = ax.pcolormesh(rest_ps_deg, anisotropy, a_net[:, :, i], cmap="RdBu_r", vmin=-lim, vmax=lim,
                           shading="nearest")
        ax.set_title(f"{name}", fontsize=9)
        ax.set_xlabel("rest PS [deg]", fontsize=8)
        ax.set_ylabel("K_RUD / K_FE", fontsize=8)
        ax.tick_params(labelsize=7)
    axes[1, 1].axis("off")
    fig.colorbar(im, ax=axes[1, 1], fraction=0.8, label="A_net (outbound)")
    fig.suptitle("λ0-PMP curvature A_net per target over stiffness anisotropy and rest posture")
    fig.tight_layout()
    return fig


#: Donders power analysis: postures drawn per subject (rows use the first ``n_postures``).
N_MAX = 64


def donders_power_row(p, *, n_max: int = N_MAX, n_starts: int = 2, max_steps: int = 60,
                      half_angle_deg: float = 20.0):
    """One synthetic subject's NIO fit (the compiled fit behind ``fitting.fit_donders``) from
    ``p["n_postures"]`` steady postures with ``p["noise_deg"]`` RMS orientation noise.

    Row ``p``: ``logK`` (5,) and ``q_rest`` (3,) of the true subject (``fitting.params_from_stiffness``
    parameterisation, trace 4), ``n_postures`` (<= ``n_max``), ``noise_deg`` [deg], ``seed``.
    Data as ``pmpjax.synthetic_recordings`` makes them (jax.random instead of NumPy): targets
    uniform on the ±``half_angle_deg`` screen square, equilibrium postures, a hand-frame noise
    rotation with isotropic Gaussian rotation vector, and the pointing of the noisy orientation.
    Returns ``KJ_error`` (max |KJ_fit − KJ| [Nm/rad]), ``KJ_fit`` (3, 3) and ``status``.
    """
    from pmpjax.internal import equilibrium_one

    from .._donders import fit_nio_batch, nio_starts, stiffness_from_params

    chain = pj.Wrist()
    KJ = stiffness_from_params(p["logK"], 3)
    q_rest = p["q_rest"]
    key_t, key_n = jax.random.split(jax.random.PRNGKey(p["seed"]))
    h = np.sin(np.deg2rad(half_angle_deg))
    targets = jax.random.uniform(key_t, (n_max, 2), minval=-h, maxval=h)
    q_eq = jax.vmap(lambda x: equilibrium_one(chain, KJ, q_rest, x, q_rest)[0])(targets)
    eps = jax.random.normal(key_n, (n_max, 3)) * (jnp.deg2rad(p["noise_deg"]) / np.sqrt(3.0))
    q_obs = pj.joint_angles_from_matrix(pj.wrist_rotation(q_eq) @ pj.matrix_from_rotvec(eps))
    x_obs = chain.fk(q_obs)
    w = (jnp.arange(n_max) < p["n_postures"]).astype(float)
    q_mean = jnp.sum(q_obs * w[:, None], 0) / jnp.maximum(jnp.sum(w), 1.0)
    # fit_donders' starts: isotropic KJ at the mean observed posture, then seeded perturbations
    theta0 = jnp.asarray(nio_starts(np.zeros((1, 3)), 5, 3, n_starts, 0)).at[..., 5:].add(q_mean)
    out = fit_nio_batch(chain, theta0, x_obs[None], q_obs[None], w[None], n_k=5, trace=4.0, kind="torsion",
                     tol=1e-10, max_steps=max_steps, rcond=1e-2)
    KJ_fit = out["KJ"][0]
    return {"KJ_error": jnp.max(jnp.abs(KJ_fit - KJ)), "KJ_fit": KJ_fit, "status": out["status"][0]}
