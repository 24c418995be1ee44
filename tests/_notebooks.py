"""Notebook harness: a notebook's code cells exec'd in-process (sharing compiled functions with
the tests in the same worker), top to bottom; its own ``assert`` statements are the checks.

Each notebook has its own tiny ``tests/test_notebook_<name>.py`` so that pytest-xdist's
``--dist loadfile`` spreads the notebooks over the workers; ``test_every_notebook_is_tested``
(in ``test_notebook_index.py``) fails when a notebook has no such file."""

import os
from pathlib import Path

import matplotlib
import nbformat

NOTEBOOK_DIR = Path(__file__).parent.parent / "notebooks"


def run_notebook(name: str, monkeypatch) -> dict:
    """Run ``notebooks/<name>.ipynb``; returns its namespace (for further checks)."""
    path = NOTEBOOK_DIR / f"{name}.ipynb"
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    monkeypatch.chdir(path.parent)
    monkeypatch.setenv("PMPJAX_NOTEBOOK_TEST", "1")
    nb = nbformat.read(path, as_version=4)
    namespace = {"__name__": "__notebook__"}
    # Same JAX configuration as the other tests, so compiled functions are shared with them.
    for i, cell in enumerate(nb.cells):
        if cell.cell_type != "code":
            continue
        src = "\n".join(ln for ln in cell.source.splitlines() if not ln.lstrip().startswith(("%", "!")))
        try:
            exec(compile(src, f"{path.name}[cell {i}]", "exec"), namespace)
        except Exception as e:  # pragma: no cover - the message is the point
            raise AssertionError(f"{path.name} cell {i} failed: {e!r}") from e
    plt.close("all")
    assert os.environ["PMPJAX_NOTEBOOK_TEST"] == "1"
    return namespace
