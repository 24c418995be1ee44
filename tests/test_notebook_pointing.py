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
    # τ0, τ against the generating values (0.3 T, 0.12 T of the generator's T per subject). They are
    # fitted with the Donders-fitted KJ, q_rest, which the Donders session pins down only partly:
    # τ0 within 20 % (measured −6 %, −16 %), τ within a factor 2 (measured −10 %, +70 %); recovery
    # with known KJ to 5 % is in test_pointing.py.
    tcs_part = {r["subject"]: r for r in csv.DictReader((tmp_path / "pointing_time_constants.csv").open())}
    tau0_true = np.array([float(tcs_part[n]["tau0_true_s"]) for n in out["subjects"]])
    tau_true = np.array([float(tcs_part[n]["tau_true_s"]) for n in out["subjects"]])
    np.testing.assert_allclose(tau_true, 0.4 * tau0_true, rtol=1e-5)
    assert np.all((tau0_true > 0.3 * 0.35) & (tau0_true < 0.3 * 0.55))  # T drawn in [0.35, 0.55] s
    np.testing.assert_allclose(out["tau0_fit_s"], tau0_true, rtol=0.2)
    assert np.all(np.abs(np.log(np.array(out["tau_fit_s"]) / tau_true)) < np.log(2.0)), out["tau_fit_s"]
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
    # the command's time constants, against the generating values as the part's
    tcs = list(csv.DictReader((cmd_out / "time_constants.csv").open()))
    assert list(tcs[0])[:5] == ["subject", "status", "converged", "tau0 [s]", "tau [s]"]
    np.testing.assert_allclose([float(r["tau0 [s]"]) for r in tcs], tau0_true, rtol=0.2)
    assert np.all(np.abs(np.log(np.array([float(r["tau [s]"]) for r in tcs]) / tau_true)) < np.log(2.0))
    bad = tmp_path / "bad.csv"
    lines = pointing.read_text().splitlines()
    k = next(i for i, ln in enumerate(lines) if ln and not ln.startswith("#") and "subject" not in ln)
    lines[k] = lines[k].replace(",", ",x", 2)
    bad.write_text("\n".join(lines) + "\n")
    assert cli.main(["analyze-pointing", str(bad), "--out", str(cmd_out)]) == 2
