"""Equilibrium postures (design §3.1): SciPy SLSQP, λ0-PMP steady state, implicit gradients."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _problems import KJ_S1 as KJ1
from _problems import PLANAR_KJ, PLANAR_L, PLANAR_Q_REST
from _problems import QREST_S1 as QR1
from _reference import central_diff, compiled_names, symmetric_directions
from scipy.optimize import minimize

import pmpjax as pj

TARGETS = np.array([[0.0, 0.0], [0.25, -0.1], [-0.3, 0.3], [0.1, 0.33]])


def _fk_np(chain, q):
    """Independent NumPy forward kinematics (complex-safe): Eq 6 from rotation matrices, or the
    planar arm's cumulative angles."""
    if isinstance(chain, pj.PlanarArm):
        L, phi = np.asarray(chain.lengths), np.cumsum(q)
        return np.array([np.sum(L * np.cos(phi)), np.sum(L * np.sin(phi))])
    a, b, c = q
    rx = np.array([[1, 0, 0], [0, np.cos(a), np.sin(a)], [0, -np.sin(a), np.cos(a)]])  # Rx(−a)
    rz = np.array([[np.cos(b), -np.sin(b), 0], [np.sin(b), np.cos(b), 0], [0, 0, 1]])
    ry = np.array([[np.cos(c), 0, np.sin(c)], [0, 1, 0], [-np.sin(c), 0, np.cos(c)]])
    u = (rx @ rz @ ry)[:, 0]
    return float(chain.d) * np.array([-u[1], u[2]])


def _slsqp(chain, K, qr, x, q0):
    fk = lambda q: _fk_np(chain, q)  # noqa: E731
    # complex-step Jacobian: exact to rounding, independent of pmpjax's analytic one
    jac = lambda q: np.stack([_fk_np(chain, q + 1e-30j * e).imag / 1e-30 for e in np.eye(len(q))], -1)  # noqa: E731
    cons = {"type": "eq", "fun": lambda q: fk(q) - x, "jac": jac}
    r = minimize(
        lambda q: 0.5 * (q - qr) @ K @ (q - qr),
        q0,
        jac=lambda q: K @ (q - qr),
        constraints=[cons],
        method="SLSQP",
        options={"ftol": 1e-16, "maxiter": 500},
    )
    assert r.success, r.message
    return r.x


@pytest.fixture(scope="module")
def wrist():
    return pj.Wrist()


def test_wrist_matches_slsqp(wrist):
    eq = pj.equilibrium_posture(wrist, KJ1, QR1, TARGETS)
    assert eq.q.shape == (4, 3) and bool(np.all(eq.converged))
    assert np.all(np.asarray(eq.status) == pj.Status.SUCCESSFUL) and np.all(np.asarray(eq.steps) < 10)
    assert np.all(np.asarray(eq.kkt_residual) < 1e-12)
    for x, q in zip(TARGETS, np.asarray(eq.q)):
        ref = _slsqp(wrist, KJ1, QR1, x, QR1)
        np.testing.assert_allclose(q, ref, atol=1e-8, rtol=0)
    # the multiplier is the task force λ0 of Eq 4 with W = KJ (B J A τ_el)
    J = np.asarray(wrist.jacobian(eq.q))
    lam0 = np.asarray(pj.lambda0(J, np.broadcast_to(KJ1, (4, 3, 3)), (KJ1 @ (np.asarray(eq.q) - QR1).T).T))
    np.testing.assert_allclose(np.asarray(eq.lam), lam0, atol=1e-12)


def test_planar_arm_matches_slsqp():
    arm = pj.PlanarArm(PLANAR_L)
    K, qr = PLANAR_KJ, PLANAR_Q_REST
    xs = np.array([[0.35, 0.3], [0.1, 0.45]])
    q = np.asarray(pj.equilibrium_posture(arm, K, qr, xs).q)
    for x, qi in zip(xs, q):
        np.testing.assert_allclose(qi, _slsqp(arm, K, qr, x, qr), atol=1e-8, rtol=0)


