"""IK data: the paper's MAT layout (round trips, files built independently with scipy.io.savemat
and with h5py in MATLAB's v7.3 conventions, malformed files), the bundled HuG-MP recordings
(irregular cells, smoothing and kinematics, weights with bootstrap intervals), the Eq 25
prosthetic elbow, and bad input of every data entry point.

References: scipy.io / h5py files written here field by field; a direct scipy.io scan of the raw
HuG-MP cells; ``scipy.signal.savgol_filter`` per motion and ``np.interp``; closed forms (cubic
trajectories are reproduced exactly by a cubic Savitzky–Golay filter); the README's arm formula
with complex-step Jacobians and central differences (``_reference``); NumPy's weighted
pseudo-inverse formula.
"""

from importlib import resources
from pathlib import Path

import h5py
import jax
import numpy as np
import pytest
import scipy.io
from _reference import arm4_fk, arm4_jac, ik_fig1_numpy, planar_jac, weighted_pinv
from scipy.optimize import least_squares
from scipy.signal import savgol_filter
from scipy.stats import norm

import fitting
import pmpjax as pj
from pmpjax._data.hugmp import hugmp_directory


@pytest.fixture(scope="module")
def dataset():
    return fitting.synthetic_ik_dataset(seed=4, n_participants=3, n_trials=4)


def test_synthetic_dataset_layout(dataset):
    parts = dataset["participants"]
    assert len(parts) == 3 and list(parts[0]) == ["Natural", "Viscous"]
    assert list(parts[0]["Natural"]) == ["Target1", "Target2", "Target3"]
    tr = parts[1]["Viscous"]["Target2"][0]
    assert tr["q"].shape == (100, 4) and tr["xdot"].shape == (100, 3) and tr["J"].shape == (100, 3, 4)
    # ẋ = J q̇ and J is the README chain's Jacobian at q (NumPy, complex steps)
    assert np.allclose(tr["xdot"], np.einsum("sij,sj->si", tr["J"], tr["qdot"]))
    assert np.allclose(tr["J"][::17], [arm4_jac(q) for q in tr["q"][::17]], atol=1e-12)
    w = np.array([[d[c] for c in ("Natural", "Viscous")] for d in dataset["w_true"]])
    assert np.all(w[:, 1, 2] > 3 * w[:, 0, 2])  # joint 3 is much costlier in the viscous field
    # Human-like reaches: every goal is inside the README arm's reach and every trial stays clear
    # of the straight-elbow singularity (joint speeds of a 1 s reach stay below 5 rad/s; goals out
    # of reach once gave 1e5 rad/s).
    trials = [tr for d in parts for c in d.values() for t in c.values() for tr in t]
    assert max(np.abs(tr["qdot"]).max() for tr in trials) < 5.0
    assert min(np.linalg.svd(tr["J"], compute_uv=False)[:, -1].min() for tr in trials) > 0.05


def _equal_datasets(a, b):
    for p, (pa, pb) in enumerate(zip(a["participants"], b["participants"])):
        assert list(pa) == list(pb)
        for c in pa:
            assert list(pa[c]) == list(pb[c])
            for t in pa[c]:
                assert len(pa[c][t]) == len(pb[c][t])
                for ta, tb in zip(pa[c][t], pb[c][t]):
                    for k in ("q", "qdot", "xdot", "J"):
                        np.testing.assert_array_equal(ta[k], tb[k], err_msg=f"{p} {c} {t} {k}")


@pytest.mark.parametrize("version", ["5", "7.3"])
def test_round_trip_mat(dataset, tmp_path, version):
    path = tmp_path / f"ik_{version}.mat"
    pj.write_ik_dataset(path, dataset, version=version)
    head = path.read_bytes()[:20]
    assert head.startswith(b"MATLAB 7.3" if version == "7.3" else b"MATLAB 5.0")
    back = pj.load_ik_dataset(path)
    _equal_datasets(dataset, back)
    for p, a in enumerate(dataset["participants"]):
        for c in a:
            # IK_data: concatenation over targets and trials, ready for Algorithm 1
            cat = np.concatenate([tr["qdot"] for t in a[c] for tr in a[c][t]])
            assert np.array_equal(back["ik_data"][p][c]["qdot"], cat)
            assert back["ik_data"][p][c]["J"].shape == (cat.shape[0], 3, 4)
        assert all(np.array_equal(dataset["w_true"][p][c], back["w_true"][p][c]) for c in a)
    arr = pj.ik_dataset_arrays(back)
    assert arr["qdot"].shape[:3] == (3, 2, 3) and arr["mask"].any(-1).sum() == sum(
        len(v) for part in back["participants"] for cond in part.values() for v in cond.values())
    # the padded arrays hold the trials in order
    tr = back["participants"][2]["Viscous"]["Target3"][1]
    np.testing.assert_array_equal(arr["J"][2, 1, 2, 1, :100], tr["J"])


# ---------------------------------------------------------------------------------------------
# files built independently, in the paper's S1 layout


def _source(rng):
    """A small data set: 2 participants, Natural/Viscous, 2 targets, trials of S samples (one of
    a single sample, which MATLAB stores with squeezed dimensions)."""
    parts = []
    for p in range(2):
        part = {}
        for c in ("Natural", "Viscous"):
            part[c] = {}
            for t, sizes in (("Target1", (7, 5)), ("Target2", (6, 1, 4))):
                part[c][t] = [{"q": rng.standard_normal((S, 4)), "qdot": rng.standard_normal((S, 4)),
                               "xdot": rng.standard_normal((S, 3)), "J": rng.standard_normal((S, 3, 4))}
                              for S in sizes]
        parts.append(part)
    return {"participants": parts}


