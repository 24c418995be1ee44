"""``simulate`` knows its own accuracy: the error estimate, ``INACCURATE``, adaptive steps, and
per-item ``INVALID_INPUT`` inside a caller's ``jit``.

Reference, independent of pmpjax: SciPy ``solve_ivp`` (Radau, rtol 1e-10) of the NumPy λ0-PMP
right-hand side of ``tests/_reference.py`` (written from design §3.1 and Eqs 6–10). The rule under
test: every trajectory is within 0.05° of Radau or carries a non-successful status, and ordinary
runs stay ``SUCCESSFUL`` with an estimate that bounds the true error within the documented factor.

Compile budget: wrist problems only (a few seconds each), one compilation per (batch, step, save).
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _reference import arimoto, pmp_qdot, wrist_jac
from scipy.integrate import solve_ivp

import pmpjax as pj

RADAU = dict(method="Radau", rtol=1e-10, atol=1e-12)
KJ = np.diag([0.5, 1.5, 2.0])  # Figure 3
Q_REST = np.deg2rad([5.0, 0.0, 0.0])
TAU0 = 0.08
W = TAU0 * KJ
T = 0.4
LIMIT = np.deg2rad(0.05)  # what a SUCCESSFUL trajectory may be off by
#: 8 Figure 3 targets on the π/12 circle.
_ANGLES = np.linspace(0.0, 2 * np.pi, 9)[:8]
TARGETS = (np.pi / 12) * np.stack([np.cos(_ANGLES), np.sin(_ANGLES)], -1)


def model():
    return pj.Lambda0PMP(pj.Wrist(), KJ=KJ, q_rest=Q_REST, W=W)


def radau(q0, x_d, k, tau, ts, KJ=KJ, W=W):
    """Joint angles (S, 3) of one wrist movement under Arimoto's gain (Eq 8)."""
    g = arimoto(k, tau)
    sol = solve_ivp(lambda t, q: pmp_qdot(q, t, x_d, KJ, Q_REST, W, g), (0.0, ts[-1]), q0, t_eval=ts, **RADAU)
    assert sol.success
    return sol.y.T


def true_error(tr, refs):
    return np.abs(np.asarray(tr.q) - refs).max(axis=(-1, -2))


def assert_honest(tr, refs):
    """Every trajectory within 0.05° of the reference or flagged."""
    err, status = true_error(tr, refs), np.asarray(tr.status)
    bad = (err > LIMIT) & (status == int(pj.Status.SUCCESSFUL))
    assert not bad.any(), (np.rad2deg(err), status)
    return err, status


@pytest.fixture(scope="module")
def figure3_refs():
    ts = np.linspace(0.0, T, 41)
    return ts, np.stack([radau(Q_REST, x, 22.5, 0.08, ts) for x in TARGETS])


def test_ordinary_runs_are_successful_and_the_estimate_bounds_the_error(figure3_refs):
    # RK4 at 1 and 5 ms, RODAS4 at 5 ms on the Figure 3 movements: accurate, SUCCESSFUL, and the
    # estimate between 1x and 2000x the true error (the documented factor).
    ts, refs = figure3_refs
    for solver, dt in (("rk4", 1e-3), ("rk4", 5e-3), ("rodas4", 5e-3)):
        tr = pj.simulate(model(), pj.ArimotoPlanner(k=22.5, tau=0.08), Q_REST, TARGETS, duration=T, dt=dt,
                         saveat=pj.SaveAt(ts=tuple(ts)), solver=solver)
        err = true_error(tr, refs)
        assert np.all(np.asarray(tr.status) == 0), (solver, dt, np.asarray(tr.status))
        assert np.all(err < LIMIT)
        ratio = np.asarray(tr.error_estimate) / err
        assert np.all((ratio >= 1.0) & (ratio <= 2000.0)), (solver, dt, ratio)


