"""fitting.least_squares (the one LM loop) and fitting.covariance against SciPy."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.optimize

import fitting
import pmpjax as pj


def _rosenbrock(x, args):
    a, b = args
    return jnp.stack([a - x[0], jnp.sqrt(b) * (x[1] - x[0] ** 2), 0.5 * (x[2] - x[1] * x[0])])


def test_rosenbrock_matches_scipy():
    x0, args = np.array([-1.2, 1.0, 0.3]), (1.0, 100.0)
    res = fitting.least_squares(_rosenbrock, x0, args, max_steps=200)
    ref = scipy.optimize.least_squares(lambda x: np.asarray(_rosenbrock(jnp.asarray(x), args)), x0, method="lm",
                                       xtol=1e-15, ftol=1e-15, gtol=1e-15)
    assert bool(res.converged) and int(res.status) == pj.Status.SUCCESSFUL
    np.testing.assert_allclose(np.asarray(res.x), ref.x, atol=1e-9)
    np.testing.assert_allclose(np.asarray(res.x), [1.0, 1.0, 1.0], atol=1e-9)


def test_batch_of_exponential_fits_matches_scipy():
    """y = a exp(−k t) + c with noise, 16 data sets vmapped in one call vs SciPy one by one; the
    Gauss–Newton standard errors against SciPy's Jacobian at its optimum."""
    rng = np.random.default_rng(3)
    t = np.linspace(0.0, 4.0, 40)
    true = np.stack([rng.uniform(0.5, 2, 16), rng.uniform(0.3, 2, 16), rng.uniform(-0.5, 0.5, 16)], -1)
    y = true[:, :1] * np.exp(-true[:, 1:2] * t) + true[:, 2:] + rng.normal(scale=0.02, size=(16, 40))

    def resid(p, yy):
        return p[0] * jnp.exp(-p[1] * t) + p[2] - yy

    x0 = np.array([1.0, 1.0, 0.0])
    res = jax.jit(jax.vmap(lambda yy: fitting.least_squares(resid, x0, yy)))(jnp.asarray(y))
    cov, se, _, _ = jax.vmap(fitting.covariance)(res)
    assert np.all(np.asarray(res.converged))
    for i in range(16):
        ref = scipy.optimize.least_squares(lambda p: np.asarray(resid(jnp.asarray(p), y[i])), x0, method="lm",
                                           xtol=1e-15, ftol=1e-15, gtol=1e-15)
        s2 = 2 * ref.cost / (40 - 3)
        se_ref = np.sqrt(s2 * np.diag(np.linalg.inv(ref.jac.T @ ref.jac)))
        # the same optimum to far below the statistical precision (an ftol = 1e-12 stop leaves
        # ~1e-6 SE in x)
        z = np.abs(np.asarray(res.x[i]) - ref.x) / se_ref
        assert np.all(z < 1e-4), (i, z)
        np.testing.assert_allclose(float(res.cost[i]), ref.cost, rtol=1e-10)
        np.testing.assert_allclose(np.asarray(se[i]), se_ref, rtol=1e-6)


def test_a_parameter_with_a_zero_column_is_held_and_counts_nowhere():
    """A parameter the residual does not see (a held one: an exactly zero Jacobian column) stays
    where it starts, and the fit is the fit without it: the same iterates, stop and status. Stopped
    by the statistical rule (``stol``, whose σ² divides by N − p) and by the step rule (``xtol``,
    relative to |x|), a held parameter counted in p or |x| (here 1e3, against the others' ~2)
    would stop the fit at another iterate."""
    rng = np.random.default_rng(5)
    t = np.linspace(0.0, 4.0, 12)
    y = 1.3 * np.exp(-0.7 * t) + 0.2 + rng.normal(scale=0.05, size=t.size)

    def resid(p, yy):
        return p[0] * jnp.exp(-p[1] * t) + p[2] - yy

    x0 = np.array([0.6, 1.8, -0.3])
    for opts in (dict(stol=0.3, ftol=0.0, xtol=0.0), dict(xtol=3e-4, ftol=0.0)):
        fitted = fitting.least_squares(resid, x0, y, **opts)
        held = fitting.least_squares(lambda z, yy: resid(z[:3], yy), np.r_[x0, 1e3], y, **opts)
        assert float(held.x[3]) == 1e3 and int(held.steps) == int(fitted.steps) >= 2, opts
        np.testing.assert_allclose(np.asarray(held.x[:3]), np.asarray(fitted.x), rtol=1e-12, atol=1e-14)
        assert int(held.status) == int(fitted.status) == int(pj.Status.SUCCESSFUL)


