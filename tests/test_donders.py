"""Orientations, Donders surfaces, Donders recordings (files) and the batched NIO fit."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg
import scipy.stats
from _problems import TABLE2, table_kj
from _reference import central_diff, symmetric_directions, wrist_equilibria
from scipy.spatial.transform import Rotation

import fitting
import pmpjax as pj

# --- orientations ------------------------------------------------------------------------


@pytest.fixture(scope="module")
def q_data():
    """Wrist postures over (beyond) the data range of the Donders experiments."""
    rng = np.random.default_rng(1)
    return rng.uniform([-1.2, -1.0, -1.0], [1.2, 1.0, 1.0], size=(300, 3))


def test_wrist_rotation_matches_scipy_euler(q_data):
    # Eq 6: R = Rx(−q_PS) Rz(q_FE) Ry(q_RUD) = intrinsic X-Z-Y Euler angles (−q_PS, q_FE, q_RUD)
    ref = Rotation.from_euler("XZY", q_data * [-1, 1, 1]).as_matrix()
    np.testing.assert_allclose(np.asarray(pj.wrist_rotation(q_data)), ref, atol=1e-14)


def test_quaternion_and_rotvec_conventions_match_scipy(q_data):
    R = np.asarray(pj.wrist_rotation(q_data))
    quat = np.asarray(pj.quat_from_matrix(R))
    ref = Rotation.from_matrix(R).as_quat()[:, [3, 0, 1, 2]]  # SciPy is scalar-last
    ref *= np.sign(ref[:, :1])
    np.testing.assert_allclose(quat, ref, atol=1e-14)
    np.testing.assert_allclose(np.asarray(pj.matrix_from_quat(quat)), R, atol=1e-14)
    rv = np.asarray(pj.rotvec_from_matrix(R))
    np.testing.assert_allclose(rv, Rotation.from_matrix(R).as_rotvec(), atol=1e-13)
    np.testing.assert_allclose(np.asarray(pj.matrix_from_rotvec(rv)), R, atol=1e-13)
    rod = np.asarray(pj.rotvec_from_quat(quat, convention="rodrigues"))
    np.testing.assert_allclose(rod, ref[:, 1:] / ref[:, :1], atol=1e-13)


def test_joint_angle_round_trip_over_data_range(q_data):
    quat = pj.quat_from_joint_angles(q_data)
    np.testing.assert_allclose(np.asarray(pj.joint_angles_from_quat(quat)), q_data, atol=1e-12)


def test_inverse_returns_branch_with_small_fe():
    # the other branch (q_PS + π, π − q_FE, q_RUD + π) has |q_FE| > π/2 and the same R
    q = np.array([[0.3, 0.4, -0.2], [-0.5, -0.7, 0.9]])
    other = np.stack([q[:, 0] + np.pi, np.pi - q[:, 1], q[:, 2] + np.pi], -1)
    np.testing.assert_allclose(
        np.asarray(pj.wrist_rotation(other)), np.asarray(pj.wrist_rotation(q)), atol=1e-14
    )
    back = np.asarray(pj.joint_angles_from_matrix(pj.wrist_rotation(other)))
    np.testing.assert_allclose(back, q, atol=1e-12)
    assert np.all(np.abs(back[:, 1]) < np.pi / 2)


def test_rotvec_gradient_smooth_through_identity():
    f = lambda r: jnp.sum(pj.rotvec_from_quat(pj.quat_from_rotvec(r)) ** 2)  # noqa: E731
    for r0 in (np.zeros(3), np.array([1e-9, -2e-9, 0.0]), np.array([0.3, -0.2, 0.1])):
        np.testing.assert_allclose(np.asarray(jax.grad(f)(jnp.asarray(r0))), 2 * r0, atol=1e-12)


def test_joint_angles_and_torsion_match_scipy(q_data):
    """Inverse of Eq 6 = SciPy's intrinsic X-Z-Y Euler angles (−q_PS, q_FE, q_RUD); the torsion
    between two postures pointing the same way = SciPy's angle of the relative rotation."""
    R = Rotation.from_euler("XZY", q_data * [-1, 1, 1])
    q_back = np.asarray(pj.joint_angles_from_matrix(R.as_matrix()))
    np.testing.assert_allclose(q_back, R.as_euler("XZY") * [-1, 1, 1], atol=1e-12)
    np.testing.assert_allclose(np.asarray(pj.joint_angles_from_quat(R.as_quat()[:, [3, 0, 1, 2]])), q_data,
                               atol=1e-12)
    np.testing.assert_allclose(np.asarray(pj.rotvec_from_joint_angles(q_data)), R.as_rotvec(), atol=1e-13)
    tw = np.random.default_rng(2).uniform(-0.5, 0.5, len(q_data))
    R2 = R * Rotation.from_rotvec(np.stack([tw, 0 * tw, 0 * tw], -1))  # twist about the hand's e_x
    np.testing.assert_allclose(np.asarray(pj.torsion_between(R.as_matrix(), R2.as_matrix())), tw, atol=1e-13)
    np.testing.assert_allclose(np.abs(tw), (R.inv() * R2).magnitude(), atol=1e-13)


