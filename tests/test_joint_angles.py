"""``pj.read_joint_angles`` / ``pj.write_joint_angles`` / ``pj.JointRecording``: OpenSim .mot/.sto,
CSV and HuG-MP .mat joint-angle recordings, checked against hand-written files with known values."""

import warnings

import numpy as np
import pytest

import pmpjax as pj

MOT = """Coordinates
version=1
nRows=5
nColumns=4
inDegrees=yes

Units are S.I. units (second, meters, Newtons, ...)
endheader
time\tshoulder_elv\televation_angle\telbow_flexion
0.00\t10.0\t-20.0\t45.0
0.01\t11.5\t-19.0\t46.0
0.02\t13.0\t-18.0\t48.0
0.03\t14.5\t-17.0\t50.0
0.04\t16.0\t-16.0\t52.0
"""
LINE1 = 10  # file line of the first sample of MOT
DEG = np.array([[10.0, -20.0, 45.0], [11.5, -19.0, 46.0], [13.0, -18.0, 48.0], [14.5, -17.0, 50.0],
                [16.0, -16.0, 52.0]])
T = np.array([0.0, 0.01, 0.02, 0.03, 0.04])
NAMES = ("shoulder_elv", "elevation_angle", "elbow_flexion")


def write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return p


def csv_text(rows, header="time,a,b", pre=""):
    return pre + header + "\n" + "\n".join(rows) + "\n"


def test_mot_in_degrees_reads_radians_times_and_names(tmp_path):
    rec = pj.read_joint_angles(write(tmp_path, "P1_reach1.mot", MOT))
    np.testing.assert_array_equal(rec.q, np.deg2rad(DEG))
    np.testing.assert_array_equal(rec.t, T)
    assert rec.q.dtype == np.float64 and rec.q.shape == (5, 3)
    assert rec.joint_names == NAMES and rec.n == 3
    assert rec.fs == pytest.approx(100.0, rel=1e-12)
    assert (rec.subject, rec.name) == ("P1_reach1", "P1_reach1")
    assert rec.source.endswith("P1_reach1.mot")
    assert rec.ignored_columns == () and rec.filled_gaps == ()
    assert pj.read_joint_angles(tmp_path / "P1_reach1.mot", subject="P1").subject == "P1"


def test_space_separated_reads_as_tab_separated(tmp_path):
    tabs = pj.read_joint_angles(write(tmp_path, "tabs.mot", MOT))
    spaced = MOT.replace("\t", "  ")
    spaced = spaced.replace("0.02  13.0", "0.02 \t 13.0")  # mixed separators on one row
    sp = pj.read_joint_angles(write(tmp_path, "spaces.sto", spaced))
    np.testing.assert_array_equal(sp.q, tabs.q)
    np.testing.assert_array_equal(sp.t, tabs.t)
    assert sp.joint_names == tabs.joint_names


def test_in_degrees_no_keeps_radians(tmp_path):
    text = ("arm\nversion=1\ninDegrees=no\nendheader\ntime\tshoulder\telbow\n"
            "0.0\t0.1\t1.5\n0.02\t-0.25\t1.625\n0.04\t-0.5\t3.0\n")
    rec = pj.read_joint_angles(write(tmp_path, "rad.mot", text))
    np.testing.assert_array_equal(rec.q, [[0.1, 1.5], [-0.25, 1.625], [-0.5, 3.0]])
    assert rec.fs == pytest.approx(50.0, rel=1e-12)


def test_in_degrees_true_and_false_read_as_yes_and_no(tmp_path):
    # OpenSim writes booleans either way: 'false' means radians (values kept), 'true' degrees.
    body = "endheader\ntime\tshoulder\telbow\n0.0\t0.1\t1.5\n0.02\t-0.25\t1.625\n0.04\t-0.5\t3.0\n"
    rad = pj.read_joint_angles(write(tmp_path, "f.mot", "arm\ninDegrees=false\n" + body))
    np.testing.assert_array_equal(rad.q, [[0.1, 1.5], [-0.25, 1.625], [-0.5, 3.0]])
    deg = pj.read_joint_angles(write(tmp_path, "t.sto", "arm\ninDegrees=TRUE\n" + body))
    np.testing.assert_allclose(deg.q, np.pi / 180 * np.array([[0.1, 1.5], [-0.25, 1.625], [-0.5, 3.0]]),
                               rtol=1e-15, atol=0)


