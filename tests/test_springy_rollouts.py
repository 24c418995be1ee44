"""Open-loop rollouts of the springy arm (Williamson 1996), MJX and C MuJoCo: λ0-PMP plans
executed on the arm, gradients through ``mjx.step``.

References, each independent of the code under test (``tests/_springy.py``): C MuJoCo ``mj_step``
loops written here (spring torque in ``qfrc_applied``), settled C rollouts for statics, central
differences of C MuJoCo.

MJX compiles are slow on this CPU, so the MJX rollout is compiled once, with one shape (no
contacts, 3 arms × 1000 steps). Its gradient: ``test_springy_rollout_gradient.py`` (a file of its
own so that the two long compiles run on different xdist workers); closed-loop runs:
``test_springy_reflexes.py``.
"""

import jax
import numpy as np
import pytest
from _springy import c_replay, c_settle

import pmpjax as pj

# ----------------------------------------------------------------------------------------------
# Open-loop rollouts: MJX, C MuJoCo batch rollout, λ0-PMP plans executed on the springy arm


@pytest.fixture(scope="module")
def planned(free_arm, P):
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
    executed = pj.rollout(free_arm, q_set, **args)  # MJX, batch (3,)
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
