"""The reflex network of the springy arm (Williamson 1996) in closed loop, MJX and C MuJoCo:
grasp, withdrawal, lead, summed moves; figures.

References, each independent of the code under test (``tests/_springy.py``): C MuJoCo ``mj_step``
loops written here (spring torque in ``qfrc_applied``), settled C rollouts for statics, the
paper's minimum-jerk velocity formula, central differences of C MuJoCo.

MJX compiles are slow on this CPU, so each MJX function is compiled once per module with one
shape: the reflex network (contacts, 3 scenarios × 3 s). Closed-loop behaviour is mostly
checked on the C MuJoCo backend (no compile).
"""

import jax
import mujoco
import numpy as np
import pytest
from _springy import _paper_velocity, c_replay, c_settle

import pmpjax as pj
from pmpjax._springy_arm.arm import PROBE_PARK
from pmpjax._springy_arm.reflexes import GRASP, LEAD, WITHDRAW

# ----------------------------------------------------------------------------------------------
# Reflex network, closed loop on C MuJoCo (no compile) and on MJX (one compile, checked against C)

DUR = 3.0
PUSH = (1.8, 2.4)  # the reach to P[1] (0-1 s) has rung down by then (damping ratio ≈ 0.5)
LEAD_ON = (1.6, 2.6)
RELEASE = 2.6
TOUCH_1J = 0.4  # the grasp case: one-joint reach 0 -> 1, touched at 0.4 s
LEAD_THRESHOLD_DOC = 0.5  # [Nm]: ReflexNetwork's documented default lead_threshold
TOUCH_THRESHOLD_DOC = 0.5  # [N]: its documented default touch_threshold (scripted touches 10 % below / above)
# Lead pushes ramped up over RAMP s, sized by the documented threshold: the static joint torque
# J^T F of the largest-loaded joint at the settled posture times these factors (the record's own
# torque deviation, checked in the test, lies just below / just above the threshold).
LEAD_PUSH_FACTORS = (0.85, 1.15)
RAMP = 0.3
MOVE_TARGETS = np.array([[1.0, 0, 0, 0, 0, 0], [1.5, 0, 0, 0.3, 0, 0], [0.5, 0.2, 0, 0.6, 0, 0]])  # + rest