def _matlab_trial(tr):
    return {"q": tr["q"], "dq": tr["qdot"], "dx": tr["xdot"], "J": np.moveaxis(tr["J"], 0, -1)}


def test_reads_a_scipy_savemat_v5_file(tmp_path):
    """Cells as (N, 1) object arrays, structs as dicts, Target2's trials as a 1×T struct array,
    extra numeric and char fields (the paper's files carry estimated weights): as MATLAB saves."""
    src = _source(np.random.default_rng(1))
    data = np.empty((2, 1), dtype=object)
    for p, part in enumerate(src["participants"]):
        ps = {"subject": f"P{p + 1:02d}", "w_est": np.ones((1, 4))}
        for c, targets in part.items():
            t1 = np.empty((len(targets["Target1"]), 1), dtype=object)
            for i, tr in enumerate(targets["Target1"]):
                t1[i, 0] = _matlab_trial(tr)
            t2 = np.empty((1, len(targets["Target2"])), dtype=[(k, object) for k in ("q", "dq", "dx", "J")])
            for i, tr in enumerate(targets["Target2"]):
                for k, v in _matlab_trial(tr).items():
                    t2[0, i][k] = v
            ps[c] = {"Target1": t1, "Target2": t2}
        data[p, 0] = ps
    path = tmp_path / "s1_v5.mat"
    scipy.io.savemat(path, {"data": data})
    back = pj.load_ik_dataset(path)
    _equal_datasets(src, back)
    assert back["w_true"] is None and back["ik_data"] == [{}, {}]
    raw = pj.read_mat(path)
    assert raw["data"][1]["subject"] == "P02" and np.array_equal(raw["data"][0]["w_est"], np.ones(4))


class _Mat73:
    """A MATLAB v7.3 writer written from MATLAB's conventions (not the library's): structs are
    groups with ``MATLAB_class`` 'struct' and ``MATLAB_fields``; cells are reference datasets into
    ``#refs#``; struct arrays are groups of reference datasets; arrays are stored transposed
    (column-major); char is uint16; a 512-byte user block starts with MATLAB's text header."""

    def __init__(self, path):
        self.f = h5py.File(path, "w", userblock_size=512)
        self.refs = self.f.create_group("#refs#")
        self.count = 0

    def close(self, path):
        self.f.close()
        head = b"MATLAB 7.3 MAT-file, Platform: test, Created on: 2026 HDF5 schema 1.00 ."
        with open(path, "r+b") as fh:
            fh.write(head.ljust(116) + b"\0" * 8 + b"\x00\x02IM")

    def _fields(self, g, names):
        g.attrs["MATLAB_class"] = np.bytes_("struct")
        fields = np.empty(len(names), dtype=object)
        for i, k in enumerate(names):
            fields[i] = np.array([c.encode() for c in k], dtype="S1")
        g.attrs.create("MATLAB_fields", fields, dtype=h5py.vlen_dtype(np.dtype("S1")))

    def _ref(self, value):
        self.count += 1
        return self.put(self.refs, f"x{self.count}", value).ref

    def put(self, group, name, value):
        if isinstance(value, dict):
            g = group.create_group(name)
            self._fields(g, list(value))
            for k, v in value.items():
                self.put(g, k, v)
            return g
        if isinstance(value, tuple) and value[0] == "struct_array":
            g = group.create_group(name)
            items = value[1]
            self._fields(g, list(items[0]))
            for k in items[0]:
                refs = [self._ref(it[k]) for it in items]
                g.create_dataset(k, data=np.array(refs, dtype=h5py.ref_dtype).reshape(len(items), 1))
            return g
        if isinstance(value, list):  # an N×1 cell: HDF5 shape (1, N)
            ds = group.create_dataset(name, data=np.array([self._ref(v) for v in value],
                                                          dtype=h5py.ref_dtype).reshape(1, -1))
            ds.attrs["MATLAB_class"] = np.bytes_("cell")
            return ds
        if isinstance(value, str):
            ds = group.create_dataset(name, data=np.frombuffer(value.encode("utf-16-le"), np.uint16)[:, None])
            ds.attrs["MATLAB_class"] = np.bytes_("char")
            ds.attrs["MATLAB_int_decode"] = np.int32(2)
            return ds
        a = np.asarray(value)
        cls = {"f": "double", "b": "logical", "i": "int32"}[a.dtype.kind]
        if a.size == 0:
            ds = group.create_dataset(name, data=np.array(a.shape, np.uint64))
            ds.attrs["MATLAB_empty"] = np.uint8(1)
        else:
            a = a.reshape(a.shape + (1,) * (2 - a.ndim))
            ds = group.create_dataset(name, data=(a.astype(np.uint8) if cls == "logical" else a).T)
        ds.attrs["MATLAB_class"] = np.bytes_(cls)
        return ds