def test_gauss_newton_gain_matches_lstsq():
    """The statistical stopping rule's predicted decrease ``½ gᵀ (JᵀJ)⁺ g`` against NumPy's
    least-squares step ``½ |J δ|²``, ``δ = lstsq(J, r)``: a tall Jacobian with columns of very
    different scales, and one with an exactly repeated column (a null direction)."""
    from fitting._optimise.least_squares import _gauss_newton_gain

    rng = np.random.default_rng(3)
    J = rng.normal(size=(500, 6)) * np.array([1e-3, 1.0, 10.0, 1e3, 0.1, 5.0])
    r = rng.normal(size=500)
    for Jc in (J, np.concatenate([J, J[:, 2:3]], axis=1)):
        delta = np.linalg.lstsq(Jc, r, rcond=None)[0]
        ref = 0.5 * np.sum((Jc @ delta) ** 2)
        assert abs(float(_gauss_newton_gain(jnp.asarray(Jc), jnp.asarray(r))) / ref - 1) < 1e-10


def test_status_max_steps_and_nonfinite():
    r = fitting.least_squares(_rosenbrock, np.array([-1.2, 1.0, 0.3]), (1.0, 100.0), max_steps=2)
    assert int(r.status) == pj.Status.MAX_STEPS and not bool(r.converged) and int(r.steps) == 2
    r = fitting.least_squares(lambda x, _: jnp.log(x - 1.0), np.array([0.5]))
    assert int(r.status) == pj.Status.NONFINITE and not bool(r.converged)


def test_approximate_jacobian_steps_end_at_the_exact_optimum():
    """``approximate=True``: steps from an approximate Jacobian (here one that
    ``pmpjax.internal.frozen_tangents`` switches to, one column off along the data's misfit:
    alone it moves the stationary point by several standard errors, where the misfit is
    systematic as in the reaching fits; a milder one that the approximate steps converge on by
    the cost rule), then from the exact one near the optimum. The
    optimum, within 0.02 standard errors of SciPy's, the exact Jacobian in ``jac`` also when the
    step limit stops the fit, and the status are the exact Jacobian's."""
    from pmpjax.internal import frozen_tangents

    rng = np.random.default_rng(11)
    t = np.linspace(0.0, 4.0, 60)
    y = 1.3 * np.exp(-0.7 * t) + 0.2 + 0.15 * np.sin(2.5 * t) + rng.normal(scale=0.02, size=t.size)

    def model(p):
        return p[0] * jnp.exp(-p[1] * t) + p[2] - y

    def resid(p, _, always=False, c=0.3):
        fr = frozen_tangents()
        skew = c * p[1] * jnp.sin(2.5 * t)  # (value 0 below; adds c sin(2.5 t) to the k column)
        on = jnp.asarray(True) if always else (jnp.asarray(False) if fr is None else fr)
        return model(p) + jnp.where(on, 1.0, 0.0) * (skew - jax.lax.stop_gradient(skew))

    x0 = np.array([0.6, 1.8, -0.3])
    ref = scipy.optimize.least_squares(lambda p: np.asarray(model(jnp.asarray(p))), x0, method="lm",
                                       xtol=1e-15, ftol=1e-15, gtol=1e-15)
    se = np.sqrt(2 * ref.cost / (t.size - 3) * np.diag(np.linalg.inv(ref.jac.T @ ref.jac)))
    opts = dict(stol=1e-4, ftol=0.0, xtol=0.0)
    alone = fitting.least_squares(lambda p, a: resid(p, a, always=True), x0, None, **opts)
    assert np.max(np.abs(np.asarray(alone.x) - ref.x) / se) > 1.0  # (what the exact steps must undo)
    res = fitting.least_squares(resid, x0, None, approximate=True, **opts)
    assert int(res.status) == int(pj.Status.SUCCESSFUL)
    assert np.max(np.abs(np.asarray(res.x) - ref.x) / se) < 0.02
    exact = lambda x: np.asarray(jax.jacfwd(model)(x))  # noqa: E731
    np.testing.assert_allclose(np.asarray(res.jac), exact(res.x), rtol=1e-12, atol=1e-14)
    short = fitting.least_squares(resid, x0, None, approximate=True, max_steps=2, **opts)
    assert int(short.status) == int(pj.Status.MAX_STEPS) and int(short.steps) == 2
    np.testing.assert_allclose(np.asarray(short.jac), exact(short.x), rtol=1e-12, atol=1e-14)
    start = jax.jit(lambda m: fitting.least_squares(resid, x0, None, approximate=True, max_steps=m, **opts))(0)
    np.testing.assert_allclose(np.asarray(start.jac), exact(x0), rtol=1e-12, atol=1e-14)
    assert int(start.steps) == 0
    # a milder skew that the approximate steps converge on smoothly (by the cost rule, no statistical
    # one): that test holding with the approximate Jacobian must not end the fit
    mild = dict(ftol=1e-10, xtol=0.0)
    alone = fitting.least_squares(lambda p, a: resid(p, a, always=True, c=0.1), x0, None, **mild)
    assert int(alone.status) == int(pj.Status.SUCCESSFUL) and np.max(np.abs(np.asarray(alone.x) - ref.x) / se) > 1.0
    res = fitting.least_squares(lambda p, a: resid(p, a, c=0.1), x0, None, approximate=True, **mild)
    assert int(res.status) == int(pj.Status.SUCCESSFUL)
    assert np.max(np.abs(np.asarray(res.x) - ref.x) / se) < 0.02


