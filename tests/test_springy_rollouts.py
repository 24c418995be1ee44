"""Springy arm rollouts (Williamson 1996), MJX and C MuJoCo: the reflex network (grasp,
withdrawal, lead, summed moves) in closed loop, open-loop rollouts of λ0-PMP plans, gradients
through ``mjx.step``, figures.

References, each independent of the code under test (``tests/_springy.py``): C MuJoCo ``mj_step``
loops written here (spring torque in ``qfrc_applied``), settled C rollouts for statics, the
paper's minimum-jerk velocity formula, central differences of C MuJoCo.

MJX compiles are slow on this CPU, so each MJX function is compiled once per module with one
shape: the reflex network (contacts, 3 scenarios × 3 s), the open-loop rollout (no contacts,
3 arms × 1000 steps), its gradient (1 arm × 100 steps). Closed-loop behaviour is mostly checked on
the C MuJoCo backend (no compile).
"""

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from _springy import _paper_velocity, c_replay, c_settle, central_diff

import pmpjax as pj
from pmpjax._springy_arm.arm import PROBE_PARK
from pmpjax._springy_arm.reflexes import GRASP, LEAD, WITHDRAW


@pytest.fixture(scope="module")
def arm():
    return pj.load_arm()


@pytest.fixture(scope="module")
def free_arm():
    return pj.load_arm(contacts=False)


@pytest.fixture(scope="module")
def P():
    return np.asarray(pj.default_primitives())


# ----------------------------------------------------------------------------------------------
# Reflex network, closed loop on C MuJoCo (no compile) and on MJX (one compile, checked against C)

DUR = 3.0
PUSH = (1.8, 2.4)  # the reach to P[1] (0-1 s) has rung down by then (damping ratio ≈ 0.5)
LEAD_ON = (1.6, 2.6)
RELEASE = 2.6
TOUCH_1J = 0.4  # the case: one-joint reach 0 -> 1, touched at 0.4 s
SMALL_PUSH = 0.2  # [N]: below the lead threshold on every joint (checked in the test)
MOVE_TARGETS = np.array([[1.0, 0, 0, 0, 0, 0], [1.5, 0, 0, 0.3, 0, 0], [0.5, 0.2, 0, 0.6, 0, 0]])  # + rest


@pytest.fixture(scope="module")
def scenarios(arm, P):
    """Closed-loop scenarios, one arm each: 0 grasp (probe contact at the palm), 1 withdrawal
    (probe at the back of the hand), 2 lead + 15 N push, 3 the same push without lead, 4 lead +
    small push, 5 one-joint reach touched at 0.4 s (scripted), 6 two moves issued at 0 and 0.5 s,
    7 three moves issued at 0.1, 0.4 and 0.6 s."""
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
    ]
    n = len(inputs)
    probe = np.tile(np.asarray(PROBE_PARK), (n, T, 1))
    probe[0] = hands[250] + 0.05 * palm_normal
    probe[1] = hands[250] - 0.05 * palm_normal
    probe[:2, t >= 0.7] = PROBE_PARK  # a tap: the object goes away again
    force = np.zeros((n, T, 3))
    push = (t >= PUSH[0]) & (t < PUSH[1])
    force[2:4, push] = [0.0, 0.0, 15.0]  # lift the hand (lead) / the same push without lead
    force[4, push] = [0.0, 0.0, SMALL_PUSH]
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
    """The issue's case: a one-joint reach 0 -> 1 touched at 0.4 s. The arm 'quickly stops, and
    holds itself in the stopped position' (Figure 8): it brakes within a few cm, never swings back
    past the touched posture, and holds that posture (not a gravity sag below it). With the old
    network (a 0.25 s move added on top of the running reach) the same run went 0.13 rad past the
    touched posture, swung 0.10 rad back below it and was still 0.06 rad off at the end."""
    tr, mode, t = scenarios["traj"], scenarios["mode"], scenarios["t"]
    i = 5
    k = int(np.argmax(mode[i] == GRASP))
    assert t[k] == pytest.approx(TOUCH_1J)
    q_touch = tr.q[i, k - 1]  # the posture where the touch was sensed
    after = tr.q[i, k:] - q_touch
    assert after.max() < 0.05  # stops within 0.05 rad (the arm moved at ~1 rad/s)
    assert after.min() > -0.005  # no swing back past the touched posture (before the fix: -0.45)
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


