"""Subcommands for users' own files (fit-donders, ik-weights) on shipped examples and bad files."""

import csv
import json
import re
import types
import warnings
from importlib import resources

import numpy as np
import pytest

import fitting
import pmpjax as pj
from pmpjax._app import cli
from pmpjax._app import reproduce as main_job


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
    # the columns of every command: what was fitted, its status, converged, then values with units
    assert list(rows[0])[:3] == ["subject", "status", "converged"]
    assert [r["subject"] for r in rows] == ["subj1", "subj2"]
    assert [r["converged"] for r in rows] == ["True", "False"]
    assert rows[1]["status"] == pj.status_message(int(pj.Status.MAX_STEPS))
    for i, r in enumerate(rows):
        for a in range(3):
            for b in range(3):
                assert float(r[f"KJ_{min(a, b)}{max(a, b)} [Nm/rad]"]) == pytest.approx(KJ[i][a, b], rel=1e-5, abs=1e-9)
        q = np.deg2rad([float(r[f"q_rest_{j} [deg]"]) for j in ("ps", "fe", "rud")])
        np.testing.assert_allclose(q, q_rest[i], rtol=1e-3, atol=1e-6)
        assert int(r["samples"]) == 80 and 0.15 < float(r["rms_torsion [deg]"]) < 0.6
    report = json.loads((tmp_path / "donders_fit.json").read_text())
    np.testing.assert_allclose(report["KJ"], KJ[:2])
    np.testing.assert_allclose(report["q_rest"], q_rest[:2])
    assert report["report"] == ["report 0", "report 1"] and report["converged"] == [True, False]


def test_ik_weights_command_exits_1_when_an_item_did_not_converge(tmp_path, monkeypatch, capsys):
    """The exit-status policy: the results are written, and the status says not every fit converged."""
    def fake(qdot, xdot, J, gamma, *, mask, on_invalid):
        return types.SimpleNamespace(w=np.ones((2, 3)), converged=np.array([True, False]), error=np.zeros(2),
                                     status=np.array([0, int(pj.Status.MAX_STEPS)]))

    monkeypatch.setattr(fitting._ik, "estimate_ik_weights", fake)
    assert cli.main(["ik-weights", example("ik_example.csv"), "--out", str(tmp_path)]) == 1
    assert [r["converged"] for r in read_rows(tmp_path / "ik_weights.csv")] == ["True", "False"]
    assert capsys.readouterr().out.startswith("1 of 2 items converged")


def test_ik_weights_command_recovers_the_weights_of_the_example(tmp_path):
    # ik_example.csv: a planar 3-link arm whose joint velocities are W-weighted pseudo-inverse
    # solutions (γ = 0) with w = (1, 0.5, 0.2) and (0.3, 1, 0.6), generated with plain NumPy.
    assert cli.main(["ik-weights", example("ik_example.csv"), "--method", "lm", "--gamma", "0",
                      "--out", str(tmp_path)]) == 0
    rows = read_rows(tmp_path / "ik_weights.csv")
    assert list(rows[0])[:3] == ["item", "status", "converged"]
    w = np.array([[float(r[f"w{j}"]) for j in (1, 2, 3)] for r in rows])
    np.testing.assert_allclose(w, [[1.0, 0.5, 0.2], [0.3, 1.0, 0.6]], atol=1e-5)
    beta = np.array([[float(r[f"beta{j}"]) for j in (1, 2, 3)] for r in rows])
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