def test_reads_an_h5py_v73_file(tmp_path):
    src = _source(np.random.default_rng(2))
    path = tmp_path / "s1_v73.mat"
    w = _Mat73(path)
    parts = []
    for p, part in enumerate(src["participants"]):
        ps = {"subject": f"P{p + 1:02d}", "ok": np.array([[True, False]]), "n": np.array([[4]], np.int32),
              "none": np.zeros((0, 3))}
        for c, targets in part.items():
            ps[c] = {"Target1": [_matlab_trial(tr) for tr in targets["Target1"]],
                     "Target2": ("struct_array", [_matlab_trial(tr) for tr in targets["Target2"]])}
        cat = [tr for t in part["Natural"].values() for tr in t]
        ps["IK_data"] = {"Natural": {"dq": np.concatenate([tr["qdot"] for tr in cat]).T,
                                     "dx": np.concatenate([tr["xdot"] for tr in cat]).T,
                                     "J": np.concatenate([tr["J"] for tr in cat]).transpose(1, 2, 0)}}
        ps["w_true"] = {"Natural": np.array([[1.0, 0.5, 0.2, 1.0]]), "Viscous": np.array([[1.0, 0.4, 0.9, 1.0]])}
        parts.append(ps)
    w.put(w.f, "data", parts)
    w.close(path)
    assert path.read_bytes()[:10] == b"MATLAB 7.3"
    back = pj.load_ik_dataset(path)
    _equal_datasets(src, back)
    cat = [tr for t in src["participants"][1]["Natural"].values() for tr in t]
    np.testing.assert_array_equal(back["ik_data"][1]["Natural"]["J"], np.concatenate([tr["J"] for tr in cat]))
    np.testing.assert_array_equal(back["w_true"][0]["Viscous"], [1.0, 0.4, 0.9, 1.0])
    raw = pj.read_mat(path)["data"][0]
    assert raw["subject"] == "P01" and raw["ok"].tolist() == [True, False] and int(raw["n"]) == 4
    assert raw["ok"].dtype == bool and raw["none"].size == 0
    # the same content read from a v5 file (written by scipy) gives the same Python objects
    v5 = tmp_path / "same_v5.mat"
    scipy.io.savemat(v5, {"s": {"a": np.arange(6.0).reshape(2, 3), "name": "abc"}})
    w = _Mat73(tmp_path / "same_v73.mat")
    w.put(w.f, "s", {"a": np.arange(6.0).reshape(2, 3), "name": "abc"})
    w.close(tmp_path / "same_v73.mat")
    r5, r73 = pj.read_mat(v5)["s"], pj.read_mat(tmp_path / "same_v73.mat")["s"]
    assert r5["name"] == r73["name"] == "abc" and np.array_equal(r5["a"], r73["a"])


@pytest.mark.bad_input("pj.read_mat", "pj.load_ik_dataset")
def test_malformed_mat_files_name_the_file_and_the_field(tmp_path, dataset):
    with pytest.raises(FileNotFoundError, match="missing.mat"):
        pj.load_ik_dataset(tmp_path / "missing.mat")
    with pytest.raises(TypeError, match="path"):
        pj.read_mat(3)
    junk = tmp_path / "junk.mat"
    junk.write_bytes(b"not a mat file" * 20)
    with pytest.raises(ValueError, match="junk.mat: not a MATLAB"):
        pj.load_ik_dataset(junk)
    short = tmp_path / "short.mat"
    short.write_bytes(b"MATLAB")
    with pytest.raises(ValueError, match="short.mat.*too short"):
        pj.read_mat(short)
    other = tmp_path / "other.mat"
    scipy.io.savemat(other, {"x": np.ones(3)})
    with pytest.raises(ValueError, match="other.mat: no variable `data`"):
        pj.load_ik_dataset(other)
    bad = tmp_path / "bad.mat"
    trial = {"q": np.ones((5, 4)), "dq": np.ones((5, 4)), "dx": np.ones((5, 3)), "J": np.ones((3, 4, 4))}
    scipy.io.savemat(bad, {"data": np.array([[{"Natural": {"Target1": np.array([[trial]], dtype=object)}}]],
                                            dtype=object)})
    with pytest.raises(ValueError, match=r"bad.mat: data\{1\}.Natural.Target1\{1\}.*inconsistent shapes"):
        pj.load_ik_dataset(bad)
    nodq = tmp_path / "nodq.mat"
    scipy.io.savemat(nodq, {"data": np.array([[{"Natural": {"T": {"q": np.ones((2, 4)), "J": np.ones((3, 4, 2))}}}]],
                                             dtype=object)})
    with pytest.raises(ValueError, match=r"nodq.mat: data\{1\}.Natural.T\{1\}.*missing field `dq`"):
        pj.load_ik_dataset(nodq)
    cell = tmp_path / "cell.mat"
    scipy.io.savemat(cell, {"data": np.array([[{"Natural": {"T": np.array([[np.ones(3)]], dtype=object)}}]],
                                             dtype=object)})
    with pytest.raises(ValueError, match=r"cell.mat: data\{1\}.Natural.T\{1\}.*expected a struct"):
        pj.load_ik_dataset(cell)
    obj = tmp_path / "obj.mat"
    w = _Mat73(obj)
    g = w.f.create_group("data")
    g.attrs["MATLAB_class"] = np.bytes_("struct")
    ds = g.create_dataset("fh", data=np.zeros((1, 1)))
    ds.attrs["MATLAB_class"] = np.bytes_("function_handle")
    w.close(obj)
    with pytest.raises(ValueError, match=r"obj.mat.*variable `data.fh`: unsupported MATLAB class 'function_handle'"):
        pj.read_mat(obj)
    trunc = tmp_path / "trunc.mat"
    pj.write_ik_dataset(trunc, dataset, version="7.3")
    trunc.write_bytes(trunc.read_bytes()[:3000])
    with pytest.raises(ValueError, match="trunc.mat"):
        pj.load_ik_dataset(trunc)