ORIENTATION_FUNCS = {
    "wrist_rotation": (lambda q: pj.wrist_rotation(q), "q"),
    "quat_from_joint_angles": (lambda q: pj.quat_from_joint_angles(q), "q"),
    "rotvec_from_joint_angles": (lambda q: pj.rotvec_from_joint_angles(q), "q"),
    "rotvec_rodrigues": (lambda q: pj.rotvec_from_joint_angles(q, convention="rodrigues"), "q"),
    "quat_from_matrix": (lambda R: pj.quat_from_matrix(R), "R"),
    "rotvec_from_matrix": (lambda R: pj.rotvec_from_matrix(R), "R"),
    "joint_angles_from_matrix": (lambda R: pj.joint_angles_from_matrix(R), "R"),
    "torsion_between": (lambda R: pj.torsion_between(R.T @ R.T, R), "R"),
    "matrix_from_quat": (lambda u: pj.matrix_from_quat(u), "quat"),
    "rotvec_from_quat": (lambda u: pj.rotvec_from_quat(u), "quat"),
    "joint_angles_from_quat": (lambda u: pj.joint_angles_from_quat(u), "quat"),
    "quat_from_rotvec": (lambda r: pj.quat_from_rotvec(r), "r"),
    "matrix_from_rotvec": (lambda r: pj.matrix_from_rotvec(r), "r"),
}


@pytest.mark.parametrize("name", list(ORIENTATION_FUNCS))
def test_orientation_gradients_match_central_differences(name):
    f, kind = ORIENTATION_FUNCS[name]
    q = np.array([0.4, -0.3, 0.25])
    x = {"q": q, "R": Rotation.from_euler("XZY", q * [-1, 1, 1]).as_matrix(),
         "quat": np.array([0.9, 0.1, -0.3, 0.2]), "r": np.array([0.3, -0.5, 0.2])}[kind]
    jac = np.asarray(jax.jacfwd(f)(jnp.asarray(x)))
    fd = np.moveaxis(central_diff(f, x), 0, -1).reshape(jac.shape)
    np.testing.assert_allclose(jac, fd, rtol=1e-6, atol=1e-8)


@pytest.mark.bad_input(
    "pj.wrist_rotation", "pj.quat_from_matrix", "pj.matrix_from_quat", "pj.rotvec_from_quat",
    "pj.quat_from_rotvec", "pj.rotvec_from_matrix", "pj.matrix_from_rotvec", "pj.joint_angles_from_matrix",
    "pj.joint_angles_from_quat", "pj.quat_from_joint_angles", "pj.rotvec_from_joint_angles", "pj.torsion_between",
)
def test_orientation_bad_input():
    R, nan3 = np.eye(3), np.array([np.nan, 0.0, 0.0])
    cases = [
        (lambda: pj.wrist_rotation(np.zeros(2)), "`q`.*shape"),
        (lambda: pj.wrist_rotation(nan3), "`q`.*NaN"),
        (lambda: pj.quat_from_matrix(np.eye(2)), "`R`.*shape"),
        (lambda: pj.matrix_from_quat(np.zeros(4)), "`quat`.*zero"),
        (lambda: pj.matrix_from_quat(np.ones(3)), "`quat`.*shape"),
        (lambda: pj.rotvec_from_quat(np.ones(4), convention="euler"), "convention"),
        (lambda: pj.quat_from_rotvec(np.zeros(4)), "`r`.*shape"),
        (lambda: pj.rotvec_from_matrix(R, convention="x"), "convention"),
        (lambda: pj.matrix_from_rotvec(nan3), "`r`.*NaN"),
        (lambda: pj.joint_angles_from_matrix(np.ones((3, 2))), "`R`.*shape"),
        (lambda: pj.joint_angles_from_quat(np.array([1.0, np.inf, 0, 0])), "`quat`.*NaN"),
        (lambda: pj.quat_from_joint_angles(np.zeros((2, 4))), "`q`.*shape"),
        (lambda: pj.rotvec_from_joint_angles(np.zeros(3), convention="rod"), "convention"),
        (lambda: pj.torsion_between(np.eye(2), R), "`R_ref`.*shape"),
        (lambda: pj.torsion_between(R, np.full((3, 3), np.nan)), "`R`.*NaN"),
    ]
    for call, match in cases:
        with pytest.raises(ValueError, match=match):
            call()


# --- Donders surfaces ----------------------------------------------------------------------

C_TRUE = np.array([0.05, 0.2, -0.1, 0.3, -0.5, 0.15])


def _samples(rng, n):
    ry, rz = rng.uniform(-0.35, 0.35, (2, n))
    A = np.stack([np.ones(n), ry, rz, ry**2, ry * rz, rz**2], -1)
    return ry, rz, A


def test_surface_fit_exact_on_noiseless_samples():
    ry, rz, A = _samples(np.random.default_rng(2), 50)
    r = np.stack([A @ C_TRUE, ry, rz], -1)
    s = pj.fit_donders_surface(r)
    np.testing.assert_allclose(np.asarray(s.coef), C_TRUE, atol=1e-13)
    assert float(s.thickness) < 1e-13
    np.testing.assert_allclose(np.asarray(s(ry, rz)), A @ C_TRUE, atol=1e-13)


