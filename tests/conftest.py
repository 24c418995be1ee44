"""Test configuration: float64, strict rank promotion, shared problems."""

import jax

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_rank_promotion", "raise")


def _shared_compilation_cache() -> None:
    """One persistent compilation cache per test run, shared by the xdist workers (a function that
    two test files compile, e.g. a test module and its notebook, is compiled once). Fresh every
    run, so every run measures cold compilation as CI does."""
    import os
    import tempfile
    import uuid

    run = os.environ.get("PYTEST_XDIST_TESTRUNUID") or uuid.uuid4().hex
    path = os.path.join(tempfile.gettempdir(), f"pmpjax-test-jax-cache-{run}")
    os.makedirs(path, exist_ok=True)
    jax.config.update("jax_compilation_cache_dir", path)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)


_shared_compilation_cache()

import numpy as np  # noqa: E402
import pytest  # noqa: E402


@pytest.fixture
def rng():
    return np.random.default_rng(0)


# Springy-arm fixtures (test_primitives.py, test_springy_*.py): one arm per test module.
@pytest.fixture(scope="module")
def arm():
    import pmpjax as pj

    return pj.load_arm()


@pytest.fixture(scope="module")
def free_arm():
    import pmpjax as pj

    return pj.load_arm(contacts=False)


@pytest.fixture(scope="module")
def P():
    import pmpjax as pj

    return np.asarray(pj.default_primitives())