def test_four_missing_samples_at_100_hz_are_filled_by_default(tmp_path):
    # The documented default max_gap (0.05 s) bridges 4 missing samples at 100 Hz, not 5, wherever
    # the gap falls on the clock (decimal times are not exact in binary).
    for first in range(1, 30):
        times = [f"{k / 100:.2f}" for k in range(first + 6)]
        value = lambda k, gap: "nan" if first <= k < first + gap else f"{k / 10:.1f}"  # noqa: E731
        rows = [f"{s},{value(k, 4)},1" for k, s in enumerate(times)]
        rec = pj.read_joint_angles(write(tmp_path, "four.csv", csv_text(rows)))
        np.testing.assert_allclose(rec.q[:, 0], np.arange(first + 6) / 10, rtol=0, atol=1e-12)
        assert rec.filled_gaps == (("a", float(times[first]), float(times[first + 3])),)
        five = [f"{s},{value(k, 5)},1" for k, s in enumerate(times)]
        with pytest.raises(ValueError, match="longer than max_gap = 0.05 s"):
            pj.read_joint_angles(write(tmp_path, "five.csv", csv_text(five)))


def test_without_in_degrees_degrees_are_assumed_and_radian_like_values_warn(tmp_path):
    text = MOT.replace("inDegrees=yes\n", "")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rec = pj.read_joint_angles(write(tmp_path, "deg.mot", text))
    np.testing.assert_array_equal(rec.q, np.deg2rad(DEG))
    small = text.replace("10.0\t-20.0\t45.0", "0.1\t-0.2\t1.5")
    for row in ("11.5\t-19.0\t46.0", "13.0\t-18.0\t48.0", "14.5\t-17.0\t50.0", "16.0\t-16.0\t52.0"):
        small = small.replace(row, "0.2\t-0.1\t1.4")
    with pytest.warns(UserWarning, match=r"no inDegrees line, so degrees are assumed.*within ±π.*inDegrees=no"):
        rec = pj.read_joint_angles(write(tmp_path, "small.mot", small))
    np.testing.assert_array_equal(rec.q[0], np.deg2rad([0.1, -0.2, 1.5]))


@pytest.mark.parametrize("in_degrees", [True, False])
def test_mot_sto_csv_round_trip_identically(tmp_path, in_degrees):
    rng = np.random.default_rng(1)
    t = 0.25 + np.arange(200) / 120.0
    q = rng.uniform(-2.5, 2.5, (200, 4))
    rec = pj.JointRecording("P2", "reach3", t, q, ("sh_abd", "sh_flex", "sh_rot", "elbow"))
    back = {}
    for ext in (".mot", ".sto", ".csv"):
        p = pj.write_joint_angles(tmp_path / f"reach3{ext}", rec, in_degrees=in_degrees)
        back[ext] = pj.read_joint_angles(p, subject="P2")
    for ext, r in back.items():
        np.testing.assert_allclose(r.q, q, rtol=0, atol=1e-12, err_msg=ext)
        np.testing.assert_allclose(r.t, t, rtol=0, atol=1e-12, err_msg=ext)
        assert r.joint_names == rec.joint_names and r.subject == "P2" and r.name == "reach3"
        assert r.fs == pytest.approx(120.0, rel=1e-9)
    head = (tmp_path / "reach3.mot").read_text().splitlines()
    assert head[1:6] == ["version=1", "nRows=200", "nColumns=5", f"inDegrees={'yes' if in_degrees else 'no'}",
                         "endheader"]
    assert (tmp_path / "reach3.csv").read_text().startswith(f"# units: {'deg' if in_degrees else 'rad'}\n")