@pytest.fixture(scope="module")
def scenarios(arm, free_arm, P):
    """Closed-loop scenarios, one arm each: 0 grasp (probe contact at the palm), 1 withdrawal
    (probe at the back of the hand), 2 lead + 15 N push, 3 the same push without lead, 4 lead +
    a push just below the documented lead threshold, 5 one-joint reach touched at 0.4 s
    (scripted), 6 two moves issued at 0 and 0.5 s, 7 three moves issued at 0.1, 0.4 and 0.6 s,
    8 lead + a push just above the threshold, 9 and 10 scenario 5 touched on the palm 10 % below
    and 10 % above the documented touch threshold."""
    dt = arm.dt
    T = int(round(DUR / dt))
    t = np.arange(T) * dt
    # Where the hand passes 0.5 s into the reach rest -> up (C MuJoCo, open loop): the probe waits
    # 5 cm off the palm (grasp) or off the back of the hand (withdrawal), so the hand runs into it.
    mv = pj.moves_from_targets(arm.q_rest, P[2][None], [0.0], [1.0])
    qs_open, _ = pj.summed_moves(mv, arm.q_rest, t[:300])
    _, hands, xm, _ = c_replay(arm, np.asarray(qs_open), q0=arm.q_rest)
    palm_normal = xm[250][:, 1]  # the palm site sits on the hand's +y side
    targets = [(0.0, P[2]), (1.2, P[0]), (2.7, P[3])]
    one_joint = arm.q_rest.copy()
    one_joint[0] = 1.0
    a, b, c = MOVE_TARGETS + arm.q_rest
    inputs = [
        pj.script_inputs(arm, DUR, targets=targets, release=[RELEASE]),
        pj.script_inputs(arm, DUR, targets=targets, release=[RELEASE]),
        pj.script_inputs(arm, DUR, targets=[(0.0, P[1])], lead=[LEAD_ON]),
        pj.script_inputs(arm, DUR, targets=[(0.0, P[1])]),
        pj.script_inputs(arm, DUR, targets=[(0.0, P[1])], lead=[LEAD_ON]),
        pj.script_inputs(arm, DUR, targets=[(0.0, one_joint)], touch=[(TOUCH_1J, TOUCH_1J + 0.05, 5.0, 0.0)]),
        pj.script_inputs(arm, DUR, targets=[(0.0, a), (0.5, b)]),
        pj.script_inputs(arm, DUR, targets=[(0.1, a), (0.4, b), (0.6, c)]),
        pj.script_inputs(arm, DUR, targets=[(0.0, P[1])], lead=[LEAD_ON]),
        *(pj.script_inputs(arm, DUR, targets=[(0.0, one_joint)],
                           touch=[(TOUCH_1J, TOUCH_1J + 0.05, fac * TOUCH_THRESHOLD_DOC, 0.0)]) for fac in (0.9, 1.1)),
    ]
    n = len(inputs)
    probe = np.tile(np.asarray(PROBE_PARK), (n, T, 1))
    probe[0] = hands[250] + 0.05 * palm_normal
    probe[1] = hands[250] - 0.05 * palm_normal
    probe[:2, t >= 0.7] = PROBE_PARK  # a tap: the object goes away again
    force = np.zeros((n, T, 3))
    push = (t >= PUSH[0]) & (t < PUSH[1])
    force[2:4, push] = [0.0, 0.0, 15.0]  # lift the hand (lead) / the same push without lead
    # the lift whose static torque on the most loaded joint is the documented threshold: C MuJoCo's
    # Jacobian at the hand's centre of mass (where the force acts), at the posture settled on P[1]
    q_sag, _, _ = c_settle(free_arm, P[1], free_arm.K)
    d = mujoco.MjData(free_arm.mj_model)
    d.qpos[:] = q_sag[0]
    mujoco.mj_forward(free_arm.mj_model, d)
    Jc = np.zeros((3, arm.n))
    mujoco.mj_jacBodyCom(free_arm.mj_model, d, Jc, None, free_arm.layout.hand_body)
    f_thr = LEAD_THRESHOLD_DOC / np.abs(Jc[2]).max()
    ramp = np.clip((t - PUSH[0]) / RAMP, 0.0, 1.0) * push
    force[4, :, 2], force[8, :, 2] = (fac * f_thr * ramp for fac in LEAD_PUSH_FACTORS)
    net = pj.reflex_network(arm)
    stacked = pj.stack_inputs(inputs)
    traj = pj.run_reflexes(arm, net, stacked, probe=probe, force=force, backend="mujoco")
    return dict(traj=traj, t=t, inputs=stacked, probe=probe, force=force, net=net, mode=traj.log["mode"], push=push)


@pytest.fixture(scope="module")
def mjx_reflex(arm, scenarios):
    """The first three scenarios (contacts, lead) on MJX."""
    s = scenarios
    sub = jax.tree_util.tree_map(lambda x: x[:3], s["inputs"])
    traj = pj.run_reflexes(arm, s["net"], sub, probe=s["probe"][:3], force=s["force"][:3])
    return jax.tree_util.tree_map(np.asarray, traj)