def test_surface_fit_noisy_within_standard_errors_and_matches_numpy():
    rng = np.random.default_rng(3)
    ry, rz, A = _samples(rng, 400)
    sig = np.deg2rad(0.5)
    rx = A @ C_TRUE + rng.normal(scale=sig, size=400)
    s = pj.fit_donders_surface(np.stack([rx, ry, rz], -1))
    coef, ssr = np.linalg.lstsq(A, rx, rcond=None)[:2]
    se = np.sqrt(ssr[0] / (400 - 6) * np.diag(np.linalg.inv(A.T @ A)))
    np.testing.assert_allclose(np.asarray(s.coef), coef, atol=1e-12)
    np.testing.assert_allclose(np.asarray(s.stderr), se, rtol=1e-9)
    assert np.all(np.abs(np.asarray(s.coef) - C_TRUE) < 3 * se)
    np.testing.assert_allclose(float(s.thickness), np.sqrt(ssr[0] / 400), rtol=1e-10)


@pytest.mark.bad_input("pj.fit_donders_surface")
def test_surface_fit_mask_equals_subset():
    rng = np.random.default_rng(4)
    ry, rz, A = _samples(rng, 60)
    r = np.stack([A @ C_TRUE + rng.normal(scale=0.01, size=60), ry, rz], -1)
    mask = np.arange(60) < 40
    a, b = pj.fit_donders_surface(r, mask=mask), pj.fit_donders_surface(r[:40])
    np.testing.assert_allclose(np.asarray(a.coef), np.asarray(b.coef), atol=1e-12)
    np.testing.assert_allclose(np.asarray(a.stderr), np.asarray(b.stderr), rtol=1e-9)
    with pytest.raises(ValueError, match="at least 7"):
        pj.fit_donders_surface(r[:5])
    with pytest.raises(ValueError, match="r.*NaN"):
        pj.fit_donders_surface(np.where(np.arange(60)[:, None] == 3, np.nan, r))


def test_model_surface_and_torsion_gradients():
    """∂/∂(KJ, q_rest) of the model surface's coefficients (equilibria → rotation vectors → QR fit)
    and of predicted_torsion (also ∂/∂pointing), against central differences."""
    K0, q0 = table_kj(1, normalize=True), TABLE2[1]
    grid = pj.screen_grid(3)
    c = np.array([1.0, -0.5, 2.0, 0.3, -1.0, 0.7])

    def loss(K, qr, x):  # one compiled function for both entry points
        surface = jnp.sum(c * pj.model_donders_surface(K, qr, grid)[0].coef)
        return surface + jnp.sum(jnp.sin(5.0 * fitting.predicted_torsion(pj.Wrist(), K, qr, x)))

    sym = symmetric_directions(3)
    args = (K0, q0, grid[[1, 5]] * 0.9)
    vg = pj.fast_compile_jit(jax.value_and_grad(loss, argnums=(0, 1, 2)))  # one compile for both
    grads = vg(*args)[1]
    for i, (a, g) in enumerate(zip(args, grads)):
        dirs = sym if a.shape == (3, 3) else None
        fd = central_diff(lambda v: float(vg(*args[:i], v, *args[i + 1:])[0]), a, dirs)
        ad = np.asarray(g).reshape(-1) if dirs is None else np.einsum("ij,kij->k", np.asarray(g), sym)
        # equilibria are exact to ~1e-15; over the sqrt(eps) step that is ~1e-7 of the scale
        np.testing.assert_allclose(ad, fd, rtol=1e-6, atol=1e-7 * np.max(np.abs(fd)))


def test_model_surface_and_plot():
    import matplotlib

    matplotlib.use("Agg")
    _, K, q = pj.paper_subjects()
    surf, r, qe = pj.model_donders_surface(K, q, pj.screen_grid(7))
    assert r.shape == (6, 49, 3) and surf.coef.shape == (6, 6)
    # independent: rotation vectors of the equilibria by SciPy
    ref = (
        Rotation.from_matrix(np.asarray(pj.wrist_rotation(qe)).reshape(-1, 3, 3))
        .as_rotvec()
        .reshape(6, 49, 3)
    )
    np.testing.assert_allclose(np.asarray(r), ref, atol=1e-12)
    ax = pj.plot_donders(r[0], [surf.coef[0], surf.coef[1]], labels=["subj1", "subj2"])
    assert len(ax.collections) == 3


# --- subjects and recordings -----------------------------------------------------------------


