"""λ0-PMP, PMP1, PMP2 on the wrist against SciPy (solve_ivp, SLSQP) and finite differences."""

import importlib

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.integrate
import scipy.optimize
from _reference import arimoto, pmp_qdot, wrist_fk, wrist_jac
from jax.flatten_util import ravel_pytree

import pmpjax as pj

simulate_module = importlib.import_module("pmpjax._pmp.simulate")  # (the face binds simulate to the function)

# Table 1–2 subject 2 (off-diagonal stiffness) and the Figure 3 example.
KJ_S2 = np.array([[1.20, 0.04, -0.12], [0.04, 1.47, 0.26], [-0.12, 0.26, 1.33]])
QREST_S2 = np.array([0.51, 0.11, -0.11])
KJ_F3 = np.diag([0.5, 1.5, 2.0])
QREST_F3 = np.deg2rad([5.0, 0.0, 0.0])
TAU0 = 0.08
R = np.pi / 12
TG = pj.center_out_targets()
CHAIN = pj.Wrist(1.0)
# One schedule for the single-movement tests, so that they share compilations (each new shape or
# static argument of `simulate` compiles the integrator again).
KW = dict(duration=0.4, dt=1e-3, saveat=pj.SaveAt(every=10))
ARIMOTO = pj.ArimotoPlanner(k=22.5, tau=0.08)


def lam0(KJ=KJ_S2, q_rest=QREST_S2, tau0=TAU0):
    return pj.Lambda0PMP(CHAIN, KJ=KJ, q_rest=q_rest, W=tau0 * KJ)


def slsqp_posture(KJ, q_rest, target):
    res = scipy.optimize.minimize(
        lambda q: 0.5 * (q - q_rest) @ KJ @ (q - q_rest), q_rest, jac=lambda q: KJ @ (q - q_rest),
        constraints=[{"type": "eq", "fun": lambda q: wrist_fk(q) - target, "jac": wrist_jac}],
        method="SLSQP", options={"ftol": 1e-15, "maxiter": 500},
    )
    assert res.success
    return res.x


@pytest.fixture(scope="module")
def long_runs():
    """Three 2 s movements per model from the same start: E directly, and N then E."""
    q0 = QREST_S2 + np.array([0.05, -0.1, 0.08])
    seqs = np.stack([np.stack([TG["E"], TG["E"]]), np.stack([TG["N"], TG["E"]])])
    planner = pj.ArimotoPlanner(k=22.5, tau=0.08)
    kw = dict(duration=2.0, dt=1e-3, saveat=pj.SaveAt(every=50))
    out = {"q0": q0}
    out["lam0"] = pj.simulate_sequence(lam0(), planner, q0, seqs, **kw)
    out["pmp1"] = pj.simulate_sequence(pj.PMP1(CHAIN, W=TAU0 * KJ_S2), planner, q0, seqs, **kw)
    out["pmp2"] = pj.simulate_sequence(pj.PMP2(CHAIN, KJ=KJ_S2, q_rest=QREST_S2, W=TAU0 * KJ_S2),
                                       planner, q0, seqs, **kw)
    return out


def test_lambda0_reaches_target_in_the_energy_minimising_posture(long_runs):
    tr = long_runs["lam0"]
    assert np.all(np.asarray(tr.status) == 0)
    q_star = slsqp_posture(KJ_S2, QREST_S2, TG["E"])
    for seq in range(2):
        np.testing.assert_allclose(tr.x[seq, -1, -1], TG["E"], atol=1e-6)
        np.testing.assert_allclose(tr.q[seq, -1, -1], q_star, atol=1e-6)
    # Donders' law: E directly and E via N end in the same posture.
    assert np.max(np.abs(tr.q[0, -1, -1] - tr.q[1, -1, -1])) < 1e-6