def test_csv_units_by_comment_line_and_column_suffixes(tmp_path):
    rows = ["0.0,10,0.5,90", "0.1,20,0.25,-90"]
    rec = pj.read_joint_angles(write(tmp_path, "s.csv", csv_text(rows, "Time [s],a_deg,b_rad,c (deg)")))
    assert rec.joint_names == ("a", "b", "c")
    np.testing.assert_array_equal(rec.q, [[np.deg2rad(10), 0.5, np.pi / 2], [np.deg2rad(20), 0.25, -np.pi / 2]])
    np.testing.assert_array_equal(rec.t, [0.0, 0.1])
    # a file-wide '# units: deg'; a column's own [rad] suffix wins
    rec = pj.read_joint_angles(write(tmp_path, "u.csv", csv_text(rows, "t,a,b [rad],c", pre="# units: deg\n")))
    np.testing.assert_array_equal(rec.q[:, 0], np.deg2rad([10, 20]))
    np.testing.assert_array_equal(rec.q[:, 1], [0.5, 0.25])
    # radians are the default; the header suffix need not be repeated in `joints`
    rec = pj.read_joint_angles(write(tmp_path, "r.csv", csv_text(["0,1,2,3", "0.1,1.5,2.5,3.5"], "time,a,b,c")))
    np.testing.assert_array_equal(rec.q, [[1, 2, 3], [1.5, 2.5, 3.5]])
    assert pj.read_joint_angles(tmp_path / "u.csv", joints=["b"]).joint_names == ("b",)


def test_columns_matched_by_name_extras_listed_missing_named(tmp_path):
    p = write(tmp_path, "P1.mot", MOT)
    rec = pj.read_joint_angles(p, joints=["elbow_flexion", "SHOULDER_ELV"])
    assert rec.joint_names == ("elbow_flexion", "shoulder_elv")
    np.testing.assert_array_equal(rec.q, np.deg2rad(DEG[:, [2, 0]]))
    assert rec.ignored_columns == ("elevation_angle",)
    with pytest.raises(ValueError, match=r"P1\.mot: line 9: joint\(s\) \['elbow_flex', 'wrist'\] not found "
                                         r"\('elbow_flex': did you mean 'elbow_flexion'\?\); the file's columns: "
                                         r"\['shoulder_elv', 'elevation_angle', 'elbow_flexion'\]"):
        pj.read_joint_angles(p, joints=["shoulder_elv", "elbow_flex", "wrist"])
    # case-insensitive matching must be unambiguous
    amb = write(tmp_path, "amb.csv", csv_text(["0,1,2", "0.1,1,2"], "time,Elbow,elbow"))
    with pytest.raises(ValueError, match=r"amb\.csv: line 1: joint 'ELBOW' matches several columns"):
        pj.read_joint_angles(amb, joints=["ELBOW"])
    assert pj.read_joint_angles(amb, joints=["elbow"]).joint_names == ("elbow",)


