"""Postural primitives on MuJoCo MJX (issue 5): springy Cog-like arm, primitives, summed moves,
reflexes, λ0-PMP planning, fits. References: C MuJoCo ``mj_step``/``mj_jacSite``/``qfrc_bias``,
closed-form quintics, SciPy quadrature, central differences, numpy least squares.

MJX compiles are slow on this CPU, so every MJX function is compiled once per module, with one
shape: the reflex network (contacts, 4 scenarios × 3 s), the open-loop rollout (no contacts,
1.2 s), its gradient (0.2 s), the equilibrium solver (one batch of 64 postures) and the fits.
"""

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from scipy import integrate

import fitting
import pmpjax as pj
from pmpjax._springy_arm import arm as _arm
from pmpjax._springy_arm import reflexes as _reflexes

N_EQ = 64  # one equilibrium batch shape for the whole module


@pytest.fixture(scope="module")
def arm():
    return pj.load_arm()


@pytest.fixture(scope="module")
def free_arm():
    return pj.load_arm(contacts=False)


@pytest.fixture(scope="module")
def P():
    return np.asarray(pj.default_primitives())


def c_replay(arm, q_set, *, q0, probe=None, force=None, K=None, B=None):
    """Plain C MuJoCo: the same spring law written into qfrc_applied, one mj_step per set-point."""
    m = arm.mj_model
    K = arm.K if K is None else np.asarray(K)
    B = arm.B if B is None else np.asarray(B)
    d = mujoco.MjData(m)
    d.qpos[:] = q0
    qs, hands, xmats = [], [], []
    for k in range(len(q_set)):
        qs.append(d.qpos.copy())
        d.qfrc_applied[:] = -K * (d.qpos - q_set[k]) - B * d.qvel
        if probe is not None:
            d.mocap_pos[0] = probe[k]
        if force is not None:
            d.xfrc_applied[arm.layout.hand_body, :3] = force[k]
        mujoco.mj_step(m, d)
        hands.append(d.site_xpos[arm.layout.hand_site].copy())
        xmats.append(d.xmat[arm.layout.hand_body].reshape(3, 3).copy())
    return np.array(qs), np.array(hands), np.array(xmats), d.qpos.copy()


# ----------------------------------------------------------------------------------------------
# Reflex network: one batched closed-loop run shared by several tests

DUR = 3.0
PUSH = (1.4, 2.4)
LEAD = (1.2, 2.6)
RELEASE = 2.6


@pytest.fixture(scope="module")
def reflex_run(arm, P):
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
    grasp = pj.script_inputs(arm, DUR, targets=targets, release=[RELEASE])
    withdraw = pj.script_inputs(arm, DUR, targets=targets, release=[RELEASE])
    lead = pj.script_inputs(arm, DUR, targets=[(0.0, P[1])], lead=[LEAD])
    control = pj.script_inputs(arm, DUR, targets=[(0.0, P[1])])
    inputs = pj.stack_inputs([grasp, withdraw, lead, control])
    probe = np.tile(np.asarray(_arm.PROBE_PARK), (4, T, 1))
    probe[0] = hands[250] + 0.05 * palm_normal
    probe[1] = hands[250] - 0.05 * palm_normal
    probe[:2, t >= 0.7] = _arm.PROBE_PARK  # a tap: the object goes away again
    force = np.zeros((4, T, 3))
    push = (t >= PUSH[0]) & (t < PUSH[1])
    force[2:, push] = [0.0, 0.0, 15.0]  # lift the hand (lead) / same push without lead (control)
    net = pj.reflex_network(arm)
    traj = pj.run_reflexes(arm, net, inputs, probe=probe, force=force)
    return dict(
        traj=jax.tree_util.tree_map(np.asarray, traj),
        t=t,
        probe=probe,
        force=force,
        net=net,
        mode=np.asarray(traj.log["mode"]),
        push=push,
    )


