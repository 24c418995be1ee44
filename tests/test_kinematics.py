import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _problems import PLANAR_KJ, PLANAR_L, PLANAR_Q_REST, PLANAR_TARGETS
from _reference import central_diff, planar_fk, planar_jac, slsqp_equilibrium, wrist_fk, wrist_jac

import pmpjax as pj
from pmpjax._base.trig import sincos


def _fd_jac(f, q):
    return np.moveaxis(central_diff(f, q), 0, -1)


def test_sincos_matches_numpy():
    x = np.concatenate([np.linspace(-50, 50, 200001), [0.0, np.pi / 2, -np.pi, 1e4]])
    s, c = sincos(jnp.asarray(x))
    assert np.max(np.abs(np.asarray(s) - np.sin(x))) < 5e-16 * max(1, 1)
    assert np.max(np.abs(np.asarray(c) - np.cos(x))) < 5e-16
    g = jax.vmap(jax.grad(lambda v: sincos(v)[0]))(jnp.asarray(x[:1000]))
    np.testing.assert_allclose(g, np.cos(x[:1000]), atol=5e-16)
    # the tangent rule: d cos = −sin dx, and second derivatives through it (d² sin = −sin)
    gc = jax.vmap(jax.grad(lambda v: sincos(v)[1]))(jnp.asarray(x[:1000]))
    np.testing.assert_allclose(gc, -np.sin(x[:1000]), atol=5e-16)
    g2 = jax.vmap(jax.grad(jax.grad(lambda v: sincos(v)[0])))(jnp.asarray(x[:1000]))
    np.testing.assert_allclose(g2, -np.sin(x[:1000]), atol=5e-16)
    assert np.isnan(np.asarray(sincos(jnp.array([np.nan, np.inf]))[0])).all()


def test_wrist_fk_and_jacobian_match_rotation_products(rng):
    chain = pj.Wrist(d=1.3)
    qs = rng.uniform(-1.2, 1.2, size=(20, 3))
    x = np.asarray(chain.fk(qs))
    J = np.asarray(chain.jacobian(qs))
    for i, q in enumerate(qs):
        np.testing.assert_allclose(x[i], wrist_fk(q, 1.3), atol=1e-14)
        np.testing.assert_allclose(J[i], wrist_jac(q, 1.3), atol=1e-14)
        np.testing.assert_allclose(J[i], _fd_jac(lambda v: wrist_fk(v, 1.3), q), atol=1e-7)
    R = np.asarray(chain.rotation(qs[0]))
    np.testing.assert_allclose(1.3 * np.array([-R[1, 0], R[2, 0]]), x[0], atol=1e-14)


def test_wrist_screen_directions():
    chain = pj.Wrist()
    # Positive FE rotates the pointer about +z: towards -x1 (West); positive RUD: down (-x2).
    assert chain.fk(np.array([0.0, 0.1, 0.0]))[0] < 0
    assert chain.fk(np.array([0.0, 0.0, 0.1]))[1] < 0
    np.testing.assert_allclose(chain.fk(np.array([0.7, 0.0, 0.0])), 0.0, atol=1e-16)


def test_planar_arm_against_loop(rng):
    L = np.array([0.3, 0.25, 0.2])
    chain = pj.PlanarArm(L)

    def fk(q):
        phi = np.cumsum(q)
        return np.array([np.sum(L * np.cos(phi)), np.sum(L * np.sin(phi))])

    qs = rng.uniform(-2, 2, size=(10, 3))
    for q, x, J in zip(qs, np.asarray(chain.fk(qs)), np.asarray(chain.jacobian(qs))):
        np.testing.assert_allclose(x, fk(q), atol=1e-15)
        np.testing.assert_allclose(J, planar_jac(q, L), atol=1e-15)
        np.testing.assert_allclose(J, _fd_jac(fk, q), atol=1e-7)


def test_function_chain_matches_analytic(rng):
    wrist = pj.Wrist()
    user = pj.FunctionChain(lambda q: wrist.fk(q), n=3, m=2)
    qs = rng.uniform(-1, 1, size=(4, 2, 3))
    np.testing.assert_allclose(user.fk(qs), wrist.fk(qs), atol=1e-15)
    np.testing.assert_allclose(user.jacobian(qs), wrist.jacobian(qs), atol=1e-14)
    with pytest.raises(ValueError, match="fn"):
        pj.FunctionChain(lambda q: q, n=3, m=2)