@pytest.mark.bad_input("pj.write_mat", "pj.write_ik_dataset", "pj.ik_dataset_arrays")
def test_writers_reject_what_matlab_cannot_hold(tmp_path, dataset):
    with pytest.raises(ValueError, match="version"):
        pj.write_mat(tmp_path / "a.mat", {"x": 1.0}, version="6")
    with pytest.raises(ValueError, match="'1x'"):
        pj.write_mat(tmp_path / "a.mat", {"1x": 1.0})
    with pytest.raises(ValueError, match=r"`s`: field name 'a b'"):
        pj.write_mat(tmp_path / "a.mat", {"s": {"a b": 1.0}})
    with pytest.raises(TypeError, match=r"`c\{2\}`: cannot write a NoneType"):
        pj.write_mat(tmp_path / "a.mat", {"c": [1.0, None]})
    with pytest.raises(TypeError, match="variables"):
        pj.write_mat(tmp_path / "a.mat", [1.0])
    with pytest.raises(FileNotFoundError, match="directory"):
        pj.write_mat(tmp_path / "no" / "a.mat", {"x": 1.0})
    bad = {"participants": [{"Natural": {"T1": [{"q": np.ones((5, 4)), "qdot": np.ones((5, 4)),
                                                  "xdot": np.ones((4, 3)), "J": np.ones((5, 3, 4))}]}}]}
    with pytest.raises(ValueError, match="participant 1, Natural/T1, trial 1: inconsistent shapes"):
        pj.write_ik_dataset(tmp_path / "b.mat", bad)
    with pytest.raises(ValueError, match="participants"):
        pj.write_ik_dataset(tmp_path / "b.mat", {"trials": []})
    with pytest.raises(ValueError, match="w_true"):
        pj.write_ik_dataset(tmp_path / "b.mat", dict(dataset, w_true=[{}]))
    with pytest.raises(ValueError, match="trial 1: a trial must be a dict"):
        pj.write_ik_dataset(tmp_path / "b.mat", {"participants": [{"N": {"T": [np.ones(3)]}}]})
    with pytest.raises(ValueError, match="participant 1, Natural/T1, trial 1: inconsistent"):
        pj.ik_dataset_arrays(bad)
    with pytest.raises(ValueError, match="conditions"):
        pj.ik_dataset_arrays(dataset, conditions=["Cold"])
    parts = [dict(p) for p in dataset["participants"]]
    del parts[1]["Viscous"]
    with pytest.raises(ValueError, match="participant 2 has no condition 'Viscous'"):
        pj.ik_dataset_arrays({"participants": parts})


# ---------------------------------------------------------------------------------------------
# HuG-MP


def test_hugmp_loader_reports_irregular_cells():
    for s in (1, 2, 3, 4):
        sub = pj.load_hugmp(s)
        raw = scipy.io.loadmat(hugmp_directory() / f"S0{s}_trajs.mat")["tasks"]
        empty = [(r + 1, t + 1) for r in range(raw.shape[0]) for t in range(6) if raw[r, t].size == 0]
        assert [(r, t) for r, t, why in sub.skipped if why == "empty cell"] == empty
        n_raw = sum(raw[r, t].size for r in range(raw.shape[0]) for t in range(6))
        assert sum(len(v) for v in sub.motions.values()) == n_raw
        r, i, q = sub.motions[2][0]
        np.testing.assert_array_equal(q, np.deg2rad(raw[r - 1, 1].reshape(-1)[i - 1].T))
    assert len(pj.load_hugmp("S03").skipped) == 5 and len(pj.load_hugmp(4).skipped) == 4


@pytest.mark.bad_input("pj.load_hugmp")
def test_hugmp_loader_bad_input(tmp_path):
    with pytest.raises(FileNotFoundError, match="S01_trajs.mat"):
        pj.load_hugmp(1, directory=tmp_path)
    for s, err in ((0, ValueError), ("foo", ValueError), (1.5, TypeError), (True, TypeError)):
        with pytest.raises(err, match="subject"):
            pj.load_hugmp(s)
    with pytest.raises(ValueError, match="min_samples"):
        pj.load_hugmp(1, min_samples=0)
    scipy.io.savemat(tmp_path / "S05_trajs.mat", {"tasks": np.ones((3, 4))})
    with pytest.raises(ValueError, match=r"S05_trajs.mat: variable `tasks` must be a repetitions × 6 cell"):
        pj.load_hugmp(5, directory=tmp_path)
    scipy.io.savemat(tmp_path / "S06_trajs.mat", {"other": np.ones(3)})
    with pytest.raises(ValueError, match="S06_trajs.mat: no variable `tasks`"):
        pj.load_hugmp("S06", directory=tmp_path)
    (tmp_path / "S07_trajs.mat").write_bytes(b"x" * 200)
    with pytest.raises(ValueError, match="S07_trajs.mat: not a MATLAB"):
        pj.load_hugmp(7, directory=tmp_path)


def _cubic(t, c):
    """q(t) = c0 + c1 t + c2 t² + c3 t³ per joint, and its derivative; c (4, n)."""
    return (c[0] + c[1] * t[:, None] + c[2] * t[:, None] ** 2 + c[3] * t[:, None] ** 3,
            c[1] + 2 * c[2] * t[:, None] + 3 * c[3] * t[:, None] ** 2)