def test_lead_yields_to_a_push_above_threshold_only(free_arm, scenarios):
    """Leading (Figure 10): 'backing off the joint equilibrium positions to keep the torque low'.
    Measured on the C-MuJoCo runs: under a 15 N lift the led arm yields far more than the same
    arm without lead (whose springs load up), and once leading stops it stays where it was led
    (set-point constant) while the arm without lead springs back; a push whose joint torques stay
    below the threshold does not move the set-point at all."""
    tr, mode, t, push = scenarios["traj"], scenarios["mode"], scenarios["t"], scenarios["push"]
    thr = float(scenarios["net"].lead_threshold)
    k0 = int(np.argmax(push)) - 1
    k_end = int(np.argmax(t >= PUSH[1]))
    k_off = int(np.argmax(t >= LEAD_ON[1]))
    assert np.all(mode[2][(t >= LEAD_ON[0]) & (t < LEAD_ON[1])] == LEAD)
    rise_lead = tr.hand[2, k_end - 1, 2] - tr.hand[2, k0, 2]
    rise_free = tr.hand[3, k_end - 1, 2] - tr.hand[3, k0, 2]
    assert rise_lead > 3 * rise_free > 0.3  # yields with lead (~0.67 m vs ~0.19 m)
    assert np.abs(tr.tau[3, push] - tr.tau[3, k0]).max() > 5 * thr  # without lead the springs load up
    assert np.abs(tr.q_set[2, k_off:] - tr.q_set[2, k_off]).max() == 0.0  # released: set-point constant
    assert tr.hand[2, -1, 2] - tr.hand[2, k0, 2] > 0.2  # led to a new position...
    assert abs(tr.hand[3, -1, 2] - tr.hand[3, k0, 2]) < 0.01  # ...the unled arm springs back
    # The small push: its static joint torques (Jᵀ F, C MuJoCo's Jacobian at the hand's centre of
    # mass, where the force acts) stay below the threshold...
    m = free_arm.mj_model
    d = mujoco.MjData(m)
    d.qpos[:] = tr.q[4, k0]
    mujoco.mj_forward(m, d)
    J = np.zeros((3, 6))
    mujoco.mj_jacBodyCom(m, d, J, None, free_arm.layout.hand_body)
    assert np.abs(J.T @ [0.0, 0.0, SMALL_PUSH]).max() < 0.5 * thr
    # ...so the set-point does not back off and the arm returns.
    assert np.abs(tr.q_set[4, k0:] - tr.q_set[4, k0]).max() < 1e-12  # (round-off of q + τ/K)
    assert np.abs(tr.hand[4, -1] - tr.hand[4, k0]).max() < 0.01


def test_overlapping_reflex_moves_sum(arm, scenarios):
    """Williamson's Figure 4 inside the network: the set-point velocity is the sum of the moves'
    minimum-jerk velocities (paper formula, each move from the previous target), whatever the
    issue times (before the fix a reach issued at t = 0 was replaced by the next target)."""
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
# Open-loop rollouts: MJX, C MuJoCo batch rollout, λ0-PMP plans executed on the springy arm


@pytest.fixture(scope="module")
def rollout_value_and_grad(free_arm, P):
    """The module's one MJX open-loop rollout compile: value and reverse-mode gradient (w.r.t.
    ``q_set``, ``K``, ``B``, ``q0``) of a tracking loss summed over 3 arms × 1000 steps, with the
    trajectory as aux output. The executed plans and the gradient check call it with equal shapes."""
    q_ref = P[2]

    def loss(q_set, K, B, q0, qdot0):
        tr = pj.rollout(free_arm, q_set, K=K, B=B, q0=q0, qdot0=qdot0)
        return jnp.sum((tr.q - q_ref) ** 2) * free_arm.dt + jnp.sum((tr.q_final - q_ref) ** 2), tr

    def loss_c(q_set, K, B, q0):
        """The same loss of one arm from a plain C MuJoCo mj_step loop."""
        qs, _, _, qT = c_replay(free_arm, q_set, q0=q0, K=K, B=B)
        return np.sum((qs - q_ref) ** 2) * free_arm.dt + np.sum((qT - q_ref) ** 2)

    return jax.value_and_grad(loss, argnums=(0, 1, 2, 3), has_aux=True), loss_c


@pytest.fixture(scope="module")
def planned(free_arm, P, rollout_value_and_grad):
    """A λ0-PMP plan on the MJCF chain (1 s, held 1 s more), executed with three arms at once
    (default gains; stiffer/softer with a velocity kick; another start posture)."""
    chain = pj.MjcfChain(free_arm, "hand")
    KJ = np.diag(free_arm.K)
    model = pj.Lambda0PMP(chain, KJ=KJ, q_rest=free_arm.q_rest, W=0.05 * KJ)
    target = c_settle(free_arm, P[2], free_arm.K)[1][0] + np.array([0.0, 0.05, 0.1])  # near "up"
    traj = pj.simulate(model, pj.MinimumJerkPlanner(1.0), free_arm.q_rest, target, duration=1.0, dt=free_arm.dt)
    q_plan = np.asarray(traj.q)  # (501, 6) at 2 ms
    q_set = np.concatenate([q_plan, np.tile(q_plan[-1], (499, 1))])  # 1000 steps
    K = np.stack([free_arm.K, 1.3 * free_arm.K, 0.8 * free_arm.K])
    B = np.stack([free_arm.B, 0.7 * free_arm.B, 1.2 * free_arm.B])
    q0 = np.stack([free_arm.q_rest, free_arm.q_rest, free_arm.q_rest + 0.05])
    qdot0 = np.stack([np.zeros(6), 0.3 * np.ones(6), np.zeros(6)])
    args = dict(K=K, B=B, q0=q0, qdot0=qdot0)
    (_, executed), _ = rollout_value_and_grad[0](np.broadcast_to(q_set, (3,) + q_set.shape), **args)  # MJX
    return dict(chain=chain, traj=traj, target=target, q_set=q_set, args=args,
                executed=jax.tree_util.tree_map(np.asarray, executed))


