"""Postural primitives (Williamson 1996) on the springy Cog-like arm: minimum-jerk moves, blends,
equilibria under gravity, MJCF kinematics and force fields, fits, bad input.

References, each independent of the code under test (``tests/_springy.py``): settled C MuJoCo
rollouts for statics, ``mj_jacSite`` / ``qfrc_bias``, the paper's minimum-jerk velocity formula,
SciPy quadrature, central differences. Fits of blend weights and stiffness:
``test_primitives_fits.py``; reflexes: ``test_springy_reflexes.py``; rollouts:
``test_springy_rollouts.py``. Every equilibrium call compiles one shape (batches pad to 8).
"""

import os
import subprocess
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from _springy import _paper_velocity, c_settle, central_diff
from scipy import integrate

import pmpjax as pj

ROOT = Path(__file__).resolve().parents[1]
N_EQ = 64  # one equilibrium batch shape for the whole module


# ----------------------------------------------------------------------------------------------
# Import: no MuJoCo/MJX until used, and no warp noise


def test_import_is_lazy_and_building_the_arm_prints_nothing():
    code = (
        "import sys, pmpjax\n"
        "assert 'mujoco' not in sys.modules and 'mujoco.mjx' not in sys.modules, 'eager MuJoCo import'\n"
        "sys.stdout.write('imported\\n'); sys.stdout.flush()\n"
        "arm = pmpjax.load_arm(contacts=False)\n"
        "assert 'mujoco.mjx' in sys.modules\n"
    )
    env = dict(os.environ, PYTHONPATH=str(ROOT), JAX_PLATFORMS="cpu")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=600)
    assert out.returncode == 0, out.stderr
    assert out.stdout == "imported\n"  # nothing printed by `import pmpjax` nor by building the arm
    assert "warp" not in out.stderr.lower()


# ----------------------------------------------------------------------------------------------
# Minimum-jerk moves (Figure 4)


def test_summed_minimum_jerk_moves():
    # Figure 4: a move 0 -> 1, and half-way through a second move from the old target 1 to 1.5.
    mv = pj.moves_from_targets([0.0], [[1.0], [1.5]], t0=[0.0, 0.5], duration=[1.0, 1.0])
    t = np.linspace(0.0, 2.0, 2001)
    q, v = (np.asarray(a)[:, 0] for a in pj.summed_moves(mv, [0.0], t))
    assert q[-1] == pytest.approx(1.5, abs=1e-14)  # the sum of the moves
    v_ref = _paper_velocity(t, 1.0, 0.0, 1.0) + _paper_velocity(t, 0.5, 0.5, 1.0)
    assert np.abs(v - v_ref).max() < 1e-13  # velocities are added
    q_ref = integrate.cumulative_trapezoid(v_ref, t, initial=0.0)
    assert np.abs(q - q_ref).max() < 1e-6  # ...and integrated (trapezoid error ~ dt² |v''| / 12)
    for tk in (0.0, 0.5, 1.0, 1.5):  # continuity of the velocity at every start and end of a move
        vv = np.asarray(pj.move_velocity(mv, jnp.array([tk - 1e-9, tk + 1e-9])))[:, 0]
        assert abs(vv[0] - vv[1]) < 1e-8


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
        assert np.abs(vv).max() < 2e-10  # 30 (h/d)² Δ/d = 1.1e-10 one step h inside
        assert abs(vv[2] - vv[0]) / (2 * h) < 1e-4