def test_motion_kinematics_closed_forms_and_savgol_filter():
    """A cubic trajectory is reproduced exactly by the cubic Savitzky–Golay filter (angles and
    velocities to rounding); ẋ = J q̇ equals the time derivative of the README's forward
    kinematics (central differences); a noisy signal equals scipy.signal.savgol_filter."""
    rng = np.random.default_rng(3)
    fs, N = 100.0, 83
    t = np.arange(N) / fs
    c = np.array([[-0.5, -0.6, -0.2, 0.8], [0.3, -0.4, 0.5, 0.6], [0.2, 0.3, -0.4, -0.2], [-0.1, 0.2, 0.1, 0.05]])
    q, qd_true = _cubic(t, c)
    qs, qd, xd, J = pj.motion_kinematics(q, pj.ShoulderElbowArm(), fs=fs, samples=None)
    np.testing.assert_allclose(qs, q, atol=1e-12)
    np.testing.assert_allclose(qd, qd_true, atol=1e-10)
    np.testing.assert_allclose(J[::10], [arm4_jac(a) for a in q[::10]], atol=1e-12)
    h = 1e-6
    fd = np.array([(arm4_fk(_cubic(np.array([s + h]), c)[0][0]) - arm4_fk(_cubic(np.array([s - h]), c)[0][0])) / (2 * h)
                   for s in t[::10]])
    np.testing.assert_allclose(xd[::10], fd, atol=1e-8)
    # time normalisation: resampled to 25 points of the same motion, velocities in real time
    qs25, qd25, _, _ = pj.motion_kinematics(q, pj.ShoulderElbowArm(), fs=fs, samples=25)
    t25 = np.linspace(0, t[-1], 25)
    np.testing.assert_allclose(qd25, _cubic(t25, c)[1], atol=2e-3)  # linear interpolation of q̇
    np.testing.assert_allclose(qs25[[0, -1]], q[[0, -1]], atol=1e-12)
    noisy = q + 0.01 * rng.standard_normal(q.shape)
    qs, qd, _, _ = pj.motion_kinematics(noisy, pj.ShoulderElbowArm(), fs=fs, window=0.21, samples=None)
    np.testing.assert_allclose(qs, savgol_filter(noisy, 21, 3, axis=0), rtol=0, atol=1e-13)
    np.testing.assert_allclose(qd, savgol_filter(noisy, 21, 3, deriv=1, delta=1 / fs, axis=0), rtol=0, atol=1e-10)


def test_hugmp_arrays_against_per_motion_savgol():
    """Motions of different lengths, smoothed all at once, equal scipy.signal.savgol_filter called
    on each motion and np.interp to S samples; J from the README's chain; padding masked."""
    rng = np.random.default_rng(6)
    motions = {t: [] for t in range(1, 7)}
    for t, r, i, N in ((1, 1, 1, 40), (1, 1, 2, 133), (1, 2, 1, 61), (3, 2, 3, 17), (6, 1, 1, 250)):
        q = np.cumsum(0.01 * rng.standard_normal((N, 4)), axis=0) + np.array([-0.5, -0.6, -0.2, 0.8])
        motions[t].append((r, i, q))
    sub = pj.HugmpSubject(subject="S99", motions=motions, skipped=[], notes=[])
    out = pj.hugmp_arrays(sub, pj.ShoulderElbowArm(), samples=30)
    assert out["qdot"].shape == (6, 2, 3, 30, 4) and out["J"].shape == (6, 2, 3, 30, 3, 4)
    assert out["mask"].sum() == 5 * 30
    for t, items in motions.items():
        for r, i, q in items:
            sl = (t - 1, r - 1, i - 1)
            t0, t1 = np.linspace(0, 1, len(q)), np.linspace(0, 1, 30)
            ref_q = savgol_filter(q, 15, 3, axis=0)
            ref_qd = savgol_filter(q, 15, 3, deriv=1, delta=0.01, axis=0)
            for got, ref in ((out["q"][sl], ref_q), (out["qdot"][sl], ref_qd)):
                np.testing.assert_allclose(got, np.stack([np.interp(t1, t0, ref[:, j]) for j in range(4)], -1),
                                           rtol=0, atol=1e-11)
            np.testing.assert_allclose(out["J"][sl][::7], [arm4_jac(a) for a in out["q"][sl][::7]], atol=1e-12)
            np.testing.assert_allclose(out["xdot"][sl], np.einsum("sij,sj->si", out["J"][sl], out["qdot"][sl]))
    assert np.array_equal(out["J"][1, 0, 0, 0], np.eye(3, 4)) and not out["mask"][1].any()


@pytest.mark.bad_input("pj.motion_kinematics", "pj.hugmp_arrays")
def test_kinematics_bad_input():
    q = np.zeros((40, 4))
    arm = pj.ShoulderElbowArm()
    mk = pj.motion_kinematics
    with pytest.raises(ValueError, match="`q`"):
        mk(np.zeros(40), arm)
    with pytest.raises(ValueError, match="`q`"):
        mk(np.full((40, 4), np.nan), arm)
    with pytest.raises(ValueError, match="`q` has 10 samples"):
        mk(q[:10], arm)
    with pytest.raises(ValueError, match="`chain` has 4 joints"):
        mk(q[:, :3], arm)
    with pytest.raises(TypeError, match="chain"):
        mk(q, "arm")
    with pytest.raises(ValueError, match="fs"):
        mk(q, arm, fs=0.0)
    with pytest.raises(ValueError, match="window"):
        mk(q, arm, window=-1.0)
    with pytest.raises(ValueError, match="samples"):
        mk(q, arm, samples=0)
    sub = pj.HugmpSubject(subject="S99", motions={1: [(1, 1, q[:12])]}, skipped=[], notes=[])
    with pytest.raises(ValueError, match=r"motions\[1\]`: repetition 1, motion 1"):
        pj.hugmp_arrays(sub, arm)
    with pytest.raises(TypeError, match="HugmpSubject"):
        pj.hugmp_arrays({"motions": {}}, arm)
    with pytest.raises(ValueError, match="samples"):
        pj.hugmp_arrays(pj.load_hugmp(1), arm, samples=1)
    with pytest.raises(ValueError, match="`chain` has 3 joints"):
        pj.hugmp_arrays(pj.load_hugmp(1), pj.PlanarArm([0.3, 0.3, 0.3]))


