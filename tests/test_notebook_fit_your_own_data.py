from _notebooks import run_notebook


def test_notebook_fit_your_own_data_runs_and_its_assertions_hold(monkeypatch):
    run_notebook("fit_your_own_data", monkeypatch)