def test_mjx_matches_c_mujoco(arm, reflex_run):
    """MJX (float64) vs C ``mj_step`` on the same model and inputs (the set-points the network
    commanded, the probe path, the push), over the first 1 s and the whole 3 s.

    Without contact the two agree to round-off (~1e-16 rad). With contact (the probe hits the
    palm / back of the hand at 0.48 s) the agreement is ~6e-6 rad: both run the Newton
    constraint solver to the model's tolerance (1e-8) but MJX's line search differs from C's,
    so the contact forces differ at the solver-tolerance level and the difference then persists.
    """
    tr = reflex_run["traj"]
    n1 = int(round(1.0 / arm.dt)) + 1
    errs = []
    for i in range(4):
        qc, _, _, qT = c_replay(
            arm, tr.q_set[i], q0=arm.q_rest, probe=reflex_run["probe"][i], force=reflex_run["force"][i]
        )
        errs.append(np.abs(qc - tr.q[i]).max(axis=1))
        assert np.abs(qT - tr.q_final[i]).max() < 1e-4
    errs = np.array(errs)
    assert reflex_run["traj"].touch[:2].max() > 1.0  # contacts really happened
    assert errs[:, :n1].max() < 1e-5  # 1 s, with contacts
    assert errs[2:].max() < 1e-12  # no contact: round-off only, over 3 s


def test_grasp_holds_touched_posture(arm, free_arm, reflex_run, P):
    tr, t, mode, net = reflex_run["traj"], reflex_run["t"], reflex_run["mode"], reflex_run["net"]
    g = 0
    k_touch = int(np.argmax(mode[g] == _reflexes.GRASP))
    assert k_touch > 0 and tr.touch[g, k_touch - 1, 0] > float(net.touch_threshold)  # measured palm contact
    assert 0.3 < t[k_touch] < 0.8
    k_rel = int(round(RELEASE / arm.dt))
    held = tr.q[g, k_touch]  # the posture where the palm was touched
    # The grasp move takes the set-point to that posture and holds it: the target issued at
    # 1.2 s is suppressed until the release at 2.6 s.
    k_hold = k_touch + int(round(float(net.grasp_duration) / arm.dt)) + 1
    assert np.abs(tr.q_set[g, k_hold:k_rel] - held).max() < 1e-12
    # The arm stopped (the probe was withdrawn at 0.7 s) and rests where the springs balance
    # gravity at the touched posture (Newton equilibrium, independent of the dynamics).
    eq = pj.equilibrium(free_arm, np.tile(held, (N_EQ, 1)))
    # (Residual ringing after ~1.9 s of settling at damping ratio ≈ 0.5: ~1e-4 rad.)
    assert np.abs(tr.qdot[g, k_rel - 1]).max() < 1e-2
    assert np.abs(tr.q[g, k_rel - 1] - np.asarray(eq.q[0])).max() < 2e-3
    # The hand is where touched, lowered only by the static gravity sag at that posture.
    assert np.linalg.norm(tr.hand[g, k_rel - 1] - np.asarray(eq.hand[0])) < 3e-3
    # Released: the next target (2.7 s, the "side" primitive) is followed again.
    assert np.abs(tr.q_set[g, -1] - held).max() > 0.05


def test_withdrawal_returns_to_rest_and_suppresses_targets(arm, free_arm, reflex_run, eq_batch):
    tr, mode, net = reflex_run["traj"], reflex_run["mode"], reflex_run["net"]
    w = 1
    k_touch = int(np.argmax(mode[w] == _reflexes.WITHDRAW))
    assert k_touch > 0 and tr.touch[w, k_touch - 1, 1] > float(net.touch_threshold)  # back of hand
    assert tr.touch[w, :, 0].max() == 0.0  # the palm was never touched
    k_rel = int(round(RELEASE / arm.dt))
    k_done = k_touch + int(round(float(net.withdraw_duration) / arm.dt)) + 1
    # Winner-take-all: the ongoing reach is dropped, the set-point is exactly the rest primitive,
    # and the 1.2 s target is suppressed until release.
    assert np.abs(tr.q_set[w, k_done:k_rel] - arm.q_rest).max() < 1e-12
    # The arm settles where the springs balance gravity at the rest set-point (equilibrium solver).
    q_eq = eq_batch["q"][eq_batch["rest_index"]]
    assert np.abs(tr.q[w, k_rel - 1] - q_eq).max() < 2e-3
    assert np.abs(tr.q_set[w, -1] - arm.q_rest).max() > 0.05  # after release, targets again


