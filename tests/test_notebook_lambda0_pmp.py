from _notebooks import run_notebook


def test_notebook_lambda0_pmp_runs_and_its_assertions_hold(monkeypatch):
    run_notebook("lambda0_pmp", monkeypatch)
