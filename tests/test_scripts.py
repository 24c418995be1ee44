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