def test_gimbal_lock_is_detectable():
    chain = pj.Wrist()
    w0 = pj.manipulability(chain, np.zeros(3))
    w_lock = pj.manipulability(chain, np.array([0.2, np.pi / 2, 0.3]))
    assert abs(float(w0) - 1.0) < 1e-12
    assert float(w_lock) < 1e-12
    np.testing.assert_array_equal(chain.reachable(np.array([[0.5, 0.5], [0.99, 0.0]])), [True, False])


class MinimalArm(pj.Chain):
    """A user chain written to the contract: n, m and a per-posture ``fk`` only (a plain class)."""

    n, m = 3, 2

    def __init__(self, lengths):
        self.lengths = tuple(float(v) for v in lengths)

    def fk(self, q):
        phi = jnp.cumsum(q)
        L = jnp.asarray(self.lengths)
        return jnp.stack([jnp.sum(L * jnp.cos(phi)), jnp.sum(L * jnp.sin(phi))])


def test_user_chain_with_fk_only(rng):
    """Batched fk/jacobian, the λ0-PMP equilibrium and a simulated movement of a chain that implements
    nothing but ``fk(q)`` for one posture, against NumPy and SciPy SLSQP."""
    arm = MinimalArm(PLANAR_L)
    qs = rng.uniform(-1, 1, size=(2, 4, 3))
    x, J = np.asarray(arm.fk(qs)), np.asarray(arm.jacobian(qs))
    assert x.shape == (2, 4, 2) and J.shape == (2, 4, 2, 3)
    np.testing.assert_allclose(x[1, 2], planar_fk(qs[1, 2], PLANAR_L), atol=1e-15)
    np.testing.assert_allclose(J[0, 3], _fd_jac(lambda q: planar_fk(q, PLANAR_L), qs[0, 3]), atol=1e-7)
    eq = pj.equilibrium_posture(arm, PLANAR_KJ, PLANAR_Q_REST, PLANAR_TARGETS)
    assert np.all(np.asarray(eq.converged))
    for xt, q in zip(PLANAR_TARGETS, np.asarray(eq.q)):
        ref = slsqp_equilibrium(lambda v: planar_fk(v, PLANAR_L), None, PLANAR_KJ, PLANAR_Q_REST, xt)
        np.testing.assert_allclose(q, ref, atol=1e-8)
    model = pj.Lambda0PMP(arm, KJ=PLANAR_KJ, q_rest=PLANAR_Q_REST, W=0.05 * PLANAR_KJ)
    tr = pj.simulate(model, pj.ConstantPlanner(k=40.0), PLANAR_Q_REST, PLANAR_TARGETS[0], duration=1.0, dt=2e-3,
                     saveat=pj.SaveAt(final=True))
    np.testing.assert_allclose(np.asarray(tr.q[-1]), np.asarray(eq.q[0]), atol=1e-6)
    np.testing.assert_allclose(float(pj.manipulability(arm, qs[0, 0])),
                               np.sqrt(np.linalg.det(J[0, 0] @ J[0, 0].T)), rtol=1e-12)

    class NoKinematics(pj.Chain):
        n, m = 2, 1

    with pytest.raises(NotImplementedError, match="fk"):
        NoKinematics().fk(np.zeros(2))


@pytest.mark.bad_input("pj.Wrist", "pj.PlanarArm", "pj.FunctionChain", "pj.manipulability")
def test_chain_bad_input():
    with pytest.raises(ValueError, match="lengths"):
        pj.PlanarArm([0.3, -0.2])
    with pytest.raises(ValueError, match="lengths"):
        pj.PlanarArm([0.3])
    with pytest.raises(ValueError, match="d"):
        pj.Wrist(d=0.0)
    with pytest.raises(ValueError, match="`q`"):
        pj.Wrist().fk(np.zeros(2))
    with pytest.raises(ValueError, match="`q`"):
        pj.Wrist().fk(np.array([np.nan, 0, 0]))
    with pytest.raises(ValueError, match="`q`"):
        pj.PlanarArm([0.3, 0.2]).jacobian(np.zeros(3))
    with pytest.raises(TypeError, match="fn"):
        pj.FunctionChain(3.0, n=3, m=2)
    with pytest.raises(ValueError, match="fn"):
        pj.FunctionChain(lambda q: q, n=3, m=2)
    with pytest.raises(TypeError, match="chain"):
        pj.manipulability("wrist", np.zeros(3))
    with pytest.raises(ValueError, match="`q`"):
        pj.manipulability(pj.Wrist(), np.zeros(4))