def test_a_chain_as_joints(tmp_path):
    two = write(tmp_path, "two.csv", csv_text(["0,0.1,0.2", "0.01,0.3,0.4"], "time,sh,el"))
    rec = pj.read_joint_angles(two, joints=pj.PlanarArm([0.3, 0.33]))  # no names: file order, n = 2
    assert rec.joint_names == ("sh", "el")
    np.testing.assert_array_equal(rec.q, [[0.1, 0.2], [0.3, 0.4]])

    class NamedArm(pj.PlanarArm):
        joint_names = ("el", "sh")

    rec = pj.read_joint_angles(two, joints=NamedArm([0.3, 0.33]))  # names: the chain's order
    assert rec.joint_names == ("el", "sh")
    np.testing.assert_array_equal(rec.q, [[0.2, 0.1], [0.4, 0.3]])

    class HalfNamedArm(pj.PlanarArm):
        joint_names = ("el", "shoulder")

    # one name is a column, so both must be: no silent fall back to the file's order
    with pytest.raises(ValueError, match=r"two\.csv: line 1: joint\(s\) \['shoulder'\] of HalfNamedArm\.joint_names "
                                         r"not found"):
        pj.read_joint_angles(two, joints=HalfNamedArm([0.3, 0.33]))
    # ShoulderElbowArm's names are plot labels, not columns: its 4 joints take a 4-column file in order
    four = write(tmp_path, "four.mot", "arm\ninDegrees=yes\nendheader\ntime\tabd\tflex\trot\telbow\n"
                                       "0\t-10\t-20\t5\t90\n0.01\t-11\t-21\t6\t91\n")
    rec = pj.read_joint_angles(four, joints=pj.ShoulderElbowArm())
    assert rec.joint_names == ("abd", "flex", "rot", "elbow")
    np.testing.assert_array_equal(rec.q, np.deg2rad([[-10, -20, 5, 90], [-11, -21, 6, 91]]))
    with pytest.raises(ValueError, match=r"P1\.mot: line 9: `joints` is a ShoulderElbowArm with 4 joints \(its "
                                         r".*the file has 3 angle columns.*pass joints=\[the 4 column names"):
        pj.read_joint_angles(write(tmp_path, "P1.mot", MOT), joints=pj.ShoulderElbowArm())
    with pytest.raises(ValueError, match=r"`joints` is a Wrist with 3 joints and no joint names, but the file has "
                                         r"2 angle columns \['sh', 'el'\]"):
        pj.read_joint_angles(two, joints=pj.Wrist())


def test_opensim_translations_are_left_out(tmp_path):
    text = ("ik\ninDegrees=yes\nendheader\ntime pelvis_tx elbow pelvis_ty\n0 0.5 30 0.9\n0.01 0.6 31 0.9\n")
    p = write(tmp_path, "full.mot", text)
    rec = pj.read_joint_angles(p)
    assert rec.joint_names == ("elbow",) and rec.ignored_columns == ("pelvis_tx", "pelvis_ty")
    np.testing.assert_array_equal(rec.q[:, 0], np.deg2rad([30, 31]))
    with pytest.raises(ValueError, match=r"\['pelvis_tx'\] are translational coordinates \[m\]"):
        pj.read_joint_angles(p, joints=["elbow", "pelvis_tx"])


def test_short_nan_gaps_are_interpolated_and_reported(tmp_path):
    rows = ["0.00,1.0,10", "0.01,nan,20", "0.02,,30", "0.03,4.0,40", "0.04,5.0,NaN", "0.05,6.5,60"]
    rec = pj.read_joint_angles(write(tmp_path, "gap.csv", csv_text(rows, pre="# units: deg\n")))
    # linear interpolation in time between the valid neighbours: a from 1.0 (t=0) to 4.0 (t=0.03) [deg]
    np.testing.assert_allclose(rec.q[:, 0], np.deg2rad([1.0, 2.0, 3.0, 4.0, 5.0, 6.5]), rtol=0, atol=1e-12)
    np.testing.assert_allclose(rec.q[:, 1], np.deg2rad([10, 20, 30, 40, 50, 60]), rtol=0, atol=1e-12)
    assert rec.filled_gaps == (("a", 0.01, 0.02), ("b", 0.04, 0.04))


def test_long_gaps_and_gaps_at_the_ends_are_refused(tmp_path):
    rows = ["0.00,1,1"] + [f"0.0{i},nan,1" for i in range(1, 6)] + ["0.06,1.5,1"]
    p = write(tmp_path, "long.csv", csv_text(rows))
    with pytest.raises(ValueError, match=r"long\.csv: column 2 \('a'\): missing values \(NaN\) from t = 0\.01 to "
                                         r"0\.05 s \(lines 3-7\): the gap between valid samples, 0\.06 s, is longer "
                                         r"than max_gap = 0\.05 s"):
        pj.read_joint_angles(p)
    assert pj.read_joint_angles(p, max_gap=0.06).filled_gaps == (("a", 0.01, 0.05),)
    assert pj.read_joint_angles(p, joints=["b"]).filled_gaps == ()  # an ignored column's NaN do not matter
    start = write(tmp_path, "start.csv", csv_text(["0,1,nan", "0.01,1,2", "0.02,1,3"]))
    with pytest.raises(ValueError, match=r"column 3 \('b'\): missing values \(NaN\) from t = 0\.0 to 0\.0 s "
                                         r"\(lines 2-2\) at the start of the recording"):
        pj.read_joint_angles(start)
    end = write(tmp_path, "end.csv", csv_text(["0,1,1", "0.01,1,2", "0.02,nan,3"]))
    with pytest.raises(ValueError, match=r"column 2 \('a'\).*at the end of the recording"):
        pj.read_joint_angles(end)