def test_lead_keeps_torque_deviation_under_threshold(arm, reflex_run):
    tr, t, mode, net = reflex_run["traj"], reflex_run["t"], reflex_run["mode"], reflex_run["net"]
    thr = float(net.lead_threshold)
    leading = mode[2] == _reflexes.LEAD
    assert np.allclose(t[leading][[0, -1]], [LEAD[0], LEAD[1] - arm.dt])
    dev = np.abs(tr.tau[2] - tr.log["tau_ref"][2])[leading]
    assert dev.max() <= thr * (1 + 1e-9)
    # Control: the same push without the lead behaviour loads the springs far beyond it.
    push = reflex_run["push"]
    k0 = int(np.argmax(push)) - 1
    assert np.abs(tr.tau[3][push] - tr.tau[3, k0]).max() > 5 * thr
    # The arm was led upwards and stays there; without lead it springs back.
    z0 = tr.hand[2, k0, 2]
    assert tr.hand[2, -1, 2] - z0 > 0.1
    assert abs(tr.hand[3, -1, 2] - tr.hand[3, k0, 2]) < 0.01
    # After the push ends (still leading) and after leading stops, the set-point stays put.
    k_end = int(round(PUSH[1] / arm.dt)) + 100
    assert np.abs(tr.q_set[2, k_end:] - tr.q_set[2, k_end]).max() < 1e-3


# ----------------------------------------------------------------------------------------------
# Primitives, equilibria, superposition


def _simplex_boundary(k_sub):
    """Barycentric vertices and triangles of a regular subdivision of the 4 faces of a 3-simplex."""
    verts, tris = [], []
    for face in range(4):
        idx = [c for c in range(4) if c != face]
        local = {}
        for i in range(k_sub + 1):
            for j in range(k_sub + 1 - i):
                w = np.zeros(4)
                w[idx[0]], w[idx[1]], w[idx[2]] = i / k_sub, j / k_sub, (k_sub - i - j) / k_sub
                local[(i, j)] = len(verts)
                verts.append(w)
        for i in range(k_sub):
            for j in range(k_sub - i):
                tris.append((local[(i, j)], local[(i + 1, j)], local[(i, j + 1)]))
                if i + j + 1 < k_sub:
                    tris.append((local[(i + 1, j)], local[(i + 1, j + 1)], local[(i, j + 1)]))
    return np.array(verts), np.array(tris)


def _orient(bary, tris):
    """Orient triangles outward in the regular-tetrahedron embedding of the simplex, so the
    mapped mesh has one consistent orientation (the sign of the winding number is then global)."""
    E = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], float)
    p = bary @ E
    a, b, c = p[tris[:, 0]], p[tris[:, 1]], p[tris[:, 2]]
    outward = np.einsum("ij,ij->i", np.cross(b - a, c - a), (a + b + c) / 3) > 0
    return np.where(outward[:, None], tris, tris[:, [0, 2, 1]])


def _winding_number(points, verts, tris):
    """Generalised winding number of closed triangle mesh around points (Van Oosterom–Strackee)."""
    a = verts[tris[:, 0]][None] - points[:, None]
    b = verts[tris[:, 1]][None] - points[:, None]
    c = verts[tris[:, 2]][None] - points[:, None]
    la, lb, lc = (np.linalg.norm(v, axis=-1) for v in (a, b, c))
    num = np.einsum("...i,...i", a, np.cross(b, c))
    den = (
        la * lb * lc
        + np.einsum("...i,...i", a, b) * lc
        + np.einsum("...i,...i", a, c) * lb
        + np.einsum("...i,...i", b, c) * la
    )
    return np.sum(2 * np.arctan2(num, den), axis=-1) / (4 * np.pi)


@pytest.fixture(scope="module")
def eq_batch(free_arm, P):
    """All equilibria of the module in one call: primitives, simplex-boundary mesh, interior and
    extrapolated blends, padded to N_EQ postures."""
    rng = np.random.default_rng(5)
    verts, tris = _simplex_boundary(4)  # 34 distinct vertices after merging shared edges
    tris = _orient(verts, tris)
    uniq, inv = np.unique(np.round(verts, 12), axis=0, return_inverse=True)
    inside = rng.dirichlet(np.ones(4), size=40)
    inside = inside[inside.min(axis=1) > 0.08][:12]
    outside = np.array([[-0.3, 0.5, 0.4, 0.4], [0.2, -0.25, 0.6, 0.45], [0.3, 0.3, 0.6, -0.2]])
    alphas = np.concatenate([np.eye(4), uniq, inside, outside])
    assert len(alphas) <= N_EQ
    pad = np.tile(alphas[:1], (N_EQ - len(alphas), 1))
    q_set = np.concatenate([alphas, pad]) @ P
    eq = pj.equilibrium(free_arm, q_set)
    return dict(
        q=np.asarray(eq.q),
        hand=np.asarray(eq.hand),
        converged=np.asarray(eq.converged),
        residual=np.asarray(eq.residual),
        q_set=q_set,
        n_uniq=len(uniq),
        inv=inv.reshape(-1),
        tris=tris,
        n_in=len(inside),
        n_out=len(outside),
        rest_index=0,
    )


