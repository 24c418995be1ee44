"""Subcommands for users' own files (fit-donders, ik-weights) on shipped examples and bad files."""

import csv
from importlib import resources

import numpy as np
import pytest

import fitting
import pmpjax as pj
from pmpjax import _cli


def example(name):
    return str(resources.files("pmpjax") / "data" / "examples" / name)


def read_rows(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def test_fit_donders_command_on_the_shipped_example(tmp_path):
    # The example holds Table 1-2 subjects 1 and 2 (80 steady postures, 0.5° orientation noise).
    assert _cli.main(["fit-donders", example("donders_example.csv"), "--out", str(tmp_path), "--starts", "2"]) == 0
    rows = read_rows(tmp_path / "donders_fit.csv")
    _, KJ, q_rest = pj.paper_subjects()
    assert [r["subject"] for r in rows] == ["subj1", "subj2"]
    for i, r in enumerate(rows):
        K = np.zeros((3, 3))
        for a in range(3):
            for b in range(a, 3):
                K[a, b] = K[b, a] = float(r[f"KJ_{a}{b}"])
        assert r["converged"] == "True"
        assert abs(np.trace(K) - 4.0) < 1e-4
        assert float(r["rms_torsion_deg"]) < 0.6  # residual at the 0.5° noise level
        # What Donders' law pins down (80 postures leave K_PS,PS and q_rest,PS weak): the torsion
        # surface. Held-out torsion of the fitted parameters vs the Tables' within 0.5°.
        q = np.deg2rad([float(r[f"q_rest_{j}_deg"]) for j in ("ps", "fe", "rud")])
        grid = np.stack(np.meshgrid(*(np.linspace(-0.2, 0.2, 5),) * 2), -1).reshape(-1, 2)
        tx_fit = np.asarray(fitting.predicted_torsion(pj.Wrist(), K, q, grid))
        tx_true = np.asarray(fitting.predicted_torsion(pj.Wrist(), KJ[i], q_rest[i], grid))
        assert np.rad2deg(np.sqrt(np.mean((tx_fit - tx_true) ** 2))) < 0.5


def test_ik_weights_command_recovers_the_weights_of_the_example(tmp_path):
    # ik_example.csv: a planar 3-link arm whose joint velocities are W-weighted pseudo-inverse
    # solutions (γ = 0) with w = (1, 0.5, 0.2) and (0.3, 1, 0.6), generated with plain NumPy.
    assert _cli.main(["ik-weights", example("ik_example.csv"), "--method", "lm", "--gamma", "0",
                      "--out", str(tmp_path)]) == 0
    rows = read_rows(tmp_path / "ik_weights.csv")
    w = np.array([[float(r[f"w_{j}"]) for j in (1, 2, 3)] for r in rows])
    np.testing.assert_allclose(w, [[1.0, 0.5, 0.2], [0.3, 1.0, 0.6]], atol=1e-5)
    beta = np.array([[float(r[f"beta_{j}"]) for j in (1, 2, 3)] for r in rows])
    np.testing.assert_allclose(beta[0], (1 / w[0]) / np.sum(1 / w[0]), atol=1e-5)  # β_i = w_i⁻¹ / Σ w⁻¹


@pytest.mark.parametrize("command, content, expect", [
    ("fit-donders", "subject,sample,qw,qx,qy,qz,x1,x2\ns1,0,1,0,0,0,0.1,oops\n", "line 2, column 8"),
    ("fit-donders", "", "empty"),
    ("ik-weights", "item,qdot_1,qdot_2,xdot_1,J_1_1,J_1_2\na,0.1,0.2,zz,1,0\n", "line 2, column 4"),
    ("ik-weights", "item,qdot_1,qdot_2\na,0.1,0.2\n", "header"),
])
def test_commands_reject_malformed_files_with_file_line_and_column(tmp_path, capsys, command, content, expect):
    path = tmp_path / "bad.csv"
    path.write_text(content)
    assert _cli.main([command, str(path), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "bad.csv" in err and expect in err and "Traceback" not in err


def test_commands_have_help(capsys):
    for command in ("reproduce", "simulate", "fit-donders", "ik-weights"):
        with pytest.raises(SystemExit) as e:
            _cli.main([command, "--help"])
        assert e.value.code == 0
        assert command in capsys.readouterr().out