@pytest.mark.bad_input("fitting.hugmp_ik_weights", "fitting.plot_ik_weights")
def test_hugmp_weights_with_intervals(monkeypatch):
    # the bootstrap replicates the intervals come from (the kernel's own samples, recorded on the way)
    from fitting._ik import analysis

    seen = []
    boot = analysis.bootstrap_ik_weights
    monkeypatch.setattr(analysis, "bootstrap_ik_weights", lambda *a, **kw: seen.append(boot(*a, **kw)) or seen[-1])
    res = fitting.hugmp_ik_weights(subjects=(1, 2, 3, 4, 9), samples=10, n_boot=6, max_steps=40,
                                   step_tol=1e-4, level=0.8)
    assert res["subjects"] == ["S01", "S02", "S03", "S04"] and "9" in res["failed"]
    assert list(res["fixed"]) == [False, False, False, True]  # the elbow is over-specified
    w, lo, hi = res["w"], res["lo"], res["hi"]
    assert w.shape == (4, 6, 4)
    assert np.all(np.isfinite(w)) and np.all((w > 0) & (w <= 1))
    assert np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(lo <= hi)
    assert np.allclose(w.max(-1), 1.0)
    # the intervals are the documented (1 ± level)/2 percentiles of the replicates, at the level asked
    # for (the replicates' spread itself is checked against Monte Carlo in the next test)
    (b,) = seen
    smp = np.asarray(b.samples)
    assert smp.shape == (6, 4, 6, 4)
    srt = np.sort(smp, axis=0)  # 6 replicates: the 10 % point lies at 0.5 of the way from the 1st to the 2nd
    np.testing.assert_allclose(lo, srt[0] + 0.5 * (srt[1] - srt[0]), atol=1e-12)
    np.testing.assert_allclose(hi, srt[5] - 0.5 * (srt[5] - srt[4]), atol=1e-12)
    assert np.all(np.isin(res["status"], [pj.Status.STALLED, pj.Status.MAX_STEPS, pj.Status.SUCCESSFUL]))
    assert res["stalled"].shape == (4, 6) and np.all((res["stalled"] >= 0) & (res["stalled"] <= 1))
    assert res["skipped"]["S03"] and not res["skipped"]["S01"]
    fig = fitting.plot_ik_weights(w, lo, hi, panels=res["subjects"])
    assert len(fig.axes) == 4
    with pytest.raises(ValueError, match="subjects"):
        fitting.hugmp_ik_weights(subjects=())
    with pytest.raises(ValueError, match="no HuG-MP subject"):
        fitting.hugmp_ik_weights(subjects=(9,))
    with pytest.raises(ValueError, match="gamma"):
        fitting.hugmp_ik_weights(gamma=1.5)
    with pytest.raises(ValueError, match="samples"):
        fitting.hugmp_ik_weights(samples=1)
    with pytest.raises(ValueError, match="`w`"):
        fitting.plot_ik_weights(np.ones(4))
    with pytest.raises(ValueError, match="`lo`"):
        fitting.plot_ik_weights(w, lo[:2], hi)
    with pytest.raises(ValueError, match="both"):
        fitting.plot_ik_weights(w, lo)
    with pytest.raises(ValueError, match="groups"):
        fitting.plot_ik_weights(w, groups=["a"])
    with pytest.raises(ValueError, match="`w`"):
        fitting.plot_ik_weights([["a"]])


def test_bootstrap_intervals_are_calibrated_against_monte_carlo():
    """The bootstrap's uncertainty against the spread it stands for: R independent data sets of
    the paper's Figure 1 (NumPy, 20 trials of 10 samples each), one bootstrap each (all in one
    call). The 95 % interval's half-width / 1.96 (a normal SE) matches the Monte Carlo standard
    deviation of the estimate over the R data sets (measured ratio 1.17 here, 0.90 with other
    seeds; R = 32 leaves it ±15 % uncertain), and so does its replicates' own spread; a 68 %
    interval would give half of that, replicates of the wrong spread a factor off."""
    R, T, S = 32, 20, 10
    qd, xd, J = ik_fig1_numpy(np.random.default_rng(1), n_reps=R, K=T * S)
    split = lambda a: a.reshape(R, T, S, *a.shape[2:])  # noqa: E731
    res = fitting.bootstrap_ik_weights(split(qd), split(xd), split(J), n_boot=32, gamma=0.6, max_steps=400,
                                       seed=jax.random.PRNGKey(3))
    w, lo, hi, smp = (np.asarray(a) for a in (res.w, res.lo, res.hi, res.samples))
    assert np.all(np.isfinite(w)) and np.mean(np.asarray(res.converged)) > 0.8
    mc = w[:, 1:].std(0, ddof=1)  # joint 1 is pinned at 1 by the normalisation
    half = ((hi - lo)[:, 1:] / (2 * norm.ppf(0.975))).mean(0)
    assert 0.7 < np.mean(half / mc) < 1.5, half / mc
    assert 0.7 < np.mean(smp[:, :, 1:].std(0, ddof=1).mean(0) / mc) < 1.5


