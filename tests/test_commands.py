"""Subcommands for users' own files (fit-donders, ik-weights) on shipped examples and bad files."""

import csv
import json
import types
from importlib import resources

import numpy as np
import pytest

import fitting
import pmpjax as pj
from pmpjax._app import cli


def example(name):
    return str(resources.files("pmpjax") / "data" / "examples" / name)


def read_rows(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def test_fit_donders_command_on_the_shipped_example(tmp_path, monkeypatch):
    """The command reads the example, hands fit_donders its subjects with the options given, and
    writes what it returns. The fit itself (its compile costs a minute) is replaced by a stand-in
    returning the truth: fit_donders' accuracy on these Table subjects at 0.5° noise is checked
    in tests/test_donders.py (``nio``); here the example must hold exactly that data."""
    _, KJ, q_rest = pj.paper_subjects()
    calls = []

    def fake_fit(chain, pointing, postures, *, mask, n_starts):
        calls.append(n_starts)
        assert np.shape(pointing) == (2, 80, 2) and np.shape(postures) == (2, 80, 3) and np.all(mask)
        # The example holds Table 1-2 subjects 1 and 2 (80 steady postures, 0.5° orientation noise):
        # the observed torsion is the Tables' model torsion at the observed pointing plus that noise.
        model = np.asarray(fitting.predicted_torsion(chain, KJ[:2], q_rest[:2], pointing))
        observed = np.asarray(pj.rotvec_from_joint_angles(postures))[..., 0]
        rms = np.rad2deg(np.sqrt(np.mean((observed - model) ** 2, axis=-1)))
        assert np.all((rms > 0.15) & (rms < 0.6)), rms  # 0.5°/√3 ≈ 0.29° of torsion
        np.testing.assert_allclose(np.asarray(chain.fk(postures)), pointing, atol=1e-9)  # torsion-only noise
        return types.SimpleNamespace(KJ=KJ[:2], q_rest=q_rest[:2], converged=np.array([True, False]),
                                     status=np.array([0, int(pj.Status.MAX_STEPS)]), rms=np.deg2rad(rms),
                                     report=lambda i: f"report {i}")

    monkeypatch.setattr(fitting._donders, "fit_donders", fake_fit)
    # exit code 1: not every subject converged
    assert cli.main(["fit-donders", example("donders_example.csv"), "--out", str(tmp_path), "--starts", "3"]) == 1
    assert calls == [3]
    rows = read_rows(tmp_path / "donders_fit.csv")
    assert [r["subject"] for r in rows] == ["subj1", "subj2"]
    assert [r["converged"] for r in rows] == ["True", "False"]
    assert rows[1]["status"] == pj.status_message(int(pj.Status.MAX_STEPS))
    for i, r in enumerate(rows):
        for a in range(3):
            for b in range(3):
                assert float(r[f"KJ_{min(a, b)}{max(a, b)}"]) == pytest.approx(KJ[i][a, b], rel=1e-5, abs=1e-9)
        q = np.deg2rad([float(r[f"q_rest_{j}_deg"]) for j in ("ps", "fe", "rud")])
        np.testing.assert_allclose(q, q_rest[i], rtol=1e-3, atol=1e-6)
        assert int(r["samples"]) == 80 and 0.15 < float(r["rms_torsion_deg"]) < 0.6
    report = json.loads((tmp_path / "donders_fit.json").read_text())
    np.testing.assert_allclose(report["KJ"], KJ[:2])
    np.testing.assert_allclose(report["q_rest"], q_rest[:2])
    assert report["report"] == ["report 0", "report 1"] and report["converged"] == [True, False]


def test_ik_weights_command_recovers_the_weights_of_the_example(tmp_path):
    # ik_example.csv: a planar 3-link arm whose joint velocities are W-weighted pseudo-inverse
    # solutions (γ = 0) with w = (1, 0.5, 0.2) and (0.3, 1, 0.6), generated with plain NumPy.
    assert cli.main(["ik-weights", example("ik_example.csv"), "--method", "lm", "--gamma", "0",
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
@pytest.mark.bad_input("fitting.read_ik_file")
def test_commands_reject_malformed_files_with_file_line_and_column(tmp_path, capsys, command, content, expect):
    path = tmp_path / "bad.csv"
    path.write_text(content)
    assert cli.main([command, str(path), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "bad.csv" in err and expect in err and "Traceback" not in err
    if command == "ik-weights":
        with pytest.raises(ValueError, match=expect):
            fitting.read_ik_file(path)


def test_commands_have_help(capsys):
    for command in ("reproduce", "simulate", "fit-donders", "ik-weights"):
        with pytest.raises(SystemExit) as e:
            cli.main([command, "--help"])
        assert e.value.code == 0
        assert command in capsys.readouterr().out


# Each subcommand that reads a file: its shipped example and how to spoil one column/key of it.
READERS = [
    ("fit-donders", "donders_example.csv", ("qw,", "qw_,")),
    ("analyze-pointing", "pointing_example.csv", ("qw,", "qw_,")),
    ("ik-weights", "ik_example.csv", ("xdot_1,", "xdot1,")),
    ("simulate", "simulate_figure3.toml", ("KJ_diag", "KJ_dag")),
    ("sweep", "sweep_figure3.toml", ("KJ_diag", "KJ_dag")),
]


@pytest.mark.parametrize("command, name, rename", READERS, ids=[r[0] for r in READERS])
@pytest.mark.parametrize("spoil", ["directory", "empty", "binary", "renamed"])
def test_every_subcommand_refuses_bad_files_by_name(tmp_path, capsys, command, name, rename, spoil):
    from pathlib import Path

    good = Path(example(name)).read_text()
    path = tmp_path / f"spoilt_{name}"
    if spoil == "directory":
        path.mkdir()
    elif spoil == "empty":
        path.write_text("")
    elif spoil == "binary":
        path.write_bytes(b"\x89PNG\r\n\x1a\n\x00\xff\xfe" + bytes(range(256)))
    else:
        assert rename[0] in good
        path.write_text(good.replace(rename[0], rename[1], 1))
    assert cli.main([command, str(path), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert path.name in err and "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    if spoil == "renamed":
        assert rename[1].strip(",") in err  # the unknown column or key is named


def test_output_folder_that_is_a_file_is_refused(tmp_path, capsys):
    (tmp_path / "taken").write_text("x")
    assert cli.main(["simulate", example("simulate_figure3.toml"), "--out", str(tmp_path / "taken")]) == 2
    err = capsys.readouterr().err
    assert "--out" in err and "taken" in err and "not a folder" in err and "Traceback" not in err


@pytest.mark.parametrize("name, old, new, expect", [
    ("simulate_figure3.toml", "q0_deg = [5, 0, 0]", "q0 = [25, 0, 0]", "above 2π rad.*degrees"),
    ("simulate_figure3.toml", "duration = 0.4", "duration = 400000", "milliseconds"),
    ("simulate_figure3.toml", "duration = 0.4", "duration = 1e300", "milliseconds"),
    ("pointing_example.csv", None, "ms", "milliseconds"),
    ("donders_example.csv", None, "deg", "degrees"),
])
def test_values_in_the_wrong_unit_get_a_hint(tmp_path, capsys, name, old, new, expect):
    from pathlib import Path

    text = Path(example(name)).read_text()
    if name == "pointing_example.csv":  # time in milliseconds
        lines = text.splitlines()
        i = next(k for k, ln in enumerate(lines) if ln.startswith("subject"))
        rows = [ln.split(",") for ln in lines[i + 1:]]
        text = "\n".join(lines[: i + 1] + [",".join(r[:2] + [f"{1000 * float(r[2]):.6g}"] + r[3:]) for r in rows])
    elif name == "donders_example.csv":  # joint-angle columns in degrees instead of quaternions
        rec = pj.read_recordings(example(name))
        q = np.rad2deg(np.asarray(rec.joint_angles))
        lines = ["subject,sample,q_ps,q_fe,q_rud,x1,x2"]
        for s, subj in enumerate(rec.subjects):
            for k in range(int(rec.n_samples[s])):
                lines.append(f"{subj},{k}," + ",".join(f"{v:.6g}" for v in (*q[s, k], *rec.pointing[s, k])))
        text = "\n".join(lines)
    else:
        assert old in text
        text = text.replace(old, new)
    path = tmp_path / f"units_{name}"
    path.write_text(text + "\n")
    command = {"simulate_figure3.toml": "simulate", "pointing_example.csv": "analyze-pointing",
               "donders_example.csv": "fit-donders"}[name]
    assert cli.main([command, str(path), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert path.name in err and "Traceback" not in err
    import re
    assert re.search(expect, err), err


def test_every_file_reading_subcommand_names_its_example_and_columns(capsys):
    import re
    from pathlib import Path

    for command, name, _ in READERS:
        with pytest.raises(SystemExit):
            cli.main([command, "--help"])
        out = capsys.readouterr().out
        shown = re.search(r"Example: (\S+)", out.replace("\n", " "))
        assert shown and Path(shown.group(1)).name == name and Path(shown.group(1)).is_file(), (command, out)
        assert "cp " in out.replace("\n", " ")
    for command, columns in (("fit-donders", "subject,sample,qw,qx,qy,qz,x1,x2"),
                             ("analyze-pointing", "subject,trial,time,qw,qx,qy,qz,target")):
        with pytest.raises(SystemExit):
            cli.main([command, "--help"])
        assert columns in capsys.readouterr().out.replace("\n", "")


def test_analyze_pointing_can_skip_invalid_trials_and_says_so_with_the_option_name(tmp_path, capsys):
    from pathlib import Path

    lines = Path(example("pointing_example.csv")).read_text().splitlines()
    i = next(k for k, ln in enumerate(lines) if ln.startswith("subject")) + 5
    f = lines[i].split(",")
    lines[i] = ",".join(f[:3] + ["nan"] + f[4:])  # one NaN sample in trial 1
    path = tmp_path / "one_bad_trial.csv"
    path.write_text("\n".join(lines) + "\n")
    assert cli.main(["analyze-pointing", str(path), "--out", str(tmp_path / "a"), "--no-figures"]) == 2
    err = capsys.readouterr().err
    assert "--skip-invalid" in err and "on_invalid" not in err
    assert cli.main(["analyze-pointing", str(path), "--out", str(tmp_path / "b"), "--no-figures",
                      "--skip-invalid"]) == 0
    assert "trial 1" in (tmp_path / "b" / "excluded.txt").read_text()
