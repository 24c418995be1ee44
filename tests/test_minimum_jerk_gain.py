"""The time-base generator's gain ``γ = ξ̇/(1 − ξ)`` (``MinimumJerkPlanner``) and the derivatives of
simulations with respect to its ``duration``, ``gain_cap`` and ``delay``.

References, independent of pmpjax: the definition ``ξ̇/(1 − ξ)`` of ``ξ(s) = 10 s³ − 15 s⁴ + 6 s⁵``
in exact rational arithmetic (``fractions.Fraction``; its derivatives by exact central differences
of step 1e-30), and SciPy ``solve_ivp`` (Radau, rtol 1e-10) of the NumPy λ0-PMP field of
tests/_reference.py under ``F = γ B (x_d − x)``, differentiated by central differences.

The old gain clamped ``1 − ξ`` at 1e-12 (computed as 1 minus the rounded ``ξ``): ``γ`` was off by
more than 1e-9 relative from ``1 − s ≈ 2e-3`` on and collapsed from the cap towards 0 in the
last ~1e-6 of the movement, where a stage of the step that ends at ``t = duration`` lands when
``duration`` is on the step grid. Compile budget: one ``jacfwd`` of a wrist simulation per solver.
"""

from fractions import Fraction

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _reference import minjerk_gain, pmp_field, wrist_fk, wrist_jac
from scipy.integrate import solve_ivp

import pmpjax as pj

TINY = Fraction(1, 10**30)


def gamma_exact(t, T):
    """``ξ̇/(1 − ξ)`` at time ``t`` of a move of duration ``T`` (Fractions), from the definition."""
    s = t / T
    xi = 10 * s**3 - 15 * s**4 + 6 * s**5
    dxi = (30 * s**2 - 60 * s**3 + 30 * s**4) / T
    return dxi / (1 - xi)


def gamma_at(t, T):
    """The exact ratio at the floats ``t``, ``T`` (a Python float)."""
    return float(gamma_exact(Fraction(float(t)), Fraction(float(T))))


def rel_tolerance(s, rtol=1e-12):
    """``rtol``, plus 1 ulp of the phase ``s = t/T`` (XLA's division on CPU is not always correctly
    rounded) times the ratio's condition number ``≈ 1/(1 − s)``."""
    return rtol + 2.3e-16 / (1.0 - s)


# phases in (0, 1), crowded towards 1 where 1 − ξ cancels
PHASES = np.concatenate([np.linspace(0.01, 0.99, 23), 1 - np.geomspace(1e-2, 1e-13, 12), [1 - 1e-9, 1 - 1e-7]])


@pytest.mark.parametrize("T", [0.5, 2.0, 0.4, 2.5])
def test_gain_is_the_exact_ratio_up_to_the_cap(T):
    t = PHASES * T
    ref = np.array([gamma_at(ti, T) for ti in t])
    # T a power of two: t/T is exact, the ratio to 1e-12 relative; otherwise within what 1 ulp of
    # the phase moves it (the ratio's condition number is 1/(1 − s): 1e-7 relative at 1 − 1e-9)
    rtol = np.full(PHASES.shape, 1e-12) if T in (0.5, 2.0) else rel_tolerance(PHASES)
    huge = pj.MinimumJerkPlanner(duration=T, gain_cap=1e300)
    g = np.asarray(huge.gain(jnp.asarray(t)))
    assert np.all(np.abs(g - ref) <= rtol * ref), np.abs(g / ref - 1).max()
    for ti, r, tol in zip(t[::3], ref[::3], rtol[::3]):  # one at a time (scalar t) as well
        assert abs(float(huge.gain(float(ti))) - r) <= tol * r
    # capped at 200 /s: the ratio below the cap, the cap itself above it (near T), at and after T
    cap = 200.0
    capped = pj.MinimumJerkPlanner(duration=T, gain_cap=cap)
    g = np.asarray(capped.gain(jnp.asarray(t)))
    assert np.sum(ref > cap) >= 12 and np.all(g[ref > cap] == cap)
    assert np.all(np.abs(g - np.minimum(ref, cap)) <= rtol * np.minimum(ref, cap))
    after = np.asarray(capped.gain(jnp.asarray([T, T * (1 + 1e-15), 1.5 * T, 10 * T])))
    assert np.all(after == cap)
    assert float(capped.gain(0.0)) == 0.0
    # the simulations' reference below (tests/_reference.py) is the same function
    np.testing.assert_allclose([minjerk_gain(ti, T, cap) for ti in t], np.minimum(ref, cap), rtol=1e-12)


def test_the_default_cap_is_200_per_second():
    # The signature's default gain_cap = 200 /s: the exact ratio up to where it reaches 200 (found
    # here by bisection on the Fractions), 200 from there on and after the end.
    T = 0.5
    lo, hi = Fraction(1, 2), Fraction(1)
    for _ in range(40):
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if gamma_exact(mid * T, Fraction(T)) < 200 else (lo, mid)
    s_cap = float(lo)
    assert abs((1 - s_cap) - 3 / (T * 200)) < 0.1 * 3 / (T * 200)  # documented: 1 − s ≈ 3/(T·cap)
    s = np.array([0.3, s_cap - 1e-4, s_cap + 1e-4, 0.999, 1.0, 1.5])
    g = np.asarray(pj.MinimumJerkPlanner(duration=T).gain(jnp.asarray(s * T)))
    np.testing.assert_allclose(g[:2], [gamma_at(v * T, T) for v in s[:2]], rtol=1e-12)
    assert g[1] < 200.0 and np.all(g[2:] == 200.0), g