def test_lm_weights_converge_where_scipy_finds_the_optimum():
    """The LM variant's "converged" against SciPy's least squares from its stopping point, on the
    model error of Eq 16 written here in NumPy (``e_k = (1 − γ) q̇_k − J#_W (ẋ_k − γ J q̇_k)``, log
    weights relative to joint 1): no parameter moves by more than 0.1 of its Gauss–Newton
    standard error (measured 1e-7)."""
    gamma = 0.6
    qd, xd, J = ik_fig1_numpy(np.random.default_rng(5), n_reps=3, K=200)
    res = fitting.estimate_ik_weights_lm(qd, xd, J, gamma)
    assert np.all(np.asarray(res.converged))

    def residual(theta, q, x, Jm):
        Jp = weighted_pinv(Jm, np.exp(np.r_[0.0, theta]))
        e = (1 - gamma) * q - np.einsum("kij,kj->ki", Jp, x - gamma * np.einsum("kij,kj->ki", Jm, q))
        return e.ravel() / np.sqrt(len(q))

    for i, w in enumerate(np.asarray(res.w)):
        th = np.log(w[1:] / w[0])
        sol = least_squares(residual, th, args=(qd[i], xd[i], J[i]), xtol=1e-15, ftol=1e-15, gtol=1e-15)
        se = np.sqrt(np.diag(sol.fun @ sol.fun / (sol.fun.size - th.size) * np.linalg.inv(sol.jac.T @ sol.jac)))
        assert np.all(np.abs(sol.x - th) < 0.1 * se), np.abs(sol.x - th) / se


def test_prosthetic_conditions_and_eq25():
    sim = fitting.prosthetic_simulation(n_targets=4, hold=1.5, w_user=(1.0, 1.0, 0.02))
    q, qd, xd, J, v = (sim[k] for k in ("q", "qdot", "xdot", "J", "v"))
    nat, lock, coup, assist = range(4)
    assert np.allclose(qd[lock, :, 2], 0.0) and np.allclose(qd[coup, :, 2], qd[coup, :, 1])
    # Eq 25 against NumPy's weighted pseudo-inverse
    K = np.diag([2.0, 0.2, 0.0])
    for s in range(0, q.shape[1], 97):
        Js = J[assist, s]
        Jp = weighted_pinv(Js, [1.0, 1.0, 0.15])
        N = np.eye(3) - Jp @ Js
        ref = Jp[2] @ v[assist, s] - N[2] @ K @ (q[assist, s] - sim["q_hat"])
        if 0.0 < q[assist, s, 2] < np.pi:
            assert np.isclose(qd[assist, s, 2], ref, atol=1e-12)
    # Natural: the user's own weighted IK, q̇ = J#_W ẋ (NumPy)
    for s in range(0, q.shape[1], 131):
        np.testing.assert_allclose(qd[nat, s], weighted_pinv(J[nat, s], [1.0, 1.0, 0.02]) @ xd[nat, s], atol=1e-12)
    # the hand reaches every target with a full, locked or assisted elbow (the coupled synergy
    # is only locally effective, as the paper notes, and may stall)
    chain = sim["chain"]
    ends = np.asarray(chain.fk(q.reshape(4, 4, -1, 3)[:, :, -1]))
    assert np.all(np.linalg.norm(ends - sim["goals"][None], axis=-1)[[nat, lock, assist]] < 5e-3)
    assert np.all(np.isfinite(q))
    res = fitting.estimate_ik_weights(qd, xd, J, gamma=0.6, max_steps=400)
    w = np.asarray(res.w)
    # no null-space motion in Natural: the user's weights are the fixed point, and the run
    # converges to them (default tol: 10⁻³ relative)
    assert int(res.status[nat]) == pj.Status.SUCCESSFUL
    np.testing.assert_allclose(w[nat], [1.0, 1.0, 0.02], rtol=2e-3)
    assert np.isclose(w[lock, 2], 1.0)  # a locked elbow is the costliest joint
    beta = np.asarray(fitting.contribution_coefficients(w))
    assert beta[assist, 2] > beta[coup, 2] and beta[assist, 0] < beta[coup, 0]


# The shipped ik-weights example (pmpjax/data/examples/ik_example.csv), written by
# ``_write_ik_example`` from this recipe: a planar 3-link arm with links of 0.3 m at 150 postures
# per item (q1 anywhere, the two distal joints bent 0.3–2.6 rad, away from the stretched-arm
# singularity), hand velocities ẋ ~ N(0, 0.3² I) and q̇ = J#_W ẋ (no null-space motion).
IK_EXAMPLE_W = {"arm_a": (1.0, 0.5, 0.2), "arm_b": (0.3, 1.0, 0.6)}
IK_EXAMPLE_HEADER = (
    "# pmpjax ik-weights example: planar 3-link arm (links 0.3 m), qdot = J#_W xdot with W = diag(w), "
    "gamma = 0 (no null-space motion)\n"
    "# arm_a: w = (1, 0.5, 0.2); arm_b: w = (0.3, 1, 0.6); 150 postures each, q1 in [-pi, pi], "
    "q2 and q3 in [0.3, 2.6] rad\n")


def _ik_example_arrays(seed=0, K=150):
    rng = np.random.default_rng(seed)
    out = {}
    for item, w in IK_EXAMPLE_W.items():
        q = rng.uniform((-np.pi, 0.3, 0.3), (np.pi, 2.6, 2.6), (K, 3))
        J = np.stack([planar_jac(a, (0.3, 0.3, 0.3)) for a in q])
        xd = 0.3 * rng.standard_normal((K, 2))
        out[item] = (np.einsum("kij,kj->ki", weighted_pinv(J, np.array(w)), xd), xd, J)
    return out


