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