@pytest.mark.bad_input("pj.load_subject", "pj.paper_subjects", "pj.subject_names")
def test_paper_subjects_table():
    names, K, q = pj.paper_subjects(normalize=False)
    assert names == ["subj1", "subj2", "subj3", "subj4", "subj5", "subj6"]
    np.testing.assert_allclose(K[0], [[1.22, 0.07, 0.08], [0.07, 1.68, 0.03], [0.08, 0.03, 1.09]])
    np.testing.assert_allclose(q[3], [0.36, 0.25, -0.09])
    s = pj.load_subject("Subj 4")
    np.testing.assert_allclose(np.trace(s.KJ), 4.0)
    np.testing.assert_allclose(s.KJ / K[3], 4.0 / np.trace(K[3]))
    assert np.all(np.linalg.eigvalsh(K) > 0)
    with pytest.raises(ValueError, match="unknown subject"):
        pj.load_subject("subj9")
    with pytest.raises(TypeError, match="normalize"):
        pj.paper_subjects(normalize="yes")
    with pytest.raises(TypeError):
        pj.subject_names("subj1")
    # Tables 1–2 as typed in tests/_problems.py from the paper
    for i in range(6):
        np.testing.assert_allclose(K[i], table_kj(i), atol=1e-15)
        np.testing.assert_allclose(q[i], TABLE2[i], atol=1e-15)


@pytest.fixture(scope="module")
def small_recording():
    _, K, q = pj.paper_subjects()
    return pj.synthetic_recordings(K[:2], q[:2], 40, noise_deg=0.5, seed=5)


def test_synthetic_noise_and_consistency(small_recording):
    rec = small_recording
    _, K, q = pj.paper_subjects()
    clean = pj.synthetic_recordings(K[:2], q[:2], 40, noise_deg=0.0, seed=5)
    Rn, Rc = (Rotation.from_quat(np.asarray(r.quat)[..., [1, 2, 3, 0]].reshape(-1, 4)) for r in (rec, clean))
    ang = np.rad2deg((Rc.inv() * Rn).magnitude())
    assert 0.4 < np.sqrt(np.mean(ang**2)) < 0.6
    # pointing is what the (noisy) orientation points at (Eq 6)
    np.testing.assert_allclose(np.asarray(pj.Wrist().fk(rec.joint_angles)), rec.pointing, atol=1e-12)
    # clean postures are equilibria (SciPy-free check: λ0-PMP stationarity K(q − q_rest) ∈ range Jᵀ)
    qc = clean.joint_angles[0]
    J = np.asarray(pj.Wrist().jacobian(qc))
    g = (K[0] @ (qc - q[0]).T).T
    lam = np.linalg.lstsq(J[0].T, g[0], rcond=None)[0]
    np.testing.assert_allclose(J[0].T @ lam, g[0], atol=1e-12)


@pytest.mark.parametrize("suffix", [".csv", ".npz"])
def test_file_round_trip(small_recording, tmp_path, suffix):
    path = tmp_path / f"rec{suffix}"
    pj.write_recordings(path, small_recording)
    back = pj.read_recordings(path)
    assert back.subjects == small_recording.subjects
    np.testing.assert_array_equal(back.quat, small_recording.quat)
    np.testing.assert_array_equal(back.pointing, small_recording.pointing)


def test_csv_with_joint_angles_only_and_ragged(small_recording, tmp_path):
    rec = small_recording
    q = rec.joint_angles
    lines = ["subject,sample,q_ps,q_fe,q_rud,x1,x2"]
    for s in range(2):
        for i in range(40 - 10 * s):
            vals = [float(v) for v in (*q[s, i], *rec.pointing[s, i])]
            lines.append(",".join([rec.subjects[s], str(i)] + [repr(v) for v in vals]))
    path = tmp_path / "joints.csv"
    path.write_text("\n".join(lines) + "\n")
    back = pj.read_recordings(path)
    np.testing.assert_array_equal(back.n_samples, [40, 30])
    np.testing.assert_allclose(back.joint_angles[1, :30], q[1, :30], atol=1e-12)


BAD_CSV = {
    "empty": ("", "empty file"),
    "header only": ("subject,sample,qw,qx,qy,qz,x1,x2\n", "no samples"),
    "missing column": ("subject,sample,qw,qx,qy,x1,x2\ns,0,1,0,0,0,0\n", "lacks column"),
    "non-numeric": ("subject,sample,qw,qx,qy,qz,x1,x2\ns,0,1,0,zero,0,0,0\n", r"line 2, column 5 \(qy\): not a number"),
    "nan": ("subject,sample,qw,qx,qy,qz,x1,x2\ns,0,1,0,0,0,nan,0\n", "NaN"),
    "short row": ("subject,sample,qw,qx,qy,qz,x1,x2\ns,0,1,0,0,0\n", "expected 8 fields"),
    "duplicate": ("subject,sample,qw,qx,qy,qz,x1,x2\ns,0,1,0,0,0,0,0\ns,0,1,0,0,0,0,0\n", "duplicate sample"),
    "not unit": ("subject,sample,qw,qx,qy,qz,x1,x2\ns,0,2,0,0,0,0,0\n", "unit quaternions"),
    "unreachable": ("subject,sample,qw,qx,qy,qz,x1,x2\ns,0,1,0,0,0,0.995,0\n", "reachable"),
}


@pytest.mark.bad_input("pj.read_recordings")
@pytest.mark.parametrize("case", list(BAD_CSV))
def test_bad_csv(tmp_path, case):
    text, match = BAD_CSV[case]
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(ValueError, match=match):
        pj.read_recordings(path)