def test_matches_lambda0_pmp_steady_state(wrist):
    x = TARGETS[1:3]
    model = pj.Lambda0PMP(wrist, KJ=KJ1, q_rest=QR1, W=pj.damping_from_stiffness(KJ1, 0.08))
    traj = pj.simulate(
        model,
        pj.ConstantPlanner(k=20.0),
        np.broadcast_to(QR1, (2, 3)),
        x,
        duration=4.0,
        dt=4e-3,
        saveat=pj.SaveAt(final=True),
    )
    q_sim = np.asarray(traj.q[:, -1])
    q_eq = np.asarray(pj.equilibrium_posture(wrist, KJ1, QR1, x).q)
    np.testing.assert_allclose(q_sim, q_eq, atol=1e-7)


def test_batched_over_subjects_and_targets(wrist):
    KJs = np.stack([KJ1, np.diag([0.5, 1.5, 2.0])])
    qrs = np.stack([QR1, np.deg2rad([5.0, 0.0, 0.0])])
    q = np.asarray(pj.equilibrium_posture(wrist, KJs[:, None], qrs[:, None], TARGETS[None]).q)
    assert q.shape == (2, 4, 3)
    for s in range(2):
        for t in range(4):
            np.testing.assert_allclose(q[s, t], _slsqp(wrist, KJs[s], qrs[s], TARGETS[t], qrs[s]), atol=1e-8)


def _loss(K, qr, x, chain):
    q = pj.equilibrium_posture(chain, K, qr, x).q
    return jnp.sum(jnp.sin(q) @ jnp.arange(1.0, 4.0))


def _grads(mode, wrist, cache={}):
    """d_loss/d(KJ, q_rest, x) at the two targets, once per mode and module."""
    if mode not in cache:
        diff = jax.grad if mode == "rev" else jax.jacfwd
        args = (jnp.asarray(KJ1), jnp.asarray(QR1), jnp.asarray(TARGETS[1:3]))
        # (compiled whole: the traced solver's path either way, one program instead of the eager
        # transformation's compile of every operation)
        cache[mode] = jax.jit(lambda *a: diff(_loss, argnums=(0, 1, 2))(*a, wrist))(*args)
    return cache[mode]


@pytest.mark.parametrize("mode", ["rev", "fwd"])
def test_gradients_match_central_differences(wrist, mode):
    x = TARGETS[1:3]
    gK, gq, gx = _grads(mode, wrist)
    f = lambda K, qr, xx: float(_loss(K, qr, xx, wrist))  # noqa: E731
    # KJ: symmetric perturbation directions (the solver validates symmetry)
    sym = symmetric_directions(3)
    fdK = central_diff(lambda K: f(K, QR1, x), KJ1, sym)
    np.testing.assert_allclose([np.sum(np.asarray(gK) * E) for E in sym], fdK, rtol=1e-6, atol=1e-8)
    np.testing.assert_allclose(np.asarray(gq), central_diff(lambda q: f(KJ1, q, x), QR1), rtol=1e-6, atol=1e-8)
    np.testing.assert_allclose(
        np.asarray(gx).reshape(-1), central_diff(lambda xx: f(KJ1, QR1, xx), x), rtol=1e-6, atol=1e-8
    )


def test_vmap_of_grad_equals_grad_of_sum(wrist):
    x = jnp.asarray(TARGETS[1:3])
    g_each = jax.jit(
        jax.vmap(lambda xx: jax.grad(_loss, argnums=1)(jnp.asarray(KJ1), jnp.asarray(QR1), xx, wrist))
    )(x)
    g_sum = _grads("rev", wrist)[1]  # the gradient of the sum over both targets
    np.testing.assert_allclose(np.asarray(g_each).sum(0), np.asarray(g_sum), atol=1e-12)


def test_not_converged_is_flagged(wrist):
    eq = pj.equilibrium_posture(wrist, KJ1, QR1, TARGETS[2], max_steps=1)
    assert not bool(eq.converged) and int(eq.status) == pj.Status.MAX_STEPS and int(eq.steps) == 1


def test_maximum_is_flagged_not_minimum():
    """Task ``q1² + q2² = 1`` (a circle), energy ``½ qᵀ diag(1, 2) q``: its minima on the circle are
    ``(±1, 0)``, its maxima ``(0, ±1)``. Newton started at a maximum stays there (a KKT point) and the
    second-order test flags it; started nearby elsewhere it finds the minimum."""
    circle = pj.FunctionChain(lambda q: jnp.stack([q[0] ** 2 + q[1] ** 2]), n=2, m=1)
    K = np.diag([1.0, 2.0])
    eq = pj.equilibrium_posture(circle, K, np.zeros(2), np.ones(1), q_init=np.array([0.0, 1.0]))
    np.testing.assert_allclose(np.asarray(eq.q), [0.0, 1.0], atol=1e-14)
    assert int(eq.status) == pj.Status.NOT_MINIMUM and not bool(eq.converged)
    eq = pj.equilibrium_posture(circle, K, np.zeros(2), np.ones(1), q_init=np.array([0.6, 0.5]))
    np.testing.assert_allclose(np.asarray(eq.q), [1.0, 0.0], atol=1e-12)
    assert bool(eq.converged)