def test_mjx_reflex_run_matches_c_mujoco(arm, scenarios, mjx_reflex):
    """The two engines on the same closed loop: the same modes at the same steps; postures equal
    to round-off without contact (lead), to the constraint solver's tolerance with contact."""
    c, mx = scenarios["traj"], mjx_reflex
    assert np.array_equal(mx.log["mode"], c.log["mode"][:3])
    assert c.touch[:2].max() > 1.0  # contacts really happened
    err = np.abs(mx.q - c.q[:3]).max(axis=(1, 2))
    assert err[:2].max() < 1e-4  # contact: MJX's line search differs from C's (~1e-6 per contact)
    assert err[2] < 1e-10  # no contact: round-off only, over 3 s
    # ...and the MJX record equals open-loop C replays of the set-points it commanded: a plain
    # mj_step loop, and the batch rollout with the probe (mocap) and push (xfrc) channels.
    qc, _, _, qT = c_replay(arm, mx.q_set[2], q0=arm.q_rest, force=scenarios["force"][2])
    assert np.abs(qc - mx.q[2]).max() < 1e-10 and np.abs(qT - mx.q_final[2]).max() < 1e-10
    rep = pj.rollout(arm, mx.q_set, q0=arm.q_rest, probe=scenarios["probe"][:3], force=scenarios["force"][:3],
                     backend="mujoco")
    assert np.abs(rep.q[2] - mx.q[2]).max() < 1e-10
    assert np.abs(rep.q[:2] - mx.q[:2]).max() < 1e-4 and np.abs(rep.hand - mx.hand).max() < 1e-4
    assert np.abs(rep.touch - mx.touch).max() < 0.05 * mx.touch.max()  # the same contacts, sensed alike


def test_grasp_stops_where_touched_without_overshoot(arm, free_arm, scenarios):
    """The grasp case: a one-joint reach 0 -> 1 touched at 0.4 s. The arm 'quickly stops, and
    holds itself in the stopped position' (Figure 8): it brakes within a few cm, never swings back
    past the touched posture, and holds that posture (not a gravity sag below it). Which bug: a
    stop implemented as a 0.25 s move added on top of the running reach goes 0.13 rad past the
    touched posture, swings 0.10 rad back below it and is still 0.06 rad off at the end."""
    tr, mode, t = scenarios["traj"], scenarios["mode"], scenarios["t"]
    i = 5
    k = int(np.argmax(mode[i] == GRASP))
    assert t[k] == pytest.approx(TOUCH_1J)
    q_touch = tr.q[i, k - 1]  # the posture where the touch was sensed
    after = tr.q[i, k:] - q_touch
    assert after.max() < 0.05  # stops within 0.05 rad (the arm moved at ~1 rad/s)
    assert after.min() > -0.005  # no swing back past the touched posture (a held set-point swung back 0.45 rad)
    assert np.abs(tr.q[i, -1] - q_touch).max() < 2e-4  # holds the touched posture...
    assert np.abs(tr.qdot[i, -1]).max() < 2e-3
    # ...with the set-point above it by the gravity sag: check against C statics of that set-point.
    q_held, _, speed = c_settle(free_arm, tr.q_set[i, -1], free_arm.K)
    assert speed < 1e-10
    assert np.abs(q_held[0] - q_touch).max() < 1e-4  # (the command still carries grasp_damping·q̇/K)
    assert np.abs(tr.q_set[i, -1] - q_touch).max() > 0.05


def test_grasp_on_probe_contact_holds_touched_posture(arm, mjx_reflex, scenarios):
    tr, net = mjx_reflex, scenarios["net"]
    mode = tr.log["mode"][0]
    k_touch = int(np.argmax(mode == GRASP))
    assert k_touch > 0 and tr.touch[0, k_touch - 1, 0] > float(net.touch_threshold)  # measured palm contact
    assert 0.3 < tr.t[k_touch] < 0.8
    k_rel = int(round(RELEASE / arm.dt))
    held = tr.q[0, k_touch - 1]
    assert np.all(mode[k_touch:k_rel] == GRASP)  # the 1.2 s target is suppressed until release
    assert np.abs(tr.q[0, k_rel - 1] - held).max() < 2e-3  # rests where touched (probe gone at 0.7 s)
    assert np.abs(tr.qdot[0, k_rel - 1]).max() < 1e-2
    assert np.abs(tr.q_set[0, -1] - tr.q_set[0, k_rel - 1]).max() > 0.05  # released: reaching again