@pytest.mark.bad_input("fitting.least_squares", "fitting.covariance")
def test_bad_input():
    cases = [
        (lambda: fitting.least_squares(_rosenbrock, np.zeros((3, 1)), (1.0, 1.0)), ValueError, "`x0`"),
        (lambda: fitting.least_squares(_rosenbrock, np.array([np.nan, 0, 0]), (1.0, 1.0)), ValueError, "`x0`"),
        (lambda: fitting.least_squares(lambda x, a: jnp.outer(x, x), np.zeros(2)), ValueError, "`residual`"),
        (lambda: fitting.least_squares("f", np.zeros(2)), TypeError, "`residual`"),
        (lambda: fitting.least_squares(_rosenbrock, np.zeros(3), (1.0, 1.0), max_steps=0), ValueError,
         "max_steps"),
        (lambda: fitting.least_squares(_rosenbrock, np.zeros(3), (1.0, 1.0), gtol=-1.0), ValueError, "gtol"),
        (lambda: fitting.least_squares(_rosenbrock, np.zeros(3), (1.0, 1.0), damping=0.0), ValueError,
         "damping"),
        (lambda: fitting.covariance(np.zeros((3, 3))), TypeError, "`result`"),
    ]
    for call, err, match in cases:
        with pytest.raises(err, match=match):
            call()
    r = fitting.least_squares(_rosenbrock, np.zeros(3), (1.0, 1.0))
    with pytest.raises(ValueError, match="rcond"):
        fitting.covariance(r, rcond=-1.0)


def test_group_jackknife_is_least_squares_without_each_group():
    # A linear model (the Gauss–Newton step from the optimum is then exact): 2 shared slopes, one
    # offset per group (its nuisance column), 7 groups of 5 rows, and 2 prior rows in no group.
    # Reference: the slopes refitted by lstsq without each group's rows and offset, then the
    # textbook delete-one jackknife (n − 1)/n Σ (β_(g) − β̄)(β_(g) − β̄)ᵀ.
    from fitting._optimise import group_jackknife_covariance

    rng = np.random.default_rng(11)
    n, k = 7, 5
    groups = np.concatenate([np.repeat(np.arange(n), k), [-1, -1]])
    X = rng.normal(size=(n * k, 2))
    offsets = np.zeros((n * k + 2, n))
    offsets[np.arange(n * k), groups[:-2]] = 1.0
    J = np.concatenate([np.concatenate([X, 0.1 * np.eye(2)]), offsets], axis=1)
    y = J @ np.concatenate([[0.7, -1.3], rng.normal(size=n)]) + rng.normal(scale=0.3, size=n * k + 2)
    y[: n * k] += np.repeat(rng.normal(scale=0.5, size=n), k) * X[:, 0]  # slopes that vary by group
    beta = np.linalg.lstsq(J, y, rcond=None)[0]
    r = J @ beta - y
    drop = []
    for g in range(n):
        rows = groups != g
        cols = np.r_[0, 1, 2 + np.flatnonzero(np.arange(n) != g)]
        drop.append(np.linalg.lstsq(J[np.ix_(rows, cols)], y[rows], rcond=None)[0][:2])
    D = np.array(drop) - np.mean(drop, axis=0)
    ref = (n - 1) / n * D.T @ D
    cov = group_jackknife_covariance(J, r, groups, 2, nuisance_groups=np.arange(n))
    np.testing.assert_allclose(cov, ref, rtol=1e-9, atol=1e-15)
    # Without nuisance columns (shared parameters only); fewer than two groups: NaN.
    Js, rs = J[:, :2].copy(), (J[:, :2] @ np.linalg.lstsq(J[:, :2], y, rcond=None)[0] - y)
    drop = [np.linalg.lstsq(Js[groups != g], y[groups != g], rcond=None)[0] for g in range(n)]
    D = np.array(drop) - np.mean(drop, axis=0)
    np.testing.assert_allclose(group_jackknife_covariance(Js, rs, groups, 2), (n - 1) / n * D.T @ D, rtol=1e-9)
    assert np.all(np.isnan(group_jackknife_covariance(Js, rs, np.where(groups > 0, -1, groups), 2)))