def test_equilibrium_matches_settled_c_mujoco(free_arm, eq_batch, P):
    """Newton on K(θ − θ_set) + ∇V = 0 vs a 10 s damped C MuJoCo rollout at a fixed set-point."""
    assert eq_batch["converged"].all()
    for i in (0, 3):
        _, _, _, qT = c_replay(free_arm, np.tile(P[i], (5000, 1)), q0=P[i])
        assert np.abs(qT - eq_batch["q"][i]).max() < 1e-9
    # Gravity sags every joint away from its set-point (the arm is springy).
    assert np.abs(eq_batch["q"][:4] - P).max() > 0.1


def test_gravity_terms_match_c_mujoco(free_arm):
    """Closed-form ∇V and ∇²V vs C MuJoCo's qfrc_bias at zero velocity (and its differences)."""
    from pmpjax._chains.mjcf import gravity_terms

    m = free_arm.mj_model
    q = np.array([0.6, 0.9, 0.3, 1.0, 0.4, -0.3])

    def bias(q):
        d = mujoco.MjData(m)
        d.qpos[:] = q
        mujoco.mj_forward(m, d)
        return d.qfrc_bias.copy()

    g, H, _ = gravity_terms(free_arm.mjx_model, jnp.asarray(q))
    h = 1e-6
    H_fd = np.array([(bias(q + h * e) - bias(q - h * e)) / (2 * h) for e in np.eye(6)]).T
    assert np.abs(np.asarray(g) - bias(q)).max() < 1e-12
    assert np.abs(np.asarray(H) - H_fd).max() < 1e-7


def test_superposition_stays_inside_region(eq_batch):
    """Blends with Σα = 1, α > 0 put the hand inside the region bounded by the images of the
    simplex's faces (the paper's shaded region, Figure 3); blends with a negative weight fall
    outside. The region is curved (joint-space interpolation), so it is not the convex hull."""
    nu = eq_batch["n_uniq"]
    verts = eq_batch["hand"][4 : 4 + nu]
    tris = eq_batch["inv"][eq_batch["tris"]]
    start = 4 + nu
    inside = eq_batch["hand"][start : start + eq_batch["n_in"]]
    outside = eq_batch["hand"][start + eq_batch["n_in"] : start + eq_batch["n_in"] + eq_batch["n_out"]]
    w_in = np.abs(_winding_number(inside, verts, tris))
    w_out = np.abs(_winding_number(outside, verts, tris))
    assert np.all(np.abs(w_in - 1) < 1e-6)
    assert np.all(w_out < 1e-6)


def test_winner_take_all_selects_commanded_primitive(P, eq_batch):
    scores = np.array([[0.1, 0.7, 0.2, 0.0], [0.3, 0.0, 0.1, 0.6], [2.0, 1.0, 1.5, -1.0]])
    out = np.asarray(pj.winner_take_all(scores, P))
    assert np.array_equal(out, P[[1, 3, 0]])
    # ...whereas superposition of the same (normalised) activations is a blend of all of them.
    blended = np.asarray(pj.blend(scores[:2] / scores[:2].sum(1, keepdims=True), P))
    assert np.abs(blended - out[:2]).max() > 0.05


def test_force_field_solves_transposed_jacobian_least_squares(free_arm, P):
    chain = pj.MjcfChain(free_arm, "hand")
    m = free_arm.mj_model
    q = P[3] + np.array([0.1, -0.05, 0.1, 0.2, -0.1, 0.05])
    d = mujoco.MjData(m)
    d.qpos[:] = q
    mujoco.mj_forward(m, d)
    J = np.zeros((3, 6))
    mujoco.mj_jacSite(m, d, J, None, free_arm.layout.hand_site)
    assert np.abs(np.asarray(chain.jacobian(q)) - J).max() < 1e-12
    assert np.abs(np.asarray(chain.fk(q)) - d.site_xpos[free_arm.layout.hand_site]).max() < 1e-12
    tau = -free_arm.K * (q - P[3])
    F = np.asarray(pj.force_field(chain, q, P[3], free_arm.K))
    assert np.allclose(F, np.linalg.lstsq(J.T, tau, rcond=None)[0], atol=1e-10)
    # Convergent field: the force points back towards the set-point posture's hand position.
    assert F @ (np.asarray(chain.fk(P[3])) - np.asarray(chain.fk(q))) > 0


