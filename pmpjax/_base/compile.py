"""``fast_compile_jit`` for the compile-bound kernels: XLA:CPU's legacy loop emitters instead of its MLIR fusion
emitters (``xla_cpu_use_fusion_emitters=False``).

The fits (Levenberg–Marquardt loops around Newton solves or RK4 simulations), the equilibria and
the MJX rollouts are compiled once per shape and then run for milliseconds to seconds, so their
first call is mostly XLA compilation. With the legacy emitters XLA:CPU compiles them 15–55 % faster
and most of them also run faster (``benchmarks/compile_times.py``); results agree to rounding (a
different fusion, not different arithmetic).

Every jitted kernel of ``pmpjax`` and ``fitting`` uses it, except where run time at large batches
is the point: ``simulate``'s unrolled kernel above 1 024 movements (below that ``simulate`` runs a
compile-light kernel with it, see ``pmpjax._pmp.simulate._primal_run``) and the IK weights'
Algorithm 1.
Inside a caller's ``jit`` (or ``vmap``/``grad`` trace) the caller's options apply: JAX takes options
only at the top level. :func:`fast_compile_applies` tells a kernel whether the top-level call it
is traced for compiles with :data:`FAST_COMPILE` (``simulate`` picks its kernel by it).
"""

from __future__ import annotations

import contextvars
import functools

import jax

try:  # JAX 0.10: True outside every jit/vmap/grad trace
    from jax._src.core import trace_state_clean as _trace_state_clean
except ImportError:  # pragma: no cover - a JAX without it: always the nested (option-free) path
    def _trace_state_clean():
        return False


def top_level() -> bool:
    """True outside every ``jit``/``vmap``/``grad`` trace (and outside the eager evaluation of a
    ``custom_jvp``/``custom_vmap`` function, which JAX runs under a trace)."""
    return _trace_state_clean()


#: XLA:CPU options of the compile-bound kernels (module docstring).
FAST_COMPILE = {"xla_cpu_use_fusion_emitters": False}

#: The XLA options of the top-level :class:`TopLevelOptionsJit` call (or its ``lower``/``trace``)
#: whose function is being traced; ``{}`` outside one (e.g. inside a plain ``jax.jit``).
_TRACE_OPTIONS = contextvars.ContextVar("pmpjax_trace_options", default={})


def fast_compile_applies() -> bool:
    """True where the code being run or traced compiles with :data:`FAST_COMPILE`'s emitters: at the
    top level (a kernel's own ``fast_compile_jit``) or traced for a top-level ``fast_compile_jit``."""
    options = _TRACE_OPTIONS.get()
    return top_level() or all(options.get(k, not v) == v for k, v in FAST_COMPILE.items())


class TopLevelOptionsJit:
    """Two ``jax.jit`` of one function: with XLA ``options`` for top-level calls (and ``lower``,
    ``trace``, ...), without them inside a caller's trace (JAX refuses ``compiler_options`` on
    nested ``jit``; the caller's top-level ``jit`` decides the options there)."""

    def __init__(self, fun, options, **kwargs):
        self._options = dict(options)
        self._top = jax.jit(fun, compiler_options=self._options, **kwargs)
        self._nested = jax.jit(fun, **kwargs)
        functools.update_wrapper(self, fun)

    def __call__(self, *args, **kwargs):
        if not top_level():
            return self._nested(*args, **kwargs)
        return self._with_options(self._top)(*args, **kwargs)

    def _with_options(self, method):
        """``method`` with this jit's options in ``_TRACE_OPTIONS`` while it runs (and traces)."""
        def run(*args, **kwargs):
            token = _TRACE_OPTIONS.set(self._options)
            try:
                return method(*args, **kwargs)
            finally:
                _TRACE_OPTIONS.reset(token)

        return run

    def __getattr__(self, name):
        attr = getattr(self._top, name)
        return self._with_options(attr) if name in ("lower", "trace", "eval_shape") else attr


def fast_compile_jit(fun=None, **kwargs):
    """``jax.jit`` with XLA:CPU's legacy loop emitters, for compile-bound kernels.

    ``FAST_COMPILE`` (``{"xla_cpu_use_fusion_emitters": False}``) is merged under explicit
    ``compiler_options`` for top-level calls. Usable as ``fast_compile_jit(f)``,
    ``@fast_compile_jit`` or ``@partial(fast_compile_jit, static_argnames=...)``.

    **Arguments:**

    - ``fun``: the function to compile (``None`` when used as ``partial(fast_compile_jit, ...)``).
    - ``kwargs``: keyword arguments of ``jax.jit`` (``static_argnames``, ``compiler_options``, ...).

    **Returns:**

    The jitted function (or, without ``fun``, a decorator).

    **Raises:**

    ``TypeError`` for a non-callable ``fun`` or ``compiler_options`` that are not a dict."""
    if fun is None:
        return functools.partial(fast_compile_jit, **kwargs)
    if not callable(fun):
        raise TypeError(f"`fun` must be callable, got {type(fun).__name__}")
    extra = kwargs.pop("compiler_options", None) or {}
    if not isinstance(extra, dict):
        raise TypeError(f"`compiler_options` must be a dict of XLA options, got {type(extra).__name__}")
    options = {**FAST_COMPILE, **extra}
    return TopLevelOptionsJit(fun, options, **kwargs)