@pytest.mark.parametrize("dt", [0.2, 1.0])
def test_coarse_rodas4_steps_are_flagged(dt):
    # A step of 0.2 s, or one longer than the movement (final state only): hundreds of degrees off.
    x_d = TARGETS[:3]
    ref = np.stack([radau(Q_REST, x, 22.5, 0.08, np.array([0.0, T]))[-1:] for x in x_d])
    tr = pj.simulate(model(), pj.ArimotoPlanner(k=22.5, tau=0.08), Q_REST, x_d, duration=T, dt=dt,
                     saveat=pj.SaveAt(final=True), solver="rodas4")
    err, status = assert_honest(tr, ref)
    assert np.all(err > LIMIT)  # the case is real
    assert np.all(status == int(pj.Status.INACCURATE))


def test_huge_gains_are_flagged_and_adaptive_steps_resolve_them():
    ts = np.linspace(0.0, T, 21)
    x_d = TARGETS[1]
    ref = radau(Q_REST, x_d, 1e9, 0.08, ts)
    planner = pj.ArimotoPlanner(k=1e9, tau=0.08)
    tr = pj.simulate(model(), planner, Q_REST, x_d, duration=T, dt=1e-3, saveat=pj.SaveAt(ts=tuple(ts)),
                     solver="rodas4")
    err, status = assert_honest(tr, ref)
    assert err > np.deg2rad(1.0) and status == int(pj.Status.INACCURATE)
    ad = pj.simulate(model(), planner, Q_REST, x_d, duration=T, dt=None, saveat=pj.SaveAt(ts=tuple(ts)),
                     solver="rodas4")
    assert int(ad.status) == 0
    assert true_error(ad, ref) < LIMIT


def test_rk4_on_a_field_that_stiffens_along_the_path_is_flagged():
    # Eq 10's gain at q0 = 0 with dt at 0.9 of RK4's stability limit there: the start check passes,
    # but the rate grows towards the edge of the workspace and RK4 ends degrees off.
    q0 = np.zeros(3)
    J0 = wrist_jac(q0)
    lam = np.linalg.eigvalsh(J0 @ np.linalg.inv(W) @ J0.T)
    k = 1.0 / (lam[0] * TAU0)
    n = int(np.ceil(T / (0.9 * 2.5 / (k * lam[-1]))))
    ts = np.linspace(0.0, T, n + 1)
    x_d = np.array([[0.7, 0.0], [0.0, 0.7], [0.6, 0.6], [0.8, -0.4]])
    refs = np.stack([radau(q0, x, k, 0.08, ts) for x in x_d])
    tr = pj.simulate(model(), pj.ArimotoPlanner(k=k, tau=0.08), q0, x_d, duration=T, dt=T / n)
    err, status = assert_honest(tr, refs)
    assert np.all(err > np.deg2rad(5.0))  # 7–80° off
    assert np.all(status == int(pj.Status.INACCURATE))


def test_tolerances_set_the_verdict(figure3_refs):
    # The same coarse-ish run (RODAS4, 20 ms steps, true error ~0.006°) passes a loose tolerance
    # and fails a tight one; the estimate itself does not depend on the tolerance.
    ts, refs = figure3_refs
    kw = dict(duration=T, dt=0.02, saveat=pj.SaveAt(ts=tuple(ts[::2])), solver="rodas4")
    planner = pj.ArimotoPlanner(k=22.5, tau=0.08)
    loose = pj.simulate(model(), planner, Q_REST, TARGETS[:2], rtol=0.0, atol=1e-2, **kw)
    tight = pj.simulate(model(), planner, Q_REST, TARGETS[:2], rtol=0.0, atol=1e-6, **kw)
    np.testing.assert_array_equal(np.asarray(loose.error_estimate), np.asarray(tight.error_estimate))
    est = np.asarray(loose.error_estimate)
    assert np.all((est > 1e-6) & (est < 1e-2))
    assert np.all(np.asarray(loose.status) == 0)
    assert np.all(np.asarray(tight.status) == int(pj.Status.INACCURATE))