# ----------------------------------------------------------------------------------------------
# Minimum-jerk moves (Figure 4)


def _paper_velocity(t, delta, t0, d):
    s = (t - t0) / d
    return np.where((s > 0) & (s < 1), delta / d * (30 * s**4 - 60 * s**3 + 30 * s**2), 0.0)


def test_summed_minimum_jerk_moves():
    # Figure 4: a move 0 -> 1, and half-way through a second move from the old target 1 to 1.5.
    mv = pj.moves_from_targets([0.0], [[1.0], [1.5]], t0=[0.0, 0.5], duration=[1.0, 1.0])
    t = np.linspace(0.0, 2.0, 2001)
    q, v = (np.asarray(a)[:, 0] for a in pj.summed_moves(mv, [0.0], t))
    assert q[-1] == pytest.approx(1.5, abs=1e-14)  # the sum of the moves
    v_ref = _paper_velocity(t, 1.0, 0.0, 1.0) + _paper_velocity(t, 0.5, 0.5, 1.0)
    assert np.abs(v - v_ref).max() < 1e-12  # velocities are added
    q_ref = integrate.cumulative_trapezoid(v_ref, t, initial=0.0)
    assert np.abs(q - q_ref).max() < 1e-6  # ...and integrated (trapezoid error ~ dt²)
    for tk in (0.0, 0.5, 1.0, 1.5):  # continuity at every start and end of a move
        vm, vp = (np.asarray(pj.move_velocity(mv, jnp.array([tk - e, tk + e])))[:, 0] for e in (1e-9,) * 2)
        assert abs(vm[0] - vm[1]) < 1e-6 and abs(vp[1] - vp[0]) < 1e-6
    assert np.abs(np.diff(v)).max() < 2.0 * 1e-3 * 6  # bounded jerk-free steps (|a| ≤ 5.8 Δ/d²)


def test_single_move_is_the_quintic():
    delta, d, t0 = 0.8, 0.6, 0.2
    mv = pj.Moves(t0=jnp.array([t0]), duration=jnp.array([d]), delta=jnp.array([[delta]]))
    t = np.linspace(0.0, 1.0, 501)
    q, v = (np.asarray(a)[:, 0] for a in pj.summed_moves(mv, [0.3], t))
    s = np.clip((t - t0) / d, 0, 1)
    assert np.abs(q - (0.3 + delta * np.polyval([6, -15, 10, 0, 0, 0], s))).max() < 1e-14
    assert integrate.quad(lambda x: _paper_velocity(x, delta, t0, d), t0, t0 + d)[0] == pytest.approx(
        delta, rel=1e-12
    )
    h = 1e-6
    for te in (t0, t0 + d):  # zero velocity and acceleration at both ends
        vv = np.asarray(pj.move_velocity(mv, jnp.array([te - h, te, te + h])))[:, 0]
        assert np.abs(vv).max() < 1e-9
        assert abs(vv[2] - vv[0]) / (2 * h) < 1e-4


# ----------------------------------------------------------------------------------------------
# λ0-PMP planning on the MJCF chain, executed on the springy arm (gravity sag, Figure 8)


@pytest.fixture(scope="module")
def planned(free_arm, eq_batch):
    chain = pj.MjcfChain(free_arm, "hand")
    KJ = np.diag(free_arm.K)
    model = pj.Lambda0PMP(chain, KJ=KJ, q_rest=free_arm.q_rest, W=0.05 * KJ)
    target = eq_batch["hand"][2] + np.array([0.0, 0.05, 0.1])
    traj = pj.simulate(
        model, pj.MinimumJerkPlanner(1.0), free_arm.q_rest, target, duration=1.0, dt=free_arm.dt
    )
    q_plan = np.asarray(traj.q)  # (501, 6) at 2 ms
    q_set = np.concatenate([q_plan, np.tile(q_plan[-1], (500, 1))])  # hold 1 s more
    executed = pj.rollout(free_arm, q_set, q0=free_arm.q_rest)
    return dict(
        chain=chain,
        traj=traj,
        target=target,
        q_set=q_set,
        executed=jax.tree_util.tree_map(np.asarray, executed),
    )


