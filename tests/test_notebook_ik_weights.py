from _notebooks import run_notebook


def test_notebook_ik_weights_runs_and_its_assertions_hold(monkeypatch):
    run_notebook("ik_weights", monkeypatch)
