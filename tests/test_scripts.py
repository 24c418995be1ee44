"""Benchmarks and notebooks-adjacent scripts are not imported by the tests; at least they must parse."""

import ast
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPTS = sorted((ROOT / "benchmarks").glob("*.py"))


@pytest.mark.parametrize("path", SCRIPTS, ids=[p.name for p in SCRIPTS])
def test_benchmark_script_parses_and_has_figures(path):
    tree = ast.parse(path.read_text(), filename=str(path))
    if not path.name.startswith("_"):
        doc = ast.get_docstring(tree)
        assert doc and "2026" in doc, f"{path.name}: module docstring with the latest dated figures"


def test_simulate_benchmark_captures_concrete_kernel_arguments():
    """benchmarks/simulate.py times ``_run`` ahead of time with the arguments ``simulate`` passes
    its kernel: they must be concrete arrays that ``_run`` lowers with (a capture inside the
    kernel's custom_jvp/custom_vmap wrappers got tracers, and ``--quick`` crashed)."""
    import importlib.util
    import sys

    import jax

    sys.path.insert(0, str(ROOT / "benchmarks"))
    try:
        spec = importlib.util.spec_from_file_location("bench_simulate", ROOT / "benchmarks" / "simulate.py")
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        bl = mod.bl
        run, args, kwargs = mod.capture_run(bl.start_postures(3), bl.targets(3), "final")
    finally:
        sys.path.remove(str(ROOT / "benchmarks"))
    leaves = jax.tree_util.tree_leaves(args)
    assert leaves and not any(isinstance(a, jax.core.Tracer) for a in leaves)
    assert kwargs["batch"] == (3,)
    run.trace(*args, **kwargs)  # traces with these arguments (no compile)


def test_simulate_benchmark_sharded_worker_runs_on_two_devices(tmp_path):
    """``benchmarks/simulate.py``'s two-device worker (GSPMD and shard_map) runs and gives the final
    postures of SciPy's solve_ivp (the benchmark's NumPy field) on the same wrist movements; it
    crashed on JAX's default Explicit mesh axes and on shard_map's varying-axes check."""
    import json
    import os
    import subprocess
    import sys

    B, out = 4, tmp_path / "q.npy"
    env = {**os.environ, "XLA_FLAGS": f"{os.environ.get('XLA_FLAGS', '')} --xla_force_host_platform_device_count=2"}
    proc = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "simulate.py"), "--worker", "sharded",
                           "--B", str(B), "--out", str(out)], capture_output=True, text=True, env=env, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    res = json.loads(proc.stdout.strip().splitlines()[-1])
    assert res["max_diff_gspmd_vs_shard_map"] < 1e-12
    sys.path.insert(0, str(ROOT / "benchmarks"))
    try:
        import _baselines as bl
    finally:
        sys.path.remove(str(ROOT / "benchmarks"))
    ref = bl.scipy_final(bl.start_postures(B), bl.targets(B), rtol=1e-11, atol=1e-12)[0]  # NumPy field
    np.testing.assert_allclose(np.load(out), ref, atol=1e-8)
