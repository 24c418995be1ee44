"""Every notebook runs top to bottom (code cells exec'd in-process, sharing compiled functions)."""

import os
from pathlib import Path

import matplotlib
import nbformat
import pytest

NOTEBOOKS = sorted((Path(__file__).parent.parent / "notebooks").glob("*.ipynb"))


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_runs(path, monkeypatch):
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
