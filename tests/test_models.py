"""PMP1, PMP2 and λ0-PMP (design §3.1): fields and trajectories against independent NumPy/SciPy
(``tests/_reference.py``), gradients against central differences, planners, bad input."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.integrate
from _problems import KJ_S2, PLANAR_KJ, PLANAR_L, PLANAR_Q_REST, QREST_S2, RADIUS
from _reference import (
    arimoto,
    central_diff,
    planar_fk,
    planar_jac,
    pmp_field,
    symmetric_directions,
    wrist_fk,
    wrist_jac,
)

import pmpjax as pj

WRIST = pj.Wrist()
PLANAR = pj.PlanarArm(PLANAR_L)
TAU0 = 0.08
KINDS = ("pmp1", "pmp2", "lambda0")


def _model(kind, chain, KJ, q_rest, W):
    if kind == "pmp1":
        return pj.PMP1(chain, W=W)
    cls = pj.PMP2 if kind == "pmp2" else pj.Lambda0PMP
    return cls(chain, KJ=KJ, q_rest=q_rest, W=W)


def _wrist_fk_jac(q):
    return wrist_fk(q), wrist_jac(q)


def _planar_fk_jac(q):
    return planar_fk(q, PLANAR_L), planar_jac(q, PLANAR_L)


PROBLEMS = {
    "wrist": (WRIST, _wrist_fk_jac, KJ_S2, QREST_S2),
    "planar": (PLANAR, _planar_fk_jac, PLANAR_KJ, PLANAR_Q_REST),
}


@pytest.mark.parametrize("chain_name", list(PROBLEMS))
@pytest.mark.parametrize("kind", KINDS)
def test_fields_match_numpy_reference(kind, chain_name):
    """The three fields of Figure 1B at random postures and forces, batched, vs plain NumPy; for
    λ0-PMP also Eq 5 (``J q̇ = B⁻¹ F``: the elastic torque leaves the task untouched)."""
    chain, fk_jac, KJ, q_rest = PROBLEMS[chain_name]
    rng = np.random.default_rng(7)
    W = TAU0 * KJ + 0.01 * np.diag([1.0, 2.0, 3.0])  # W not proportional to KJ
    q = q_rest + rng.uniform(-0.4, 0.4, size=(6, 3))
    F = rng.normal(size=(6, 2))
    got = np.asarray(_model(kind, chain, KJ, q_rest, W).velocity(q, F))
    ref = np.stack([pmp_field(qi, Fi, fk_jac, KJ, q_rest, W, kind) for qi, Fi in zip(q, F)])
    np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-13)
    if kind == "lambda0":
        for qi, Fi, qd in zip(q, F, got):
            J = fk_jac(qi)[1]
            np.testing.assert_allclose(J @ qd, J @ np.linalg.solve(W, J.T) @ Fi, rtol=1e-11, atol=1e-13)


@pytest.mark.parametrize(
    "kind, chain_name",
    [("pmp1", "wrist"), ("pmp2", "wrist"), ("lambda0", "planar")],
)
def test_trajectories_match_solve_ivp(kind, chain_name):
    """RK4 (dt = 1 ms) against DOP853 at rtol 1e-12 on the NumPy field: a 0.4 s Arimoto movement
    (Eq 8). The λ0-PMP on the wrist is checked the same way in test_simulate.py."""
    chain, fk_jac, KJ, q_rest = PROBLEMS[chain_name]
    W = TAU0 * KJ
    if chain_name == "wrist":
        q0, target = q_rest + np.array([0.1, 0.05, -0.05]), RADIUS * np.array([np.cos(0.8), np.sin(0.8)])
    else:
        q0, target = q_rest, np.array([0.35, 0.3])
    k, tau = 22.5, 0.08
    tr = pj.simulate(_model(kind, chain, KJ, q_rest, W), pj.ArimotoPlanner(k=k, tau=tau), q0, target,
                     duration=0.4, dt=1e-3, saveat=pj.SaveAt(every=20))
    gain = arimoto(k, tau)
    ref = scipy.integrate.solve_ivp(
        lambda t, q: pmp_field(q, gain(t) * (target - fk_jac(q)[0]), fk_jac, KJ, q_rest, W, kind),
        (0.0, 0.4), q0, method="DOP853", rtol=1e-12, atol=1e-14, t_eval=np.asarray(tr.t),
    )
    assert ref.success
    err = np.max(np.abs(ref.y.T - np.asarray(tr.q)))
    # RK4 global error at dt = 1 ms: measured 4.6e-9 (wrist), 2.9e-11 (planar); halving dt divides
    # it by 16.4 (fourth order), so the difference is truncation, not a different field.
    assert err < 1e-8, err
    np.testing.assert_allclose(np.asarray(tr.x), np.stack([fk_jac(q)[0] for q in ref.y.T]), atol=1e-8)


@pytest.mark.parametrize("kind", KINDS)
def test_field_gradients_match_central_differences(kind):
    """∂/∂(q, F, W, KJ, q_rest) of a scalar of the field (wrist), forward-built models inside grad."""
    q0 = QREST_S2 + np.array([0.1, -0.2, 0.15])
    F0 = np.array([0.7, -0.4])
    W0 = TAU0 * KJ_S2 + 0.02 * np.eye(3)
    c = np.array([1.0, -2.0, 0.5])

    def loss(q, F, W, KJ, q_rest):
        return jnp.sum(c * jnp.sin(3.0 * _model(kind, WRIST, KJ, q_rest, W).velocity(q, F)))

    # one compilation: the differences use the value half of the same compiled value_and_grad
    vg = pj.fast_compile_jit(jax.value_and_grad(loss, argnums=(0, 1, 2, 3, 4)))
    f = lambda *a: vg(*a)[0]  # noqa: E731
    g = vg(q0, F0, W0, KJ_S2, QREST_S2)[1]
    args = [q0, F0, W0, KJ_S2, QREST_S2]
    sym = symmetric_directions(3)
    for i, x in enumerate(args):
        dirs = sym if x.shape == (3, 3) else None
        fd = central_diff(lambda v: f(*args[:i], v, *args[i + 1:]), x, dirs)
        ad = np.asarray(g[i]).reshape(-1) if dirs is None else np.einsum("ij,kij->k", np.asarray(g[i]), sym)
        np.testing.assert_allclose(ad, fd, rtol=1e-6, atol=1e-7 * np.max(np.abs(fd)) + 1e-9)


def test_planners_and_eq10_against_formulas():
    t = np.linspace(0.0, 0.5, 11)
    np.testing.assert_allclose(np.asarray(pj.ArimotoPlanner(k=22.5, tau=0.08).gain(t)), arimoto(22.5, 0.08)(t),
                               rtol=1e-14, atol=1e-15)
    assert float(pj.ConstantPlanner(k=3.0).gain(0.2)) == 3.0
    s = t[(t > 0) & (t < 0.38)] / 0.4
    xi, dxi = s**3 * (10 - 15 * s + 6 * s**2), 30 * s**2 * (1 - s) ** 2 / 0.4
    mj = np.asarray(pj.MinimumJerkPlanner(duration=0.4).gain(0.4 * s))
    np.testing.assert_allclose(mj, dxi / (1 - xi), rtol=1e-12)
    # Eq 10: k = b_max / τ0, b_max the largest eigenvalue of B(q0) = (J W⁻¹ Jᵀ)⁻¹
    J = wrist_jac(QREST_S2)
    M0 = J @ np.linalg.solve(TAU0 * KJ_S2, J.T)
    k = float(pj.eq10_gain(M0, TAU0))
    np.testing.assert_allclose(k, np.linalg.eigvalsh(np.linalg.inv(M0)).max() / TAU0, rtol=1e-12)
    np.testing.assert_allclose(np.trace(np.asarray(pj.normalize_trace(KJ_S2))), 4.0, rtol=1e-14)
    np.testing.assert_allclose(np.asarray(pj.damping_from_stiffness(KJ_S2, 0.05)), 0.05 * KJ_S2, rtol=1e-15)


# --- bad input -------------------------------------------------------------------------------


@pytest.mark.bad_input("pj.PMP1", "pj.PMP2", "pj.Lambda0PMP")
@pytest.mark.parametrize(
    "cls, kw, err, match",
    [
        ("PMP1", dict(W=np.eye(2)), ValueError, "`W`.*shape"),
        ("PMP1", dict(W=np.diag([1.0, -1.0, 1.0])), ValueError, "`W`.*positive definite"),
        ("PMP1", dict(W=np.diag([np.nan, 1.0, 1.0])), ValueError, "`W`.*NaN"),
        ("PMP2", dict(KJ=np.triu(np.ones((3, 3)))), ValueError, "`KJ`.*symmetric"),
        ("PMP2", dict(q_rest=np.zeros(2)), ValueError, "`q_rest`.*shape"),
        ("Lambda0PMP", dict(KJ=np.diag([1.0, 0.0, 1.0])), ValueError, "`KJ`.*positive definite"),
        ("Lambda0PMP", dict(q_rest=np.array([np.inf, 0, 0])), ValueError, "`q_rest`.*NaN"),
        ("Lambda0PMP", dict(chain="wrist"), TypeError, "`chain`"),
    ],
)
def test_models_bad_input(cls, kw, err, match):
    base = dict(chain=WRIST, W=TAU0 * KJ_S2) if cls == "PMP1" else dict(chain=WRIST, KJ=KJ_S2, q_rest=QREST_S2,
                                                                          W=TAU0 * KJ_S2)
    with pytest.raises(err, match=match):
        getattr(pj, cls)(**(base | kw))
    with pytest.raises(TypeError):
        pj.PMP1(WRIST, W=np.eye(3), KJ=np.eye(3))  # PMP1 has no stiffness
    with pytest.raises(ValueError, match="`q`"):
        pj.Lambda0PMP(WRIST, KJ=KJ_S2, q_rest=QREST_S2, W=KJ_S2).velocity(np.zeros(2), np.zeros(2))
    with pytest.raises(ValueError, match="`F`"):
        pj.Lambda0PMP(WRIST, KJ=KJ_S2, q_rest=QREST_S2, W=KJ_S2).velocity(np.zeros(3), np.zeros(3))


@pytest.mark.bad_input(
    "pj.MinimumJerkPlanner", "pj.ArimotoPlanner", "pj.ConstantPlanner", "pj.eq10_gain",
    "pj.damping_from_stiffness", "pj.normalize_trace",
)
def test_planners_and_parameters_bad_input():
    cases = [
        (lambda: pj.MinimumJerkPlanner(duration=0.0), "duration"),
        (lambda: pj.MinimumJerkPlanner(duration=0.4, gain_cap=-1.0), "gain_cap"),
        (lambda: pj.ArimotoPlanner(k=22.5, tau=-0.1), "tau"),
        (lambda: pj.ArimotoPlanner(k=None, tau=0.1), "tau0"),
        (lambda: pj.ArimotoPlanner(k=np.nan, tau=0.1), "k"),
        (lambda: pj.ConstantPlanner(k=0.0), "k"),
        (lambda: pj.eq10_gain(np.ones(3), 0.08), "M0"),
        (lambda: pj.eq10_gain(np.eye(2), 0.0), "tau0"),
        (lambda: pj.damping_from_stiffness(KJ_S2, -0.08), "tau0"),
        (lambda: pj.damping_from_stiffness(np.ones((3, 2)), 0.08), "KJ"),
        (lambda: pj.normalize_trace(np.ones(3)), "KJ"),
        (lambda: pj.normalize_trace(KJ_S2, trace=0.0), "trace"),
        (lambda: pj.normalize_trace(-KJ_S2), "trace"),
    ]
    for call, match in cases:
        with pytest.raises(ValueError, match=match):
            call()
