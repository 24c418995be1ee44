"""Test configuration: float64, strict rank promotion, one compilation cache per run, shared
fixtures."""

import os
import shutil
import tempfile

# XLA:CPU's legacy loop emitters for every compilation of the run (read when the backend starts),
# as pmpjax's compile-bound kernels use them (``pj.fast_compile_jit``): the tests' own ``jax.jit``
# of simulations and losses compile faster (tests/test_accuracy.py 67 s -> 58 s on two idle cores).
# LLVM's backend without optimisation (level 0) for the same reason: the suite is bound by
# compilation (a quick reaching fit's compilations took 25 s instead of 37-42 s at the default
# level), while its simulations run two to three times slower; the tests' times summed 11 % less
# (1 139 s against 1 281 s, two idle cores). XLA's own (HLO) passes are the same at every level.
_LEGACY_EMITTERS = "--xla_cpu_use_fusion_emitters=false"
_BACKEND_LEVEL = "--xla_backend_optimization_level=0"
for _flag in (_LEGACY_EMITTERS, _BACKEND_LEVEL):
    if _flag.split("=")[0] not in os.environ.get("XLA_FLAGS", ""):
        os.environ["XLA_FLAGS"] = f"{os.environ.get('XLA_FLAGS', '')} {_flag}".strip()

import jax  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_rank_promotion", "raise")


CACHE_ENV = "PMPJAX_TEST_CACHE_DIR"
_CREATED = []  # the directory this process made (the controller), removed when the run ends


def _cache_env(path):
    return {"JAX_COMPILATION_CACHE_DIR": path, "PMPJAX_CACHE_DIR": path,
            "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS": "0.5", "JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES": "0"}


def pytest_configure(config):
    """One persistent JAX compilation cache per test run, shared by everything the run starts: the
    controller makes a temporary directory and exports it before the xdist workers and the
    subprocess tests start, so a function that two test files, two workers, or a test and its
    subprocess compile is compiled once. Fresh every run (every run measures cold compilation, as
    CI does) and removed at the end; ``PMPJAX_TEST_CACHE_DIR=dir`` keeps one across runs instead,
    ``JAX_ENABLE_COMPILATION_CACHE=false`` turns it off."""
    # One BLAS thread per process (the xdist workers and the tests' subprocesses inherit it; this
    # process loaded OpenBLAS before reading it). Two workers on two cores, each with OpenBLAS's
    # default thread per core, oversubscribe the cores whenever both compute, and OpenBLAS's
    # threads spin while they wait: NumPy's 200 × 200 solve + eigh took 13 ms single-threaded and
    # 615 ms with two threads on a busy machine (the pointing analysis's smoothing-spline GCV).
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    path = os.environ.get(CACHE_ENV)
    if not path:  # the controller (or a run without xdist): workers inherit the environment
        path = tempfile.mkdtemp(prefix="pmpjax-test-jax-cache-")
        _CREATED.append(path)
        os.environ[CACHE_ENV] = path
    # Fresh interpreters started by tests read these at `import jax`; the command line's
    # enable_compilation_cache() reads PMPJAX_CACHE_DIR (never the user's ~/.cache here).
    os.environ.update(_cache_env(path))
    jax.config.update("jax_compilation_cache_dir", path)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    if hasattr(config.option, "loadscopereorder"):  # xdist: keep SLOWEST_FIRST's order of files
        config.option.loadscopereorder = False


def pytest_unconfigure(config):
    for path in _CREATED:
        shutil.rmtree(path, ignore_errors=True)
        for key in (CACHE_ENV, *_cache_env(path)):
            os.environ.pop(key, None)


# Test files, longest first. `--dist loadfile` hands whole files to the workers in collection order
# (xdist would otherwise sort them by number of tests, which put the single-test notebooks and the
# springy gradient last): longest first keeps the two workers even to the end instead of leaving
# one long file to run alone (and test_movements_mjcf.py runs before the notebook that finds its
# compiled fit in the run's shared cache). Files not listed (each under 5 s) follow in their usual
# order. Per-file sums of `--durations=0` (setup + call) [s] of one run in this order with
# `-n 2 --dist loadfile` on two idle cores, 2026-12-06 (761 s in all): reaching 244, ik_weights 112,
# pointing 110, movements 98, accuracy 95, movements_mjcf 93, main_job_parts 57, simulate 55, stiff 53,
# donders 51, movements_planar 37, cli 34, jit_safety 32, springy_rollout_gradient 30, movements_minjerk
# 29 (then unlisted), sweep 29, ik_data 27, notebook_pointing 26, minimum_jerk_gain 26, primitives_fits
# 21, notebook_sweeps 15, springy_reflexes 15, primitives 13, equilibria 12, notebook_ik_weights 11,
# springy_rollouts 11, notebook_fit_your_own_data 11, models 9.8, notebook_fit_your_own_arm 9.1 (its
# fit compiled by movements_mjcf, in the shared cache), docs 8.4, the others under 8.5.
SLOWEST_FIRST = (
    "test_reaching.py", "test_ik_weights.py", "test_movements_mjcf.py", "test_pointing.py", "test_simulate.py",
    "test_movements.py", "test_accuracy.py", "test_donders.py", "test_jit_safety.py",
    "test_springy_rollout_gradient.py", "test_movements_minjerk.py", "test_notebook_fit_your_own_arm.py",
    "test_primitives_fits.py",
    "test_equilibria.py", "test_cli.py", "test_stiff.py", "test_notebook_pointing.py", "test_primitives.py",
    "test_movements_planar.py", "test_main_job_parts.py", "test_ik_data.py", "test_springy_reflexes.py",
    "test_notebook_ik_weights.py", "test_springy_rollouts.py", "test_notebook_sweeps.py", "test_sweep.py",
    "test_notebook_lambda0_pmp.py", "test_minimum_jerk_gain.py", "test_notebook_fit_your_own_data.py",
    "test_commands.py", "test_primitives_part.py", "test_models.py", "test_compile_options.py",
    "test_sweep_command.py", "test_docs.py", "test_redundancy.py", "test_public_api.py", "test_units.py",
    "test_optimise.py", "test_kinematics.py",
)


def pytest_collection_modifyitems(config, items):
    rank = {name: i for i, name in enumerate(SLOWEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))  # stable: order within a file kept


@pytest.fixture
def rng():
    return np.random.default_rng(0)


# Springy-arm fixtures (test_primitives*.py, test_springy_*.py): one arm per test module.
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