def test_summed_moves_and_blend_gradients_match_central_differences(P):
    t = np.linspace(0.0, 1.6, 9)

    def loss(start, t0, duration, delta):
        mv = pj.Moves(t0=t0, duration=duration, delta=delta)
        q, v = pj.summed_moves(mv, start, t)
        return jnp.sum(jnp.sin(q)) + 0.1 * jnp.sum(v**2)

    args = (np.array([0.1, -0.2]), np.array([0.0, 0.35]), np.array([0.8, 0.9]), np.array([[1.0, 0.5], [0.4, -0.3]]))
    grads = jax.grad(loss, argnums=(0, 1, 2, 3))(*args)
    for i, g in enumerate(grads):
        f = lambda x, i=i: float(loss(*(x if j == i else a for j, a in enumerate(args))))  # noqa: E731
        # Step sqrt(eps)·scale: the difference quotient carries ~eps·|loss|/h ≈ 1e-7 of round-off.
        assert np.allclose(np.asarray(g), central_diff(f, args[i]), rtol=1e-6, atol=1e-6)

    def blended(alpha, prims):
        return jnp.sum(jnp.cos(pj.blend(alpha, prims)))

    alpha = np.array([0.4, 0.3, 0.2, 0.1])
    ga, gP = jax.grad(blended, argnums=(0, 1))(alpha, P)
    # Finite differences along the simplex (Σα = 1 is enforced): directions e_i − e_k.
    for i in range(3):
        e = np.zeros(4)
        e[i], e[3] = 1.0, -1.0
        h = np.sqrt(np.finfo(float).eps)
        fd = (blended(alpha + h * e, P) - blended(alpha - h * e, P)) / (2 * h)
        assert float(ga @ e) == pytest.approx(float(fd), rel=1e-6, abs=1e-6)
    assert np.allclose(np.asarray(gP), central_diff(lambda p: float(blended(alpha, p)), P), rtol=1e-6, atol=1e-6)


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
    extrapolated blends, stiffer and softer arms, N_EQ postures; and their settled C statics."""
    rng = np.random.default_rng(5)
    verts, tris = _simplex_boundary(4)  # 34 distinct vertices after merging shared edges
    tris = _orient(verts, tris)
    uniq, inv = np.unique(np.round(verts, 12), axis=0, return_inverse=True)
    inside = rng.dirichlet(np.ones(4), size=40)
    inside = inside[inside.min(axis=1) > 0.08][:12]
    outside = np.array([[-0.3, 0.5, 0.4, 0.4], [0.2, -0.25, 0.6, 0.45], [0.3, 0.3, 0.6, -0.2]])
    alphas = np.concatenate([np.eye(4), uniq, inside, outside])
    extra = N_EQ - len(alphas)
    assert extra > 0
    alphas = np.concatenate([alphas, rng.dirichlet(np.ones(4), size=extra)])
    q_set = alphas @ P
    K = np.tile(free_arm.K, (N_EQ, 1))
    K[-extra:] *= rng.uniform(0.6, 1.6, size=(extra, 6))  # the padding items get their own stiffness
    # Calls of 8 postures: the same compiled shape as single calls (batches pad to 8).
    eqs = [pj.arm_equilibrium(free_arm, q_set[i : i + 8], K[i : i + 8]) for i in range(0, N_EQ, 8)]
    cat = lambda f: np.concatenate([np.asarray(getattr(e, f)) for e in eqs])  # noqa: E731
    q_c, hand_c, speed = c_settle(free_arm, q_set, K)
    return dict(
        q=cat("q"),
        hand=cat("hand"),
        status=cat("status"),
        converged=cat("converged"),
        residual=cat("residual"),
        q_set=q_set,
        K=K,
        q_c=q_c,
        hand_c=hand_c,
        speed_c=speed,
        n_uniq=len(uniq),
        inv=inv.reshape(-1),
        tris=tris,
        n_in=len(inside),
        n_out=len(outside),
        rest_index=0,
    )


def test_equilibrium_matches_settled_c_mujoco(eq_batch, P):
    """Newton on K(θ − θ_set) + ∇V = 0 vs settled C MuJoCo rollouts, all 64 postures."""
    assert eq_batch["converged"].all() and (eq_batch["status"] == pj.Status.SUCCESSFUL).all()
    assert eq_batch["speed_c"] < 1e-10  # the C arms have stopped
    assert np.abs(eq_batch["q_c"] - eq_batch["q"]).max() < 1e-8
    assert np.abs(eq_batch["hand_c"] - eq_batch["hand"]).max() < 1e-8
    # Gravity sags every joint away from its set-point (the arm is springy).
    assert np.abs(eq_batch["q"][:4] - P).max() > 0.1


def test_equilibrium_batch_equals_singles_and_flags_bad_items(free_arm, eq_batch):
    for i in (0, 7, N_EQ - 1):
        one = pj.arm_equilibrium(free_arm, eq_batch["q_set"][i], eq_batch["K"][i])
        assert one.q.shape == (6,) and one.status.shape == ()
        assert np.abs(np.asarray(one.q) - eq_batch["q"][i]).max() < 1e-13
    # Straight up with soft springs: an equilibrium (no gravity torque), but an unstable one.
    up = pj.arm_equilibrium(free_arm, np.array([np.pi, 0, 0, 0, 0, 0]), np.full(6, 2.0))
    assert int(up.status) == pj.Status.NOT_MINIMUM and not bool(up.converged)
    assert float(up.residual) < 1e-12
    with pytest.warns(DeprecationWarning, match="arm_equilibrium"):
        old = pj.equilibrium(free_arm, eq_batch["q_set"][0])
    assert np.abs(np.asarray(old.q) - eq_batch["q"][0]).max() < 1e-13


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

    g, H = jax.jit(lambda mx, q: gravity_terms(mx, q)[:2])(free_arm.mjx_model, jnp.asarray(q))
    h = 1e-6
    H_fd = np.array([(bias(q + h * e) - bias(q - h * e)) / (2 * h) for e in np.eye(6)]).T
    assert np.abs(np.asarray(g) - bias(q)).max() < 1e-12
    assert np.abs(np.asarray(H) - H_fd).max() < 1e-7


def test_superposition_stays_inside_region(eq_batch):
    """Blends with Σα = 1, α > 0 put the hand inside the region bounded by the images of the
    simplex's faces (the paper's shaded region, Figure 3); blends with a negative weight fall
    outside. The region is curved (joint-space interpolation), so it is not the convex hull."""
    nu = eq_batch["n_uniq"]
    verts = eq_batch["hand_c"][4 : 4 + nu]
    tris = eq_batch["inv"][eq_batch["tris"]]
    start = 4 + nu
    inside = eq_batch["hand_c"][start : start + eq_batch["n_in"]]
    outside = eq_batch["hand_c"][start + eq_batch["n_in"] : start + eq_batch["n_in"] + eq_batch["n_out"]]
    w_in = np.abs(_winding_number(inside, verts, tris))
    w_out = np.abs(_winding_number(outside, verts, tris))
    assert np.all(np.abs(w_in - 1) < 1e-6)
    assert np.all(w_out < 1e-6)


def test_winner_take_all_selects_commanded_primitive(P):
    scores = np.array([[0.1, 0.7, 0.2, 0.0], [0.3, 0.0, 0.1, 0.6], [2.0, 1.0, 1.5, -1.0]])
    out = np.asarray(pj.winner_take_all(scores, P))
    assert np.array_equal(out, P[[1, 3, 0]])
    # ...whereas superposition of the same (normalised) activations is a blend of all of them.
    blended = np.asarray(pj.blend(scores[:2] / scores[:2].sum(1, keepdims=True), P))
    assert np.allclose(blended, (scores[:2] / scores[:2].sum(1, keepdims=True)) @ P, atol=1e-15)
    assert np.abs(blended - out[:2]).max() > 0.05


def test_mjcf_chain_and_force_field_match_c_mujoco(free_arm, P):
    chain = pj.MjcfChain(free_arm, "hand")
    m = free_arm.mj_model
    q = P[3] + np.array([0.1, -0.05, 0.1, 0.2, -0.1, 0.05])

    def c_site(q):
        d = mujoco.MjData(m)
        d.qpos[:] = q
        mujoco.mj_forward(m, d)
        J = np.zeros((3, 6))
        mujoco.mj_jacSite(m, d, J, None, free_arm.layout.hand_site)
        return d.site_xpos[free_arm.layout.hand_site].copy(), J

    x_c, J_c = c_site(q)
    assert np.abs(np.asarray(chain.jacobian(q)) - J_c).max() < 1e-12
    assert np.abs(np.asarray(chain.fk(q)) - x_c).max() < 1e-12
    # Derivatives w.r.t. q (closed-form JVP of the site Jacobian) vs central differences of C
    # MuJoCo: of fk (its Jacobian) and of a function of J (second derivatives of the kinematics).
    w = np.array([0.3, -0.5, 0.8])
    g_fk, g_J = jax.jit(
        lambda q: (jax.grad(lambda q: chain.fk(q) @ w)(q), jax.grad(lambda q: jnp.sum(chain.jacobian(q) ** 2))(q))
    )(q)
    assert np.allclose(np.asarray(g_fk), central_diff(lambda q: c_site(q)[0] @ w, q), rtol=1e-6, atol=1e-7)
    assert np.allclose(np.asarray(g_J), central_diff(lambda q: np.sum(c_site(q)[1] ** 2), q), rtol=1e-6, atol=1e-7)
    # Force field: Jᵀ F = τ in least squares (the paper's J F = K (θ − θ_set), restoring sign).
    tau = -free_arm.K * (q - P[3])
    F = np.asarray(pj.force_field(chain, q, P[3], free_arm.K))
    assert np.allclose(F, np.linalg.lstsq(J_c.T, tau, rcond=None)[0], atol=1e-10)
    # Convergent field: the force points back towards the set-point posture's hand position.
    assert F @ (np.asarray(chain.fk(P[3])) - x_c) > 0


# ----------------------------------------------------------------------------------------------
# Gradients of the equilibrium


def test_equilibrium_gradient_matches_central_differences(free_arm, P):
    """Implicit-function-theorem derivatives of the equilibrium hand height w.r.t. K and θ_set
    (the Newton solution is exact to round-off, so the difference quotient is too)."""

    def height(K, q_set):
        return pj.arm_equilibrium(free_arm, q_set, K).hand[2]

    gK, gq = jax.jit(jax.grad(height, argnums=(0, 1)))(free_arm.K, P[3])  # (one program, not one per operation)
    fdK = central_diff(lambda k: float(height(k, P[3])), free_arm.K)
    fdq = central_diff(lambda q: float(height(free_arm.K, q)), P[3])
    assert np.allclose(np.asarray(gK), fdK, rtol=1e-5, atol=2e-8)
    assert np.allclose(np.asarray(gq), fdq, rtol=1e-5, atol=2e-8)
    assert np.abs(fdK).max() > 1e-4 and np.abs(fdq).max() > 0.1  # the checks are not vacuous


# ----------------------------------------------------------------------------------------------
# Bad input: clear errors naming the argument, raised before tracing


@pytest.mark.bad_input("pj.load_arm", "pj.arm_xml_path", "pj.CogArm")
def test_bad_input_loading(tmp_path):
    with pytest.raises(ValueError, match="xml_or_model"):
        pj.load_arm("<mujoco><worldbody/></mujoco>")  # no joints
    with pytest.raises(ValueError, match="xml_or_model"):
        pj.load_arm(str(tmp_path / "missing.xml"))
    bad = tmp_path / "bad.xml"
    bad.write_text("<mujoco>\n  <worldbody>\n    <bogus/>\n  </worldbody>\n</mujoco>\n")
    with pytest.raises(ValueError, match=r"(?s)xml_or_model.*line 3"):  # MuJoCo names the line
        pj.load_arm(str(bad))
    with pytest.raises(TypeError, match="xml_or_model"):
        pj.load_arm(42)
    with pytest.raises(TypeError, match="contacts"):
        pj.load_arm(contacts="no")
    with pytest.raises(TypeError):
        pj.arm_xml_path("other.xml")  # takes no arguments
    with pytest.raises(TypeError, match="arm"):
        pj.rollout(pj.CogArm, np.zeros((3, 6)))  # the class, not a loaded arm


@pytest.mark.bad_input("pj.rollout", "pj.run_controller")
def test_bad_input_rollouts(free_arm):
    q = np.zeros((10, 6))
    with pytest.raises(ValueError, match="q_set"):
        pj.rollout(free_arm, np.zeros((10, 5)))
    with pytest.raises(ValueError, match="q_set"):
        pj.rollout(free_arm, np.full((10, 6), np.nan))
    with pytest.raises(ValueError, match="`K`"):
        pj.rollout(free_arm, q, K=np.array([40.0, -1, 20, 20, 5, 5]))
    with pytest.raises(ValueError, match="`K`"):
        pj.rollout(free_arm, q, K=np.full(6, 1e7))  # too stiff for the explicit step
    with pytest.raises(ValueError, match="`B`"):
        pj.rollout(free_arm, q, B=np.full(6, 50.0))
    with pytest.raises(ValueError, match="q0"):
        pj.rollout(free_arm, q, q0=np.zeros(5))
    with pytest.raises(ValueError, match="force"):
        pj.rollout(free_arm, q, force=np.zeros((9, 3)))
    with pytest.raises(ValueError, match="backend"):
        pj.rollout(free_arm, q, backend="gpu")
    with pytest.raises(ValueError, match="nthread"):
        pj.rollout(free_arm, q, backend="mujoco", nthread=0)
    with pytest.raises(ValueError, match="broadcast"):
        pj.rollout(free_arm, np.zeros((2, 10, 6)), K=np.ones((3, 6)) * 40, backend="mujoco")
    with pytest.raises(TypeError, match="backend='mujoco'"):
        jax.jit(lambda q: pj.rollout(free_arm, q, backend="mujoco").q)(q)
    with pytest.raises(ValueError, match="n_steps"):
        pj.run_controller(free_arm, None, q, n_steps=0)
    with pytest.raises(TypeError, match="arm"):
        pj.run_controller("arm", None, q, n_steps=10)


@pytest.mark.bad_input(
    "pj.ReflexInputs", "pj.reflex_network", "pj.run_reflexes", "pj.script_inputs", "pj.stack_inputs"
)
def test_bad_input_reflexes(arm):
    with pytest.raises(ValueError, match="network.dt"):
        pj.run_reflexes(arm, pj.ReflexNetwork(rest=arm.q_rest, dt=0.001), pj.script_inputs(arm, 0.01))
    with pytest.raises(TypeError, match="network"):
        pj.run_reflexes(arm, "net", pj.script_inputs(arm, 0.01))
    with pytest.raises(TypeError, match="inputs"):
        pj.run_reflexes(arm, pj.reflex_network(arm), np.zeros((5, 6)))
    with pytest.raises(ValueError, match="backend"):
        pj.run_reflexes(arm, pj.reflex_network(arm), pj.script_inputs(arm, 0.01), backend="cuda")
    with pytest.raises(ValueError, match="grasp_damping"):
        pj.run_reflexes(arm, pj.reflex_network(arm, grasp_damping=100.0), pj.script_inputs(arm, 0.01))
    with pytest.raises(ValueError, match="touch_threshold"):
        pj.reflex_network(arm, touch_threshold=-1.0)
    with pytest.raises(ValueError, match="lead_threshold"):
        pj.reflex_network(arm, lead_threshold=np.nan)
    with pytest.raises(ValueError, match="grasp_damping"):
        pj.reflex_network(arm, grasp_damping=-1.0)
    with pytest.raises(ValueError, match="dt"):
        pj.reflex_network(arm, dt=0.01)
    with pytest.raises(TypeError):
        pj.reflex_network(arm, grasp_duration=0.2)  # removed: the grasp no longer adds a timed move
    with pytest.raises(ValueError, match="duration"):
        pj.script_inputs(arm, -1.0)
    with pytest.raises(ValueError, match="targets"):
        pj.script_inputs(arm, 1.0, targets=[(2.0, arm.q_rest)])  # after the end
    with pytest.raises(ValueError, match="targets"):
        pj.script_inputs(arm, 1.0, targets=[(0.1, np.zeros(5))])
    with pytest.raises(ValueError, match="lead"):
        pj.script_inputs(arm, 1.0, lead=[(0.5, 0.2)])
    with pytest.raises(ValueError, match="touch"):
        pj.script_inputs(arm, 1.0, touch=[(0.1, 0.2, -1.0, 0.0)])
    with pytest.raises(ValueError, match="touch"):
        pj.script_inputs(arm, 1.0, touch=[(0.1, 0.2, 1.0)])
    with pytest.raises(ValueError, match="q_start"):
        pj.script_inputs(arm, 1.0, q_start=np.zeros(4))
    with pytest.raises(ValueError, match="touch"):
        pj.ReflexInputs(np.zeros((5, 6)), np.zeros(5), np.zeros(5), np.zeros(5), np.zeros((5, 3)))
    with pytest.raises(ValueError, match="new_target"):
        pj.ReflexInputs(np.zeros((5, 6)), np.zeros(4), np.zeros(5), np.zeros(5), np.zeros((5, 2)))
    with pytest.raises(ValueError, match="same shape"):
        pj.stack_inputs([pj.script_inputs(arm, 0.01), pj.script_inputs(arm, 0.02)])
    with pytest.raises(TypeError, match="ReflexInputs"):
        pj.stack_inputs([])


@pytest.mark.bad_input(
    "pj.Moves", "pj.moves_from_targets", "pj.move_velocity", "pj.summed_moves", "pj.blend",
    "pj.winner_take_all", "pj.default_primitives",
)
def test_bad_input_primitives_and_moves(P):
    with pytest.raises(ValueError, match="alpha"):
        pj.blend([0.5, 0.3, 0.1, 0.2], P)  # sums to 1.1
    with pytest.raises(ValueError, match="alpha"):
        pj.blend([0.5, 0.5], P)
    with pytest.raises(ValueError, match="`P`"):
        pj.blend([1.0], np.zeros(6))
    with pytest.raises(ValueError, match="scores"):
        pj.winner_take_all([1.0, 2.0], P)
    with pytest.raises(ValueError, match="`P`"):
        pj.winner_take_all([1.0], np.full((1, 6), np.inf))
    with pytest.raises(TypeError):
        pj.default_primitives(4)
    with pytest.raises(ValueError, match="duration"):
        pj.moves_from_targets([0.0], [[1.0]], t0=[0.0], duration=[0.0])
    with pytest.raises(ValueError, match="t0"):
        pj.moves_from_targets([0.0], [[1.0], [2.0]], t0=[0.0, 1.0, 2.0], duration=1.0)
    with pytest.raises(ValueError, match="targets"):
        pj.moves_from_targets([0.0, 0.0], [[1.0]], t0=0.0, duration=1.0)
    with pytest.raises(ValueError, match="start"):
        pj.moves_from_targets(np.zeros((2, 2)), [[1.0, 1.0]], t0=0.0, duration=1.0)
    with pytest.raises(ValueError, match="duration"):
        pj.Moves(t0=[0.0], duration=[-1.0], delta=[[1.0]])
    with pytest.raises(ValueError, match="delta"):
        pj.Moves(t0=[0.0], duration=[1.0], delta=[1.0])
    with pytest.raises(ValueError, match="t0"):
        pj.Moves(t0=[0.0, 1.0], duration=[1.0], delta=[[1.0]])
    mv = pj.moves_from_targets([0.0], [[1.0]], t0=0.0, duration=1.0)
    with pytest.raises(TypeError, match="moves"):
        pj.summed_moves((0.0, 1.0, 1.0), [0.0], [0.5])
    with pytest.raises(ValueError, match="start"):
        pj.summed_moves(mv, [0.0, 1.0], [0.5])
    with pytest.raises(ValueError, match="`t`"):
        pj.summed_moves(mv, [0.0], [[0.5]])
    with pytest.raises(ValueError, match="`t`"):
        pj.move_velocity(mv, [np.nan])
    with pytest.raises(TypeError, match="moves"):
        pj.move_velocity("moves", [0.5])


@pytest.mark.bad_input("pj.arm_equilibrium", "pj.equilibrium", "pj.force_field", "pj.MjcfChain")
def test_bad_input_equilibrium_and_fields(arm, free_arm, P):
    with pytest.raises(ValueError, match="q_set"):
        pj.arm_equilibrium(free_arm, np.zeros(5))
    with pytest.raises(ValueError, match="`K`"):
        pj.arm_equilibrium(free_arm, P[0], K=-free_arm.K)
    with pytest.raises(ValueError, match="max_steps"):
        pj.arm_equilibrium(free_arm, P[0], max_steps=0)
    for fn in (pj.arm_equilibrium, pj.equilibrium):  # the old keyword, passed on under the new one
        with pytest.warns(DeprecationWarning, match="n_iter"), pytest.raises(ValueError, match="max_steps"):
            fn(free_arm, P[0], n_iter=0)
    with pytest.raises(ValueError, match="broadcast"):
        pj.arm_equilibrium(free_arm, P[:3], K=np.tile(free_arm.K, (2, 1)))
    with pytest.raises(TypeError, match="arm"):
        pj.arm_equilibrium(P, P[0])
    with pytest.raises(ValueError, match="q_set"), pytest.warns(DeprecationWarning):
        pj.equilibrium(free_arm, np.full(6, np.inf))
    chain = pj.MjcfChain(free_arm, "hand")
    with pytest.raises(ValueError, match="site"):
        pj.MjcfChain(arm, "elbow")
    with pytest.raises(TypeError, match="site"):
        pj.MjcfChain(arm, 3)
    with pytest.raises(ValueError, match="xml_or_model"):
        pj.MjcfChain("<mujoco><worldbody><bogus/></worldbody></mujoco>", "hand")
    with pytest.raises(TypeError, match="chain"):
        pj.force_field(pj.PlanarArm([1.0, 1.0]), np.zeros(2), np.zeros(2), np.ones(2))
    with pytest.raises(ValueError, match="`K`"):
        pj.force_field(chain, P[0], P[1], np.zeros(6))
    with pytest.raises(ValueError, match="`q`"):
        pj.force_field(chain, np.zeros(3), P[1], free_arm.K)
    with pytest.raises(ValueError, match="broadcast"):
        pj.force_field(chain, np.zeros((2, 6)), np.zeros((3, 6)), free_arm.K)


@pytest.mark.bad_input("pj.plot_force_field", "pj.plot_reflex", "pj.plot_summed_moves")
def test_bad_input_plots(free_arm, P):
    chain = pj.MjcfChain(free_arm, "hand")
    mv = pj.moves_from_targets([0.0], [[1.0]], t0=0.0, duration=1.0)
    with pytest.raises(ValueError, match="joint"):
        pj.plot_summed_moves(mv, [0.0], [0.0, 0.5], joint=2)
    with pytest.raises(TypeError, match="moves"):
        pj.plot_summed_moves(None, [0.0], [0.0, 0.5])
    with pytest.raises(TypeError, match="traj"):
        pj.plot_reflex(np.zeros((10, 6)))
    with pytest.raises(TypeError, match="chain"):
        pj.plot_force_field("hand", P[0], free_arm.K)
    with pytest.raises(ValueError, match="joints"):
        pj.plot_force_field(chain, P[0], free_arm.K, joints=(0, 0))
    with pytest.raises(ValueError, match="span"):
        pj.plot_force_field(chain, P[0], free_arm.K, span=-0.1)
    with pytest.raises(ValueError, match="q_set"):
        pj.plot_force_field(chain, P[:2], free_arm.K)