def test_rollout_backends_agree_and_batch_equals_singles(free_arm, planned):
    """MJX batch == C MuJoCo batch rollout (2 threads) == C single calls == a plain mj_step loop."""
    mx, a = planned["executed"], planned["args"]
    c = pj.rollout(free_arm, planned["q_set"], backend="mujoco", nthread=2, **a)
    for f in ("q", "qdot", "q_set", "tau", "hand", "q_final", "qdot_final"):
        assert np.abs(getattr(c, f) - getattr(mx, f)).max() < 1e-11, f
    assert np.allclose(c.t, mx.t, rtol=0, atol=1e-12)  # (MJX accumulates time step by step)
    for i in range(3):
        one = pj.rollout(free_arm, planned["q_set"], backend="mujoco", **{k: v[i] for k, v in a.items()})
        assert one.q.shape == (1000, 6)
        assert np.array_equal(one.q, c.q[i]) and np.array_equal(one.hand, c.hand[i])
        qc, hc, _, qT = c_replay(free_arm, planned["q_set"], **{k: v[i] for k, v in a.items()})
        assert np.abs(qc - mx.q[i]).max() < 1e-11 and np.abs(hc - mx.hand[i]).max() < 1e-11


def test_lambda0_plan_executed_on_springy_arm_sags(free_arm, planned):
    traj, ex = planned["traj"], planned["executed"]
    assert int(traj.status) == 0
    assert np.abs(np.asarray(traj.x[-1]) - planned["target"]).max() < 1e-4  # the plan reaches it
    # Executed hand sags below the planned one (gravity), by the static sag at the end.
    x_plan = np.asarray(planned["chain"].fk(planned["q_set"]))
    sag = x_plan[:, 2] - ex.hand[0, :, 2]
    assert sag[-1] > 0.05 and np.all(sag[250:] > 0)
    # It ends near the statics of the final set-point (settled C MuJoCo; ringing ~1e-3 rad left).
    q_c, hand_c, _ = c_settle(free_arm, planned["q_set"][-1], free_arm.K)
    assert np.abs(ex.q[0, -1] - q_c[0]).max() < 2e-3
    assert np.linalg.norm(ex.hand[0, -1] - hand_c[0]) < 2e-3


# ----------------------------------------------------------------------------------------------
# Gradients


def test_rollout_gradient_matches_c_mujoco_central_differences(free_arm, P, rollout_value_and_grad):
    """jax.grad through 2 s of mjx.step (lax.scan), 3 arms at once, w.r.t. blend weights α (by
    the chain rule through the set-points ``α P``), stiffness K, damping B and the initial
    posture q0, vs central differences of the same loss on C MuJoCo, arm by arm."""
    value_and_grad, loss_c = rollout_value_and_grad
    T = 1000
    alpha = np.array([[0.4, 0.3, 0.2, 0.1], [0.1, 0.2, 0.3, 0.4], [0.7, 0.0, 0.1, 0.2]])
    K = np.stack([free_arm.K, 1.2 * free_arm.K, 0.9 * free_arm.K])
    B = np.stack([free_arm.B, 0.8 * free_arm.B, 1.1 * free_arm.B])
    q0 = free_arm.q_rest + np.array([[0.05, 0.0, -0.05, 0.1, 0.0, 0.05], [0.0] * 6, [-0.1, 0.05, 0.0, 0.0, 0.1, 0.0]])
    q_set = np.broadcast_to((alpha @ P)[:, None], (3, T, 6))
    (val, _), (g_qs, gK, gB, gq0) = value_and_grad(q_set, K, B, q0, np.zeros((3, 6)))
    g_alpha = np.einsum("btn,kn->bk", np.asarray(g_qs), P)  # q_set = α P at every step
    grads = (g_alpha, np.asarray(gK), np.asarray(gB), np.asarray(gq0))
    total = 0.0
    for b in range(3):
        x0 = (alpha[b], K[b], B[b], q0[b])

        def f_b(*x):
            return loss_c(np.tile(x[0] @ P, (T, 1)), *x[1:])

        total += f_b(*x0)
        for i, g in enumerate(grads):
            f = lambda x, i=i: f_b(*(x if j == i else a for j, a in enumerate(x0)))  # noqa: E731
            fd = central_diff(f, x0[i])
            # Step sqrt(eps)·max(|x|, 1): the quotient carries ~eps·|loss|/h ≈ 1e-7 of round-off.
            assert np.allclose(g[b], fd, rtol=2e-6, atol=1e-7), (b, i, np.abs(g[b] - fd).max())
    assert float(val) == pytest.approx(total, rel=1e-12)


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