@pytest.mark.bad_input("pj.read_joint_angles")
def test_time_must_increase_evenly_in_seconds(tmp_path):
    back = MOT.replace("0.02\t13.0", "0.01\t13.0")
    with pytest.raises(ValueError, match=rf"back\.mot: line {LINE1 + 2}, column 1 \('time'\): time not strictly "
                                         r"increasing \(0\.01 then 0\.01\)"):
        pj.read_joint_angles(write(tmp_path, "back.mot", back))
    uneven = MOT.replace("0.03\t14.5", "0.035\t14.5")
    with pytest.raises(ValueError, match=rf"uneven\.mot: line {LINE1 + 3}, column 1 \('time'\): uneven sampling: "
                                         r"interval 0\.015 s"):
        pj.read_joint_angles(write(tmp_path, "uneven.mot", uneven))
    # a 0.5 % jitter passes the default 1 % tolerance, not a 0.1 % one
    jitter = write(tmp_path, "jitter.mot", MOT.replace("0.03\t14.5", "0.03005\t14.5"))
    assert pj.read_joint_angles(jitter).t[3] == 0.03005
    with pytest.raises(ValueError, match=rf"line {LINE1 + 3}, .*sample_tol = 0\.001"):
        pj.read_joint_angles(jitter, sample_tol=0.001)
    ms = write(tmp_path, "ms.csv", csv_text(["0,1,2", "10,1,2", "20,1,2"]))
    with pytest.raises(ValueError, match=r"median sample interval 10 s: time must be in seconds"):
        pj.read_joint_angles(ms)
    with pytest.raises(ValueError, match=r"only 1 sample"):
        pj.read_joint_angles(write(tmp_path, "one.csv", csv_text(["0,1,2"])))


@pytest.mark.bad_input("pj.read_joint_angles")
def test_unreadable_files_are_refused_for_the_right_reason(tmp_path):
    (tmp_path / "dir.mot").mkdir()
    with pytest.raises(ValueError, match=r"dir\.mot: is a directory, not a file"):
        pj.read_joint_angles(tmp_path / "dir.mot")
    with pytest.raises(ValueError, match=r"empty\.csv: empty file"):
        pj.read_joint_angles(write(tmp_path, "empty.csv", ""))
    with pytest.raises(FileNotFoundError, match=r"nothere\.mot: no such file"):
        pj.read_joint_angles(tmp_path / "nothere.mot")
    (tmp_path / "bin.mot").write_bytes(b"Coordinates\nendheader\n\x00\x01\x02\xff\xfe")
    with pytest.raises(ValueError, match=r"bin\.mot: a binary file \(NUL byte at byte 22, line 3\), not a \.mot "
                                         r"text file"):
        pj.read_joint_angles(tmp_path / "bin.mot")
    (tmp_path / "latin1.csv").write_bytes("# angles in °\ntime,a\n0,1\n0.01,2\n".encode("latin-1"))
    with pytest.raises(ValueError, match=r"latin1\.csv: not a UTF-8 text file \(line 1, byte 12.*text in another "
                                         r"encoding.*save it as UTF-8"):
        pj.read_joint_angles(tmp_path / "latin1.csv")
    with pytest.raises(ValueError, match=r"no header row \(only comments or blank lines\)"):
        pj.read_joint_angles(write(tmp_path, "comments.csv", "# units: deg\n\n"))
    with pytest.raises(ValueError, match=r"`path` must end in \.mot, \.sto, \.csv, \.mat, got '.*a\.txt'"):
        pj.read_joint_angles(write(tmp_path, "a.txt", "time,a\n0,1\n"))
    with pytest.raises(TypeError, match=r"`path` must be a path"):
        pj.read_joint_angles(3)


