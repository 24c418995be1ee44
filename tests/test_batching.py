"""The shared routines of pmpjax._base: batch broadcasting/padding and the one Newton solver."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.optimize
from _reference import central_diff, compiled_names

from pmpjax._base.batching import broadcast_batch, bucket, flatten_batch, head_rows, pad_rows, unflatten_batch
from pmpjax._base.newton import newton_solve
from pmpjax._base.validate import to_jax

# --- batching -----------------------------------------------------------------------------------


def test_broadcast_flatten_round_trip():
    K = np.arange(2 * 3 * 3, dtype=float).reshape(2, 1, 3, 3)
    q = np.arange(4 * 3, dtype=float).reshape(4, 3)
    batch = broadcast_batch(K=(K, 2), q=(q, 1), none=(None, 1))
    assert batch == (2, 4)
    Kf, qf = flatten_batch(K, batch, 2), flatten_batch(q, batch, 1)
    assert Kf.shape == (8, 3, 3) and qf.shape == (8, 3)
    np.testing.assert_array_equal(np.asarray(unflatten_batch(qf, batch))[1], q)  # like np.broadcast_to
    np.testing.assert_array_equal(np.asarray(unflatten_batch(Kf, batch))[1, 2], K[1, 0])
    with pytest.raises(ValueError, match=r"`K` \(2,\), `q` \(4,\)"):
        broadcast_batch(K=(K[:, 0], 2), q=(q, 1))


def test_concrete_arrays_are_batched_without_compiling():
    # Which bug: a routine that reshapes, pads or slices a concrete jax.Array with an eager jnp op
    # (or converts NumPy with jnp.asarray) compiles an XLA program for every new shape: 30-100 ms
    # each, hundreds in one `pmpjax reproduce`.
    a = jax.device_put(np.arange(7 * 3, dtype=float).reshape(7, 3) + 0.25)  # a shape nothing else uses
    with compiled_names() as names:
        f, p = flatten_batch(a, (7,), 1), pad_rows(a, 11)
        u, h, t = unflatten_batch(p, (7, 1), 7), head_rows(p, 7), to_jax(np.ones((13, 3)))
    assert names == []
    assert all(isinstance(x, jax.Array) for x in (f, p, u, h, t))
    np.testing.assert_array_equal(np.asarray(p)[7:], np.broadcast_to(np.asarray(a)[-1], (4, 3)))  # "edge"
    np.testing.assert_array_equal(np.asarray(u)[:, 0], np.asarray(a))
    np.testing.assert_array_equal(np.asarray(h), np.asarray(a))


def test_bucket_and_pad():
    assert [bucket(n, minimum=8) for n in (1, 8, 9, 100)] == [8, 8, 16, 128]
    assert bucket(0) == 1 and bucket(5) == 8
    a = np.arange(6.0).reshape(3, 2)
    e = pad_rows(a, 5)
    assert isinstance(e, np.ndarray) and e.shape == (5, 2)
    np.testing.assert_array_equal(e[3:], [[4, 5], [4, 5]])
    z = pad_rows(jnp.asarray(a), 4, axis=1, fill="zeros")
    np.testing.assert_array_equal(np.asarray(z)[:, 2:], 0.0)
    assert pad_rows(a, 3) is a
    with pytest.raises(ValueError, match="fill"):
        pad_rows(a, 4, fill="mean")
    with pytest.raises(ValueError, match="cannot pad"):
        pad_rows(a, 2)


# --- Newton -------------------------------------------------------------------------------------
# F(y, θ) = y + a y³ − b (elementwise), θ = (a, b): one real root for a > 0; ∂F/∂y = 1 + 3 a y².


def _F(y, params, consts):
    a, b = params
    return y + a * y**3 - b


def _solve(y, params, consts, rhs):
    return rhs / (1.0 + 3.0 * params[0] * y**2)


def _root(a, b):
    return scipy.optimize.brentq(lambda y: y + a * y**3 - b, -10.0, 10.0, xtol=1e-15)


def test_newton_solves_and_counts_steps():
    a, b = np.array([0.5, 2.0, 0.1]), np.array([1.0, -3.0, 0.2])
    y, steps = newton_solve(_F, _solve, jnp.zeros(3), (jnp.asarray(a), jnp.asarray(b)), max_steps=50, tol=1e-12)
    np.testing.assert_allclose(np.asarray(y), [_root(*ab) for ab in zip(a, b)], rtol=1e-14)
    assert 3 <= int(steps) < 50
    # The cap: from y0 = 5 every step moves at most 0.1 until the last few.
    traj = [newton_solve(_F, _solve, jnp.full(1, 5.0), (jnp.full(1, 0.5), jnp.full(1, 1.0)), max_steps=k,
                         step_cap=0.1)[0][0] for k in (1, 2, 3)]
    np.testing.assert_allclose(np.diff(np.concatenate([[5.0], np.asarray(traj)])), -0.1, rtol=1e-12)
    _, steps = newton_solve(_F, _solve, jnp.full(1, 5.0), (jnp.full(1, 0.5), jnp.full(1, 1.0)), max_steps=4,
                            step_cap=0.1, tol=1e-12)
    assert int(steps) == 4  # the limit was hit


@pytest.mark.parametrize("mode", ["rev", "fwd"])
def test_newton_implicit_gradients_match_central_differences(mode):
    """d y*/d(a, b) by the implicit rule vs central differences of SciPy's root, under vmap and jit."""
    a, b = np.array([0.5, 2.0]), np.array([1.0, -3.0])

    def y_star(a, b):
        return newton_solve(_F, _solve, jnp.zeros_like(a), (a, b), max_steps=50, tol=1e-13)[0]

    diff = jax.jacrev if mode == "rev" else jax.jacfwd
    ja, jb = jax.jit(diff(lambda a, b: jnp.sum(jnp.sin(y_star(a, b))), argnums=(0, 1)))(a, b)
    f = lambda a, b: np.sum(np.sin([_root(ai, bi) for ai, bi in zip(a, b)]))  # noqa: E731
    np.testing.assert_allclose(np.asarray(ja), central_diff(lambda v: f(v, b), a), rtol=1e-6)
    np.testing.assert_allclose(np.asarray(jb), central_diff(lambda v: f(a, v), b), rtol=1e-6)
    # grad of vmap equals vmap of grad
    g1 = jax.vmap(jax.grad(lambda a, b: jnp.sin(y_star(a[None], b[None])[0])))(jnp.asarray(a), jnp.asarray(b))
    np.testing.assert_allclose(np.asarray(g1), np.asarray(ja), rtol=1e-12)


def test_newton_ignores_tangents_of_start_and_consts():
    def y_star(y0, c):
        return newton_solve(lambda y, p, k: _F(y, p, k) + 0.0 * k, _solve, y0, (jnp.ones(1), jnp.ones(1)), c,
                            max_steps=50, tol=1e-13)[0][0]

    gy0, gc = jax.grad(y_star, argnums=(0, 1))(jnp.full(1, 3.0), jnp.ones(1))
    assert float(jnp.abs(gy0).max()) == 0.0 and float(jnp.abs(gc).max()) == 0.0
