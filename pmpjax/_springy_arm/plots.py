"""Figures of Williamson (1996): summed set-point moves (Figure 4), reflex traces (Figures 8–10),
and the force field of a posture (Figure 2 style). Each returns the matplotlib ``Figure``."""

from __future__ import annotations

import numpy as np

from .._base import as_array, check_positive, check_positive_int
from .._chains import MjcfChain
from .arm import JOINTS, ArmTrajectory
from .primitives import Moves, force_field, summed_moves


def _check_joint(joint, n: int, name: str = "joint") -> int:
    if isinstance(joint, bool) or not isinstance(joint, int | np.integer) or not 0 <= joint < n:
        raise ValueError(f"`{name}` must be a joint index in [0, {n}), got {joint!r}")
    return int(joint)


def plot_summed_moves(moves: Moves, start, t, *, joint: int = 0):
    """Williamson (1996) Figure 4: the individual moves' set-points and velocities (thin) and their
    sum (dotted), for one joint.

    **Arguments:**

    - ``moves``: the :class:`Moves`.
    - ``start``: (n,) the set-point before the first move [rad].
    - ``t``: (T,) times [s].
    - ``joint``: the joint drawn (index).

    **Returns:**

    The matplotlib figure.
    """
    import matplotlib.pyplot as plt

    p_all, v_all = summed_moves(moves, start, t)  # validates moves, start, t
    t = np.asarray(t, float)
    start = np.atleast_1d(np.asarray(start, float))
    joint = _check_joint(joint, start.shape[-1])
    fig, (ax_p, ax_v) = plt.subplots(2, 1, sharex=True, figsize=(6, 5))
    base = start.copy()
    t0, dur, delta = (np.asarray(a) for a in (moves.t0, moves.duration, moves.delta))  # (host-side slices)
    for j in range(delta.shape[0]):
        one = Moves(t0=t0[j : j + 1], duration=dur[j : j + 1], delta=delta[j : j + 1])
        p, v = summed_moves(one, base, t)
        ax_p.plot(t, np.asarray(p)[:, joint], lw=1, label=f"move {j + 1}")
        ax_v.plot(t, np.asarray(v)[:, joint], lw=1)
        base = base + delta[j]
    ax_p.plot(t, np.asarray(p_all)[:, joint], "k:", lw=2, label="sum")
    ax_v.plot(t, np.asarray(v_all)[:, joint], "k:", lw=2)
    ax_p.set_ylabel("set-point [rad]")
    ax_v.set_ylabel("velocity [rad/s]")
    ax_v.set_xlabel("time [s]")
    ax_p.legend(frameon=False)
    return fig


def plot_reflex(traj: ArmTrajectory, *, joint: int = 0, sensor: str = "palm", title: str = ""):
    """Williamson (1996) Figures 8–10: a reflex run's sensor trace on top (touch [N], or the joint
    torque and its lead reference for ``sensor="torque"``), set-point (solid) and actual joint angle
    (dashed) below.

    **Arguments:**

    - ``traj``: one arm's :class:`ArmTrajectory` (from :func:`run_reflexes`; index a batch first).
    - ``joint``: the joint drawn (index).
    - ``sensor``: ``"palm"``, ``"back"`` or ``"torque"``.
    - ``title``: the figure's title.

    **Returns:**

    The matplotlib figure.

    **Raises:**

    - ``TypeError`` for a non-trajectory; ``ValueError`` naming the argument for a batched
      trajectory, a joint index out of range or an unknown ``sensor``.
    """
    import matplotlib.pyplot as plt

    if not isinstance(traj, ArmTrajectory):
        raise TypeError(f"`traj` must be an ArmTrajectory, got {type(traj).__name__}")
    if np.ndim(traj.q) != 2:
        raise ValueError(f"`traj` must be one arm's trajectory (q (T, n)); index a batch first, got {np.shape(traj.q)}")
    joint = _check_joint(joint, np.shape(traj.q)[-1])
    if sensor not in ("palm", "back", "torque"):
        raise ValueError(f"`sensor` must be 'palm', 'back' or 'torque', got {sensor!r}")
    t = np.asarray(traj.t)
    fig, (ax_s, ax_q) = plt.subplots(2, 1, sharex=True, figsize=(6, 5))
    if sensor == "torque":
        ax_s.plot(t, np.asarray(traj.tau)[:, joint], "k-", label="torque")
        if traj.log is not None and "tau_ref" in traj.log:
            ax_s.plot(t, np.asarray(traj.log["tau_ref"])[:, joint], "k--", label="reference")
        ax_s.set_ylabel(f"{JOINTS[joint]} torque [Nm]")
        ax_s.legend(frameon=False)
    else:
        idx = {"palm": 0, "back": 1}[sensor]
        ax_s.plot(t, np.asarray(traj.touch)[:, idx], "k-")
        ax_s.set_ylabel(f"{sensor} touch [N]")
    ax_q.plot(t, np.asarray(traj.q_set)[:, joint], "k-", label="set-point")
    ax_q.plot(t, np.asarray(traj.q)[:, joint], "k--", label="actual")
    ax_q.set_ylabel(f"{JOINTS[joint]} [rad]")
    ax_q.set_xlabel("time [s]")
    ax_q.legend(frameon=False)
    if title:
        ax_s.set_title(title)
    return fig