@pytest.mark.bad_input("pj.read_joint_angles")
def test_malformed_rows_and_headers_name_file_line_and_column(tmp_path):
    short = MOT.replace("0.02\t13.0\t-18.0\t48.0", "0.02\t13.0\t-18.0")
    with pytest.raises(ValueError, match=rf"short\.mot: line {LINE1 + 2}: expected 4 fields \(the columns of line 9\), "
                                         r"got 3"):
        pj.read_joint_angles(write(tmp_path, "short.mot", short))
    word = MOT.replace("0.03\t14.5\t-17.0\t50.0", "0.03\t14.5\tx17\t50.0")
    with pytest.raises(ValueError, match=rf"word\.mot: line {LINE1 + 3}, column 3 \('elevation_angle'\): not a "
                                         r"number: 'x17'"):
        pj.read_joint_angles(write(tmp_path, "word.mot", word))
    # inf refused as inf (not by the radian range that happens to exclude it), in degrees too
    with pytest.raises(ValueError, match=r"c\.csv: line 4, column 3 \('b'\): inf: 'inf'$"):
        pj.read_joint_angles(write(tmp_path, "c.csv", csv_text(["0,1,2", "0.01,1,2", "0.02,1,inf"])))
    with pytest.raises(ValueError, match=r"d\.csv: line 3, column 2 \('a_deg'\): inf: '-inf'$"):
        pj.read_joint_angles(write(tmp_path, "d.csv", csv_text(["0,1,2", "0.01,-inf,2"], "time,a_deg,b_deg")))
    with pytest.raises(ValueError, match=r"tn\.csv: line 3, column 1 \('time'\): not a number: ''"):
        pj.read_joint_angles(write(tmp_path, "tn.csv", csv_text(["0,1,2", ",1,2"])))
    with pytest.raises(ValueError, match=r"rows\.mot: line 3: nRows=5 but the file has 4 data rows"):
        pj.read_joint_angles(write(tmp_path, "rows.mot", MOT.replace("0.04\t16.0\t-16.0\t52.0\n", "")))
    with pytest.raises(ValueError, match=r"cols\.mot: line 4: nColumns=4 but the file has 3 columns"):
        pj.read_joint_angles(write(tmp_path, "cols.mot", "\n".join(
            line.rsplit("\t", 1)[0] if i >= 8 else line for i, line in enumerate(MOT.splitlines())) + "\n"))
    with pytest.raises(ValueError, match=r"noend\.mot: no 'endheader' line"):
        pj.read_joint_angles(write(tmp_path, "noend.mot", MOT.replace("endheader", "")))
    with pytest.raises(ValueError, match=r"frame\.mot: line 9, column 1: the first column label must be 'time', "
                                         r"got 'frame'"):
        pj.read_joint_angles(write(tmp_path, "frame.mot", MOT.replace("time\t", "frame\t")))
    with pytest.raises(ValueError, match=r"yn\.mot: line 5: inDegrees must be 'yes' or 'no', got 'maybe'"):
        pj.read_joint_angles(write(tmp_path, "yn.mot", MOT.replace("inDegrees=yes", "inDegrees=maybe")))
    with pytest.raises(ValueError, match=r"vec\.sto: line 2: DataType=Vec3"):
        pj.read_joint_angles(write(tmp_path, "vec.sto", MOT.replace("version=1", "DataType=Vec3")))
    with pytest.raises(ValueError, match=r"notime\.csv: line 1: no time column"):
        pj.read_joint_angles(write(tmp_path, "notime.csv", csv_text(["0,1,2"], "frame,a,b")))
    with pytest.raises(ValueError, match=r"dup\.csv: line 2: duplicate column 'a' \('a_deg' and 'a \[rad\]'\)"):
        pj.read_joint_angles(write(tmp_path, "dup.csv", csv_text(["0,1,2"], "time,a_deg,a [rad]", pre="# x\n")))
    with pytest.raises(ValueError, match=r"units\.csv: line 1: unknown unit 'grad'"):
        pj.read_joint_angles(write(tmp_path, "units.csv", csv_text(["0,1,2"], pre="# units: grad\n")))