def test_gain_is_elementwise_over_batches():
    T = np.array([0.3, 0.4, 1.0, 2.0])
    cap = np.array([15.0, 200.0, 1e300, 50.0])
    t = np.array([0.25, 0.4 * (1 - 1e-7), 0.999, 1.9])
    g = np.asarray(pj.MinimumJerkPlanner(duration=T, gain_cap=cap).gain(jnp.asarray(t)))
    ref = [min(gamma_at(ti, Ti), ci) for ti, Ti, ci in zip(t, T, cap)]
    assert g[0] == 15.0 and g[1] == 200.0 and g[2] < 1e300  # capped, capped, not capped
    np.testing.assert_allclose(g, ref, rtol=1e-12, atol=0)
    # one time for every trajectory
    g1 = np.asarray(pj.MinimumJerkPlanner(duration=T, gain_cap=cap).gain(0.29))
    np.testing.assert_allclose(g1, [min(float(gamma_exact(Fraction(0.29), Fraction(Ti))), ci)
                                    for Ti, ci in zip(T, cap)], rtol=1e-12)


def test_delay_shifts_the_move_and_holds_the_hand_before_it():
    # delay > 0: the move began before t = 0; delay < 0: gain 0 until t = −delay, then the move
    T, cap = 0.4, 200.0
    t = np.array([0.0, 0.03, 0.1, 0.25, 0.39, 0.5])
    for delay in (0.06, -0.06):
        g = np.asarray(pj.MinimumJerkPlanner(duration=T, gain_cap=cap, delay=delay).gain(jnp.asarray(t)))
        ref = [0.0 if ti + delay <= 0 else cap if ti + delay >= T else min(gamma_at(ti + delay, T), cap) for ti in t]
        np.testing.assert_allclose(g, ref, rtol=1e-12, atol=0)
    assert np.sum(np.asarray(ref) == 0.0) == 2  # (delay −0.06: held at t = 0 and 0.03)
    with pytest.raises(ValueError, match="delay"):
        pj.MinimumJerkPlanner(duration=T, delay=float("nan"))


def test_gain_derivatives_are_exact_and_finite_at_and_after_the_end():
    """∂γ/∂t, ∂γ/∂T, ∂γ/∂cap by reverse and forward mode against exact central differences of
    the definition (uncapped), 0, 0, 1 where capped; finite (no NaN/inf from the untaken branch)
    at ``s = 1``, just below it and past it."""
    T, cap = 0.4, 200.0

    def g(t, T, cap):
        return pj.MinimumJerkPlanner(duration=T, gain_cap=cap).gain(t)

    rev = jax.jit(jax.grad(g, argnums=(0, 1, 2)))
    fwd = jax.jit(jax.jacfwd(g, argnums=(0, 1, 2)))
    for s in (0.05, 0.3, 0.5, 0.8, 0.9, 0.95):  # uncapped: γ(0.95) = 146 /s
        t = s * T
        tf, Tf = Fraction(t), Fraction(T)
        assert gamma_exact(tf, Tf) < cap
        d_t = (gamma_exact(tf + TINY, Tf) - gamma_exact(tf - TINY, Tf)) / (2 * TINY)
        d_T = (gamma_exact(tf, Tf + TINY) - gamma_exact(tf, Tf - TINY)) / (2 * TINY)
        for got in (rev(t, T, cap), fwd(t, T, cap)):
            np.testing.assert_allclose(np.asarray(got), [float(d_t), float(d_T), 0.0], rtol=1e-11, atol=0)
    for s in (0.99, 1 - 1e-9, 1 - 2**-52, 1.0, 1 + 1e-12, 1.5):  # capped, at the end, after it
        for got in (rev(s * T, T, cap), fwd(s * T, T, cap)):
            assert np.all(np.isfinite(np.asarray(got))), (s, got)
            np.testing.assert_array_equal(np.asarray(got), [0.0, 0.0, 1.0])
    # the same with an uncapped (huge) cap: the branch not taken is exactly where the ratio is infinite
    for s in (1.0, 1.5):
        got = np.asarray(rev(s * T, T, 1e300))
        assert np.all(np.isfinite(got)) and got[2] == 1.0


# --- derivatives of simulations ----------------------------------------------------------------

KJ = np.array([[1.2, 0.3, 0.0], [0.3, 0.4, 0.1], [0.0, 0.1, 2.4]])
Q_REST = np.deg2rad([5.0, -3.0, 2.0])
W = 0.08 * KJ
Q0 = np.zeros(3)
X_D = np.array([0.15, 0.2])
WEIGHTS = np.array([1.0, -2.0, 0.5])
T, CAP = 0.4, 40.0  # the cap is reached at s ≈ 0.83: the last 70 ms approach the target at 40 /s
DELAY = -0.05  # the move begins at t = 0.05 s and ends at T − DELAY = 0.45 s
RADAU = dict(method="Radau", rtol=1e-10, atol=1e-12)