def plot_force_field(chain, q_set, K, *, joints=(0, 3), span: float = 0.6, n: int = 9, gravity: bool = False):
    """Williamson (1996) Figure 2: the force field of a posture in the sagittal (x, z) plane.

    The two ``joints`` are swept ±``span`` rad around the set-point (the others held), and the hand
    force ``F`` from ``Jᵀ F = τ`` (least squares, :func:`force_field`) is drawn at the hand: the
    frog-leg fields of the paper's Section 2.2.

    **Arguments:**

    - ``chain``: the arm's hand site as a :class:`MjcfChain` (``pj.MjcfChain(arm, "hand")``).
    - ``q_set``: (n,) the set-point [rad].
    - ``K``: (n,) joint stiffness [Nm/rad].
    - ``joints``: the two joints swept (indices).
    - ``span``: half-width of the sweep [rad].
    - ``n``: postures per joint.
    - ``gravity``: include the gravity torque.

    **Returns:**

    The matplotlib figure.

    **Raises:**

    - ``TypeError`` for a non-``MjcfChain``; ``ValueError`` naming the argument for a batched
      ``q_set``, joints that are not two different indices in range, or as :func:`force_field`.
    """
    import matplotlib.pyplot as plt

    if not isinstance(chain, MjcfChain):
        raise TypeError(f"`chain` must be a pmpjax.MjcfChain, got {type(chain).__name__}")
    q_set = np.asarray(as_array("q_set", q_set, tail=(chain.n,)), float)
    if q_set.ndim != 1:
        raise ValueError(f"`q_set` must be one set-point (n,), got shape {q_set.shape}")
    if len(joints) != 2 or joints[0] == joints[1]:
        raise ValueError(f"`joints` must be two different joint indices, got {joints!r}")
    for j in joints:
        _check_joint(j, q_set.shape[0], "joints")
    check_positive("span", span)
    n = check_positive_int("n", n)
    a = np.linspace(-span, span, n)
    A, Bg = np.meshgrid(a, a, indexing="ij")
    q = np.broadcast_to(q_set, A.shape + q_set.shape).copy()
    q[..., joints[0]] += A
    q[..., joints[1]] += Bg
    x = np.asarray(chain.fk(q))
    F = np.asarray(force_field(chain, q, q_set, K, gravity=gravity))
    x0 = np.asarray(chain.fk(q_set))
    fig, ax = plt.subplots(figsize=(5, 5.4), layout="constrained")
    ax.quiver(x[..., 0], x[..., 2], F[..., 0], F[..., 2], angles="xy", label="hand force")
    ax.plot([x0[0]], [x0[2]], "ro", label="set-point posture")
    ax.set_xlabel("x (forward) [m]")
    ax.set_ylabel("z (up) [m]")
    ax.set_aspect("equal")
    # Above the axes: the arrows fill the axes, and any place inside would hide some.
    ax.legend(loc="lower center", bbox_to_anchor=(0.5, 1.01), ncol=2, frameon=False)
    return fig