@pytest.mark.bad_input("pj.read_joint_angles")
def test_radians_that_look_like_degrees_get_a_hint(tmp_path):
    p = write(tmp_path, "deg.csv", csv_text(["0,0.5,30", "0.01,0.6,95"], "time,shoulder,elbow"))
    with pytest.raises(ValueError, match=r"deg\.csv: line 2, column 3 \('elbow'\): 30\.0 rad is beyond ±2π: these "
                                         r"look like degrees; if they are, name the column elbow_deg \(or elbow "
                                         r"\[deg\]\), or put '# units: deg' before the header"):
        pj.read_joint_angles(p)
    assert pj.read_joint_angles(p, joints=["shoulder"]).q[1, 0] == 0.6  # the column read is fine
    with pytest.raises(ValueError, match=rf"line {LINE1}, column 2 \('shoulder_elv'\): 10\.0 rad .*set "
                                         r"'inDegrees=yes' in the header"):
        pj.read_joint_angles(write(tmp_path, "no.mot", MOT.replace("inDegrees=yes", "inDegrees=no")))


@pytest.mark.bad_input("pj.read_joint_angles")
def test_bad_arguments_are_named(tmp_path):
    p = write(tmp_path, "P1.mot", MOT)
    with pytest.raises(TypeError, match=r"`joints` must be None, a sequence of joint names or a pmpjax chain, got int"):
        pj.read_joint_angles(p, joints=3)
    with pytest.raises(TypeError, match=r"`joints` must hold non-empty joint names"):
        pj.read_joint_angles(p, joints=["elbow_flexion", 2])
    with pytest.raises(ValueError, match=r"`joints` names \['elbow_flexion'\] more than once"):
        pj.read_joint_angles(p, joints=["elbow_flexion", "elbow_flexion"])
    with pytest.raises(TypeError, match=r"`subject` must be a non-empty str"):
        pj.read_joint_angles(p, subject=1)
    with pytest.raises(ValueError, match=r"`max_gap` must be a duration >= 0"):
        pj.read_joint_angles(p, max_gap=-0.1)
    with pytest.raises(ValueError, match=r"`sample_tol` must be positive"):
        pj.read_joint_angles(p, sample_tol=0)
    with pytest.raises(ValueError, match=r"`motion` picks a motion of a HuG-MP \.mat file; P1\.mot is a \.mot file"):
        pj.read_joint_angles(p, motion=(1, 1, 1))
    assert pj.read_joint_angles(p, joints="elbow_flexion").joint_names == ("elbow_flexion",)


@pytest.mark.bad_input("pj.read_joint_angles")
def test_hugmp_motion_from_the_shipped_data(tmp_path):
    from pmpjax._data.hugmp import hugmp_directory

    path = hugmp_directory() / "S01_trajs.mat"
    subject = pj.load_hugmp(1)
    want = next(q for r, i, q in subject.motions[2] if (r, i) == (3, 2))
    rec = pj.read_joint_angles(path, motion=(2, 3, 2))
    np.testing.assert_array_equal(rec.q, want)
    np.testing.assert_array_equal(rec.t, np.arange(want.shape[0]) / 100.0)
    assert (rec.subject, rec.name, rec.fs) == ("S01", "S01_task2_rep3_motion2", 100.0)
    assert rec.joint_names == ("q1", "q2", "q3", "q4")
    sub = pj.read_joint_angles(path, motion=(2, 3, 2), joints=["q4", "q1"], subject="P7")
    np.testing.assert_array_equal(sub.q, want[:, [3, 0]])
    assert sub.ignored_columns == ("q2", "q3") and sub.subject == "P7"
    np.testing.assert_array_equal(pj.read_joint_angles(path, motion=(2, 3, 2), joints=pj.ShoulderElbowArm()).q, want)
    with pytest.raises(ValueError, match=r"S01_trajs\.mat: a HuG-MP file holds 300 separate motions; pick one with "
                                         r"motion=\(task, repetition, index\)"):
        pj.read_joint_angles(path)
    with pytest.raises(ValueError, match=r"S01_trajs\.mat: no motion \(task 5, repetition 1, index 3\)"):
        pj.read_joint_angles(path, motion=(5, 1, 3))
    with pytest.raises(TypeError, match=r"`motion` must be \(task, repetition, index\), three integers"):
        pj.read_joint_angles(path, motion=(1, 1))
    with pytest.raises(ValueError, match=r"S01_trajs\.mat: joint\(s\) \['q5'\] not found"):
        pj.read_joint_angles(path, motion=(1, 1, 1), joints=["q5"])
    (tmp_path / "reach.mat").write_bytes(path.read_bytes())
    with pytest.raises(ValueError, match=r"reach\.mat: a \.mat file is read as a HuG-MP subject file, named "
                                         r"S<nn>_trajs\.mat"):
        pj.read_joint_angles(tmp_path / "reach.mat", motion=(1, 1, 1))