def test_help_and_the_list_of_parts_read_as_plain_text(capsys):
    """Every command's --help, `pmpjax --help` and `reproduce --list`: no docstring markup (RST
    double backticks, literal-block colons, bold), no doubled %; the exit statuses documented;
    developers' notes (the entry-point protocol) left out."""
    import re
    from importlib.metadata import version

    commands = list(cli.build_parser()._subparsers._group_actions[0].choices)  # noqa: SLF001
    assert {"reproduce", "simulate", "fit-donders", "ik-weights", "analyze-pointing", "sweep"} <= set(commands)
    texts = {}
    for argv in ([], *([c] for c in commands)):
        with pytest.raises(SystemExit) as e:
            cli.main([*argv, "--help"])
        assert e.value.code == 0
        texts[" ".join(argv) or "pmpjax"] = capsys.readouterr().out
    assert cli.main(["reproduce", "--list"]) == 0
    texts["--list"] = capsys.readouterr().out
    for where, text in texts.items():
        assert "``" not in text and "%%" not in text and "**" not in text, (where, text)
        assert not re.search(r"::\s*$", text, re.MULTILINE), (where, text)
    assert "segmentation at 20 % of peak speed" in " ".join(texts["analyze-pointing"].split())
    for where in texts.keys() - {"--list"}:  # one exit-status policy, laid out as a table in every --help
        assert re.search(r"^ +1 +done and written, but not everything succeeded", texts[where], re.MULTILINE), where
        assert re.search(r"^ +130 +interrupted", texts[where], re.MULTILINE), where
        assert "Exit status 0:" not in " ".join(texts[where].split()), where
    assert not re.search(r"Read IK data|the reader behind", " ".join(texts["ik-weights"].split()))
    assert not re.search(r"entry.point|pmpjax\._app|func\(args\)", texts["reproduce"]), texts["reproduce"]
    assert all(f"{name} " in texts["--list"] for name in ("figure3", "figure4", "primitives"))
    with pytest.raises(SystemExit) as e:
        cli.main(["--version"])
    assert e.value.code == 0 and capsys.readouterr().out.strip() == f"pmpjax {version('pmpjax')}"


# Each subcommand that reads a file: its shipped example and how to spoil one column/key of it.
READERS = [
    ("fit-donders", "donders_example.csv", ("qw,", "qw_,")),
    ("analyze-pointing", "pointing_example.csv", ("qw,", "qw_,")),
    ("ik-weights", "ik_example.csv", ("xdot_1,", "xdot1,")),
    ("simulate", "simulate_figure3.toml", ("KJ_diag", "KJ_dag")),
    ("sweep", "sweep_figure3.toml", ("KJ_diag", "KJ_dag")),
]


# What each spoilt file must be refused as (the reason, not only the file's name).
PNG = b"\x89PNG\r\n\x1a\n\x00\xff\xfe" + bytes(range(256))  # its first NUL: byte 8, after two newlines
REASONS = {
    "directory": r"is a directory, not a file",
    "empty": r"empty file",
    "binary": r"a binary file \(NUL byte at byte 8, line 3\)",
    "latin-1": r"not a UTF-8 text file \(line 2, byte 9: b'\\xe9'\)",
}