@pytest.mark.bad_input("pj.read_recordings", "pj.write_recordings")
def test_bad_npz_and_paths(tmp_path, small_recording):
    p = tmp_path / "bad.npz"
    p.write_bytes(b"not a zip")
    with pytest.raises(ValueError, match=r"bad\.npz: not an NPZ archive \(not a zip archive"):
        pj.read_recordings(p)
    np.savez(tmp_path / "miss.npz", quat=small_recording.quat)
    with pytest.raises(ValueError, match="missing array"):
        pj.read_recordings(tmp_path / "miss.npz")
    np.savez(
        tmp_path / "empty.npz",
        subjects=np.array(["a"]),
        quat=np.zeros((1, 0, 4)),
        pointing=np.zeros((1, 0, 2)),
        mask=np.zeros((1, 0), bool),
    )
    with pytest.raises(ValueError, match="N > 0"):
        pj.read_recordings(tmp_path / "empty.npz")
    with pytest.raises(ValueError, match="no such file"):
        pj.read_recordings(tmp_path / "nope.csv")
    with pytest.raises(ValueError, match=r"\.csv or \.npz"):
        pj.write_recordings(tmp_path / "x.txt", small_recording)


# --- NIO fit ---------------------------------------------------------------------------------


def test_stiffness_parameterisation():
    rng = np.random.default_rng(6)
    s = rng.normal(scale=0.4, size=5)
    K = np.asarray(fitting.stiffness_from_params(jnp.asarray(s), 3))
    S = np.zeros((3, 3))
    for k, (i, j) in enumerate([(0, 0), (1, 1), (0, 1), (0, 2), (1, 2)]):
        S[i, j] = S[j, i] = s[k]
    S[2, 2] = -s[0] - s[1]
    E = scipy.linalg.expm(S)
    np.testing.assert_allclose(K, 4 * E / np.trace(E), atol=1e-14)
    np.testing.assert_allclose(fitting.params_from_stiffness(K), s, atol=1e-12)
    _, Ks, _ = pj.paper_subjects()
    np.testing.assert_allclose(
        np.asarray(
            jax.vmap(lambda p: fitting.stiffness_from_params(p, 3))(
                jnp.asarray(fitting.params_from_stiffness(Ks))
            )
        ),
        Ks,
        atol=1e-13,
    )


N_FIT = 500
LOW_NOISE = 0.01  # deg: the regime where the Gauss–Newton (linearised) standard errors are accurate


@pytest.fixture(scope="module")
def nio():
    """One batched call: the six Table subjects (0.5° noise), one at low noise, one failing."""
    names, K, q = pj.paper_subjects()
    idx = [0, 1, 2, 3, 4, 5, 3]
    rec = pj.synthetic_recordings(K[idx], q[idx], N_FIT, noise_deg=[0.5] * 6 + [LOW_NOISE], seed=11)
    pointing = np.concatenate([rec.pointing, rec.pointing[:1]])
    postures = np.concatenate([rec.joint_angles, rec.joint_angles[:1]])
    mask = np.ones(pointing.shape[:2], bool)
    mask[-1, 5:] = False  # subject 8: 5 samples < 8 parameters -> cannot be fitted
    res = fitting.fit_donders(pj.Wrist(), pointing, postures, mask=mask, n_starts=2, seed=0)
    truth = np.concatenate([fitting.params_from_stiffness(K), q], -1)
    return res, np.concatenate([truth, truth[[3]], truth[:1]]), K, q, rec


def test_nio_converges_and_flags_failing_subject(nio):
    res, *_ = nio
    assert res.KJ.shape == (8, 3, 3) and res.start_loss.shape == (8, 2)
    assert np.all(res.converged[:7]) and np.all(res.status[:7] == 0)
    assert not res.converged[7] and res.status[7] == pj.Status.TOO_FEW_DATA
    np.testing.assert_allclose(np.trace(res.KJ, axis1=1, axis2=2), 4.0, rtol=1e-12)
    assert np.all(np.linalg.eigvalsh(res.KJ) > 0)
    # residual RMS ≈ torsional share of 0.5° isotropic noise (0.5/√3 = 0.29°)
    assert np.all(np.abs(np.rad2deg(res.rms[:6]) - 0.5 / np.sqrt(3)) < 0.05)
    # torsion over ±20° pins down at most ~6 combinations (a quadratic surface): the weakest of the
    # 8 directions are flagged, and the report names them
    assert np.all(res.identifiable[:6, :4]) and not np.any(res.identifiable[:6, -1])
    assert "UNIDENTIFIABLE" in res.report(0)


def test_nio_predicts_held_out_torsion(nio):
    res, _, K, q, _ = nio
    grid = pj.screen_grid(7) * 0.97  # held-out positions (not sampled points)
    t_fit = np.asarray(fitting.predicted_torsion(pj.Wrist(), res.KJ[:6], res.q_rest[:6], grid))
    t_true = np.asarray(fitting.predicted_torsion(pj.Wrist(), K, q, grid))
    rms = np.rad2deg(np.sqrt(np.mean((t_fit - t_true) ** 2, axis=-1)))
    assert np.all(rms < 0.25), rms