@pytest.mark.bad_input("pj.JointRecording", "pj.write_joint_angles")
def test_recording_fields_and_writer_arguments_are_checked(tmp_path):
    t, q = np.arange(3) / 100.0, np.zeros((3, 2))
    with pytest.raises(ValueError, match=r"`q` must have shape \(T, n\) = \(3, n >= 1\) \[rad\], got \(2, 2\)"):
        pj.JointRecording("s", "r", t, q[:2], ("a", "b"))
    with pytest.raises(ValueError, match=r"`joint_names` must be 2 non-empty names.*got \['a'\]"):
        pj.JointRecording("s", "r", t, q, ("a",))
    with pytest.raises(ValueError, match=r"`joint_names` must be unique"):
        pj.JointRecording("s", "r", t, q, ("a", "a"))
    with pytest.raises(ValueError, match=r"`t` must be finite and strictly increasing"):
        pj.JointRecording("s", "r", t[::-1], q, ("a", "b"))
    with pytest.raises(ValueError, match=r"`fs` must be a positive sampling rate \[Hz\], got -1"):
        pj.JointRecording("s", "r", t, q, ("a", "b"), fs=-1)
    with pytest.raises(ValueError, match=r"`q` contains NaN or inf"):
        pj.JointRecording("s", "r", t, q + np.nan, ("a", "b"))
    with pytest.raises(ValueError, match=r"`subject` must be a non-empty str"):
        pj.JointRecording("", "r", t, q, ("a", "b"))
    rec = pj.JointRecording("s", "r", t, q, ["a", "b"])
    assert rec.joint_names == ("a", "b") and rec.fs == pytest.approx(100.0) and rec.source == "<memory>"
    with pytest.raises(TypeError, match=r"`recording` must be a pmpjax.JointRecording, got ndarray"):
        pj.write_joint_angles(tmp_path / "x.mot", q)
    with pytest.raises(ValueError, match=r"`path` must end in \.mot, \.sto or \.csv, got '.*x\.mat'"):
        pj.write_joint_angles(tmp_path / "x.mat", rec)
    with pytest.raises(TypeError, match=r"`in_degrees` must be True or False"):
        pj.write_joint_angles(tmp_path / "x.mot", rec, in_degrees="yes")
    spaced = pj.JointRecording("s", "r", t, q, ("a b", "c"))
    with pytest.raises(ValueError, match=r"OpenSim column labels cannot hold whitespace: \['a b'\]"):
        pj.write_joint_angles(tmp_path / "x.mot", spaced)
    with pytest.raises(ValueError, match=r"joint name\(s\) \['b_deg'\] would read as the time column or a unit"):
        pj.write_joint_angles(tmp_path / "x.csv", pj.JointRecording("s", "r", t, q, ("a", "b_deg")))
    back = pj.read_joint_angles(pj.write_joint_angles(tmp_path / "x.csv", spaced))  # CSV holds spaces
    assert back.joint_names == ("a b", "c")