@pytest.mark.parametrize("command, name, rename", READERS, ids=[r[0] for r in READERS])
@pytest.mark.parametrize("spoil", ["directory", "empty", "binary", "latin-1", "renamed"])
def test_every_subcommand_refuses_bad_files_for_the_right_reason(tmp_path, capsys, command, name, rename, spoil):
    import re
    from pathlib import Path

    good = Path(example(name)).read_text()
    path = tmp_path / f"spoilt_{name}"
    if spoil == "directory":
        path.mkdir()
    elif spoil == "empty":
        path.write_text("")
    elif spoil == "binary":
        path.write_bytes(PNG)
    elif spoil == "latin-1":  # text in another encoding: "# café" on line 2, é (0xe9 in Latin-1) its byte 9
        path.write_bytes(b"# x\n# caf\xe9\n" + good.encode())
    else:
        assert rename[0] in good
        path.write_text(good.replace(rename[0], rename[1], 1))
    assert cli.main([command, str(path), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert path.name in err and "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    if spoil == "renamed":  # the renamed column or key is named as unknown, not found by echoing the header
        new = re.escape(rename[1].strip(","))
        assert re.search(rf"unknown (column|key)(\(s\))? \[?'?(model\.)?{new}\b", err), err
        assert rename[1] not in err.replace(rename[1].strip(","), "", 1), err  # (named once: no header echoed)
    else:
        assert re.search(REASONS[spoil], err), err
        others = [r for k, r in REASONS.items() if k != spoil] + [r"no such file", r"missing", r"unknown"]
        assert not any(re.search(r, err) for r in others), err


@pytest.mark.parametrize("command", ["fit-donders", "analyze-pointing", "ik-weights"])
def test_random_bytes_named_npz_are_not_an_npz_archive(tmp_path, capsys, command):
    """Not "pickled data" (what numpy says of any file that is not a zip or .npy)."""
    path = tmp_path / "noise.npz"
    path.write_bytes(np.random.default_rng(0).bytes(2000).replace(b"PK", b"pk"))
    assert cli.main([command, str(path), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "noise.npz: not an NPZ archive (not a zip archive" in err and "pickle" not in err, err


def test_a_renamed_ik_column_is_named_as_unknown_and_the_jacobian_is_not_blamed(tmp_path, capsys):
    from pathlib import Path

    good = Path(example("ik_example.csv")).read_text()  # 3 joints, 2 task coordinates
    for old, new in (("qdot_1,", "qdot1,"), ("qdot_3,", "qdot_3_,"), ("J_2_3", "J23")):
        path = tmp_path / "renamed.csv"
        path.write_text(good.replace(old, new, 1))
        assert cli.main(["ik-weights", str(path), "--out", str(tmp_path / "o")]) == 2
        err = capsys.readouterr().err
        assert f"unknown column(s) '{new.strip(',')}'" in err and "Traceback" not in err, err
        assert f"(missing: {old.strip(',')})" in err, err  # the column it replaces, and only that one


@pytest.mark.parametrize("command", ["fit-donders", "analyze-pointing"])
def test_option_values_are_refused_by_their_option_name(tmp_path, capsys, command):
    with pytest.raises(SystemExit) as e:
        cli.main([command, example("donders_example.csv"), "--starts", "0", "--out", str(tmp_path)])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert "argument --starts: expected a positive integer, got '0'" in err and "n_starts" not in err, err
    assert not any(tmp_path.iterdir())  # nothing run


def test_output_folder_that_is_a_file_is_refused(tmp_path, capsys):
    (tmp_path / "taken").write_text("x")
    assert cli.main(["simulate", example("simulate_figure3.toml"), "--out", str(tmp_path / "taken")]) == 2
    err = capsys.readouterr().err
    assert "--out" in err and "taken" in err and "not a folder" in err and "Traceback" not in err


@pytest.mark.parametrize("name, old, new, expect", [
    ("simulate_figure3.toml", "q0_deg = [5, 0, 0]", "q0 = [25, 0, 0]", "above 2π rad.*degrees"),
    # (angles given in degrees beyond the wrist's range: refused as such, without a hint that they are degrees)
    ("simulate_figure3.toml", "q_rest_deg = [5, 0, 0]", "q_rest_deg = [200, 0, 0]",
     r"model\.q_rest_deg = 200° \(index 0\) is beyond any Wrist joint's range \(±180°\)$"),
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
    captured = capsys.readouterr()
    # The warning: one line of its own, no source line of the code that raised it.
    assert captured.err.splitlines() == [captured.err.splitlines()[0]], captured.err
    assert captured.err.startswith(f"pmpjax analyze-pointing: warning: skipping trial: {path}:")
    # One line per exclusion, a sentence (not a Python tuple).
    excluded = (tmp_path / "b" / "excluded.txt").read_text().splitlines()
    assert len(excluded) == 1 and excluded[0].startswith(f"{path}:"), excluded
    assert "subject 'subj1', trial 1: NaN" in excluded[0], excluded
    subjects = {r["subject"] for r in csv.DictReader(ln for ln in lines if not ln.startswith("#"))}
    assert len(subjects) == 1  # counts with their nouns in the number
    assert captured.out.startswith("1 subject, ") and ", 1 exclusion (excluded.txt)" in captured.out, captured.out


def _can_write(folder) -> bool:
    try:
        (folder / "probe").open("x").close()
    except OSError:
        return False
    (folder / "probe").unlink()
    return True


@pytest.fixture(params=["read-only folder", "folder under a file"])
def unwritable_out(request, tmp_path):
    """An output folder no file can be written to: a read-only folder (as root, whom permissions do
    not stop, a sysfs folder) or a path under a regular file."""
    from pathlib import Path

    if request.param == "folder under a file":
        (tmp_path / "file").write_text("x")
        yield tmp_path / "file" / "out"
        return
    folder = tmp_path / "read_only"
    folder.mkdir()
    folder.chmod(0o500)
    try:
        if _can_write(folder):
            folder = Path("/sys/kernel")
            if not folder.is_dir() or _can_write(folder):
                pytest.skip("no read-only folder: permissions do not stop this user and there is no sysfs")
        yield folder
    finally:
        (tmp_path / "read_only").chmod(0o700)


# Each subcommand, its arguments and the function that does its work (which must not be reached).
WORK = {
    "fit-donders": (["donders_example.csv"], "fitting._donders", "fit_donders"),
    "ik-weights": (["ik_example.csv"], "fitting._ik", "estimate_ik_weights"),
    "analyze-pointing": (["pointing_example.csv"], "fitting._pointing", "analyze_pointing"),
    "simulate": (["simulate_figure3.toml"], "pmpjax", "simulate"),
    "sweep": (["sweep_figure3.toml"], "fitting._sweep", "sweep"),
    "fit-movements": (["reaching/S1_trial1.mot", "--chain", example("arm5.xml"), "--site", "hand"],
                      "fitting._movements", "fit_movements"),
    "reproduce": ([], None, None),
}


@pytest.mark.parametrize("command", list(WORK))
def test_an_output_folder_that_cannot_be_written_is_refused_before_any_work(unwritable_out, capsys, monkeypatch,
                                                                             command):
    import importlib

    files, module, name = WORK[command]
    worked = []
    if module is not None:
        monkeypatch.setattr(importlib.import_module(module), name, lambda *a, **k: worked.append(name))
    else:
        def part(ctx):
            """Works."""
            worked.append("part")

        for host in (main_job, cli):
            monkeypatch.setattr(host, "available_parts", lambda: {"part": part})
        files = ["--no-progress", "--no-cache", "--jobs", "1"]
    argv = [command, *map(example, files[:1]), *files[1:]] if module else [command, *files]
    assert cli.main([*argv, "--out", str(unwritable_out)]) == 2
    err = capsys.readouterr().err
    assert not worked
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert f"pmpjax {command}: error: `--out`: cannot " in err and str(unwritable_out) in err, err


def test_the_captured_movements_line_ends_without_a_dangling_colon():
    """analyze-pointing's pointing_statistics.txt: a subject whose movements the model captures
    none of ends its line at the count, not at a colon before an empty list."""
    from fitting._pointing.prediction import PointingPrediction

    labels = ("out-N", "in-N")
    pred = types.SimpleNamespace(subjects=("s1", "s2"), labels=labels, captured=np.array([[True, False], [False] * 2]),
                                 n_captured=np.array([1, 0]), share_captured=np.array([0.5, 0.0]),
                                 n_tested=np.array([2, 2]))
    assert PointingPrediction.table(pred).splitlines() == [
        "s1: model captures A_net of 1 of 2 movements (50 %; 2 tested): out-N",
        "s2: model captures A_net of 0 of 2 movements (0 %; 2 tested)"]


@pytest.fixture
def no_movement_fit(monkeypatch):
    """fit-movements up to its fit: reaching fit_movements fails the test (the refusals below come first)."""
    from fitting import _movements

    def fit(*a, **k):
        raise AssertionError("fit_movements was reached")

    monkeypatch.setattr(_movements, "fit_movements", fit)


def test_fit_movements_refuses_before_its_fit_a_held_out_subject_a_slide_joint_and_a_folder(
        tmp_path, capsys, no_movement_fit):
    """A held-out recording of a subject with no recording to fit (predicted after minutes of fitting,
    then refused), a chain with a slide joint (whose metres a .mot in degrees would convert as angles)
    and a folder given as a recording are refused at once, each naming the file and the reason."""
    from pathlib import Path

    arm, reach = example("arm5.xml"), Path(example("reaching"))
    s3 = tmp_path / "S3_trial2.mot"
    s3.write_text((reach / "S1_trial2.mot").read_text())
    slide = tmp_path / "slide.xml"
    slide.write_text(Path(arm).read_text().replace('<joint name="elbow_flexion" axis="0 -1 0" range="0 150"/>',
                                                   '<joint name="elbow_flexion" type="slide" axis="0 -1 0"/>'))
    (tmp_path / "trials").mkdir()
    cases = [
        ([arm, str(reach / "S1_trial1.mot"), "--holdout", str(s3)],
         f"--holdout {s3}: its subject 'S3' has no recording to fit (subjects fitted: S1;"),
        ([str(slide), str(reach / "S1_trial1.mot")],
         f"--chain {slide}: slide joint(s) 'elbow_flexion': fit-movements fits joint angles"),
        ([arm, str(tmp_path / "trials")], f"{tmp_path / 'trials'}: is a directory, not a file"),
        ([str(tmp_path), str(reach / "S1_trial1.mot")], f"--chain {tmp_path}: is a folder, not an MJCF file"),
    ]
    for (chain, *rest), expect in cases:
        assert cli.main(["fit-movements", "--chain", chain, "--site", "hand", *rest,
                         "--out", str(tmp_path / "o")]) == 2
        err = capsys.readouterr().err
        assert len(err.strip().splitlines()) == 1 and f"pmpjax fit-movements: error: {expect}" in err, err


def test_radians_declared_as_degrees_warn(tmp_path):
    """A .sto in radians whose header says inDegrees=yes reads as reaches of a few degrees, which
    the reach finder then drops as too slow; the reader says what is likely wrong."""
    from pathlib import Path

    sto = Path(example("reaching")) / "S1_trial1.sto"
    path = tmp_path / "S1_trial1.sto"
    path.write_text(sto.read_text().replace("inDegrees=no", "inDegrees=yes"))
    with pytest.warns(UserWarning, match=r"S1_trial1\.sto: the angles are declared in degrees \('inDegrees=yes'\), "
                      r"but every value lies within ±π degrees \(largest [\d.]+°\): radians\? If so, set "
                      r"'inDegrees=no'"):
        pj.read_joint_angles(path)
    csv_path = tmp_path / "S1.csv"
    csv_path.write_text("# units: deg\ntime,a,b\n0,0.1,0.2\n0.01,0.2,-1.5\n")
    with pytest.warns(UserWarning, match=r"declared in degrees \('_deg' names or '# units: deg'\).*largest 1\.5°"):
        pj.read_joint_angles(csv_path)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        pj.read_joint_angles(Path(example("reaching")) / "S1_trial1.mot")  # (degrees beyond ±π: no warning)
        csv_path.write_text("# units: deg\ntime,a,b\n0,0.1,0.2\n0.01,0.2,-4\n")
        pj.read_joint_angles(csv_path)


def test_sweep_names_where_its_unwritable_folder_comes_from(tmp_path, capsys, monkeypatch):
    """The output folder given by the file's sweep.out is named as that key, not as --out, and the
    resumable store inside the output folder is checked before any work, named by the option (not
    by fitting.sweep's argument `out`)."""
    from pathlib import Path

    import fitting._sweep

    monkeypatch.setattr(fitting._sweep, "sweep", lambda *a, **k: pytest.fail("the sweep ran"))
    (tmp_path / "taken").write_text("x")
    config = tmp_path / "sweep.toml"
    config.write_text(Path(example("sweep_figure3.toml")).read_text().replace(
        'out = "out_sweep"', f'out = "{(tmp_path / "taken").as_posix()}"'))
    assert 'out = "out_sweep"' in Path(example("sweep_figure3.toml")).read_text()
    assert cli.main(["sweep", str(config)]) == 2
    assert f"pmpjax sweep: error: `sweep.out`: {tmp_path / 'taken'} is a file, not a folder" in capsys.readouterr().err
    (tmp_path / "o").mkdir()
    (tmp_path / "o" / "store").write_text("x")
    assert cli.main(["sweep", str(config), "--out", str(tmp_path / "o")]) == 2
    assert f"pmpjax sweep: error: `--out`: {tmp_path / 'o' / 'store'} is a file" in capsys.readouterr().err


def test_an_interrupted_command_ends_at_once_while_its_work_still_runs(tmp_path):
    """Ctrl-C while work of the command still runs in other threads (XLA's: the interpreter's exit
    then crashed with a segmentation fault, exit status 139, after the message): the command ends
    its process with status 130 and one line, without waiting for them. Here the work is a thread
    that would keep the interpreter's exit waiting for a minute."""
    import subprocess
    import sys
    import textwrap

    script = textwrap.dedent(f"""
        import sys, threading, time
        import fitting._donders
        def fit(*a, **k):
            threading.Thread(target=time.sleep, args=(60,)).start()
            raise KeyboardInterrupt
        fitting._donders.fit_donders = fit
        from pmpjax._app import cli
        sys.argv = ["pmpjax", "fit-donders", {example("donders_example.csv")!r}, "--out", {str(tmp_path)!r}]
        sys.exit(cli.main())
    """)
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=50)
    assert proc.returncode == 130 and proc.stderr.splitlines() == ["pmpjax fit-donders: interrupted"], proc.stderr


def test_fit_movements_reading_limits_are_options_and_named_as_such(tmp_path, capsys, monkeypatch):
    """Recordings with jittered sample times or a long gap are refused naming the option that
    admits them (the reader's `sample_tol`, `max_gap` are no options of the command), and with it
    they are read."""
    from pathlib import Path

    from fitting import _movements

    def fit(chain, recordings, **k):
        raise ValueError(f"read {len(recordings)} recording(s), gaps filled: {recordings[0].filled_gaps}")

    monkeypatch.setattr(_movements, "fit_movements", fit)
    lines = Path(example("reaching/S1_trial1.mot")).read_text().splitlines()
    head = lines.index("endheader") + 2
    jitter = [f"{float(r.split(chr(9))[0]) + (0.003 if k == 5 else 0):.3f}\t" + r.split("\t", 1)[1]
              for k, r in enumerate(lines[head:])]
    gap = [r.split("\t", 2)[0] + "\t" + r.split("\t", 2)[1] + "\tNaN\t" + r.split("\t", 3)[3] if 300 <= k < 310
           else r for k, r in enumerate(lines[head:])]
    for name, rows, option, value, expect in [
            ("S1_jitter.mot", jitter, "--sample-tol", "0.5", r"by more than --sample-tol 0\.01 \(relative\)"),
            ("S1_gap.mot", gap, "--max-gap", "0.2", r"valid samples, 0\.11 s, is longer than --max-gap 0\.05 s$")]:
        path = tmp_path / name
        path.write_text("\n".join(lines[:head] + rows) + "\n")
        argv = ["fit-movements", "--chain", example("arm5.xml"), "--site", "hand", str(path), "--out", str(tmp_path)]
        assert cli.main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith(f"pmpjax fit-movements: error: {path}: ") and re.search(expect, err), err
        assert cli.main([*argv, option, value]) == 2
        assert "error: read 1 recording(s)" in capsys.readouterr().err


def test_a_script_beside_a_clone_named_pmpjax_is_told_why_fitting_cannot_import(tmp_path):
    """A script kept in the folder that holds a clone named pmpjax: Python imports the clone's folder
    as an empty package, and ``import fitting`` says so (it said "cannot import name 'Status' from
    'pmpjax' (unknown location)")."""
    import os
    import subprocess
    import sys

    (tmp_path / "pmpjax" / "pmpjax").mkdir(parents=True)
    (tmp_path / "analysis.py").write_text("import fitting\n")
    run = {"cwd": tmp_path, "capture_output": True, "text": True, "env": {**os.environ, "PYTHONPATH": ""}}
    probe = subprocess.run([sys.executable, "-c", "import pmpjax; print(getattr(pmpjax, '__file__', None))"], **run)
    if probe.stdout.strip() != "None":
        pytest.skip("this installation of pmpjax takes precedence over a folder in the current one")
    proc = subprocess.run([sys.executable, "analysis.py"], **run)
    assert proc.returncode == 1 and proc.stderr.strip().splitlines()[-1] == (
        f"ImportError: Python imported the folder {tmp_path / 'pmpjax'} instead of the installed pmpjax (a script "
        "or python -m run in the folder that holds a clone named pmpjax puts that folder first): run it from any "
        "other folder"), proc.stderr


def test_simulate_writes_no_negative_zeros(tmp_path, monkeypatch):
    """trajectories.csv: a coordinate that is -0.0 (the screen point of the start posture, x1 of
    Figure 3's first sample) is written 0, not -0."""
    def simulate(model, planner, q0, targets, **k):
        S = 3
        return types.SimpleNamespace(t=np.linspace(0, 0.4, S), q=np.full((len(targets), S, 3), -0.0),
                                     x=np.full((len(targets), S, 2), -0.0), status=np.zeros(len(targets), int))

    monkeypatch.setattr(pj, "simulate", simulate)
    assert cli.main(["simulate", example("simulate_figure3.toml"), "--out", str(tmp_path)]) == 0
    rows = (tmp_path / "trajectories.csv").read_text().splitlines()[1:]
    assert rows[0] == "N,0,0,0,0,0,0" and not any("-0" in r for r in rows), rows[:3]
