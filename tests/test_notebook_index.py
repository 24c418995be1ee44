from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_every_notebook_is_tested_and_stored_run_with_its_outputs():
    """Every notebook has a test file, valid cell ids, asserts a key number, and is stored as
    run top to bottom (``jupyter nbconvert --execute``): every code cell executed in order, no error."""
    import nbformat

    notebooks = sorted((ROOT / "notebooks").glob("*.ipynb"))
    assert notebooks
    for nb_path in notebooks:
        assert (ROOT / "tests" / f"test_notebook_{nb_path.stem}.py").exists(), f"{nb_path.name} has no test file"
        nb = nbformat.read(nb_path, as_version=4)
        nbformat.validate(nb)  # (cell ids included)
        code = [c for c in nb.cells if c.cell_type == "code"]
        counts = [c.get("execution_count") for c in code]
        assert counts == list(range(1, len(code) + 1)), (
            f"{nb_path.name}: store it run top to bottom in a fresh kernel, got execution counts {counts}")
        errors = [o.get("ename") for c in code for o in c.get("outputs", []) if o.get("output_type") == "error"]
        assert not errors, f"{nb_path.name}: stored with errors {errors}"
        assert any(c.get("outputs") for c in code), f"{nb_path.name}: stored without outputs"
        assert any("assert" in c.source for c in code), f"{nb_path.name}: asserts none of its key numbers"
