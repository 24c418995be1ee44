from _notebooks import run_notebook


def test_notebook_postural_primitives_runs_and_its_assertions_hold(monkeypatch):
    run_notebook("postural_primitives", monkeypatch)
