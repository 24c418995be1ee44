from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_every_notebook_is_tested_and_stored_without_outputs():
    import nbformat

    for nb in sorted((ROOT / "notebooks").glob("*.ipynb")):
        assert (ROOT / "tests" / f"test_notebook_{nb.stem}.py").exists(), f"{nb.name} has no test file"
        cells = nbformat.read(nb, as_version=4).cells
        code = [c for c in cells if c.cell_type == "code"]
        assert all(not c.get("outputs") and c.get("execution_count") is None for c in code), (
            f"{nb.name}: store notebooks with outputs stripped (diff-friendly)")
        assert any("assert" in c.source for c in code), f"{nb.name}: asserts none of its key numbers"
