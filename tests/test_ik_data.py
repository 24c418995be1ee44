"""IK data: the paper's MAT layout (v5 and v7.3 round trips, malformed files), the bundled HuG-MP
recordings (irregular cells, weights with bootstrap intervals), and the Eq 25 prosthetic elbow.
References: a direct scipy.io scan of the raw cells; NumPy's weighted pseudo-inverse formula.
"""

import numpy as np
import pytest
import scipy.io

import fitting
import pmpjax as pj


@pytest.fixture(scope="module")
def dataset():
    return fitting.synthetic_ik_dataset(seed=4, n_participants=3, n_trials=4)


def test_synthetic_dataset_layout(dataset):
    parts = dataset["participants"]
    assert len(parts) == 3 and list(parts[0]) == ["Natural", "Viscous"]
    assert list(parts[0]["Natural"]) == ["Target1", "Target2", "Target3"]
    tr = parts[1]["Viscous"]["Target2"][0]
    assert tr["q"].shape == (100, 4) and tr["xdot"].shape == (100, 3) and tr["J"].shape == (100, 3, 4)
    # ẋ = J q̇ and J is the chain's Jacobian at q
    assert np.allclose(tr["xdot"], np.einsum("sij,sj->si", tr["J"], tr["qdot"]))
    assert np.allclose(tr["J"], pj.Arm4().jacobian(tr["q"]), atol=1e-12)
    w = np.array([[d[c] for c in ("Natural", "Viscous")] for d in dataset["w_true"]])
    assert np.all(w[:, 1, 2] > 3 * w[:, 0, 2])  # joint 3 is much costlier in the viscous field


@pytest.mark.parametrize("version", ["5", "7.3"])
def test_round_trip_mat(dataset, tmp_path, version):
    path = tmp_path / f"ik_{version}.mat"
    pj.write_ik_dataset(path, dataset, version=version)
    head = path.read_bytes()[:20]
    assert head.startswith(b"MATLAB 7.3" if version == "7.3" else b"MATLAB 5.0")
    back = pj.load_ik_dataset(path)
    for p, (a, b) in enumerate(zip(dataset["participants"], back["participants"])):
        assert list(a) == list(b)
        for c in a:
            for t in a[c]:
                assert len(a[c][t]) == len(b[c][t])
                for ta, tb in zip(a[c][t], b[c][t]):
                    for k in ("q", "qdot", "xdot", "J"):
                        assert np.array_equal(ta[k], tb[k]), (p, c, t, k)
            # IK_data: concatenation over targets and trials, ready for Algorithm 1
            cat = np.concatenate([tr["qdot"] for t in a[c] for tr in a[c][t]])
            assert np.array_equal(back["ik_data"][p][c]["qdot"], cat)
            assert back["ik_data"][p][c]["J"].shape == (cat.shape[0], 3, 4)
        assert all(np.array_equal(dataset["w_true"][p][c], back["w_true"][p][c]) for c in a)
    arr = pj.ik_dataset_arrays(back)
    assert arr["qdot"].shape[:3] == (3, 2, 3) and arr["mask"].any(-1).sum() == sum(
        len(v) for part in back["participants"] for cond in part.values() for v in cond.values())


def test_malformed_mat_files(tmp_path, dataset):
    with pytest.raises(FileNotFoundError):
        pj.load_ik_dataset(tmp_path / "missing.mat")
    junk = tmp_path / "junk.mat"
    junk.write_bytes(b"not a mat file" * 20)
    with pytest.raises(ValueError, match="not a MATLAB"):
        pj.load_ik_dataset(junk)
    other = tmp_path / "other.mat"
    scipy.io.savemat(other, {"x": np.ones(3)})
    with pytest.raises(ValueError, match="no variable `data`"):
        pj.load_ik_dataset(other)
    bad = tmp_path / "bad.mat"
    trial = {"q": np.ones((5, 4)), "dq": np.ones((5, 4)), "dx": np.ones((5, 3)), "J": np.ones((3, 4, 4))}
    pj.write_mat(bad, {"data": [{"Natural": {"Target1": [trial]}}]})
    with pytest.raises(ValueError, match="participant 1, Natural/Target1, trial 1"):
        pj.load_ik_dataset(bad)
    trunc = tmp_path / "trunc.mat"
    pj.write_ik_dataset(trunc, dataset, version="7.3")
    trunc.write_bytes(trunc.read_bytes()[:3000])
    with pytest.raises(ValueError, match="malformed|not a MATLAB"):
        pj.load_ik_dataset(trunc)