def _write_ik_example(path):
    cols = ["item"] + [f"qdot_{i}" for i in (1, 2, 3)] + [f"xdot_{i}" for i in (1, 2)] + [
        f"J_{r}_{c}" for r in (1, 2) for c in (1, 2, 3)]
    lines = [",".join(cols)]
    for item, (qd, xd, J) in _ik_example_arrays().items():
        for k in range(len(qd)):
            vals = np.concatenate([qd[k], xd[k], J[k].reshape(-1)])
            lines.append(",".join([item] + [f"{v:.15g}" for v in vals]))
    Path(path).write_text(IK_EXAMPLE_HEADER + "\n".join(lines) + "\n")


def test_ik_example_file_follows_its_recipe_and_algorithm1_converges_on_it(tmp_path):
    """The shipped example holds the recipe's arrays (NumPy: planar Jacobians, weighted
    pseudo-inverse; ẋ = J q̇), and the command's default method, Algorithm 1 at γ = 0.6 with the
    default tolerances, converges on it (SUCCESSFUL) to the weights that made the data, within
    10⁻³ relative (the default ``tol``, relative to the fixed point, here the truth)."""
    path = resources.files("pmpjax") / "data" / "examples" / "ik_example.csv"
    assert path.read_text().startswith(IK_EXAMPLE_HEADER)
    _write_ik_example(tmp_path / "ik_example.csv")
    d, again = fitting.read_ik_file(path), fitting.read_ik_file(tmp_path / "ik_example.csv")
    assert d["labels"] == again["labels"] == list(IK_EXAMPLE_W) and d["mask"].all()
    for key in ("qdot", "xdot", "J"):
        np.testing.assert_allclose(d[key], again[key], rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(np.einsum("bkij,bkj->bki", d["J"], d["qdot"]), d["xdot"], atol=1e-12)
    res = fitting.estimate_ik_weights(d["qdot"], d["xdot"], d["J"], 0.6, mask=d["mask"], on_invalid="flag")
    assert np.all(np.asarray(res.status) == pj.Status.SUCCESSFUL)
    np.testing.assert_allclose(res.w, np.array(list(IK_EXAMPLE_W.values())), rtol=1e-3)


@pytest.mark.bad_input("fitting.prosthetic_simulation", "fitting.synthetic_ik_dataset", "fitting.ik_fig1_data",
                       "fitting.ik_fig3_data")
def test_generators_bad_input():
    ps = fitting.prosthetic_simulation
    with pytest.raises(ValueError, match="conditions"):
        ps(["Natural", "Frozen"])
    with pytest.raises(ValueError, match="w_user"):
        ps(w_user=(1.0, 0.0, 1.0))
    with pytest.raises(ValueError, match="lengths"):
        ps(lengths=(0.5, 0.3))
    with pytest.raises(ValueError, match="q0"):
        ps(q0=(0.0, np.nan, 0.0))
    with pytest.raises(ValueError, match="n_targets"):
        ps(n_targets=0)
    with pytest.raises(ValueError, match="hold"):
        ps(hold=0.001, dt=0.01)
    sd = fitting.synthetic_ik_dataset
    with pytest.raises(ValueError, match="seed"):
        sd(seed=-1)
    with pytest.raises(ValueError, match="n_participants"):
        sd(n_participants=0)
    with pytest.raises(ValueError, match="drop"):
        sd(drop=1.0)
    with pytest.raises(ValueError, match="noise"):
        sd(noise=-0.1)
    with pytest.raises(ValueError, match="chain"):
        sd(chain=pj.PlanarArm([0.3, 0.3, 0.3]))
    import jax

    key = jax.random.PRNGKey(0)
    with pytest.raises(ValueError, match="w_true"):
        fitting.ik_fig1_data(key, w_true=(1.0, -0.5, 0.2))
    with pytest.raises(ValueError, match="`m`"):
        fitting.ik_fig1_data(key, m=5)
    with pytest.raises(ValueError, match="n_reps"):
        fitting.ik_fig1_data(key, n_reps=0)
    with pytest.raises(ValueError, match="sigma"):
        fitting.ik_fig1_data(key, sigma=-1.0)
    with pytest.raises(TypeError, match="seed"):
        fitting.ik_fig1_data(0.5)
    with pytest.warns(DeprecationWarning, match="key"), pytest.raises(TypeError, match="seed"):
        fitting.ik_fig1_data(key="0")  # the old keyword, passed on under the new one
    with pytest.raises(ValueError, match="w_true"):
        fitting.ik_fig3_data(w_true=(1.0, 0.5, 0.2))
    with pytest.raises(ValueError, match="dt"):
        fitting.ik_fig3_data(dt=0.0)
    with pytest.raises(ValueError, match="k_null"):
        fitting.ik_fig3_data(k_null=-1.0)
    with pytest.raises(ValueError, match="q0"):
        fitting.ik_fig3_data(q0=(0.5,))


def test_fig1_data_seed_is_an_integer_or_a_key():
    """``seed=3`` draws what ``jax.random.PRNGKey(3)`` draws (the documented meaning of an integer)."""
    a = fitting.ik_fig1_data(3, n_reps=1, K=4)
    b = fitting.ik_fig1_data(jax.random.PRNGKey(3), n_reps=1, K=4)
    assert all(np.array_equal(np.asarray(x), np.asarray(y)) for x, y in zip(a, b, strict=True))