def test_lambda0_plan_executed_on_springy_arm_sags(free_arm, planned, eq_batch):
    traj, ex = planned["traj"], planned["executed"]
    assert int(traj.status) == 0
    assert np.abs(np.asarray(traj.x[-1]) - planned["target"]).max() < 1e-4  # the plan reaches it
    # MJX execution equals C MuJoCo on the free arm (round-off).
    qc, hc, _, _ = c_replay(free_arm, planned["q_set"], q0=free_arm.q_rest)
    assert np.abs(qc - ex.q).max() < 1e-12
    # Executed hand sags below the planned one (gravity), by the static sag at the end.
    x_plan = np.asarray(planned["chain"].fk(planned["q_set"]))
    sag = x_plan[:, 2] - ex.hand[:, 2]
    assert sag[-1] > 0.05 and np.all(sag[250:] > 0)
    # It ends at the equilibrium of the final set-point (Newton, independent of the dynamics).
    eq = pj.equilibrium(free_arm, np.tile(planned["q_set"][-1], (N_EQ, 1)))
    assert np.abs(ex.q[-1] - np.asarray(eq.q[0])).max() < 2e-3
    assert np.linalg.norm(ex.hand[-1] - np.asarray(eq.hand[0])) < 2e-3


# ----------------------------------------------------------------------------------------------
# Gradients


def test_rollout_gradient_matches_c_mujoco_central_differences(free_arm, P):
    """jax.grad through 0.2 s of mjx.step (lax.scan) w.r.t. blend weights α and stiffness K, vs
    central differences of the same loss computed with C MuJoCo."""
    T = 100
    alpha0 = np.array([0.4, 0.3, 0.2, 0.1])
    q_ref = P[2]

    def loss(alpha, K):
        q_set = jnp.broadcast_to(jnp.asarray(alpha) @ P, (T, 6))
        tr = pj.rollout(free_arm, q_set, K=K, q0=free_arm.q_rest)
        return jnp.sum((tr.q - q_ref[None]) ** 2) * free_arm.dt + jnp.sum((tr.q_final - q_ref) ** 2)

    def loss_c(alpha, K):
        qs, _, _, qT = c_replay(free_arm, np.tile(alpha @ P, (T, 1)), q0=free_arm.q_rest, K=K)
        return np.sum((qs - q_ref) ** 2) * free_arm.dt + np.sum((qT - q_ref) ** 2)

    val, (ga, gK) = jax.value_and_grad(loss, argnums=(0, 1))(alpha0, free_arm.K)
    assert float(val) == pytest.approx(loss_c(alpha0, free_arm.K), rel=1e-12)
    for x0, g, f in (
        (alpha0, ga, lambda a: loss_c(a, free_arm.K)),
        (free_arm.K, gK, lambda k: loss_c(alpha0, k)),
    ):
        h = np.sqrt(np.finfo(float).eps) * np.maximum(np.abs(x0), 1.0)
        fd = np.array(
            [(f(x0 + h[i] * e) - f(x0 - h[i] * e)) / (2 * h[i]) for i, e in enumerate(np.eye(len(x0)))]
        )
        assert np.allclose(np.asarray(g), fd, rtol=1e-5, atol=1e-7 * np.abs(fd).max())


def test_equilibrium_gradient_matches_central_differences(free_arm, P):
    """Implicit-function-theorem derivatives of the equilibrium hand height w.r.t. K and θ_set."""

    def height(K, q_set):
        return pj.equilibrium(free_arm, jnp.broadcast_to(q_set, (N_EQ, 6)), K).hand[0, 2]

    gK, gq = jax.grad(height, argnums=(0, 1))(free_arm.K, P[3])
    for x0, g, f in (
        (free_arm.K, gK, lambda k: height(k, P[3])),
        (P[3], gq, lambda q: height(free_arm.K, q)),
    ):
        h = 1e-5 * np.maximum(np.abs(x0), 1.0)
        fd = np.array([(f(x0 + h[i] * e) - f(x0 - h[i] * e)) / (2 * h[i]) for i, e in enumerate(np.eye(6))])
        assert np.allclose(np.asarray(g), fd, rtol=1e-6, atol=1e-9)


# ----------------------------------------------------------------------------------------------
# Fits