def test_adaptive_steps_match_radau_on_sequences_and_count_their_steps():
    # Two consecutive movements (out and back) with adaptive RK4 and RODAS4; and MAX_STEPS when
    # the allowance is too small.
    ts = np.linspace(0.0, T, 11)
    x_d = TARGETS[2]
    out = radau(Q_REST, x_d, 22.5, 0.08, ts)
    back = radau(out[-1], np.zeros(2), 22.5, 0.08, ts)
    planner = pj.ArimotoPlanner(k=22.5, tau=0.08)
    for solver in ("rk4", "rodas4"):
        tr = pj.simulate_sequence(model(), planner, Q_REST, np.stack([x_d, np.zeros(2)]), duration=T, dt=None,
                                  saveat=pj.SaveAt(ts=tuple(ts)), solver=solver)
        assert int(tr.status) == 0
        np.testing.assert_allclose(np.asarray(tr.q), np.stack([out, back]), atol=LIMIT, rtol=0)
        np.testing.assert_allclose(np.asarray(tr.t), ts)
    # (the RK4 sequence above with 5 steps allowed: the allowance is a traced bound, no new compile)
    from pmpjax.internal import simulate_module

    compiled = simulate_module._run_adaptive._cache_size()
    few = pj.simulate_sequence(model(), planner, Q_REST, np.stack([x_d, np.zeros(2)]), duration=T, dt=None,
                               saveat=pj.SaveAt(ts=tuple(ts)), max_steps=5)
    assert int(few.status) == int(pj.Status.MAX_STEPS)
    assert simulate_module._run_adaptive._cache_size() == compiled


def test_the_default_adaptive_allowance_is_4096_steps():
    # Documented (numerics): at most max_steps = 4096 adaptive steps per movement by default. The RK4
    # sequence above with a stiffer gain needs ≈ 0.84 k steps (stability, not accuracy; measured with
    # explicit allowances): 4195 at k = 5000 (MAX_STEPS by default), 3782 at k = 4500 (SUCCESSFUL).
    ts = np.linspace(0.0, T, 11)

    def status(k):
        return int(pj.simulate_sequence(model(), pj.ArimotoPlanner(k=k, tau=0.08), Q_REST,
                                        np.stack([TARGETS[2], np.zeros(2)]), duration=T, dt=None,
                                        saveat=pj.SaveAt(ts=tuple(ts))).status)

    assert status(5000.0) == int(pj.Status.MAX_STEPS) and status(4500.0) == 0


def test_adaptive_forward_derivatives_match_central_differences_of_radau():
    # d q(T) / d (k, τ) through the adaptive run (jax.jacfwd) against central differences of Radau.
    ts = np.array([0.0, T])
    x_d = TARGETS[3]
    p0 = np.array([22.5, 0.08])

    def final(p):
        tr = pj.simulate(model(), pj.ArimotoPlanner(k=p[0], tau=p[1]), Q_REST, x_d, duration=T, dt=None,
                         saveat=pj.SaveAt(final=True), solver="rodas4", rtol=0.0, atol=1e-6)
        return tr.q[-1]

    # (compiled whole: one program instead of the kernel's and some seventy eager operations' compiles)
    d = np.asarray(jax.jit(jax.jacfwd(final))(jnp.asarray(p0)))  # (3, 2)
    fd = np.stack([(radau(Q_REST, x_d, *(p0 + h * e), ts)[-1] - radau(Q_REST, x_d, *(p0 - h * e), ts)[-1]) / (2 * h)
                   for h, e in ((0.05, np.array([1.0, 0.0])), (1e-5, np.array([0.0, 1.0])))], -1)
    assert np.all(np.abs(d - fd) <= 1e-2 * np.abs(fd) + 1e-3 * np.abs(fd).max(axis=0)), (d, fd)