def test_the_stopping_rules_stop_at_the_first_iterate_that_meets_one():
    # A linear least-squares problem (every Levenberg–Marquardt step is accepted) with the cost, step
    # and statistical tolerances on, as 48 items that differ in where each rule binds: a constant
    # residual entry e (cost + e²/2: the cost and statistical rules looser) and a shift s of the
    # solution (|x| from 1e-3 to 1e4: the step rule looser or tighter). The iterates x_k come from runs
    # capped at k steps (a traced step limit). In NumPy: some rule holds between the last two iterates and none between
    # the two before (ftol: |Δcost| ≤ ftol·cost; xtol: |Δx| ≤ xtol (|x| + xtol); stol: the Gauss–Newton
    # gain, here the cost above the lstsq optimum, ≤ stol·σ² with σ² = 2 cost/(N − p)).
    rng = np.random.default_rng(5)
    N, p, B = 41, 3, 48
    A = rng.normal(size=(N - 1, p)) * [1.0, 10.0, 0.1]
    b = A @ np.array([1.0, -2.0, 3.0]) + rng.normal(scale=0.1, size=N - 1)
    x_opt = np.linalg.lstsq(A, b, rcond=None)[0]
    e = 0.1 * 10.0 ** rng.uniform(0, 4, B)
    shift = rng.normal(size=(B, p)) * 10.0 ** rng.uniform(-3, 4, (B, 1)) - x_opt  # the solutions x_opt + shift
    x_opt = x_opt + shift
    starts = x_opt + rng.normal(size=(B, p)) * 10.0 ** rng.uniform(1, 3, (B, 1)) / np.abs(A).max(0)
    cost = lambda x: 0.5 * (np.sum(((x - shift) @ A.T - b) ** 2, axis=-1) + e**2)  # noqa: E731
    ftol, xtol, stol = 1e-3, 1e-5, 1e-4

    def resid(x, args):
        s, extra = args
        return jnp.concatenate([jnp.asarray(A) @ (x - s) - jnp.asarray(b), extra[None]])

    # (one item per call: the statistical rule's eigh compiles twice as fast unbatched)
    one = jax.jit(lambda x0, m, s, extra: fitting.least_squares(
        resid, x0, (s, extra), max_steps=m, gtol=0.0, ftol=ftol, xtol=xtol, stol=stol, damping=10.0))
    res = [one(starts[i], np.int64(200), shift[i], e[i]) for i in range(B)]
    k = np.array([int(r.steps) for r in res])
    assert all(bool(r.converged) for r in res) and np.all(k >= 2), k
    x = [np.stack([np.asarray(r.x) for r in res])] + [
        np.stack([np.asarray(one(starts[i], k[i] - j, shift[i], e[i]).x) for i in range(B)]) for j in (1, 2)]

    def rules(new, old):
        return np.stack([np.abs(cost(old) - cost(new)) <= ftol * cost(old),
                         np.linalg.norm(new - old, axis=1) <= xtol * (np.linalg.norm(old, axis=1) + xtol),
                         cost(new) - cost(x_opt) <= stol * 2 * cost(new) / (N - p)])

    last, before = rules(x[0], x[1]), rules(x[1], x[2])
    assert np.all(last.any(0)) and not np.any(before), (k, last, before)