SAMPLES = (0.1, 0.2, 0.3, 0.4, T - DELAY, 0.5)  # (T − DELAY: the end of the move)


def radau_scalars(p):
    """``WEIGHTS · q(t)`` at ``SAMPLES`` of the λ0-PMP under ``F = γ(t + delay) B (x_d − x)`` by Radau,
    ``p = (T, cap, delay)``."""
    A = np.linalg.inv(W)

    def rhs(t, q):
        x, J = wrist_fk(q), wrist_jac(q)
        F = minjerk_gain(t + p[2], p[0], p[1]) * np.linalg.solve(J @ A @ J.T, X_D - x)  # γ B (x_d − x)
        return pmp_field(q, F, lambda _: (x, J), KJ, Q_REST, W, "lambda0")

    sol = solve_ivp(rhs, (0.0, SAMPLES[-1]), Q0, t_eval=SAMPLES, **RADAU)
    assert sol.success
    return WEIGHTS @ sol.y


@pytest.fixture(scope="module")
def radau():
    """Central differences (steps 1e-5 relative) of :func:`radau_scalars`:
    ``{t: (∂/∂(T, cap, delay), value)}``."""
    p = np.array([T, CAP, DELAY])
    cols, mid = [], 0.0
    for i in range(3):
        e = np.zeros(3)
        e[i] = 1e-5 * p[i]
        hi, lo = radau_scalars(p + e), radau_scalars(p - e)
        cols.append((hi - lo) / (2 * e[i]))
        mid = (hi + lo) / 2  # the value to O(1e-10)
    D = np.stack(cols, -1)
    return {t: (D[k], mid[k]) for k, t in enumerate(SAMPLES)}


def simulation(duration, dt, saveat, solver):
    """``p = (T, cap, delay) -> (∂/∂p, value)`` of ``WEIGHTS · q`` at the saved times, one compilation."""
    model = pj.Lambda0PMP(pj.Wrist(), KJ=KJ, q_rest=Q_REST, W=W)

    def scalars(p):
        planner = pj.MinimumJerkPlanner(duration=p[0], gain_cap=p[1], delay=p[2])
        tr = pj.simulate(model, planner, Q0, X_D, duration=duration, dt=dt, saveat=saveat, solver=solver)
        v = tr.q @ jnp.asarray(WEIGHTS)
        return v, v

    return jax.jit(jax.jacfwd(scalars, has_aux=True))


@pytest.mark.parametrize(
    "duration, n_steps, saveat, solver",
    [
        # duration = the move's end: the last step's stages at its end land, rounded, there
        (T - DELAY, 284, pj.SaveAt(final=True), "rodas4"),
        # past T: samples before the cap is reached, after it, at T and after T
        (SAMPLES[-1], 200, pj.SaveAt(ts=SAMPLES), "rk4"),
    ],
)
def test_simulation_derivatives_by_duration_gain_cap_and_delay(radau, duration, n_steps, saveat, solver):
    ts = (duration,) if saveat.final else saveat.ts
    jac = simulation(duration, duration / n_steps, saveat, solver)
    p = jnp.array([T, CAP, DELAY])
    D, val = (np.asarray(a) for a in jac(p))
    ref_D, ref_val = (np.stack(a) for a in zip(*(radau[t] for t in ts)))
    assert np.abs(val - ref_val).max() < 1e-6
    # the requirement: within 1 % of the true derivative (Radau's), every parameter; before the cap
    # is reached (s < 0.83) the state does not depend on the cap at all
    capped = np.asarray(ts) + DELAY > 0.83 * T
    assert 0 < capped.sum() < len(ts) or saveat.final
    np.testing.assert_allclose(D[:, 0], ref_D[:, 0], rtol=1e-2, atol=0)
    np.testing.assert_allclose(D[:, 2], ref_D[:, 2], rtol=1e-2, atol=0)
    np.testing.assert_allclose(D[capped, 1], ref_D[capped, 1], rtol=1e-2, atol=0)
    assert np.all(D[~capped, 1] == 0.0) and np.all(np.abs(ref_D[~capped, 1]) < 1e-7)
    assert np.abs(ref_D[:, 0]).min() > 1e-2 and np.abs(ref_D[capped, 1]).min() > 1e-5  # not negligible
    assert np.abs(ref_D[:, 2]).min() > 1e-2
    # the discrete solution is differentiated exactly: central differences of the simulation itself
    # (steps 1e-7 relative, inside the old gain's collapse; round-off ~1e-9 of the derivatives)
    for i in range(3):
        h = 1e-7 * abs(float(p[i]))
        fd = (np.asarray(jac(p.at[i].add(h))[1]) - np.asarray(jac(p.at[i].add(-h))[1])) / (2 * h)
        np.testing.assert_allclose(D[:, i], fd, rtol=1e-6, atol=0)
