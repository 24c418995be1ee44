"""The pointing notebook, then the main job's pointing part and the ``analyze-pointing`` command on
an experiment of the same sizes (so the three share one set of compiled functions)."""

import csv

import numpy as np
from _notebooks import run_notebook

from pmpjax._app import cli

SUBJECTS = ("subj1", "subj4")


def test_notebook_pointing_runs_and_its_assertions_hold(monkeypatch):
    run_notebook("pointing", monkeypatch)


def test_main_job_part_and_command(tmp_path):
    """`pmpjax reproduce --quick --only pointing`: Figures 5–8 and tables exist and agree with the
    ground truth; `pmpjax analyze-pointing` on the files the part wrote gives the same statistics;
    a malformed file is one line naming the file, line and column (exit status 2)."""
    res = cli.reproduce(tmp_path, quick=True, only=["pointing"], seed=3, progress=False, cache=False)["pointing"]
    assert res["status"] == "ok", res.get("error")
    names = {a["path"] for a in res["artefacts"]}
    for fig in (5, 6, 7, 8):
        assert any(n.startswith(f"pointing_figure{fig}_") and n.endswith(".png") for n in names), fig
    rows = list(csv.DictReader((tmp_path / "pointing_statistics.csv").open()))
    assert len(rows) == 2 * 16 and {r["subject"] for r in rows} == set(SUBJECTS)
    out = res["results"]
    assert out["donders_converged"] == [True, True] and all(out["time_constants_converged"])
    # (τ0, τ are fitted with the Donders-fitted KJ, q_rest, which the 64-posture session pins down
    # only partly; recovery of the generating τ0, τ is tested with known KJ in test_pointing.py.)
    assert np.all(np.isfinite(out["tau0_fit_s"])) and np.all(np.array(out["tau_fit_s"]) > 0)
    # The captured counts agree with the p-values in the table (p >= 0.05: not significantly different).
    table = {(r["subject"], r["movement"]): r for r in rows}
    for s, name in enumerate(out["subjects"]):
        p = np.array([float(table[(name, lab)]["p_model_fitted"]) for lab in out["labels"]])
        assert out["n_captured_fitted"][s] == int(np.sum(p[np.isfinite(p)] >= 0.05))

    data = tmp_path / "pointing_data"
    files = {p.name: p for p in data.iterdir()}
    pointing = next(p for n, p in files.items() if "donders" not in n)
    donders = next(p for n, p in files.items() if "donders" in n)
    cmd_out = tmp_path / "cmd"
    code = cli.main(["analyze-pointing", str(pointing), "--donders", str(donders), "--out", str(cmd_out),
                      "--no-figures"])
    assert code == 0
    cmd_rows = list(csv.DictReader((cmd_out / "pointing_statistics.csv").open()))
    np.testing.assert_allclose([float(r["A_net"]) for r in cmd_rows], [float(r["A_net"]) for r in rows], rtol=1e-5)
    tcs = list(csv.DictReader((cmd_out / "time_constants.csv").open()))
    np.testing.assert_allclose([float(r["tau0_s"]) for r in tcs], out["tau0_fit_s"], rtol=1e-5)
    bad = tmp_path / "bad.csv"
    lines = pointing.read_text().splitlines()
    k = next(i for i, ln in enumerate(lines) if ln and not ln.startswith("#") and "subject" not in ln)
    lines[k] = lines[k].replace(",", ",x", 2)
    bad.write_text("\n".join(lines) + "\n")
    assert cli.main(["analyze-pointing", str(bad), "--out", str(cmd_out)]) == 2
