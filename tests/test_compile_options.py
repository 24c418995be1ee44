"""``pmpjax.fast_compile_jit``: XLA options at the top level only, the same values everywhere."""

import importlib

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


def test_eager_small_simulate_runs_the_option_compiled_light_kernel():
    """An eager ``simulate`` of a small batch compiles the light kernel with the options at the top
    level (fails if the call goes through the custom_jvp/custom_vmap wrappers, under which JAX
    drops them, or takes the unrolled kernel); inside a caller's ``jit`` the options stay out."""
    sim = importlib.import_module("pmpjax._pmp.simulate")  # (the face binds simulate to the function)

    model = pj.Lambda0PMP(pj.Wrist(1.0), KJ=np.diag([0.5, 1.5, 2.0]), q_rest=np.zeros(3),
                          W=0.08 * np.diag([0.5, 1.5, 2.0]))
    planner = pj.ArimotoPlanner(k=22.5, tau=0.08)
    q0, tg = np.zeros((3, 3)), np.full((3, 2), 0.05)
    # a schedule no other test uses, so that the first call here compiles
    run = lambda: pj.simulate(model, planner, q0, tg, duration=0.03, dt=0.01)  # noqa: E731
    top, unrolled = sim._run_light._top._cache_size(), sim._run._cache_size()
    eager = run()
    assert sim._run_light._top._cache_size() == top + 1 and sim._run._cache_size() == unrolled
    jitted = jax.jit(lambda: run().q)()
    assert sim._run_light._top._cache_size() == top + 1  # traced into the caller's jit instead
    np.testing.assert_allclose(jitted, eager.q, rtol=0, atol=1e-15)


def test_traced_simulate_takes_the_light_kernel_only_for_tiny_batches(monkeypatch):
    """Inside a caller's ``jax.jit`` the compile options cannot apply, and the stage-loop kernel runs
    2–3.5× slower than the unrolled one from 32 movements on: such traced calls above
    ``TRACED_SMALL_BATCH`` take the unrolled kernel; eager calls, and calls traced for a caller's
    ``pj.fast_compile_jit`` (whose options do apply), keep the light one up to ``SMALL_BATCH``.
    Fails if traced calls take the light kernel by the eager rule, or if a fast-compiled caller
    is not told apart from a plain ``jax.jit``."""
    sim = importlib.import_module("pmpjax._pmp.simulate")  # (the face binds simulate to the function)

    taken = []
    for name in ("_run", "_run_light"):
        kernel = getattr(sim, name)
        monkeypatch.setattr(sim, name, lambda *a, _k=kernel, _n=name, **kw: (taken.append(_n), _k(*a, **kw))[1])
    model = pj.Lambda0PMP(pj.Wrist(1.0), KJ=np.diag([0.5, 1.5, 2.0]), q_rest=np.zeros(3),
                          W=0.08 * np.diag([0.5, 1.5, 2.0]))
    planner = pj.ArimotoPlanner(k=22.5, tau=0.08)

    def kernels(B, traced):
        taken.clear()
        q0, tg = np.zeros((B, 3)), np.full((B, 2), 0.05)
        run = lambda q, t: pj.simulate(model, planner, q, t, duration=0.03, dt=0.01).q  # noqa: E731
        if traced == "fast_compile_jit.trace":
            pj.fast_compile_jit(run).trace(q0, tg)
        elif traced == "fast_compile_jit":
            pj.fast_compile_jit(run)(q0, tg)
        else:
            jax.make_jaxpr(run)(q0, tg) if traced else run(q0, tg)
        return list(taken)

    small = sim.TRACED_SMALL_BATCH
    assert kernels(small, traced=True) == ["_run_light"]
    assert kernels(small + 1, traced=True) == ["_run"]
    assert kernels(sim.SMALL_BATCH, traced="fast_compile_jit.trace") == ["_run_light"]
    assert kernels(sim.SMALL_BATCH + 1, traced="fast_compile_jit.trace") == ["_run"]
    assert kernels(small + 1, traced="fast_compile_jit") == ["_run_light"]
    assert kernels(small + 1, traced=False) == ["_run_light"]
