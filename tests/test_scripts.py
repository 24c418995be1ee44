"""Benchmarks and notebooks-adjacent scripts are not imported by the tests; at least they must parse."""

import ast
from pathlib import Path

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
