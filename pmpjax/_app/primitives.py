"""Main-job part ``primitives``: the postural-primitives results of Williamson (1996) beyond Figure 4.

- Figures 3 and 5: the four primitives (rest, down, up, side) and blends of the three front ones
  (``Σ α_i P_i``, α on a grid of the simplex) settle under gravity where the springs balance it
  (:func:`pmpjax.arm_equilibrium`); the blends fill the region between the primitives, winner-take-all
  reaches only its corners. Every equilibrium is checked by a C MuJoCo forward rollout
  (``backend="mujoco"``) held at the set-point until the arm stops.
- Figure 2 (Cog's analogue of the frog-leg fields): the convergent force field of the 'down' posture.
- Figures 8, 9, 10: the reflex network in closed loop on C MuJoCo: grasp and withdrawal during a
  reach forward and back (scripted touch on the palm / back of the hand), and lead (the hand lifted
  by a push while leading is on).
"""

from __future__ import annotations

import itertools

import numpy as np

from .._base import status_message
from .parts import Part

# Reflex scenarios [s]: reach forward (up) and back to rest, out again, touched on the way out; a
# later target to 'side' must be suppressed by the reflex.
REACH = ((0.0, 2), (1.0, 0), (2.0, 2), (3.0, 3))  # (time, primitive index)
TOUCH = (2.4, 2.45)  # the touch on the palm (grasp) or the back of the hand (withdrawal)
DURATION = 3.6
LEAD_ON, PUSH, PUSH_N = (1.6, 2.6), (1.8, 2.4), 15.0  # lead active; upward push on the hand [s], [N]


def simplex_grid(k: int, m: int) -> np.ndarray:
    """All weights (M, k) with entries in {0, 1/m, ..., 1} summing to 1 (C order)."""
    rows = [c for c in itertools.product(range(m + 1), repeat=k) if sum(c) == m]
    return np.asarray(rows, float) / m


def _c_hand(arm, q) -> np.ndarray:
    """Hand site positions (N, 3) [m] of postures ``q`` (N, n) by C MuJoCo forward kinematics."""
    import mujoco

    m = arm.mj_model
    d = mujoco.MjData(m)
    out = np.empty((len(q), 3))
    for i, qi in enumerate(q):
        d.qpos[:] = qi
        mujoco.mj_kinematics(m, d)
        out[i] = d.site_xpos[arm.layout.hand_site]
    return out


