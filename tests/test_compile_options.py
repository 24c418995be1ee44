"""``pmpjax.fast_compile_jit``: XLA options at the top level only, the same values everywhere."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import pmpjax as pj


def _newton_sqrt(a):
    """sqrt(a) by 30 Newton steps in a loop (a fit-like kernel: loop, elementwise work)."""
    return jax.lax.fori_loop(0, 30, lambda k, x: 0.5 * (x + a / x), jnp.maximum(a, 1.0))


def test_top_level_and_nested_calls_agree_with_numpy():
    """Top-level calls compile with FAST_COMPILE; inside a caller's jit, vmap or grad the kernel is
    traced without options (JAX refuses them on nested jit: this fails if they were passed)."""
    f = pj.fast_compile_jit(_newton_sqrt)
    a = np.array([0.25, 2.0, 9.0, 1e4])
    np.testing.assert_allclose(f(a), np.sqrt(a), rtol=1e-15)
    np.testing.assert_allclose(jax.jit(lambda v: f(v) * 2.0)(a), 2.0 * np.sqrt(a), rtol=1e-15)
    np.testing.assert_allclose(jax.vmap(f)(a), np.sqrt(a), rtol=1e-15)
    np.testing.assert_allclose(jax.grad(lambda v: jnp.sum(f(v)))(a), 0.5 / np.sqrt(a), rtol=1e-12)
    # the decorator forms and the attributes of a jitted function (lower, trace)
    g = pj.fast_compile_jit(static_argnames=("n",))(lambda x, n: x * n)
    assert float(g(2.0, n=3)) == 6.0
    assert "while" in f.lower(a).as_text()


@pytest.mark.bad_input("pj.fast_compile_jit")
def test_bad_input():
    with pytest.raises(TypeError, match="`fun` must be callable"):
        pj.fast_compile_jit(3)
    with pytest.raises(TypeError, match="`compiler_options` must be a dict"):
        pj.fast_compile_jit(_newton_sqrt, compiler_options=["xla_cpu_enable_fast_math"])