def test_nio_parameters_within_three_standard_errors(nio):
    res, truth, *_ = nio
    truth_c = np.asarray(jax.vmap(lambda t: fitting.donders_coefficients(t, 3))(jnp.asarray(truth[:7])))
    # The six Table subjects at 0.5° noise: along every identifiable direction (rows of
    # `directions`, in the coefficients of Donders' law) the error is within 3 reported SE.
    for i in range(6):
        z = res.directions[i] @ (res.coefficients[i] - truth_c[i]) / res.direction_stderr[i]
        assert res.identifiable[i].sum() >= 5 and np.all(np.abs(z[res.identifiable[i]]) < 3), (i, z)
        # per coefficient too (marginal SE, all directions)
        assert np.all(np.abs(res.coefficients[i] - truth_c[i]) < 3 * res.coefficient_stderr[i] + 1e-12)
    # Low noise: the linearised errors also hold for the raw parameters (log-stiffness, q_rest).
    i = 6
    assert np.all(np.abs(res.params[i] - truth[i]) < 3 * res.stderr[i]), (res.params[i] - truth[i]) / res.stderr[i]


def test_nio_coefficient_covariance_is_the_delta_method(nio):
    res, *_ = nio
    D = np.asarray(jax.vmap(jax.jacfwd(lambda t: fitting.donders_coefficients(t, 3)))(jnp.asarray(res.params)))
    np.testing.assert_allclose(res.coefficient_cov[:7], (D @ res.cov @ D.transpose(0, 2, 1))[:7], rtol=1e-6, atol=1e-12)
    assert res.coef_names[:2] == ("K[PS,PS]", "K[FE,FE]") and res.coef_names[-1] == "b[RUD]"


def test_nio_batch_equals_single(nio):
    """Subject 7 (low noise) fitted alone gives the batch's numbers (same compiled chunk)."""
    res, _, _, _, rec = nio
    one = fitting.fit_donders(pj.Wrist(), rec.pointing[6], rec.joint_angles[6], n_starts=2, seed=0)
    for f in ("params", "loss", "stderr", "coefficient_stderr", "status", "steps"):
        np.testing.assert_allclose(getattr(one, f)[0], getattr(res, f)[6], rtol=1e-10, atol=1e-14, err_msg=f)


MC_REPLICATES, MC_SIGMA = 40, np.deg2rad(0.3)


@pytest.fixture(scope="module")
def monte_carlo():
    """Table subject 1 at 500 fixed pointing targets; postures = equilibria by NumPy (Newton on
    the Lagrange conditions, exact to 1e-12; not pmpjax's) twisted about the pointing axis by
    N(0, 0.3°) torsion, 40 replicates fitted as 40 subjects of one fit_donders call (the `nio`
    fixture's compiled chunk: 8 subjects, 2 starts).
    Torsion noise leaves the pointing unchanged, so the truth's loss is exactly ½ Σ ε²."""
    K, qr = table_kj(0, normalize=True), TABLE2[0]
    rng = np.random.default_rng(21)
    h = np.sin(np.deg2rad(20.0))
    x = rng.uniform(-h, h, size=(N_FIT, 2))
    q_eq = wrist_equilibria(K, qr, x)
    eps = rng.normal(scale=MC_SIGMA, size=(MC_REPLICATES, N_FIT))
    R_eq = Rotation.from_euler("XZY", q_eq * [-1, 1, 1])
    postures = np.stack(
        [(R_eq * Rotation.from_rotvec(np.stack([e, 0 * e, 0 * e], -1))).as_euler("XZY") * [-1, 1, 1] for e in eps]
    )
    fit = fitting.fit_donders(pj.Wrist(), np.broadcast_to(x, postures.shape[:2] + (2,)), postures, n_starts=2,
                              chunk_size=8)
    truth = np.concatenate([fitting.params_from_stiffness(K), qr])
    return fit, eps, truth


def test_nio_standard_errors_match_monte_carlo_spread(monte_carlo):
    """Reported standard errors vs the spread of 40 fitted replicates around the truth, within 25 %
    both ways: along the directions of Donders' coefficients (identifiable or not), per coefficient,
    and per raw parameter. (A σ² with the wrong degrees of freedom or a factor 2 off in the cost,
    or a Jacobian of the wrong residual, moves these ratios by > 25 %.)"""
    fit, _, truth = monte_carlo
    assert np.all(fit.converged)
    c_true = np.asarray(fitting.donders_coefficients(jnp.asarray(truth), 3))
    V = fit.directions[0]
    reported = np.sqrt(np.mean(np.einsum("ki,rij,kj->rk", V, fit.coefficient_cov, V), 0))
    spread = np.sqrt(np.mean(np.einsum("ki,ri->rk", V, fit.coefficients - c_true) ** 2, 0))
    for name, emp, rep in (
        ("directions", spread, reported),
        ("coefficients", np.sqrt(np.mean((fit.coefficients - c_true) ** 2, 0)),
         np.sqrt(np.mean(fit.coefficient_stderr**2, 0))),
        ("parameters", np.sqrt(np.mean((fit.params - truth) ** 2, 0)), np.sqrt(np.mean(fit.stderr**2, 0))),
    ):
        ratio = emp / rep
        assert np.all((ratio > 0.75) & (ratio < 1.25)), (name, ratio)