def test_withdrawal_returns_to_rest_and_suppresses_targets(arm, free_arm, mjx_reflex, scenarios):
    tr, net = mjx_reflex, scenarios["net"]
    mode = tr.log["mode"][1]
    k_touch = int(np.argmax(mode == WITHDRAW))
    assert k_touch > 0 and tr.touch[1, k_touch - 1, 1] > float(net.touch_threshold)  # back of hand
    assert tr.touch[1, :, 0].max() == 0.0  # the palm was never touched
    k_rel = int(round(RELEASE / arm.dt))
    k_done = k_touch + int(round(float(net.withdraw_duration) / arm.dt)) + 1
    # Winner-take-all: the ongoing reach is dropped, the set-point is exactly the rest primitive,
    # and the 1.2 s target is suppressed until release.
    assert np.abs(tr.q_set[1, k_done:k_rel] - arm.q_rest).max() < 1e-12
    # The arm settles where the springs balance gravity at the rest set-point (settled C statics).
    q_c, _, speed = c_settle(free_arm, arm.q_rest, free_arm.K)
    assert speed < 1e-10
    assert np.abs(tr.q[1, k_rel - 1] - q_c[0]).max() < 2e-3
    assert np.abs(tr.q_set[1, -1] - arm.q_rest).max() > 0.05  # after release, targets again


def test_lead_yields_to_a_push_above_threshold_only(arm, scenarios):
    """Leading (Figure 10): 'backing off the joint equilibrium positions to keep the torque low'.
    Measured on the C-MuJoCo runs: under a 15 N lift the led arm yields far more than the same
    arm without lead (whose springs load up), and once leading stops it stays where it was led
    (set-point constant) while the arm without lead springs back. The documented default threshold
    (0.5 Nm) by behaviour: the spring torques K (θ_set − q), from the record and the arm's K, deviate
    from their value when leading starts by at most 0.5 Nm on every joint, and by exactly that on
    the joints that yield; a push that deviates them by just under 0.5 Nm moves no set-point, one
    just over it does."""
    tr, mode, t, push = scenarios["traj"], scenarios["mode"], scenarios["t"], scenarios["push"]
    k0 = int(np.argmax(push)) - 1
    k_end = int(np.argmax(t >= PUSH[1]))
    k_on = int(np.argmax(t >= LEAD_ON[0]))
    k_off = int(np.argmax(t >= LEAD_ON[1]))
    assert np.all(mode[2][(t >= LEAD_ON[0]) & (t < LEAD_ON[1])] == LEAD)
    rise_lead = tr.hand[2, k_end - 1, 2] - tr.hand[2, k0, 2]
    rise_free = tr.hand[3, k_end - 1, 2] - tr.hand[3, k0, 2]
    assert rise_lead > 3 * rise_free > 0.3  # yields with lead (~0.67 m vs ~0.19 m)
    assert np.abs(tr.tau[3, push] - tr.tau[3, k0]).max() > 5 * LEAD_THRESHOLD_DOC  # without lead the springs load up
    assert np.abs(tr.q_set[2, k_off:] - tr.q_set[2, k_off]).max() == 0.0  # released: set-point constant
    assert tr.hand[2, -1, 2] - tr.hand[2, k0, 2] > 0.2  # led to a new position...
    assert abs(tr.hand[3, -1, 2] - tr.hand[3, k0, 2]) < 0.01  # ...the unled arm springs back

    K = np.asarray(arm.K)

    def deviation(i):  # (n,) largest |spring torque − its value at lead onset| while leading
        spring = K * (np.asarray(tr.q_set[i]) - np.asarray(tr.q[i]))
        return np.abs(spring[k_on:k_off] - spring[k_on]).max(0)

    big, below, above = deviation(2), deviation(4), deviation(8)
    assert big.max() == pytest.approx(LEAD_THRESHOLD_DOC, abs=1e-9) and np.sum(big > 0.999 * LEAD_THRESHOLD_DOC) >= 2
    # the pushes straddle the threshold: within 10 % below it, and over it once it is reached
    assert 0.9 * LEAD_THRESHOLD_DOC < below.max() < LEAD_THRESHOLD_DOC
    assert above.max() == pytest.approx(LEAD_THRESHOLD_DOC, abs=1e-9)
    moved = [np.abs(tr.q_set[i, k_on:] - tr.q_set[i, k_on]).max() for i in (4, 8)]
    assert moved[0] < 1e-12  # below: the set-point does not back off (round-off of q + τ/K)...
    assert moved[1] > 1e-3  # ...above: it does
    assert np.abs(tr.hand[4, -1] - tr.hand[4, k0]).max() < 0.01  # and the arm pushed below it returns


