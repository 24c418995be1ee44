"""Figure 3 of Tommasino & Campolo (2017): λ0-PMP center-out paths with anisotropic damping."""

from __future__ import annotations

import numpy as np

from .._chains import Wrist
from .._pmp import ArimotoPlanner, Lambda0PMP, SaveAt, damping_from_stiffness, simulate_sequence
from .center_out import DIRECTIONS, TARGET_RADIUS, center_out_targets
from .curvature import curvature_measures

#: Figure 3 example (Eq 9): KJ [Nm/rad], q_rest [rad], τ = τ0 [s], k [N/m], T [s], target radius
#: [m] (the paper's nominal π/12, which also normalises the curvature areas; see ``center_out``).
FIGURE3 = dict(KJ=np.diag([0.5, 1.5, 2.0]), q_rest=np.deg2rad([5.0, 0.0, 0.0]), tau0=0.08, tau=0.08,
               k=22.5, duration=0.4, radius=TARGET_RADIUS)


def figure3_data(*, dt: float = 1e-3, save_every: int = 5, **overrides) -> dict:
    """The movements of the paper's Figure 3: outbound and inbound λ0-PMP movements between the
    centre and each of the 8 targets.

    Each direction starts at ``q_rest`` (which points at the centre) and runs centre → target →
    centre, ``duration`` each (RK4).

    **Arguments:**

    - ``dt``: integration step [s].
    - ``save_every``: save every this many steps.
    - ``overrides``: any of the parameters in :data:`FIGURE3` (``KJ``, ``q_rest``, ``tau0``, ``tau``,
      ``k``, ``duration``, ``radius``, ...), which default to the paper's.

    **Returns:**

    A dict of NumPy arrays: ``t`` (S,) [s], ``q`` (8, 2, S, 3) [rad], ``x`` (8, 2, S, 2) [m],
    ``speed`` (8, 2, S) [m/s], ``targets`` (8, 2) [m], ``A_sum``/``A_net`` (8, 2) curvature areas
    (out, in) normalised by ``radius²``, ``A_hyst`` (8,), and the parameters used.

    **Raises:**

    - ``TypeError`` for an unknown parameter; ``ValueError`` for a non-positive ``dt``.
    """
    unknown = sorted(set(overrides) - set(FIGURE3))
    if unknown:
        raise TypeError(f"figure3_data: unknown parameter(s) {unknown}; known: {sorted(FIGURE3)}")
    if not (isinstance(dt, int | float) and dt > 0):
        raise ValueError(f"`dt` must be a positive number of seconds, got {dt!r}")
    p = {**FIGURE3, **overrides}
    chain = Wrist(1.0)
    model = Lambda0PMP(chain, KJ=p["KJ"], q_rest=p["q_rest"], W=damping_from_stiffness(p["KJ"], p["tau0"]))
    tg = center_out_targets(p["radius"])
    targets = np.stack([tg[name] for name in DIRECTIONS])
    seqs = np.stack([targets, np.zeros_like(targets)], axis=1)  # (8, 2 movements, 2)
    q0 = np.broadcast_to(np.asarray(p["q_rest"], float), (8, 3))
    tr = simulate_sequence(model, ArimotoPlanner(k=p["k"], tau=p["tau"]), q0, seqs,
                           duration=p["duration"], dt=dt, saveat=SaveAt(every=save_every))
    x = np.asarray(tr.x)
    starts = np.stack([np.zeros_like(targets), targets], axis=1)
    a_sum, a_net = (np.asarray(v) for v in curvature_measures(x, starts, seqs, scale=p["radius"]))
    return dict(t=np.asarray(tr.t), q=np.asarray(tr.q), x=x, speed=np.asarray(tr.speed),
                targets=targets, directions=DIRECTIONS, A_sum=a_sum, A_net=a_net,
                A_hyst=a_net[:, 0] + a_net[:, 1], status=np.asarray(tr.status), params=p)


def plot_figure3(data: dict, *, fig=None):
    """The paper's Figure 3: panels A (task paths), B (joint trajectories), C (tangential speed).

    **Arguments:**

    - ``data``: the result of :func:`figure3_data`.
    - ``fig``: a matplotlib figure to draw into (default a new one).

    **Returns:**

    The matplotlib figure.

    **Raises:**

    - ``ValueError`` when ``data`` lacks an entry of :func:`figure3_data`'s result.
    """
    import matplotlib.pyplot as plt

    missing = [k for k in ("t", "x", "q", "speed", "targets", "directions") if k not in data]
    if missing:
        raise ValueError(f"`data` must be figure3_data()'s result; missing {missing}")
    fig = fig or plt.figure(figsize=(13, 4.2))
    ax_a, ax_b, ax_c = fig.subplots(1, 3)
    colors = plt.cm.hsv(np.linspace(0, 1, 9)[:8])
    T = float(data["params"]["duration"])
    for i, name in enumerate(data["directions"]):
        ax_a.plot(*data["x"][i, 0].T, color=colors[i], lw=1.5)
        ax_a.plot(*data["x"][i, 1].T, color=colors[i], lw=1.0, ls="--")
        ax_a.annotate(name, data["targets"][i] * 1.12, ha="center", va="center", fontsize=8)
        t2 = np.concatenate([data["t"], T + data["t"]])
        for j, ls in enumerate(("-", "--", ":")):
            q = np.rad2deg(np.concatenate([data["q"][i, 0, :, j], data["q"][i, 1, :, j]]))
            ax_b.plot(t2, q, color=colors[i], ls=ls, lw=1)
        ax_c.plot(t2, np.concatenate([data["speed"][i, 0], data["speed"][i, 1]]), color=colors[i], lw=1)
    ax_a.scatter(*np.vstack([data["targets"], [0, 0]]).T, s=60, facecolors="none", edgecolors="k")
    ax_a.set(aspect="equal", xlabel="x1 [m] (East →)", ylabel="x2 [m] (North ↑)",
             title="A  task paths (— out, -- in)")
    ax_b.set(xlabel="time [s]", ylabel="joint angle [deg]", title="B  joints (— PS, -- FE, ··· RUD)")
    ax_c.set(xlabel="time [s]", ylabel="tangential speed [m/s]", title="C  speed profiles")
    fig.tight_layout()
    return fig
