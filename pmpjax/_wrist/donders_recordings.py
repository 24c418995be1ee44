"""Donders recordings: steady wrist postures at pointing positions; synthetic data and file I/O.

A :class:`DondersRecording` holds, for S subjects with up to N samples each,

- ``subjects`` (S,) names, ``quat`` (S, N, 4) hand orientations (unit, scalar-first ``w, x, y, z``,
  hand-to-world, the frame of Eq 6), ``pointing`` (S, N, 2) screen points ``(x1, x2)`` [m] at
  distance ``d`` [m], ``mask`` (S, N) valid samples (subjects may have different counts).

File formats (one schema, two encodings; ``write_recordings``/``read_recordings`` pick by suffix):

- **CSV** (long format, one row per sample; ``#`` lines are comments and may carry ``d=<metres>``)::

      # pmpjax donders v1
      # d=1.0
      subject,sample,qw,qx,qy,qz,x1,x2
      subj1,0,0.99,0.01,-0.05,0.08,0.16,0.09

  Required columns: ``subject``, ``sample`` (integer, unique per subject) and either the
  quaternion ``qw, qx, qy, qz`` or the joint angles ``q_ps, q_fe, q_rud`` [rad] (Eq 6 order);
  ``x1, x2`` [m]. Extra columns are ignored; quaternions win when both are present.
- **NPZ**: arrays ``subjects`` (S,) str, ``quat`` (S, N, 4), ``pointing`` (S, N, 2), ``mask``
  (S, N) bool, ``d`` () and ``format`` = "pmpjax donders v1".

Readers are strict: empty or malformed files, missing columns, non-numeric fields, NaN/inf,
duplicate samples, non-unit quaternions (|‖q‖ − 1| > 1e-3) and pointing outside the wrist's
reachable screen raise ``ValueError`` naming the file, line/array and problem.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import os

import numpy as np

from .._base import (
    as_array,
    check_finite_masked,
    check_positive,
    check_positive_int,
    check_spd,
    csv_floats,
    input_file,
    open_npz,
    read_text_file,
)
from .._chains import Wrist
from .._pmp import equilibrium_posture
from .donders import SCREEN_HALF_ANGLE_DEG
from .orientation import (
    joint_angles_from_quat,
    matrix_from_rotvec,
    quat_from_joint_angles,
    quat_from_matrix,
    wrist_rotation,
)

FORMAT = "pmpjax donders v1"
_QUAT_COLS = ("qw", "qx", "qy", "qz")
_JOINT_COLS = ("q_ps", "q_fe", "q_rud")


@dataclasses.dataclass(frozen=True)
class DondersRecording:
    """Steady wrist postures of S subjects with up to N samples each.

    Made by :func:`read_recordings`, :func:`recording_from_arrays` or :func:`synthetic_recordings`;
    construction checks shapes, finiteness, unit quaternions and reachable pointing, and raises
    ``ValueError`` naming the problem.

    **Fields:**

    - ``subjects``: (S,) names (unique).
    - ``quat``: (S, N, 4) hand orientations (unit, scalar-first ``w, x, y, z``, hand-to-world, the
      frame of Eq 6).
    - ``pointing``: (S, N, 2) screen points ``(x1, x2)`` [m].
    - ``mask``: (S, N) bool valid samples (subjects may have different counts).
    - ``d``: screen distance [m].
    """

    subjects: tuple[str, ...]
    quat: np.ndarray
    pointing: np.ndarray
    mask: np.ndarray
    d: float = 1.0

    def __post_init__(self):
        _check_recording(self, "recording")

    @property
    def joint_angles(self) -> np.ndarray:
        """Wrist joint angles (S, N, 3) [rad] (branch |q_FE| < π/2); masked samples are 0."""
        quat = np.where(self.mask[..., None], self.quat, [1.0, 0.0, 0.0, 0.0])  # padding: identity
        q = np.asarray(joint_angles_from_quat(quat))
        return np.where(self.mask[..., None], q, 0.0)

    @property
    def n_samples(self) -> np.ndarray:
        return self.mask.sum(axis=-1)


def _check_recording(rec: DondersRecording, where: str):
    S = len(rec.subjects)
    quat, pointing, mask = (np.asarray(a) for a in (rec.quat, rec.pointing, rec.mask))
    if S == 0 or quat.ndim != 3 or quat.shape[0] != S or quat.shape[1] == 0 or quat.shape[2] != 4:
        raise ValueError(
            f"{where}: `quat` must have shape (S, N, 4) with S = {S} subjects, N > 0; got {quat.shape}"
        )
    if pointing.shape != quat.shape[:2] + (2,):
        raise ValueError(f"{where}: `pointing` must have shape {quat.shape[:2] + (2,)}, got {pointing.shape}")
    if mask.shape != quat.shape[:2] or mask.dtype != bool:
        raise ValueError(
            f"{where}: `mask` must be a bool array of shape {quat.shape[:2]}, got {mask.dtype} {mask.shape}"
        )
    if len(set(rec.subjects)) != S:
        raise ValueError(f"{where}: subject names must be unique, got {list(rec.subjects)}")
    for name, a in (("quat", quat), ("pointing", pointing)):
        check_finite_masked(name, a, mask, labels=rec.subjects, where=where)
    norm = np.where(mask, np.linalg.norm(np.nan_to_num(quat), axis=-1), 1.0)
    if np.any(np.abs(norm - 1.0) > 1e-3):
        s, i = np.argwhere(np.abs(norm - 1.0) > 1e-3)[0]
        raise ValueError(
            f"{where}: `quat` must be unit quaternions; |q| = {norm[s, i]:.6g} at subject "
            f"{rec.subjects[s]!r}, sample {i}"
        )
    if not (np.isfinite(rec.d) and rec.d > 0):
        raise ValueError(f"{where}: `d` must be a positive distance [m], got {rec.d}")
    chain = Wrist(d=float(rec.d))
    chain.check_target(f"{where}: pointing", pointing[mask])
    if np.any(mask.sum(-1) == 0):
        raise ValueError(f"{where}: subject {rec.subjects[int(np.argmin(mask.sum(-1)))]!r} has no samples")


def synthetic_recordings(
    KJ,
    q_rest,
    n_samples: int,
    *,
    noise_deg: float = 0.5,
    seed: int = 0,
    half_angle_deg: float = SCREEN_HALF_ANGLE_DEG,
    d: float = 1.0,
    names=None,
) -> DondersRecording:
    """Synthetic steady postures of subjects with known ``KJ`` and ``q_rest``.

    Targets are uniform over the ±``half_angle_deg`` screen square (``|x_i| ≤ d sin(angle)``); the
    posture is the λ0-PMP's equilibrium (:func:`equilibrium_posture`); noise is a random rotation in
    the hand frame, ``R_obs = R(q_eq) exp(ε̂)`` with an isotropic Gaussian rotation vector ``ε``
    (each component ``N(0, noise²/3)``). As with an IMU, the recorded pointing is the point the
    *noisy* orientation points at (Eq 6), so pointing and orientation are consistent.

    **Arguments:**

    - ``KJ``: (S, 3, 3) SPD joint stiffness [Nm/rad].
    - ``q_rest``: (S, 3) rest postures [rad].
    - ``n_samples``: postures per subject.
    - ``noise_deg``: RMS angle of the orientation noise [deg], scalar or (S,).
    - ``seed``: seed of ``numpy.random.default_rng``.
    - ``half_angle_deg``: half-angle of the target area [deg], in (0, 90).
    - ``d``: screen distance [m].
    - ``names``: S subject names (default ``subj1``, ``subj2``, ...).

    **Returns:**

    A :class:`DondersRecording`.

    **Raises:**

    - ``ValueError`` naming the argument for shapes that do not agree, non-SPD ``KJ``, non-positive
      sizes or distances, negative noise, a half-angle outside (0, 90), the wrong number of names,
      or parameters whose equilibria cannot be computed.
    """
    KJ = np.asarray(as_array("KJ", KJ, tail=(3, 3)), dtype=float)
    q_rest = np.asarray(as_array("q_rest", q_rest, tail=(3,)), dtype=float)
    if KJ.ndim != q_rest.ndim + 1 or KJ.ndim > 3 or KJ.shape[:-2] != q_rest.shape[:-1]:
        raise ValueError(f"`KJ` (S, 3, 3) and `q_rest` (S, 3) must agree, got {KJ.shape} and {q_rest.shape}")
    check_spd("KJ", KJ)
    check_positive("d", d)
    if not (np.isfinite(half_angle_deg) and 0 < half_angle_deg < 90):
        raise ValueError(f"`half_angle_deg` must be in (0, 90), got {half_angle_deg}")
    if KJ.ndim == 2:
        KJ, q_rest = KJ[None], q_rest[None]
    S = KJ.shape[0]
    check_positive_int("n_samples", n_samples)
    noise = np.broadcast_to(np.asarray(noise_deg, dtype=float), (S,)) if np.ndim(noise_deg) <= 1 else None
    if noise is None or not np.all(np.isfinite(noise) & (noise >= 0)):
        raise ValueError(f"`noise_deg` must be >= 0 (scalar or one per subject), got {noise_deg}")
    names = tuple(names) if names is not None else tuple(f"subj{i + 1}" for i in range(S))
    if len(names) != S:
        raise ValueError(f"`names` must have {S} entries, got {len(names)}")
    rng = np.random.default_rng(seed)
    chain = Wrist(d=float(d))
    h = d * np.sin(np.deg2rad(half_angle_deg))
    targets = rng.uniform(-h, h, size=(S, n_samples, 2))
    q = equilibrium_posture(chain, KJ[:, None], q_rest[:, None], targets).q
    if not np.all(np.isfinite(np.asarray(q))):
        raise ValueError("`KJ`, `q_rest`: some equilibrium postures could not be computed (non-finite)")
    eps = rng.normal(size=(S, n_samples, 3)) * (np.deg2rad(noise)[:, None, None] / np.sqrt(3.0))
    R = np.asarray(wrist_rotation(q)) @ np.asarray(matrix_from_rotvec(eps))
    quat = np.asarray(quat_from_matrix(R))
    pointing = d * np.stack([-R[..., 1, 0], R[..., 2, 0]], -1)
    return DondersRecording(names, quat, pointing, np.ones((S, n_samples), bool), float(d))


def recording_from_arrays(subjects, pointing, *, quat=None, joint_angles=None, mask=None, d=1.0):
    """Build a validated :class:`DondersRecording` from arrays; give ``quat`` or ``joint_angles``.

    **Arguments:**

    - ``subjects``: (S,) names.
    - ``pointing``: (S, N, 2) screen points [m].
    - ``quat``: (S, N, 4) hand-to-world quaternions ``(w, x, y, z)``, or
    - ``joint_angles``: (S, N, 3) wrist joint angles ``(q_PS, q_FE, q_RUD)`` [rad].
    - ``mask``: optional (S, N) bool valid samples (default all).
    - ``d``: screen distance [m].

    **Returns:**

    The :class:`DondersRecording`.

    **Raises:**

    - ``ValueError`` for both or neither of ``quat`` and ``joint_angles``, and as
      :class:`DondersRecording` for bad shapes or values.
    """
    pointing = np.asarray(as_array("pointing", pointing, tail=(2,), finite=False), dtype=float)
    if (quat is None) == (joint_angles is None):
        raise ValueError("give exactly one of `quat` (S, N, 4) or `joint_angles` (S, N, 3)")
    if quat is None:
        ja = np.asarray(joint_angles, dtype=float)
        if ja.shape[-1:] != (3,):
            raise ValueError(f"`joint_angles` must have trailing shape (3,), got {ja.shape}")
        quat = np.asarray(quat_from_joint_angles(np.nan_to_num(ja)))
        quat = np.where(np.isfinite(ja).all(-1, keepdims=True), quat, np.nan)
    quat = np.asarray(quat, dtype=float)
    mask = np.ones(quat.shape[:2], bool) if mask is None else np.asarray(mask, bool)
    return DondersRecording(tuple(str(s) for s in subjects), quat, pointing, mask, float(d))


# --- files -----------------------------------------------------------------------------------


def write_recordings(path, rec: DondersRecording) -> None:
    """Write a Donders recording as CSV or NPZ (the format :func:`read_recordings` reads).

    **Arguments:**

    - ``path``: the file, ``.csv`` (``subject,sample,qw,qx,qy,qz,x1,x2`` with a ``# d=`` line) or
      ``.npz``.
    - ``rec``: the :class:`DondersRecording`.

    **Raises:**

    - ``ValueError`` naming ``path`` for another suffix.
    """
    path = os.fspath(path)
    if path.endswith(".npz"):
        np.savez(
            path,
            subjects=np.array(rec.subjects),
            quat=rec.quat,
            pointing=rec.pointing,
            mask=rec.mask,
            d=np.float64(rec.d),
            format=np.array(FORMAT),
        )
        return
    if not path.endswith(".csv"):
        raise ValueError(f"`path` must end in .csv or .npz, got {path!r}")
    q = rec.joint_angles
    with open(path, "w", newline="") as f:
        f.write(f"# {FORMAT}\n# d={rec.d!r}\n")
        w = csv.writer(f)
        w.writerow(("subject", "sample") + _QUAT_COLS + ("x1", "x2") + _JOINT_COLS)
        for s, name in enumerate(rec.subjects):
            for i in np.flatnonzero(rec.mask[s]):
                w.writerow(
                    [name, int(i)]
                    + [repr(float(v)) for v in rec.quat[s, i]]
                    + [repr(float(v)) for v in rec.pointing[s, i]]
                    + [repr(float(v)) for v in q[s, i]]
                )


def read_recordings(path) -> DondersRecording:
    """Read a Donders recording (CSV or NPZ, the format of the module docstring) strictly.

    CSV: ``subject,sample,qw,qx,qy,qz,x1,x2`` (or joint angles ``q_ps,q_fe,q_rud`` [rad] instead of
    the quaternion), one row per steady posture; a line ``# d=<metres>`` gives the screen distance.

    **Arguments:**

    - ``path``: a file written by :func:`write_recordings` or by hand in the same format.

    **Returns:**

    A :class:`DondersRecording`.

    **Raises:**

    - ``ValueError`` naming the file, line (or array) and problem: another suffix, empty or malformed
      files, missing columns, non-numeric fields, NaN/inf, duplicate samples, non-unit quaternions
      and pointing outside the wrist's reachable screen.
    """
    path = os.fspath(input_file("path", path))
    if path.endswith(".npz"):
        return _read_npz(path)
    if path.endswith(".csv"):
        return _read_csv(path)
    raise ValueError(f"`path` must end in .csv or .npz, got {path!r}")


def _read_npz(path):
    with open_npz(path) as z:
        missing = [k for k in ("subjects", "quat", "pointing", "mask") if k not in z.files]
        if missing:
            raise ValueError(f"{path}: missing array(s) {missing}; expected subjects, quat, pointing, mask")
        if "format" in z.files and str(z["format"]) != FORMAT:
            raise ValueError(f"{path}: unknown format {str(z['format'])!r}, expected {FORMAT!r}")
        try:
            quat = np.asarray(z["quat"], dtype=float)
            pointing = np.asarray(z["pointing"], dtype=float)
        except (TypeError, ValueError) as e:
            raise ValueError(f"{path}: `quat`/`pointing` must be numeric ({e})") from e
        mask = np.asarray(z["mask"])
        if mask.dtype != bool:
            raise ValueError(f"{path}: `mask` must be boolean, got {mask.dtype}")
        d = float(z["d"]) if "d" in z.files else 1.0
        subjects = tuple(str(s) for s in np.atleast_1d(z["subjects"]))
    return _build(path, subjects, quat, pointing, mask, d)


def _build(path, subjects, quat, pointing, mask, d):
    try:
        return DondersRecording(subjects, quat, pointing, mask, d)
    except ValueError as e:
        raise ValueError(f"{path}: {e}") from e


def _read_csv(path):
    text = read_text_file(input_file("path", path))
    d = 1.0
    lines = []
    for ln, line in enumerate(text.splitlines(), 1):
        s = line.strip()
        if not s:
            continue
        if s.startswith("#"):
            body = s.lstrip("#").strip()
            if body.startswith("d="):
                try:
                    d = float(body[2:])
                except ValueError as e:
                    raise ValueError(
                        f"{path}: line {ln}: bad distance comment {s!r} (expected '# d=<metres>')"
                    ) from e
            continue
        lines.append((ln, line))
    if not lines:
        raise ValueError(f"{path}: empty file (no header, no samples)")
    rows = list(csv.reader(io.StringIO("\n".join(line for _, line in lines))))
    header = [h.strip().lower() for h in rows[0]]
    if len(set(header)) != len(header):
        raise ValueError(f"{path}: line {lines[0][0]}: duplicate column names in header {header}")
    col = {h: i for i, h in enumerate(header)}
    has_q = all(c in col for c in _QUAT_COLS)
    has_j = all(c in col for c in _JOINT_COLS)
    need = ["subject", "sample", "x1", "x2"]
    missing = [c for c in need if c not in col]
    known = {*need, *_QUAT_COLS, *_JOINT_COLS}
    unknown = [c for c in header if c not in known]
    if missing or not (has_q or has_j):
        raise ValueError(
            f"{path}: line {lines[0][0]}: header line lacks column(s) "
            f"{missing + ([] if has_q or has_j else ['qw,qx,qy,qz or q_ps,q_fe,q_rud'])}"
            + (f" and has unknown column(s) {unknown} (renamed?)" if unknown else "")
        )
    if unknown:  # (a renamed column would otherwise be ignored silently)
        raise ValueError(f"{path}: line {lines[0][0]}: unknown column(s) {unknown}; expected "
                         f"{', '.join(need)} and {','.join(_QUAT_COLS)} or {','.join(_JOINT_COLS)}")
    if len(rows) == 1:
        raise ValueError(f"{path}: header only, no samples")
    ori_cols = _QUAT_COLS if has_q else _JOINT_COLS
    data: dict[str, dict[int, tuple]] = {}
    for (ln, _), row in zip(lines[1:], rows[1:]):
        if len(row) != len(header):
            raise ValueError(f"{path}: line {ln}: expected {len(header)} fields, got {len(row)}")
        name = row[col["subject"]].strip()
        if not name:
            raise ValueError(f"{path}: line {ln}: empty subject name")
        try:
            sample = int(row[col["sample"]])
        except ValueError as e:
            raise ValueError(f"{path}: line {ln}, column {col['sample'] + 1} (sample): must be an integer, "
                             f"got {row[col['sample']]!r}") from e
        vals = csv_floats(path, ln, row, col, (*ori_cols, "x1", "x2"))
        ori, x = vals[: len(ori_cols)], vals[len(ori_cols):]
        if not has_q and np.any(np.abs(ori) > 2 * np.pi):
            c = ori_cols[int(np.argmax(np.abs(ori) > 2 * np.pi))]
            raise ValueError(f"{path}: line {ln}, column {col[c] + 1} ({c}): {ori[ori_cols.index(c)]:g} is above 2π: "
                             "joint angles are in radians (degrees?)")
        if sample in data.setdefault(name, {}):
            raise ValueError(f"{path}: line {ln}: duplicate sample {sample} for subject {name!r}")
        data[name][sample] = (ori, x)
    subjects = tuple(data)
    N = max(len(v) for v in data.values())
    ori = np.zeros((len(subjects), N, len(ori_cols)))
    pointing = np.zeros((len(subjects), N, 2))
    mask = np.zeros((len(subjects), N), bool)
    for s, name in enumerate(subjects):
        for i, k in enumerate(sorted(data[name])):
            ori[s, i], pointing[s, i] = data[name][k]
            mask[s, i] = True
    if not has_q:
        ori = np.where(mask[..., None], np.asarray(quat_from_joint_angles(ori)), 0.0)
    return _build(path, subjects, ori, pointing, mask, d)