def test_hugmp_loader_reports_irregular_cells():
    for s in (1, 2, 3, 4):
        sub = pj.load_hugmp(s)
        raw = scipy.io.loadmat(pj._data.matlab.hugmp_directory() / f"S0{s}_trajs.mat")["tasks"]
        empty = [(r + 1, t + 1) for r in range(raw.shape[0]) for t in range(6) if raw[r, t].size == 0]
        assert [(r, t) for r, t, why in sub.skipped if why == "empty cell"] == empty
        n_raw = sum(raw[r, t].size for r in range(raw.shape[0]) for t in range(6))
        assert sum(len(v) for v in sub.motions.values()) == n_raw
    assert len(pj.load_hugmp("S03").skipped) == 5 and len(pj.load_hugmp(4).skipped) == 4
    with pytest.raises(FileNotFoundError):
        pj.load_hugmp(1, directory="/nonexistent")


def test_hugmp_weights_with_intervals():
    res = fitting.hugmp_ik_weights(subjects=(1, 2, 3, 4, 9), samples=10, n_boot=6, max_iter=40,
                                   step_tol=1e-4)
    assert res["subjects"] == ["S01", "S02", "S03", "S04"] and "9" in res["failed"]
    assert list(res["fixed"]) == [False, False, False, True]  # the elbow is over-specified
    w, lo, hi = res["w"], res["lo"], res["hi"]
    assert w.shape == (4, 6, 4)
    assert np.all(np.isfinite(w)) and np.all((w > 0) & (w <= 1))
    assert np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(lo <= hi)
    assert np.allclose(w.max(-1), 1.0)
    assert res["skipped"]["S03"] and not res["skipped"]["S01"]


def test_prosthetic_conditions_and_eq25():
    sim = fitting.prosthetic_simulation(n_targets=4, hold=1.5, w_user=(1.0, 1.0, 0.02))
    q, qd, xd, J, v = (sim[k] for k in ("q", "qdot", "xdot", "J", "v"))
    nat, lock, coup, assist = range(4)
    assert np.allclose(qd[lock, :, 2], 0.0) and np.allclose(qd[coup, :, 2], qd[coup, :, 1])
    # Eq 25 against NumPy's weighted pseudo-inverse
    W_inv = np.diag(1 / np.array([1.0, 1.0, 0.15]))
    K = np.diag([2.0, 0.2, 0.0])
    for s in range(0, q.shape[1], 97):
        Js = J[assist, s]
        Jp = W_inv @ Js.T @ np.linalg.inv(Js @ W_inv @ Js.T)
        N = np.eye(3) - Jp @ Js
        ref = Jp[2] @ v[assist, s] - N[2] @ K @ (q[assist, s] - sim["q_hat"])
        if 0.0 < q[assist, s, 2] < np.pi:
            assert np.isclose(qd[assist, s, 2], ref, atol=1e-12)
    # the hand reaches every target with a full, locked or assisted elbow (the coupled synergy
    # is only locally effective, as the paper notes, and may stall)
    chain = sim["chain"]
    ends = np.asarray(chain.fk(q.reshape(4, 4, -1, 3)[:, :, -1]))
    assert np.all(np.linalg.norm(ends - sim["goals"][None], axis=-1)[[nat, lock, assist]] < 5e-3)
    assert np.all(np.isfinite(q))
    res = fitting.estimate_ik_weights(qd, xd, J, gamma=0.6, max_iter=400)
    w = np.asarray(res.w)
    assert np.allclose(w[nat], [1.0, 1.0, 0.02], atol=0.03)  # the user's own weights come back
    assert np.isclose(w[lock, 2], 1.0)  # a locked elbow is the costliest joint
    beta = np.asarray(fitting.contribution_coefficients(w))
    assert beta[assist, 2] > beta[coup, 2] and beta[assist, 0] < beta[coup, 0]