def test_nio_likelihood_ratio_is_chi2(monte_carlo):
    """LR = 2 (loss(truth) − loss(fit)) / σ̂² with loss(truth) = ½ Σ ε² known exactly (no pmpjax
    residual involved): never negative (the fit is at least as good as the truth), and over the 40
    replicates distributed as χ²_8 (p = 8 parameters; mean within 3.5 SE, KS test)."""
    fit, eps, _ = monte_carlo
    p = 8
    s2 = 2 * fit.loss / (N_FIT - p)
    lr = 2 * (0.5 * np.sum(eps**2, 1) - fit.loss) / s2
    assert np.all(lr >= 0), lr.min()
    assert abs(lr.mean() - p) < 3.5 * np.sqrt(2 * p / len(lr)), lr.mean()
    assert scipy.stats.kstest(lr, scipy.stats.chi2(p).cdf).pvalue > 0.01


def test_nio_joint_residual_planar_arm():
    """``residual='joint'`` on a non-wrist chain: a 3-link planar arm reaching 2-D targets, postures
    with 0.05° joint noise; the fit is as good as the truth and recovers the coefficients of
    Donders' law within 3 SE along identifiable directions; KJ, q_rest close to the truth."""
    arm = pj.PlanarArm([0.3, 0.3, 0.2])
    K_true = np.array([[1.6, 0.3, 0.1], [0.3, 1.4, -0.2], [0.1, -0.2, 1.0]])
    q_true = np.array([0.4, 1.3, 1.1])
    rng = np.random.default_rng(3)
    # targets of postures spread ±0.6 rad around q_rest (a ±12 cm box would leave q_rest
    # unidentifiable: the fit then reports max_steps in a flat valley)
    targets = np.asarray(arm.fk(jnp.asarray(q_true + rng.uniform(-0.6, 0.6, size=(2, 64, 3)))))
    q_eq = np.asarray(pj.equilibrium_posture(arm, K_true, q_true, targets).q)
    postures = q_eq + np.deg2rad(0.05) * rng.normal(size=q_eq.shape)
    res = fitting.fit_donders(arm, targets, postures, n_starts=1)
    truth = np.concatenate([fitting.params_from_stiffness(K_true), q_true])
    tc = np.asarray(fitting.donders_coefficients(jnp.asarray(truth), 3))
    assert np.all(res.converged) and res.param_names[-1] == "q_rest[2]"
    for i in range(2):
        assert np.sqrt(2 * res.loss[i] / (3 * 64)) < np.deg2rad(0.05)  # at or below the noise
        z = res.directions[i] @ (res.coefficients[i] - tc) / res.direction_stderr[i]
        assert res.identifiable[i].sum() >= 5 and np.all(np.abs(z[res.identifiable[i]]) < 3), z
        assert np.all(np.abs(res.params[i] - truth) < 3 * res.stderr[i]), (res.params[i] - truth) / res.stderr[i]
        np.testing.assert_allclose(res.KJ[i], K_true, atol=0.05)


@pytest.mark.bad_input("fitting.fit_donders")
def test_nio_bad_input():
    w = pj.Wrist()
    x = np.zeros((2, 10, 2))
    q = np.zeros((2, 10, 3))
    with pytest.raises(ValueError, match="postures.*NaN"):
        fitting.fit_donders(w, x, np.where(np.arange(10)[:, None] == 2, np.nan, q))
    with pytest.raises(ValueError, match="pointing.*reachable"):
        fitting.fit_donders(w, np.where(np.arange(10)[:, None] == 2, 0.995, x), q)
    with pytest.raises(ValueError, match="postures.*shape"):
        fitting.fit_donders(w, x, np.zeros((2, 10, 2)))
    with pytest.raises(ValueError, match="agree"):
        fitting.fit_donders(w, x, np.zeros((2, 9, 3)))
    with pytest.raises(ValueError, match="mask"):
        fitting.fit_donders(w, x, q, mask=np.ones((2, 9), bool))
    with pytest.raises(ValueError, match="residual"):
        fitting.fit_donders(w, x, q, residual="angles")
    with pytest.raises(TypeError, match="chain"):
        fitting.fit_donders("wrist", x, q)
    with pytest.raises(ValueError, match="n_starts"):
        fitting.fit_donders(w, x, q, n_starts=0)
    with pytest.raises(ValueError, match="torsion"):
        fitting.fit_donders(pj.PlanarArm([0.3, 0.3, 0.2]), x, q, residual="torsion")