def test_a_touch_grasps_above_the_documented_threshold_only(scenarios):
    """The documented default touch threshold (0.5 N) by behaviour: the one-joint reach touched on
    the palm at 0.4 s with 0.45 N goes on reaching, with 0.55 N it grasps (from the touch on)."""
    mode, t = scenarios["mode"], scenarios["t"]
    touched = (t >= TOUCH_1J) & (t < TOUCH_1J + 0.05)
    assert np.all(mode[9] != GRASP)
    assert np.any(mode[10][touched] == GRASP) and not np.any(mode[10][t < TOUCH_1J] == GRASP)


def test_overlapping_reflex_moves_sum(arm, scenarios):
    """Williamson's Figure 4 inside the network: the set-point velocity is the sum of the moves'
    minimum-jerk velocities (paper formula, each move from the previous target), whatever the
    issue times (a reach issued at t = 0 must not be replaced by the next target)."""
    tr, t, dt = scenarios["traj"], scenarios["t"], arm.dt
    rest = arm.q_rest
    a, b, c = MOVE_TARGETS + rest
    for i, moves in ((6, [(0.0, rest, a), (0.5, a, b)]), (7, [(0.1, rest, a), (0.4, a, b), (0.6, b, c)])):
        v = np.diff(tr.q_set[i], axis=0) / dt  # average velocity over each step
        tm = t[:-1] + dt / 2
        v_ref = sum(_paper_velocity(tm[:, None], (end - start)[None], t0, 1.0) for t0, start, end in moves)
        assert np.abs(v - v_ref).max() < 2e-5  # midpoint rule: O(dt²)
        assert np.abs(v_ref).max() > 1.5
        assert np.abs(tr.q_set[i, -1] - moves[-1][2]).max() < 1e-12


# ----------------------------------------------------------------------------------------------
# Figures


def test_figures_show_the_data(scenarios, free_arm, P):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    mv = pj.moves_from_targets([0.0], [[1.0], [1.5]], t0=[0.0, 0.5], duration=[1.0, 1.0])
    t = np.linspace(0, 2, 201)
    fig = pj.plot_summed_moves(mv, [0.0], t)
    summed = fig.axes[0].lines[-1].get_ydata()
    assert summed[-1] == pytest.approx(1.5)
    tr = jax.tree_util.tree_map(lambda a: a[0] if np.ndim(a) > 1 else a, scenarios["traj"])
    fig8 = pj.plot_reflex(tr, joint=0, sensor="palm")
    assert np.array_equal(fig8.axes[1].lines[0].get_ydata(), tr.q_set[:, 0])
    assert np.array_equal(fig8.axes[0].lines[0].get_ydata(), tr.touch[:, 0])
    chain = pj.MjcfChain(free_arm, "hand")
    fig2 = pj.plot_force_field(chain, P[1], free_arm.K, n=3)
    U = fig2.axes[0].collections[0].U
    assert np.isfinite(U).all() and np.abs(U).max() > 0
    plt.close("all")