def test_pmp1_is_path_dependent_and_pmp2_misses(long_runs):
    p1, p2 = long_runs["pmp1"], long_runs["pmp2"]
    np.testing.assert_allclose(p1.x[:, -1, -1], np.stack([TG["E"], TG["E"]]), atol=1e-6)
    assert np.max(np.abs(p1.q[0, -1, -1] - p1.q[1, -1, -1])) > 1e-3
    assert np.linalg.norm(p2.x[0, -1, -1] - TG["E"]) > 1e-3
    # PMP2 ends at the (path-independent) equilibrium of both springs, which is not the target.
    assert np.max(np.abs(p2.q[0, -1, -1] - p2.q[1, -1, -1])) < 1e-6


def test_task_dynamics_identity_along_trajectory(long_runs):
    """Eq 5: B(q) ẋ = K(t) (x_d − x), i.e. ẋ = (J W⁻¹ Jᵀ) K(t) (x_d − x), at every saved step."""
    tr = long_runs["lam0"]
    gain = arimoto(22.5, 0.08)
    A = np.linalg.inv(TAU0 * KJ_S2)
    q, xdot, t = np.asarray(tr.q[1, 0]), np.asarray(tr.xdot[1, 0]), np.asarray(tr.t)
    for i in range(len(t)):
        J = wrist_jac(q[i])
        expected = J @ A @ J.T @ (gain(t[i]) * (TG["N"] - wrist_fk(q[i])))
        np.testing.assert_allclose(xdot[i], expected, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("kernel", ["small batch", "large batch"])
def test_matches_solve_ivp(kernel, monkeypatch):
    """Both kernels (RK4 stages in a loop below ``SMALL_BATCH`` movements, unrolled above) follow
    a tight DOP853 solution to 2e-8 rad (measured 5e-9, at the Arimoto gain's onset): a wrong stage
    coefficient or stage observation leaves an error of order 1e-5 or more."""
    if kernel == "large batch":
        monkeypatch.setattr(simulate_module, "SMALL_BATCH", 0)
    q0 = QREST_S2 + np.array([0.1, 0.05, -0.05])
    target = TG["NE"]
    tr = pj.simulate(lam0(), ARIMOTO, q0, target, **KW)
    gain = arimoto(22.5, 0.08)
    ref = scipy.integrate.solve_ivp(
        lambda t, q: pmp_qdot(q, t, target, KJ_S2, QREST_S2, TAU0 * KJ_S2, gain),
        (0, 0.4), q0, method="DOP853", rtol=1e-12, atol=1e-14, t_eval=np.asarray(tr.t), dense_output=False,
    )
    assert np.max(np.abs(ref.y.T - np.asarray(tr.q))) < 2e-8
    np.testing.assert_allclose(tr.x, np.stack([wrist_fk(q) for q in ref.y.T]), atol=2e-8)


def test_bell_shaped_speed_profile():
    tr = pj.simulate(lam0(KJ_F3, QREST_F3), ARIMOTO, QREST_F3, TG["NE"], **KW)
    v = np.asarray(tr.speed)
    assert v[0] < 1e-12
    peaks = [i for i in range(1, len(v) - 1) if v[i] > v[i - 1] and v[i] >= v[i + 1]]
    assert len(peaks) == 1 and 2 < peaks[0] < len(v) - 5
    assert np.all(np.diff(v[: peaks[0] + 1]) > 0) and np.all(np.diff(v[peaks[0]:]) < 0)


def test_minimum_jerk_planner_gives_straight_minimum_jerk_path():
    T = 0.4
    tr = pj.simulate(lam0(), pj.MinimumJerkPlanner(duration=T), QREST_S2, TG["SW"], **KW)
    s = np.asarray(tr.t) / T
    xi = s**3 * (10 - 15 * s + 6 * s**2)
    x0 = np.asarray(tr.x[0])
    expected = x0 + xi[:, None] * (TG["SW"] - x0)
    keep = s <= 0.9
    np.testing.assert_allclose(np.asarray(tr.x)[keep], expected[keep], atol=1e-7)


def test_batch_equals_single_runs(rng):
    B = 5
    q0 = QREST_S2 + rng.normal(scale=0.05, size=(B, 3))
    ang = rng.uniform(0, 2 * np.pi, B)
    targets = R * np.stack([np.cos(ang), np.sin(ang)], -1)
    KJ = np.stack([KJ_S2 * s for s in rng.uniform(0.8, 1.2, B)])
    model = pj.Lambda0PMP(CHAIN, KJ=KJ, q_rest=QREST_S2, W=TAU0 * KJ)
    planner, kw = ARIMOTO, KW
    batch = pj.simulate(model, planner, q0, targets, **kw)
    assert batch.q.shape == (B, 41, 3)
    for i in range(B):
        one = pj.simulate(lam0(KJ[i]), planner, q0[i], targets[i], **kw)
        np.testing.assert_allclose(batch.q[i], one.q, rtol=0, atol=1e-13)
    # (compiled whole: one program instead of the kernel's and some sixty eager operations' compiles)
    vm = jax.jit(jax.vmap(lambda q, x: pj.simulate(lam0(), planner, q, x, **kw).q))(jnp.asarray(q0),
                                                                                   jnp.asarray(targets))
    np.testing.assert_allclose(vm[0], pj.simulate(lam0(), planner, q0[0], targets[0], **kw).q, atol=1e-13)


FIELDS = ("q", "x", "qdot", "xdot", "manipulability")


def test_save_modes_agree_at_shared_steps():
    """Every step, every 10th (KW), given times without t = 0, and final-only save the same states.

    Catches samples written at the wrong row (block writes, the overwritten unsaved start of
    ``ts``), derived outputs of the wrong state or time, and a wrong status; the derived outputs
    are checked against NumPy (x = fk(q), ẋ = J q̇, manipulability = sqrt(det J Jᵀ)).
    """
    planner, model = ARIMOTO, lam0()
    q0 = np.stack([QREST_S2, [0.0, np.pi / 2 - 1e-6, 0.0]])  # the second starts singular
    tg = np.stack([TG["W"], TG["C"]])
    run = lambda sv: pj.simulate(model, planner, q0, tg, duration=0.4, dt=1e-3, saveat=sv)  # noqa: E731
    every = run(pj.SaveAt())
    tenth = run(KW["saveat"])
    assert every.q.shape == (2, 401, 3) and tenth.q.shape == (2, 41, 3)
    np.testing.assert_allclose(every.t, np.arange(401) * 1e-3, atol=1e-15)
    for f in FIELDS:
        # (1e-9: the second movement starts at a singular posture, which amplifies the rounding
        # differences of two compiled programs; a sample of the wrong step differs by > 1e-5)
        np.testing.assert_allclose(getattr(tenth, f), getattr(every, f)[:, ::10], rtol=1e-8, atol=1e-9)
    np.testing.assert_array_equal(every.status, [pj.Status.SUCCESSFUL, pj.Status.SINGULAR])
    np.testing.assert_array_equal(tenth.status, every.status)
    q, qd = np.asarray(every.q[0]), np.asarray(every.qdot[0])
    J = np.stack([wrist_jac(v) for v in q])
    np.testing.assert_allclose(every.x[0], np.stack([wrist_fk(v) for v in q]), atol=1e-14)
    np.testing.assert_allclose(every.xdot[0], np.einsum("sij,sj->si", J, qd), atol=1e-13)
    np.testing.assert_allclose(every.manipulability[0], np.sqrt(np.linalg.det(J @ J.transpose(0, 2, 1))),
                               atol=1e-13)
    ts = (0.1, 0.2, 0.3, 0.4)  # on the 1 ms grid, without t = 0
    at = run(pj.SaveAt(ts=ts))
    np.testing.assert_allclose(at.t, ts)
    for f in FIELDS:
        np.testing.assert_allclose(getattr(at, f), getattr(every, f)[:, 100::100], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(at.status, every.status)
    fin = run(pj.SaveAt(final=True))
    assert fin.q.shape == (2, 1, 3)
    for f in FIELDS:
        np.testing.assert_allclose(getattr(fin, f), getattr(every, f)[:, -1:], rtol=0, atol=1e-13)
    # the status looks at saved samples only: the final posture is regular
    np.testing.assert_array_equal(fin.status, [pj.Status.SUCCESSFUL, pj.Status.SUCCESSFUL])


def test_every_step_saving_writes_in_place():
    """The compiled every-step run holds no second copy of its outputs: XLA's own buffer count
    (``memory_analysis``) stays below a tenth of the output. Catches equal initial fills that XLA
    merges and then copies apart (q and q̇, x and ẋ: 6/11 of the output), and an output written
    through a reshaped view (copied after the loop: 1/11)."""
    model, B = lam0(), 64
    q0, tg = np.tile(QREST_S2, (B, 1)), np.tile(TG["E"], (B, 1))
    run = jax.jit(lambda q, t: pj.simulate(model, ARIMOTO, q, t, duration=0.4, dt=1e-3, saveat=pj.SaveAt()))
    mem = run.lower(q0, tg).compile().memory_analysis()
    assert mem.output_size_in_bytes >= B * 401 * 11 * 8
    assert mem.temp_size_in_bytes < 0.1 * mem.output_size_in_bytes, (mem.temp_size_in_bytes, mem.output_size_in_bytes)


def test_eq10_gain_against_numpy():
    q0 = QREST_S2
    planner = pj.ArimotoPlanner(k=None, tau=0.08, tau0=TAU0)
    tr = pj.simulate(lam0(), planner, q0, TG["S"], **KW)
    J = wrist_jac(q0)
    b_max = np.linalg.eigvalsh(np.linalg.inv(J @ np.linalg.inv(TAU0 * KJ_S2) @ J.T)).max()
    gain = arimoto(b_max / TAU0, 0.08)
    ref = scipy.integrate.solve_ivp(
        lambda t, q: pmp_qdot(q, t, TG["S"], KJ_S2, QREST_S2, TAU0 * KJ_S2, gain),
        (0, 0.4), q0, method="DOP853", rtol=1e-10, atol=1e-12, t_eval=np.asarray(tr.t))
    assert np.max(np.abs(ref.y.T - np.asarray(tr.q))) < 1e-6


def test_gradients_match_central_differences():
    """d/dθ of a trajectory loss, θ = (KJ, q_rest, τ0, τ, k, target)."""
    q0 = QREST_S2 + np.array([0.05, 0.0, 0.05])

    def loss(p):
        KJ = p["KJ"] + p["KJ"].T  # symmetric parameterisation
        model = pj.Lambda0PMP(CHAIN, KJ=KJ, q_rest=p["q_rest"], W=p["tau0"] * KJ)
        tr = pj.simulate(model, pj.ArimotoPlanner(k=p["k"], tau=p["tau"]), q0, p["target"], **KW)
        return jnp.sum(tr.x**2) + jnp.sum(jnp.sin(tr.q[-1]))

    p0 = {"KJ": jnp.asarray(KJ_S2 / 2), "q_rest": jnp.asarray(QREST_S2), "tau0": jnp.asarray(0.08),
          "tau": jnp.asarray(0.06), "k": jnp.asarray(20.0), "target": jnp.asarray(TG["NW"])}
    # one compilation: the differences use the value half of the same compiled value_and_grad
    vg = pj.fast_compile_jit(jax.value_and_grad(loss))
    f = lambda p: vg(p)[0]  # noqa: E731
    flat, unravel = ravel_pytree(p0)
    g = vg(unravel(flat))[1]  # unravel's (strong) dtypes, as in the differences: no second compile
    gflat = ravel_pytree(g)[0]
    for i in range(flat.size):
        h = 1e-6 * max(1.0, abs(float(flat[i])))
        e = jnp.zeros_like(flat).at[i].set(h)
        fd = (f(unravel(flat + e)) - f(unravel(flat - e))) / (2 * h)
        assert abs(float(gflat[i]) - float(fd)) <= 1e-5 * max(abs(float(fd)), 1e-2), (i, gflat[i], fd)


def test_singular_start_is_flagged():
    q0 = np.array([0.0, np.pi / 2 - 1e-6, 0.0])
    tr = pj.simulate(lam0(), ARIMOTO, q0, TG["C"], **KW)
    assert int(tr.status) == pj.Status.SINGULAR and float(tr.manipulability[0]) < 1e-4


@pytest.mark.parametrize(
    "change, match",
    [
        (dict(KJ=np.array([[1.0, 0.2, 0], [0, 1, 0], [0, 0, 1]])), "KJ"),
        (dict(KJ=np.diag([1.0, -1.0, 1.0])), "KJ"),
        (dict(W=np.diag([1.0, 1.0])), "W"),
        (dict(W=np.diag([np.nan, 1.0, 1.0])), "W"),
        (dict(q_rest=np.zeros(2)), "q_rest"),
        (dict(q_rest=np.array([np.inf, 0, 0])), "q_rest"),
    ],
)
def test_bad_model_input(change, match):
    kw = dict(KJ=KJ_S2, q_rest=QREST_S2, W=TAU0 * KJ_S2) | change
    with pytest.raises(ValueError, match=match):
        pj.Lambda0PMP(CHAIN, **kw)


@pytest.mark.parametrize(
    "kw, match",
    [
        (dict(target=np.array([0.99, 0.0])), "target"),
        (dict(target=np.array([0.1, 0.1, 0.1])), "target"),
        (dict(target=np.array([np.nan, 0.1])), "target"),
        (dict(q0=np.zeros(4)), "q0"),
        (dict(duration=0.0), "duration"),
        (dict(duration=-1.0), "duration"),
        (dict(dt=0.0), "dt"),
        (dict(dt=0.05), "dt"),
    ],
)
def test_bad_simulation_input(kw, match):
    args = dict(q0=QREST_S2, target=TG["E"], duration=0.4, dt=1e-3) | kw
    with pytest.raises(ValueError, match=match):
        pj.simulate(lam0(), pj.ArimotoPlanner(k=22.5, tau=0.08), args.pop("q0"), args.pop("target"), **args)


def test_bad_planner_input():
    with pytest.raises(ValueError, match="tau"):
        pj.ArimotoPlanner(k=1.0, tau=-0.1)
    with pytest.raises(ValueError, match="k"):
        pj.ConstantPlanner(k=0.0)
    with pytest.raises(ValueError, match="tau0"):
        pj.ArimotoPlanner(k=None, tau=0.1)


def test_center_out_protocol():
    order, seq = pj.center_out_trials(3, seed=7)
    order2, _ = pj.center_out_trials(3, seed=7)
    np.testing.assert_array_equal(order, order2)
    assert seq.shape == (3, 16, 2)
    for row, s in zip(order, seq):
        assert sorted(row) == sorted(pj.DIRECTIONS)
        np.testing.assert_allclose(s[1::2], 0.0)
        np.testing.assert_allclose(np.linalg.norm(s[0::2], axis=-1), R)
    np.testing.assert_allclose(TG["E"], [R, 0], atol=1e-16)
    np.testing.assert_allclose(TG["N"], [0, R], atol=1e-16)


def test_planar_arm_and_user_chain():
    """Any chain: 3-link planar arm (analytic) and the same arm as a user FK function agree, and
    the λ0-PMP ends in the SLSQP minimiser of the elastic energy on the target manifold."""
    L = np.array([0.3, 0.25, 0.15])
    KJ = np.array([[2.0, 0.3, 0.0], [0.3, 1.0, 0.1], [0.0, 0.1, 0.5]])
    q_rest = np.array([0.3, 0.8, 0.4])
    target = np.array([0.35, 0.3])

    def fk(q):
        phi = jnp.cumsum(q)
        return jnp.stack([jnp.sum(L * jnp.cos(phi)), jnp.sum(L * jnp.sin(phi))])

    kw = dict(duration=1.5, dt=1e-3, saveat=pj.SaveAt(final=True))
    planner = pj.ArimotoPlanner(k=None, tau=0.05, tau0=0.05)
    ends = []
    for chain in (pj.PlanarArm(L), pj.FunctionChain(fk, n=3, m=2)):
        model = pj.Lambda0PMP(chain, KJ=KJ, q_rest=q_rest, W=0.05 * KJ)
        ends.append(np.asarray(pj.simulate(model, planner, q_rest, target, **kw).q[-1]))
    np.testing.assert_allclose(ends[0], ends[1], atol=1e-12)
    fk_np = lambda q: np.asarray(fk(jnp.asarray(q)))  # noqa: E731
    res = scipy.optimize.minimize(
        lambda q: 0.5 * (q - q_rest) @ KJ @ (q - q_rest), q_rest, method="SLSQP",
        constraints=[{"type": "eq", "fun": lambda q: fk_np(q) - target}], options={"ftol": 1e-15},
    )
    np.testing.assert_allclose(ends[0], res.x, atol=1e-6)
    with pytest.raises(ValueError, match="target"):
        pj.simulate(pj.Lambda0PMP(pj.PlanarArm(L), KJ=KJ, q_rest=q_rest, W=KJ), planner, q_rest,
                    np.array([1.0, 0.0]), **kw)


def test_folded_forward_jacobians_match_central_differences():
    """``forward_jacobians`` (tangent and vmapped axes folded into simulate's batch, as in
    ``fitting.least_squares``): jacfwd in (τ0, τ) under vmap over movements with their own
    targets, against central differences of the plain primal."""
    from pmpjax.internal import forward_jacobians

    q0 = QREST_S2 + np.array([0.05, 0.0, 0.05])
    targets = jnp.stack([jnp.asarray(TG["NW"]), jnp.asarray(TG["E"])])
    kw = dict(duration=0.2, dt=2e-3, saveat=pj.SaveAt(final=True))

    def final(theta, target):
        model = pj.Lambda0PMP(CHAIN, KJ=KJ_S2, q_rest=QREST_S2, W=theta[0] * KJ_S2)
        tr = pj.simulate(model, pj.ArimotoPlanner(k=None, tau=theta[1], tau0=theta[0]), q0, target, **kw)
        return jnp.concatenate([tr.q[-1], tr.xdot[-1]])

    def jac(thetas):
        with forward_jacobians():
            return jax.vmap(jax.jacfwd(final))(thetas, targets)

    thetas = jnp.array([[0.08, 0.06], [0.1, 0.05]])
    J = np.asarray(pj.fast_compile_jit(jac)(thetas))
    f = pj.fast_compile_jit(jax.vmap(final))
    for i in range(2):
        e = np.zeros((2, 2))
        e[:, i] = 1e-6
        fd = (np.asarray(f(thetas + e, targets)) - np.asarray(f(thetas - e, targets))) / 2e-6
        np.testing.assert_allclose(J[..., i], fd, rtol=1e-5, atol=1e-7)


def test_frozen_tangents_hold_rodas4s_field_jacobian_only_where_asked():
    """``forward_jacobians(frozen=flag)`` with a traced flag: false gives RODAS4's exact derivative
    (central differences, to 1e-6); true an approximate one (the field Jacobian held along the
    tangents) that differs from it, but not by more than a few per cent at these coarse steps; the
    trajectory itself is the same either way."""
    from pmpjax.internal import forward_jacobians

    q0 = QREST_S2 + np.array([0.05, 0.0, 0.05])
    kw = dict(duration=0.2, dt=0.02, saveat=pj.SaveAt(ts=np.linspace(0.0, 0.2, 6)), solver="rodas4")

    def path(theta):
        model = pj.Lambda0PMP(CHAIN, KJ=theta[2] * KJ_S2, q_rest=QREST_S2, W=theta[0] * KJ_S2)
        return pj.simulate(model, pj.ArimotoPlanner(k=None, tau=theta[1], tau0=theta[0]), q0, TG["NW"], **kw).q

    @pj.fast_compile_jit
    def jac(theta, frozen):
        with forward_jacobians(frozen=frozen):
            return jax.jacfwd(lambda th: (path(th),) * 2, has_aux=True)(theta)

    theta = jnp.array([0.08, 0.06, 1.3])
    (J, q), (Jf, qf) = jac(theta, jnp.asarray(False)), jac(theta, jnp.asarray(True))
    np.testing.assert_array_equal(np.asarray(q), np.asarray(qf))
    f = lambda th: np.asarray(jac(th, jnp.asarray(False))[1])  # noqa: E731  (the path, from the same compile)
    fd = np.stack([(f(theta + e) - f(theta - e)) / 2e-6 for e in 1e-6 * np.eye(3)], -1)
    np.testing.assert_allclose(np.asarray(J), fd, rtol=1e-6, atol=1e-8)
    rel = np.max(np.abs(np.asarray(Jf) - fd)) / np.max(np.abs(fd))
    assert 1e-5 < rel < 0.05, rel


def test_float32_runs_warn_once_and_x64_runs_do_not(tmp_path):
    # Without jax_enable_x64 JAX computes in float32: the first simulate/fit says so, once.
    import subprocess
    import sys

    code = ("import warnings, numpy as np, pmpjax as pj\n"
            "m = pj.Lambda0PMP(pj.Wrist(), KJ=np.eye(3), q_rest=np.zeros(3), W=0.1 * np.eye(3))\n"
            "with warnings.catch_warnings(record=True) as w:\n"
            "    warnings.simplefilter('always')\n"
            "    for _ in range(2):\n"
            "        t = pj.simulate(m, pj.ConstantPlanner(5.0), np.zeros(3), np.array([0.1, 0.0]), duration=0.02)\n"
            "print(t.q.dtype, sum('float32' in str(x.message) for x in w))\n")
    env = {**__import__("os").environ, "JAX_ENABLE_X64": "0"}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["float32", "1"], out.stderr[-2000:]
    # x64 on (as in this process, set by conftest.py, as JAX_ENABLE_X64=1 would): float64, no warning
    # (in-process, with the schedule of the tests above: no second interpreter, no new compile)
    import warnings

    assert jax.config.jax_enable_x64
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        for _ in range(2):
            t = pj.simulate(lam0(), ARIMOTO, QREST_S2, TG["E"], **KW)
    assert t.q.dtype == np.float64 and not [x for x in w if "float32" in str(x.message)]


def test_traced_positive_definiteness_check_is_lapack_free_and_equals_eigvalsh():
    # Under vmap at more than ~1 500 rows jaxlib 0.10's batched LAPACK kernels can deadlock
    # XLA:CPU (fitting.sweep's chunks hung): the traced validity check of W and KJ runs without them.
    from pmpjax._pmp.simulate import _positive_definite

    rng = np.random.default_rng(0)
    for n in range(1, 9):
        A = rng.normal(size=(400, n, n))
        S = A + np.swapaxes(A, -1, -2)
        S[:100] = A[:100] @ np.swapaxes(A[:100], -1, -2) + 1e-9 * np.eye(n)
        np.testing.assert_array_equal(np.asarray(jax.jit(_positive_definite)(S)), np.linalg.eigvalsh(S)[:, 0] > 0)
    hlo = jax.jit(_positive_definite).lower(jax.ShapeDtypeStruct((2000, 3, 3), np.float64)).as_text()
    assert "custom_call" not in hlo