@pytest.mark.bad_input(
    "fitting.donders_coefficients", "fitting.coefficient_names", "fitting.parameter_names",
    "fitting.params_from_stiffness", "fitting.predicted_torsion", "fitting.stiffness_from_params",
)
def test_parameterisation_bad_input():
    cases = [
        (lambda: fitting.stiffness_from_params(jnp.zeros(4), 3), ValueError, "`s`.*shape"),
        (lambda: fitting.stiffness_from_params(jnp.zeros(5), 1), ValueError, "`n`"),
        (lambda: fitting.donders_coefficients(jnp.zeros(7), 3), ValueError, "`params`.*shape"),
        (lambda: fitting.params_from_stiffness(np.diag([1.0, -1.0, 2.0])), ValueError, "`KJ`.*positive definite"),
        (lambda: fitting.params_from_stiffness(np.ones(3)), ValueError, "`KJ`.*shape"),
        (lambda: fitting.coefficient_names("wrist"), TypeError, "`chain`"),
        (lambda: fitting.parameter_names(None), TypeError, "`chain`"),
        (lambda: fitting.predicted_torsion(pj.PlanarArm([0.3, 0.3, 0.2]), np.eye(3), np.zeros(3), np.zeros((1, 2))),
         TypeError, "`chain`"),
        (lambda: fitting.predicted_torsion(pj.Wrist(), np.eye(3), np.zeros(3), np.full((1, 2), 0.99)), ValueError,
         "target.*reachable"),
    ]
    for call, err, match in cases:
        with pytest.raises(err, match=match):
            call()


@pytest.mark.bad_input(
    "pj.evaluate_surface", "pj.plot_donders", "pj.screen_grid", "pj.surface_grid", "pj.model_donders_surface",
    "pj.recording_from_arrays", "pj.synthetic_recordings", "pj.center_out_trials",
)
def test_surfaces_recordings_protocol_bad_input():
    K, qr = table_kj(0), TABLE2[0]
    cases = [
        (lambda: pj.evaluate_surface(np.zeros(5), 0.0, 0.0), ValueError, "`coef`.*shape"),
        (lambda: pj.evaluate_surface(np.zeros(6), np.nan, 0.0), ValueError, "`r_y`.*NaN"),
        (lambda: pj.plot_donders(np.zeros((4, 2))), ValueError, "`r`.*shape"),
        (lambda: pj.screen_grid(0), ValueError, "`n`"),
        (lambda: pj.screen_grid(3, half_angle_deg=95.0), ValueError, "half_angle_deg"),
        (lambda: pj.surface_grid(np.zeros(4)), ValueError, "surface_or_coef"),
        (lambda: pj.surface_grid(np.zeros(6), extent=-1.0), ValueError, "extent"),
        (lambda: pj.model_donders_surface(K, qr, np.full((2, 2), 0.99)), ValueError, "pointing.*reachable"),
        (lambda: pj.model_donders_surface(K, qr, np.zeros((2, 3))), ValueError, "`pointing`.*shape"),
        (lambda: pj.model_donders_surface(np.eye(2), qr), ValueError, "`KJ`.*shape"),
        (lambda: pj.model_donders_surface(K, qr, chain=pj.PlanarArm([0.3, 0.3, 0.2])), TypeError, "`chain`"),
        (lambda: pj.recording_from_arrays(["a"], np.zeros((1, 3, 2))), ValueError, "exactly one"),
        (lambda: pj.recording_from_arrays(["a"], np.zeros((1, 3, 3)), joint_angles=np.zeros((1, 3, 3))),
         ValueError, "`pointing`.*shape"),
        (lambda: pj.recording_from_arrays(["a", "b"], np.zeros((1, 3, 2)), joint_angles=np.zeros((1, 3, 3))),
         ValueError, "`quat`"),
        (lambda: pj.synthetic_recordings(K, qr, 0), ValueError, "n_samples"),
        (lambda: pj.synthetic_recordings(K, qr, 5, noise_deg=-1.0), ValueError, "noise_deg"),
        (lambda: pj.synthetic_recordings(-K, qr, 5), ValueError, "`KJ`.*positive definite"),
        (lambda: pj.synthetic_recordings(K, qr[:2], 5), ValueError, "`q_rest`.*shape"),
        (lambda: pj.synthetic_recordings(K, qr, 5, d=0.0), ValueError, "`d`"),
        (lambda: pj.center_out_trials(0), ValueError, "n_trials"),
    ]
    for call, err, match in cases:
        with pytest.raises(err, match=match):
            call()


def test_main_job_part_recovers_the_table_subjects(tmp_path):
    """`pmpjax reproduce --quick --only donders_nio` (the sizes of the ``nio`` fixture's fit)."""
    import csv

    from pmpjax._app import cli

    out = tmp_path
    res = cli.reproduce(out, quick=True, only=["donders_nio"], progress=False, cache=False)
    assert res["donders_nio"]["status"] == "ok", res["donders_nio"].get("error")
    assert (out / "donders_subject1.png").read_bytes()[:4] == b"\x89PNG"
    r = res["donders_nio"]["results"]
    names, KJ, q_rest = pj.paper_subjects()
    assert r["subjects"] == list(names)
    ok = np.array(r["converged"])
    assert ok.sum() >= 5  # (every fit reports its own status; a failed start is flagged, not hidden)
    # Held-out torsion of the converged fits within a degree of the Tables' model (0.5° data noise).
    assert np.all(np.array(r["held_out_torsion_rms_deg"])[ok] < 1.0)
    rows = list(csv.DictReader((out / "donders_nio.csv").open()))
    assert [row["subject"] for row in rows] == list(names)
    np.testing.assert_allclose([float(row["KJ_00 true [Nm/rad]"]) for row in rows], KJ[:, 0, 0], rtol=1e-5)