def test_fit_blend_weights_reaches_targets(free_arm, P, eq_batch):
    alphas = np.array([[0.4, 0.3, 0.2, 0.1], [0.1, 0.2, 0.3, 0.4]])
    targets = alphas @ eq_batch["hand"][:4]  # not reachable exactly by the curved map...
    eq = pj.equilibrium(free_arm, np.concatenate([alphas, np.tile(alphas[:1], (N_EQ - 2, 1))]) @ P)
    reachable = np.asarray(eq.hand[:2])  # ...these are: equilibria of known blends
    far = np.array([[1.5, 0.0, 0.0]])  # beyond the arm's reach
    fit = fitting.fit_blend_weights(free_arm, P, np.concatenate([reachable, far]))
    assert np.all(np.asarray(fit.converged) == [True, True, False])  # per-item, far one flagged
    assert np.abs(np.asarray(fit.alpha[:2]) - alphas).max() < 1e-6
    assert np.asarray(fit.error[:2]).max() < 1e-8
    assert np.allclose(np.asarray(fit.alpha).sum(-1), 1.0)
    assert targets.shape == (2, 3)


def test_fit_stiffness_from_gravity_sag(free_arm, P):
    rng = np.random.default_rng(1)
    K_true = free_arm.K * rng.uniform(0.7, 1.3, size=(2, 6))
    q_set = np.concatenate([P, [[0.9, 0.5, 0.6, 1.4, 0.6, 0.5]]])
    pad = np.concatenate([q_set, np.tile(q_set[:1], (N_EQ - len(q_set), 1))])
    q_obs = np.stack([np.asarray(pj.equilibrium(free_arm, pad, k).q)[: len(q_set)] for k in K_true])
    fit = fitting.fit_stiffness(free_arm, q_set, q_obs)
    assert np.asarray(fit.converged).all()
    assert np.allclose(np.asarray(fit.K), K_true, rtol=1e-6)


# ----------------------------------------------------------------------------------------------
# Bad input


def test_bad_input_raises_clear_errors(arm, free_arm, P):
    with pytest.raises(ValueError, match="alpha"):
        pj.blend([0.5, 0.3, 0.1, 0.2], P)
    with pytest.raises(ValueError, match="q_set"):
        pj.equilibrium(free_arm, np.zeros(5))
    with pytest.raises(ValueError, match="q_set"):
        pj.rollout(free_arm, np.zeros((10, 5)))
    with pytest.raises(ValueError, match="`K`"):
        pj.equilibrium(free_arm, P[0], K=-free_arm.K)
    with pytest.raises(ValueError, match="`K`"):
        pj.rollout(free_arm, np.zeros((10, 6)), K=np.array([40.0, -1, 20, 20, 5, 5]))
    with pytest.raises(ValueError, match="`B`"):
        pj.rollout(free_arm, np.zeros((10, 6)), B=np.full(6, 50.0))
    with pytest.raises(ValueError, match="duration"):
        pj.moves_from_targets([0.0], [[1.0]], t0=[0.0], duration=[0.0])
    with pytest.raises(ValueError, match="site"):
        pj.MjcfChain(arm, "elbow")
    with pytest.raises(ValueError, match="xml_or_model"):
        pj.load_arm("<mujoco><worldbody/></mujoco>")
    with pytest.raises(ValueError, match="network.dt"):
        pj.run_reflexes(arm, pj.ReflexNetwork(rest=arm.q_rest, dt=0.001), pj.script_inputs(arm, 0.01))
    with pytest.raises(ValueError, match="target"):
        fitting.fit_blend_weights(free_arm, P, np.zeros(2))


# ----------------------------------------------------------------------------------------------
# Figures


def test_figures_show_the_data(reflex_run, arm):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    mv = pj.moves_from_targets([0.0], [[1.0], [1.5]], t0=[0.0, 0.5], duration=[1.0, 1.0])
    t = np.linspace(0, 2, 201)
    fig = pj.plot_summed_moves(mv, [0.0], t)
    summed = fig.axes[0].lines[-1].get_ydata()
    assert summed[-1] == pytest.approx(1.5)
    tr = jax.tree_util.tree_map(lambda a: a[0] if np.ndim(a) > 1 else a, reflex_run["traj"])
    fig8 = pj.plot_reflex(tr, joint=0, sensor="palm")
    assert np.array_equal(fig8.axes[1].lines[0].get_ydata(), tr.q_set[:, 0])
    assert np.array_equal(fig8.axes[0].lines[0].get_ydata(), tr.touch[:, 0])
    plt.close("all")