def test_bad_stiffness_inside_jit_gives_invalid_input_per_item():
    # Inside a caller's jit the eager checks cannot run: a non-symmetric, a non-positive-definite
    # and a NaN KJ each mark their own trajectory, the good one stays SUCCESSFUL; so do the two the
    # eager check refuses at its edges: asymmetric by 1e-6 of the largest entry, and singular (a zero
    # pivot: positive semi-definite only).
    good = KJ
    slight = good + np.array([[0, 2e-6, 0], [0, 0, 0], [0, 0, 0]])
    singular = np.diag([0.5, 0.0, 2.0])
    for K in (slight, singular):
        with pytest.raises(ValueError, match="symmetric|positive definite"):
            pj.Lambda0PMP(pj.Wrist(), KJ=K, q_rest=Q_REST, W=W)
    bad = np.stack([good, good + np.array([[0, 0.3, 0], [0, 0, 0], [0, 0, 0]]), np.diag([0.5, -1.5, 2.0]),
                    np.full((3, 3), np.nan), slight, singular])

    @jax.jit
    def run(K):
        m = pj.Lambda0PMP(pj.Wrist(), KJ=K, q_rest=Q_REST, W=W)
        return pj.simulate(m, pj.ArimotoPlanner(k=22.5, tau=0.08), Q_REST, TARGETS[0], duration=T, dt=0.01,
                           saveat=pj.SaveAt(final=True)).status

    status = np.asarray(run(jnp.asarray(bad)))
    assert status.tolist() == [0] + [int(pj.Status.INVALID_INPUT)] * 5
    # and a non-SPD damping W
    @jax.jit
    def run_w(Wb):
        m = pj.Lambda0PMP(pj.Wrist(), KJ=KJ, q_rest=Q_REST, W=Wb)
        return pj.simulate(m, pj.ArimotoPlanner(k=22.5, tau=0.08), Q_REST, TARGETS[0], duration=T, dt=0.01,
                           saveat=pj.SaveAt(final=True)).status

    assert np.asarray(run_w(jnp.stack([W, -W]))).tolist() == [0, int(pj.Status.INVALID_INPUT)]


@pytest.mark.bad_input("pj.simulate", "pj.simulate_sequence")
def test_bad_tolerances_and_adaptive_saves_are_refused_by_name():
    planner = pj.ArimotoPlanner(k=22.5, tau=0.08)
    kw = dict(duration=T)
    for name, bad in (("rtol", -1e-3), ("atol", np.nan), ("rtol", [1e-3, 1e-3])):
        with pytest.raises(ValueError, match=f"`{name}`"):
            pj.simulate(model(), planner, Q_REST, TARGETS[0], **{name: bad}, **kw)
    with pytest.raises(ValueError, match="`saveat.every`"):
        pj.simulate(model(), planner, Q_REST, TARGETS[0], dt=None, saveat=pj.SaveAt(every=2), **kw)
    with pytest.raises(ValueError, match="`max_steps`"):
        pj.simulate(model(), planner, Q_REST, TARGETS[0], dt=None, max_steps=0, **kw)


def test_rk4_refusal_no_longer_promises_stability_is_accuracy():
    with pytest.raises(ValueError, match="too large for RK4") as info:
        pj.simulate(model(), pj.ArimotoPlanner(k=1e6, tau=0.08), Q_REST, TARGETS[0], duration=T, dt=0.01)
    assert "any dt" not in str(info.value) and "accuracy" in str(info.value)


def _rk4_step_and_estimate(q, x_d, h, g):
    """One classical RK4 step of the reference field and its third-order companion's difference
    ``h (k4 − k5)/6`` (weights 1/6, 1/3, 1/3, 0, 1/6 with ``k5 = f(t + h, y_next)``), in NumPy."""
    f = lambda t, y: pmp_qdot(y, t, x_d, KJ, Q_REST, W, g)  # noqa: E731
    k1 = f(0.0, q)
    k2 = f(0.5 * h, q + 0.5 * h * k1)
    k3 = f(0.5 * h, q + 0.5 * h * k2)
    k4 = f(h, q + h * k3)
    y = q + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return y, np.abs(h / 6 * (k4 - f(h, y))).max()


