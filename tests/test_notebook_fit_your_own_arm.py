"""The "fit your own arm" notebook (public names only) and the main job's movements part, which run
the same fit (subject S1 of the shipped synthetic example at ``--quick`` sizes) in one worker."""

import json
from pathlib import Path

from _layout import checking_part_figures
from _notebooks import run_notebook

import pmpjax as pj
from pmpjax._app import cli


def test_notebook_fit_your_own_arm_runs_and_its_assertions_hold(monkeypatch):
    ns = run_notebook("fit_your_own_arm", monkeypatch)
    assert ns["fit"].subjects == ("S1",) and len(ns["pred"]) == 6


def test_movements_part(tmp_path):
    """`pmpjax reproduce --quick --only movements`: S1's fit converges, its time constants are within
    15 % of the example's truth, its held-out reaches are predicted within 1° median RMSE and at
    most half the pseudo-inverse's, and its tables and figures are written (titles and legends inside
    the figures, off the data)."""
    with checking_part_figures() as layout:
        res = cli.reproduce(tmp_path, quick=True, only=["movements"], progress=False, cache=False)["movements"]
    assert res["status"] == "ok", res
    # plot_movements and plot_movement_parameters: titles and legends inside, off the data
    assert set(layout) == {"movements_S1.png", "movements_parameters.png"}
    assert {name: problems for name, problems in layout.items() if problems} == {}
    r = res["results"]
    truth = json.loads((Path(pj.__file__).parent / "data" / "examples" / "reaching" / "truth.json").read_text())
    assert r["converged"] == [1, 1] and r["held_out_reaches"] == 6
    assert abs(r["tau0"][0] / truth["subjects"]["S1"]["tau0"] - 1) < 0.15
    assert abs(r["tau"][0] / truth["subjects"]["S1"]["tau"] - 1) < 0.15
    last = r["summary"][-1]
    assert last["model_median_rmse [deg]"] < 1.0
    assert last["model_median_rmse [deg]"] <= 0.5 * last["pinv_minjerk_median_rmse [deg]"]
    for name in ("movements_fit.csv", "movements_held_out.csv", "movements_S1.png", "movements_parameters.png"):
        assert (tmp_path / name).stat().st_size > 0, name