def _primitives(ctx) -> dict:
    """Williamson (1996) beyond Figure 4: primitives under gravity, blends vs winner-take-all, reflexes.

    Gravity equilibria of the primitives and their blends vs winner-take-all (Figs 3, 5), the convergent
    force field of a posture (Fig 2), and the grasp, withdrawal and lead reflexes (Figs 8-10); forward
    rollouts on C MuJoCo."""
    import jax
    import matplotlib.pyplot as plt

    from .._chains import MjcfChain
    from .._springy_arm import (
        PRIMITIVE_NAMES,
        arm_equilibrium,
        blend,
        default_primitives,
        load_arm,
        plot_force_field,
        plot_reflex,
        reflex_network,
        rollout,
        run_reflexes,
        script_inputs,
        stack_inputs,
        winner_take_all,
    )

    arm = load_arm(contacts=False)  # touch is scripted; no probe contacts needed
    P = np.asarray(default_primitives())
    chain = MjcfChain(arm, "hand")

    # --- Figures 3 and 5: blends of the three front primitives vs winner-take-all ---------------
    front = simplex_grid(3, 2 if ctx.quick else 6)  # weights of (down, up, side)
    alpha = np.concatenate([np.zeros((len(front), 1)), front], axis=1)
    alpha = np.concatenate([np.eye(4)[:1], alpha])  # + the rest primitive
    q_blend = np.asarray(blend(alpha, P))
    q_wta = np.asarray(winner_take_all(alpha, P))  # the strongest activation wins (ties: the first)
    q_set = np.concatenate([q_blend, q_wta])
    # Calls of 8 set-points: one compiled shape for every size (and the one the test suite compiles).
    eqs = [arm_equilibrium(arm, q_set[i:i + 8]) for i in range(0, len(q_set), 8)]
    q_eq, hand_eq, residual, status = (np.concatenate([np.asarray(getattr(e, f)) for e in eqs])
                                       for f in ("q", "hand", "residual", "status"))
    hand_set = _c_hand(arm, q_set)  # where the hand would be without gravity
    # C MuJoCo forward rollout, each set-point held from the set-point posture for 3 s.
    T = int(round(3.0 / arm.dt))
    ro = rollout(arm, np.repeat(q_set[:, None], T, axis=1), backend="mujoco")
    settle = np.abs(np.asarray(ro.q_final) - q_eq).max(axis=1)
    speed = np.abs(np.asarray(ro.qdot_final)).max()
    n = len(alpha)
    rows = []
    for i in range(2 * n):
        a = alpha[i % n]
        rows.append({
            "rule": "blend" if i < n else "winner-take-all", "status": status_message(int(status[i])),
            **{f"alpha_{nm}": float(a[j]) for j, nm in enumerate(PRIMITIVE_NAMES)},
            **{f"q_set_{j + 1} [rad]": f"{q_set[i, j]:.12g}" for j in range(arm.n)},  # full precision: re-checkable
            **{f"q_eq_{j + 1} [rad]": f"{q_eq[i, j]:.12g}" for j in range(arm.n)},
            **{f"hand_set_{c} [m]": float(hand_set[i, k]) for k, c in enumerate("xyz")},
            **{f"hand_eq_{c} [m]": f"{hand_eq[i, k]:.12g}" for k, c in enumerate("xyz")},
            "sag [m]": float(np.linalg.norm(hand_eq[i] - hand_set[i])),
            "residual [Nm]": float(residual[i]),
            "c_rollout_vs_equilibrium [rad]": float(settle[i]),
        })
    ctx.table(rows, "primitives_equilibria.csv",
              "Set-points (blends Σ α_i P_i of the down/up/side primitives, and winner-take-all of the same "
              "activations), their equilibria under gravity (springs balance gravity), hand positions with and "
              "without gravity, and the C MuJoCo rollout's settled posture against the equilibrium.",
              "Williamson (1996) Figures 3 and 5: four primitives; blends reach the region between them.")
    fig, axs = plt.subplots(1, 2, figsize=(10, 4.6))
    for ax, (u, v, lu, lv) in zip(axs, ((0, 2, "x (forward) [m]", "z (up) [m]"), (0, 1, "x (forward) [m]", "y [m]"))):
        b = slice(1, n)
        ax.plot(hand_set[b, u], hand_set[b, v], "o", mfc="none", color="0.6", label="blend set-point (no gravity)")
        ax.plot(hand_eq[b, u], hand_eq[b, v], "o", color="C0", label="blend equilibrium (gravity)")
        for s, e in zip(hand_set[b], hand_eq[b]):
            ax.plot([s[u], e[u]], [s[v], e[v]], "-", color="0.8", lw=0.8)
        corners = np.unique(np.round(hand_eq[n:], 9), axis=0)
        ax.plot(corners[:, u], corners[:, v], "*", ms=14, color="C3", label="winner-take-all equilibria")
        ax.plot(hand_eq[0, u], hand_eq[0, v], "s", color="k", label="rest")
        for j, nm in enumerate(PRIMITIVE_NAMES):
            k = int(np.argmax(np.all(alpha == np.eye(4)[j], axis=1)))
            ax.annotate(nm, hand_eq[k, [u, v]], textcoords="offset points", xytext=(5, 5), fontsize=8)
        ax.set_xlabel(lu)
        ax.set_ylabel(lv)
        ax.set_aspect("equal", adjustable="datalim")
    axs[0].legend(fontsize=7, frameon=False, loc="best")
    fig.suptitle("Postural primitives: blends fill the region between primitives; winner-take-all reaches its corners")
    fig.tight_layout()
    ctx.figure(fig, "primitives_blends.png",
               "Hand positions of the blended set-points without gravity (hollow) and of their equilibria under "
               "gravity (filled, grey lines = sag), with winner-take-all (stars), sagittal and top views.",
               "Williamson (1996) Figure 3 (shaded region spanned by the primitives) and Figure 5 (the four postures).")
    blends = slice(1, n)
    ctx.log(f"{n} activations: {int((status == 0).sum())}/{2 * n} equilibria converged; hand sag "
            f"{min(r['sag [m]'] for r in rows):.3f}..{max(r['sag [m]'] for r in rows):.3f} m; C rollouts settle within "
            f"{settle.max():.1e} rad of the equilibria")

    # --- Figure 2: convergent force field of the 'down' posture ---------------------------------
    # 7 × 7 postures in both sizes: the shape the postural-primitives notebook compiles.
    ctx.figure(plot_force_field(chain, P[1], arm.K, n=7), "primitives_force_field.png",
               "Hand force field of the 'down' set-point (springs only) with the shoulder flexion and elbow swept "
               "±0.6 rad, sagittal plane: the forces converge on the set-point's hand position.",
               "Williamson (1996) Section 2.2 / Figure 2: convergent force fields (frog spinal cord).")

    # --- Figures 8-10: reflexes on C MuJoCo ------------------------------------------------------
    dur = DURATION
    T = int(round(dur / arm.dt))
    t = np.arange(T) * arm.dt
    targets = [(tk, P[j]) for tk, j in REACH]
    inputs = stack_inputs([
        script_inputs(arm, dur, targets=targets, touch=[(TOUCH[0], TOUCH[1], 5.0, 0.0)]),  # grasp (palm)
        script_inputs(arm, dur, targets=targets, touch=[(TOUCH[0], TOUCH[1], 0.0, 5.0)]),  # withdrawal (back)
        script_inputs(arm, dur, targets=[(0.0, P[1])], lead=[LEAD_ON]),  # lead
    ])
    force = np.zeros((3, T, 3))
    force[2, (t >= PUSH[0]) & (t < PUSH[1])] = [0.0, 0.0, PUSH_N]
    tr = jax.tree_util.tree_map(np.asarray, run_reflexes(arm, reflex_network(arm), inputs, force=force,
                                                         backend="mujoco"))

    def one(i):
        return jax.tree_util.tree_map(lambda a: a[i] if np.ndim(a) > 1 else a, tr)

    mode = tr.log["mode"]
    k = int(np.argmax(mode[0] == 1))  # first grasp step
    q_touch = tr.q[0, k - 1]
    hold = float(np.abs(tr.q[0, -1] - q_touch).max())
    gap = float((tr.q_set[0, -1] - q_touch)[0])
    withdrawn = float(np.abs(tr.q_set[1, -1] - arm.q_rest).max())
    at_rest = np.flatnonzero((np.abs(tr.q_set[1] - arm.q_rest).max(axis=1) < 1e-6) & (t > TOUCH[0]))
    back_at_rest = float(t[at_rest[0]]) if at_rest.size else float("nan")
    push = (t >= PUSH[0]) & (t < PUSH[1])
    lead_shift = float(tr.q_set[2, push][-1, 0] - tr.q_set[2, int(np.argmax(push)) - 1, 0])
    for i, (name, fname, sensor, paper) in enumerate((
        ("grasp", "primitives_grasp.png", "palm", "Williamson (1996) Figure 8: the arm quickly stops and stays where "
         "it was touched; set-point and posture differ by the gravity load."),
        ("withdrawal", "primitives_withdrawal.png", "back", "Williamson (1996) Figure 9: on the withdraw sensor the "
         "arm quickly returns to the rest position."),
        ("lead", "primitives_lead.png", "torque", "Williamson (1996) Figure 10: when the torque departs from its "
         "reference the set-point is backed off, so the arm is led."),
    )):
        fig = plot_reflex(one(i), joint=0, sensor=sensor, title=name)
        if sensor != "torque":  # the touch is scripted (no probe contact): show the scripted reading
            ax = fig.axes[0]
            ax.lines[0].set_ydata(np.asarray(inputs.touch)[i, :, ("palm", "back").index(sensor)])
            ax.relim()
            ax.autoscale_view()
            ax.set_ylabel(f"{sensor} touch [N] (scripted)")
        ctx.figure(fig, fname,
                   f"Reflex network on C MuJoCo, {name}: shoulder-flexion set-point (solid) and actual angle "
                   f"(dashed), with the {'touch sensor' if sensor != 'torque' else 'torque and its lead reference'}.",
                   paper)
    ctx.table([
        {"scenario": "grasp", "event [s]": float(t[k]), "quantity": "max |q_end - q_touched| [rad]", "value": hold},
        {"scenario": "grasp", "event [s]": float(t[k]), "quantity": "shoulder set-point above posture at end [rad]",
         "value": gap},
        {"scenario": "withdrawal", "event [s]": TOUCH[0], "quantity": "max |set-point_end - rest| [rad]",
         "value": withdrawn},
        {"scenario": "withdrawal", "event [s]": TOUCH[0], "quantity": "set-point back at rest at [s]",
         "value": back_at_rest},
        {"scenario": "lead", "event [s]": PUSH[0], "value": lead_shift,
         "quantity": f"shoulder set-point shift during a {PUSH_N:g} N lift [rad]"},
    ], "primitives_reflexes.csv", "Reflex outcomes on C MuJoCo: grasp holds the touched posture, withdrawal returns "
       "the set-point to rest (later targets suppressed), lead moves the set-point with the push.",
       "Williamson (1996) Figures 8-10 (qualitative: stop and hold; return to rest; set-point follows the push).")
    ctx.log(f"grasp at {t[k]:.3f} s holds within {hold:.1e} rad; withdrawal set-point at rest "
            f"({withdrawn:.1e} rad); lead moved the shoulder set-point by {lead_shift:+.3f} rad")
    return {
        "activations": n, "converged": int((status == 0).sum()), "equilibria": 2 * n,
        "max_sag_m": max(r["sag [m]"] for r in rows),
        "blend_region_hand_span_m": np.ptp(hand_eq[blends], axis=0).round(4).tolist(),
        "winner_take_all_distinct_postures": int(len(np.unique(np.round(q_wta, 12), axis=0))),
        "max_c_rollout_vs_equilibrium_rad": float(settle.max()), "max_final_speed_rad_s": float(speed),
        "grasp_time_s": float(t[k]), "grasp_hold_error_rad": hold, "grasp_set_point_gap_rad": gap,
        "withdrawal_set_point_vs_rest_rad": withdrawn, "lead_set_point_shift_rad": lead_shift,
    }


primitives = Part(_primitives, seconds=6, seconds_full=6, order=90,
                  title="Postural primitives: blends, force fields and reflexes (Williamson 1996)")