def test_rk4_estimate_is_the_embedded_difference_on_both_kernels():
    # One 10 ms step from a posture off the rest: the step and its estimate against NumPy, on the
    # compile-light kernel (an eager call of a few movements) and on the unrolled one (a caller's
    # jit of more than 16 movements).
    h = 0.01
    q0 = Q_REST + np.deg2rad([3.0, -4.0, 2.0])
    g = arimoto(22.5, 0.02)
    x_d = np.concatenate([TARGETS] * 3)  # 24 movements
    ref = [_rk4_step_and_estimate(q0, x, h, g) for x in x_d]
    y_ref, e_ref = np.stack([r[0] for r in ref]), np.array([r[1] for r in ref])
    planner = pj.ArimotoPlanner(k=22.5, tau=0.02)
    kw = dict(duration=h, dt=h, saveat=pj.SaveAt(final=True))
    light = pj.simulate(model(), planner, q0, x_d[:3], **kw)
    heavy = jax.jit(lambda x: pj.simulate(model(), planner, q0, x, **kw))(jnp.asarray(x_d))
    for tr, n in ((light, 3), (heavy, 24)):
        np.testing.assert_allclose(np.asarray(tr.q)[:, -1], y_ref[:n], rtol=0, atol=1e-12)
        np.testing.assert_allclose(np.asarray(tr.error_estimate), e_ref[:n], rtol=1e-9, atol=1e-15)
    assert e_ref.min() > 1e-9  # the step is coarse enough for the estimate to be far from round-off


def test_the_default_tolerance_is_half_a_milliradian():
    # The documented defaults (atol = 5e-4 rad, rtol = 1e-4): a run whose estimate lies between
    # 5e-4 and 5e-3 rad (RODAS4 at 20 ms on Figure 3; truly within 0.01°) is INACCURATE by default
    # and SUCCESSFUL at atol = 5e-3: the conservative side of the bound, pinned by behaviour.
    kw = dict(duration=T, dt=0.02, saveat=pj.SaveAt(final=True), solver="rodas4")
    planner = pj.ArimotoPlanner(k=22.5, tau=0.08)
    default = pj.simulate(model(), planner, Q_REST, TARGETS[:2], **kw)
    est = np.asarray(default.error_estimate)
    scale = np.abs(np.concatenate([np.asarray(default.q)[:, -1], np.broadcast_to(Q_REST, (2, 3))], 1)).max(1)
    assert np.all((est > 5e-4 + 1e-4 * scale) & (est < 5e-3))
    assert np.all(np.asarray(default.status) == int(pj.Status.INACCURATE))
    loose = pj.simulate(model(), planner, Q_REST, TARGETS[:2], atol=5e-3, **kw)
    assert np.all(np.asarray(loose.status) == 0)


def test_the_default_relative_tolerance_scales_with_the_largest_angle():
    # The documented verdict with the default tolerances: INACCURATE exactly where the estimate
    # exceeds 5e-4 + 1e-4·max|q| [rad]. Small RODAS4 movements (20 ms steps) around a posture 0.9 rad
    # from zero put estimates between that bound and the one of a 10× larger rtol.
    q_rest = np.array([0.0, 0.9, 0.2])
    m = pj.Lambda0PMP(pj.Wrist(), KJ=KJ, q_rest=q_rest, W=W)
    x0 = np.asarray(pj.Wrist().fk(q_rest))
    targets = x0 + np.array([[0.04, 0.0], [0.08, 0.0]])
    kw = dict(duration=T, dt=0.02, saveat=pj.SaveAt(final=True), solver="rodas4")
    tr = pj.simulate(m, pj.ArimotoPlanner(k=22.5, tau=0.08), q_rest, targets, **kw)
    est = np.asarray(tr.error_estimate)
    scale = np.maximum(np.abs(np.asarray(tr.q)[:, -1]).max(1), np.abs(q_rest).max())
    bound = 5e-4 + 1e-4 * scale
    assert np.any((est > bound) & (est < 5e-4 + 1e-3 * scale)), (est, scale)
    np.testing.assert_array_equal(np.asarray(tr.status), np.where(est > bound, int(pj.Status.INACCURATE), 0))