def test_batch_equals_singles(wrist):
    """One broadcast call (2 subjects × 3 targets) equals six single calls."""
    KJs = np.stack([KJ1, np.diag([0.5, 1.5, 2.0])])
    qrs = np.stack([QR1, np.deg2rad([5.0, 0.0, 0.0])])
    batch = pj.equilibrium_posture(wrist, KJs[:, None], qrs[:, None], TARGETS[None, 1:])
    for s in range(2):
        for t in range(3):
            one = pj.equilibrium_posture(wrist, KJs[s], qrs[s], TARGETS[t + 1])
            for field in ("q", "lam", "status", "kkt_residual", "steps"):
                np.testing.assert_allclose(np.asarray(getattr(batch, field))[s, t], np.asarray(getattr(one, field)),
                                           rtol=0, atol=1e-15)


def test_eager_batch_sizes_share_the_kernel(wrist):
    """Eager calls pad to 64 rows or solve chunks of 1024: every size reuses one of two compiled
    kernels and every row is still its own solution. Which bug: per-size padding recompiles the
    solver (seconds) for each new batch size; a wrong chunk offset or unpadding mixes up rows."""
    targets = np.random.default_rng(7).uniform(-0.3, 0.3, (1100, 2))
    pj.equilibrium_posture(wrist, KJ1, QR1, targets[:3])  # the 64-row kernel
    with compiled_names() as names:
        small = pj.equilibrium_posture(wrist, KJ1, QR1, targets[:50])
    assert names == []
    big = pj.equilibrium_posture(wrist, KJ1, QR1, targets)  # two chunks of the 1024-row kernel
    with compiled_names() as names:
        pj.equilibrium_posture(wrist, KJ1, QR1, targets[:700])
    assert names == []
    assert big.q.shape == (1100, 3) and bool(np.all(big.converged))
    q = np.asarray(big.q)
    np.testing.assert_allclose([_fk_np(wrist, qi) for qi in q], targets, atol=1e-12)  # on its own target
    np.testing.assert_allclose(q[:50], np.asarray(small.q), rtol=0, atol=1e-15)
    for i in (1023, 1024, 1099):  # across the chunk boundary and in the padded last chunk
        np.testing.assert_allclose(q[i], np.asarray(pj.equilibrium_posture(wrist, KJ1, QR1, targets[i]).q),
                                   rtol=0, atol=1e-15)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(KJ=np.diag([1.0, -1.0, 1.0])), "KJ.*positive definite"),
        (dict(KJ=np.eye(2)), "KJ.*shape"),
        (dict(KJ=KJ1 + np.triu(np.ones((3, 3)), 1)), "KJ.*symmetric"),
        (dict(q_rest=np.array([np.nan, 0.0, 0.0])), "q_rest.*NaN"),
        (dict(target=np.array([0.99, 0.0])), "target.*reachable"),
        (dict(target=np.zeros(3)), "target.*shape"),
        (dict(q_init=np.zeros(2)), "q_init.*shape"),
        (dict(q_rest=np.zeros((2, 3)), target=np.zeros((3, 2))), "broadcast"),
        (dict(tol=0.0), "tol"),
        (dict(max_steps=0), "max_steps"),
    ],
)
@pytest.mark.bad_input("pj.equilibrium_posture")
def test_bad_input(wrist, kwargs, match):
    args = dict(KJ=KJ1, q_rest=QR1, target=TARGETS[0])
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        pj.equilibrium_posture(wrist, **args)



def test_max_iter_is_the_old_name_of_max_steps(wrist):
    with pytest.warns(DeprecationWarning, match="max_iter"), pytest.raises(ValueError, match="max_steps"):
        pj.equilibrium_posture(wrist, KJ1, QR1, TARGETS[0], max_iter=0)

def test_non_chain_rejected():
    with pytest.raises(TypeError, match="chain"):
        pj.equilibrium_posture(object(), KJ1, QR1, TARGETS[0])
