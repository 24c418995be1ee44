from _notebooks import run_notebook


def test_notebook_sweeps_runs_and_its_assertions_hold(monkeypatch):
    run_notebook("sweeps", monkeypatch)
