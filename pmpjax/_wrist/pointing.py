"""Wrist-pointing recordings (center-out task, paper Section 2): format, reader/writer, synthetic experiment.

A :class:`PointingRecording` is the long table of IMU samples of any number of subjects and
trials, one row per sample (the paper: 120 Hz):

- **CSV**: ``#`` lines are comments (``# d=<metres>`` the screen distance, ``# radius=<metres>``
  the nominal target distance, default π/12); then the header and one row per sample::

      # pmpjax pointing v1
      # d=1.0
      subject,trial,time,qw,qx,qy,qz,target
      subj1,1,0.0,0.9999,0.0021,-0.0003,0.0131,C

  ``time`` [s] from the start of the trial, strictly increasing within a trial; ``qw..qz`` the
  unit hand orientation quaternion (scalar first, hand-to-world in the frame of Eq 6, so joint
  angles are ``joint_angles_from_quat``); ``target`` the target on screen at that sample (``C``,
  ``N``, ``NE``, ``E``, ``SE``, ``S``, ``SW``, ``W``, ``NW``). Extra columns are ignored; rows of
  a trial need not be adjacent, but their order is their time order.
- **NPZ**: the same columns as arrays (``subject``, ``trial``, ``time``, ``qw``, ``qx``, ``qy``,
  ``qz``, ``target``) plus ``format`` = "pmpjax pointing v1" and optional ``d``, ``radius``.

The reader is strict. Structural problems (missing file, no header, missing or duplicate
columns, wrong field counts, non-numeric fields, a non-integer trial) raise ``ValueError`` naming
the file, line and column. Problems of one trial's data — NaN/inf samples, time not strictly
increasing, non-unit quaternions (``| |q| − 1 | > 1e-3``), an empty or unknown target name —
raise the same way, naming also the subject and trial, unless ``on_invalid="skip"``: then the
trial is dropped, a warning is issued and the trial is listed in ``recording.skipped``, which
the analysis reports (``fitting.analyze_pointing``).

:func:`synthetic_pointing_experiment` makes a seeded experiment in this format from the λ0-PMP
(six Table subjects × trials × 16 movements) with a Donders session per subject, and returns the
ground truth beside the files.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import os
import warnings
from functools import partial

import jax.numpy as jnp
import numpy as np

from .._base import (
    bucket,
    check_positive_int,
    fast_compile_jit,
    head_rows,
    input_file,
    is_concrete,
    open_npz,
    pad_rows,
    read_text_file,
    replace,
    row_chunks,
    without_unit_checks,
)
from .._chains import Wrist
from .._pmp import ArimotoPlanner, Lambda0PMP, equilibrium_posture, simulate
from .center_out import DIRECTIONS, center_out_targets, center_out_trials, target_radius
from .donders_recordings import DondersRecording, synthetic_recordings, write_recordings
from .orientation import matrix_from_rotvec, quat_from_matrix, wrist_rotation
from .subjects import paper_subjects

FORMAT = "pmpjax pointing v1"
COLUMNS = ("subject", "trial", "time", "qw", "qx", "qy", "qz", "target")
TARGET_NAMES = ("C",) + DIRECTIONS
#: The 16 movements: ``out-X`` from the centre to X, ``in-X`` from X back to the centre.
MOVEMENT_LABELS = tuple(f"{way}-{d}" for d in DIRECTIONS for way in ("out", "in"))
_QCOLS = ("qw", "qx", "qy", "qz")
_UNIT_TOL = 1e-3


@dataclasses.dataclass(frozen=True)
class PointingRecording:
    """IMU samples of a center-out pointing experiment, one entry per sample (N rows).

    Made by :func:`read_pointing` or :func:`synthetic_pointing_experiment`; construction checks the
    shapes and raises ``ValueError`` naming the source and the field.

    **Fields:**

    - ``subject``: (N,) str subject names.
    - ``trial``: (N,) int trial numbers.
    - ``time``: (N,) time from the trial's start [s].
    - ``quat``: (N, 4) unit hand-to-world orientation ``(w, x, y, z)``, scalar first, in the frame of
      Eq 6.
    - ``target``: (N,) str, the target on screen (``C``, ``N``, ``NE``, … ``NW``).
    - ``d``: screen distance [m].
    - ``radius``: nominal target distance [m] (normalises curvature).
    - ``source``: the file it was read from (named in messages).
    - ``line``: (N,) the file line of each row (None when built in memory: messages then give the
      row index).
    - ``skipped``: the trials the reader dropped, as ``(subject, trial, reason)``.
    """

    subject: np.ndarray
    trial: np.ndarray
    time: np.ndarray
    quat: np.ndarray
    target: np.ndarray
    d: float = 1.0
    radius: float = float(np.pi / 12)
    source: str = "<memory>"
    line: np.ndarray | None = None
    skipped: tuple = ()

    def __post_init__(self):
        N = np.shape(self.time)[0] if np.ndim(self.time) == 1 else -1
        set_ = partial(object.__setattr__, self)
        set_("subject", np.asarray(self.subject).astype(str))
        set_("target", np.asarray(self.target).astype(str))
        set_("time", np.asarray(self.time, dtype=float))
        set_("quat", np.asarray(self.quat, dtype=float))
        tr = np.asarray(self.trial)
        if tr.dtype.kind not in "iu":
            if tr.dtype.kind != "f" or not np.all(np.isfinite(tr) & (tr == np.round(tr))):
                raise ValueError(f"{self.source}: `trial` must hold integers, got dtype {tr.dtype}")
        set_("trial", tr.astype(np.int64))
        if N <= 0:
            raise ValueError(f"{self.source}: `time` must be a non-empty 1-D array, got shape {np.shape(self.time)}")
        for name, shape in (("subject", (N,)), ("trial", (N,)), ("target", (N,)), ("quat", (N, 4))):
            if getattr(self, name).shape != shape:
                raise ValueError(f"{self.source}: `{name}` must have shape {shape}, got {getattr(self, name).shape}")
        if self.line is not None:
            line = np.asarray(self.line, dtype=np.int64)
            if line.shape != (N,):
                raise ValueError(f"{self.source}: `line` must have shape {(N,)}, got {line.shape}")
            set_("line", line)
        if not (np.isfinite(self.d) and self.d > 0):
            raise ValueError(f"{self.source}: `d` must be a positive screen distance [m], got {self.d}")
        if not (np.isfinite(self.radius) and 0 < self.radius < self.d):
            raise ValueError(f"{self.source}: `radius` must lie in (0, d), got {self.radius}")
        set_("d", float(self.d))
        set_("radius", float(self.radius))
        set_("skipped", tuple(self.skipped))

    @property
    def subjects(self) -> tuple[str, ...]:
        """Subject names in order of first appearance."""
        _, first = np.unique(self.subject, return_index=True)
        return tuple(str(v) for v in self.subject[np.sort(first)])

    def trials(self, subject: str) -> tuple[int, ...]:
        """Trial numbers of a subject, in order of first appearance.

        **Arguments:**

        - ``subject``: a subject name.

        **Returns:**

        The trial numbers (tuple of int; empty for an unknown subject).
        """
        tr = self.trial[self.subject == subject]
        _, first = np.unique(tr, return_index=True)
        return tuple(int(v) for v in tr[np.sort(first)])

    def rows(self, subject: str, trial: int) -> np.ndarray:
        """Row indices of one trial, in file order.

        **Arguments:**

        - ``subject``: a subject name.
        - ``trial``: a trial number.

        **Returns:**

        (k,) int row indices.
        """
        return np.flatnonzero((self.subject == subject) & (self.trial == trial))

    @property
    def pointing(self) -> np.ndarray:
        """Screen points (N, 2) [m] of the orientations (Eq 6: ``x = d (−R₂₁, R₃₁)``)."""
        return screen_point_from_quat(self.quat, self.d)

    def where(self, row: int, column: str | None = None) -> str:
        """Where a row came from, for messages: ``file:line`` (read from a file) or ``source, row i``
        (built in memory), and the column.

        **Arguments:**

        - ``row``: a row index.
        - ``column``: a column name (of the CSV format) to add, or None.

        **Returns:**

        The location (str).
        """
        col = f", column {column!r} (#{COLUMNS.index(column) + 1})" if column in COLUMNS else ""
        at = f"{self.source}, row {int(row)}" if self.line is None else f"{self.source}:{int(self.line[row])}"
        return at + col


def screen_point_from_quat(quat, d: float = 1.0) -> np.ndarray:
    """Eq 6 from quaternions ``(w, x, y, z)`` (..., 4): ``x = d (−R[1,0], R[2,0])`` [m] (NumPy)."""
    q = np.asarray(quat, dtype=float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = (q[..., i] for i in range(4))
    return d * np.stack([-2 * (x * y + w * z), 2 * (x * z - w * y)], -1)


def trial_problems(rec: PointingRecording) -> list[tuple[str, int, int, str, str]]:
    """Data problems of each trial: ``(subject, trial, row, column, message)``, at most one per trial
    (the first found): NaN/inf samples, time not strictly increasing, non-unit quaternions, an empty
    or unknown target name, fewer than 2 samples."""
    out = []
    for s in rec.subjects:
        for t in rec.trials(s):
            rows = rec.rows(s, t)
            p = _one_trial_problem(rec, rows)
            if p is not None:
                out.append((s, t) + p)
    return out


def _one_trial_problem(rec, rows):
    time, quat, target = rec.time[rows], rec.quat[rows], rec.target[rows]
    bad = ~np.isfinite(time)
    if bad.any():
        i = int(np.argmax(bad))
        return int(rows[i]), "time", f"NaN or inf time {time[i]}"
    badq = ~np.all(np.isfinite(quat), axis=-1)
    if badq.any():
        i = int(np.argmax(badq))
        col = _QCOLS[int(np.argmax(~np.isfinite(quat[i])))]
        return int(rows[i]), col, f"NaN or inf orientation sample {quat[i].tolist()}"
    if rows.size < 2:
        return int(rows[0]), "time", "a trial needs at least 2 samples"
    step = np.diff(time)
    if np.any(step <= 0):
        i = int(np.argmax(step <= 0)) + 1
        return int(rows[i]), "time", f"time not strictly increasing ({float(time[i - 1])!r} then {float(time[i])!r})"
    if np.median(step) > 0.5:  # an IMU samples at tens of Hz or faster
        return int(rows[1]), "time", (f"median sample interval {float(np.median(step)):.4g} s: time must be in "
                                      "seconds (milliseconds?)")
    norm = np.linalg.norm(quat, axis=-1)
    off = np.abs(norm - 1.0) > _UNIT_TOL
    if off.any():
        i = int(np.argmax(off))
        return int(rows[i]), "qw", f"not a unit quaternion (|q| = {norm[i]:.6g})"
    unknown = ~np.isin(target, TARGET_NAMES)
    if unknown.any():
        i = int(np.argmax(unknown))
        what = "missing (empty) target" if not target[i].strip() else f"unknown target {str(target[i])!r}"
        return int(rows[i]), "target", f"{what}; expected one of {', '.join(TARGET_NAMES)}"
    return None


def problem_message(rec: PointingRecording, problem) -> str:
    s, t, row, col, msg = problem
    return f"{rec.where(row, col)}: subject {s!r}, trial {t}: {msg}"


def drop_trials(rec: PointingRecording, problems, *, warn: bool = True) -> PointingRecording:
    """``rec`` without the trials of ``problems``; they are listed in ``skipped``."""
    if not problems:
        return rec
    keep = np.ones(rec.time.shape[0], bool)
    skipped = list(rec.skipped)
    for p in problems:
        keep[rec.rows(p[0], p[1])] = False
        skipped.append((p[0], int(p[1]), problem_message(rec, p)))
        if warn:
            warnings.warn(f"skipping trial: {problem_message(rec, p)}", stacklevel=3)
    if not keep.any():
        raise ValueError(f"{rec.source}: every trial has invalid data; first: {problem_message(rec, problems[0])}")
    return PointingRecording(rec.subject[keep], rec.trial[keep], rec.time[keep], rec.quat[keep], rec.target[keep],
                             d=rec.d, radius=rec.radius, source=rec.source,
                             line=None if rec.line is None else rec.line[keep],
                             skipped=tuple(skipped))


# --- files -----------------------------------------------------------------------------------


def write_pointing(path, rec: PointingRecording) -> None:
    """Write a pointing recording as CSV or NPZ (the format :func:`read_pointing` reads).

    **Arguments:**

    - ``path``: the file; ``.csv`` (``subject,trial,time,qw,qx,qy,qz,target`` with ``# d=`` and
      ``# radius=`` lines) or ``.npz``.
    - ``rec``: the :class:`PointingRecording`.

    **Raises:**

    - ``TypeError`` for a non-recording; ``ValueError`` naming ``path`` for another suffix.
    """
    path = os.fspath(path)
    if not isinstance(rec, PointingRecording):
        raise TypeError(f"`rec` must be a PointingRecording, got {type(rec).__name__}")
    if path.endswith(".npz"):
        np.savez(path, subject=rec.subject, trial=rec.trial, time=rec.time, qw=rec.quat[:, 0], qx=rec.quat[:, 1],
                 qy=rec.quat[:, 2], qz=rec.quat[:, 3], target=rec.target, d=np.float64(rec.d),
                 radius=np.float64(rec.radius), format=np.array(FORMAT))
        return
    if not path.endswith(".csv"):
        raise ValueError(f"`path` must end in .csv or .npz, got {path!r}")
    with open(path, "w", newline="") as f:
        f.write(f"# {FORMAT}\n# d={rec.d!r}\n# radius={rec.radius!r}\n")
        f.write(",".join(COLUMNS) + "\n")
        # %.17g round-trips float64 exactly; the join is a fast path for large experiments.
        num = np.column_stack([rec.time, rec.quat])
        body = [f"{s},{int(t)},{v[0]:.17g},{v[1]:.17g},{v[2]:.17g},{v[3]:.17g},{v[4]:.17g},{g}"
                for s, t, v, g in zip(rec.subject, rec.trial, num, rec.target)]
        f.write("\n".join(body) + "\n")


def read_pointing(path, *, on_invalid: str = "raise") -> PointingRecording:
    """Read a pointing recording (``.csv`` or ``.npz``, the format of the module docstring) strictly.

    CSV columns ``subject,trial,time,qw,qx,qy,qz,target``, one row per IMU sample; lines
    ``# d=<metres>`` and ``# radius=<metres>`` give the screen distance and the target radius.

    **Arguments:**

    - ``path``: the file.
    - ``on_invalid``: ``"raise"`` (default) raises for invalid trial data, naming file, line, column,
      subject and trial; ``"skip"`` drops such trials (warning) and lists them in
      ``recording.skipped``. Structural problems always raise.

    **Returns:**

    A :class:`PointingRecording`.

    **Raises:**

    - ``ValueError`` naming the file, line and column: another suffix, a missing, duplicate or
      unknown column, wrong field counts, non-numeric fields, non-integer trials, empty subject
      names, and (with ``on_invalid="raise"``) invalid trial data; an unknown ``on_invalid``.
    """
    path = os.fspath(path)
    if on_invalid not in ("raise", "skip"):
        raise ValueError(f"`on_invalid` must be 'raise' or 'skip', got {on_invalid!r}")
    path = os.fspath(input_file("path", path))
    if path.endswith(".npz"):
        rec = _read_npz(path)
    elif path.endswith(".csv"):
        rec = _read_csv(path)
    else:
        raise ValueError(f"`path` must end in .csv or .npz, got {path!r}")
    problems = trial_problems(rec)
    if problems and on_invalid == "raise":
        raise ValueError(problem_message(rec, problems[0])
                         + f" ({len(problems)} invalid trial(s); pass on_invalid='skip' to drop them and go on)")
    return drop_trials(rec, problems)


def _read_npz(path):
    with open_npz(path) as z:
        if "format" in z.files and str(z["format"]) != FORMAT:
            raise ValueError(f"{path}: unknown format {str(z['format'])!r}, expected {FORMAT!r}")
        missing = [c for c in COLUMNS if c not in z.files]
        if missing:
            raise ValueError(f"{path}: missing array(s) {missing}; expected {', '.join(COLUMNS)}")
        cols = {c: np.asarray(z[c]) for c in COLUMNS}
        d = float(z["d"]) if "d" in z.files else 1.0
        radius = float(z["radius"]) if "radius" in z.files else float(np.pi / 12)
    N = cols["time"].shape[0] if cols["time"].ndim == 1 else -1
    for c, a in cols.items():
        if a.ndim != 1 or a.shape[0] != N:
            raise ValueError(f"{path}: array {c!r} must be 1-D with the length of 'time' ({N}), got {a.shape}")
    num = {}
    for c in ("time",) + _QCOLS:
        if cols[c].dtype.kind not in "fiu":
            raise ValueError(f"{path}: array {c!r} must be numeric, got dtype {cols[c].dtype}")
        num[c] = cols[c].astype(float)
    tr = cols["trial"]
    if tr.dtype.kind not in "iu":
        bad = np.flatnonzero(~(np.isfinite(tr.astype(float)) & (tr.astype(float) == np.round(tr.astype(float))))) \
            if tr.dtype.kind == "f" else np.array([0])
        if bad.size:
            raise ValueError(f"{path}: array 'trial', row {int(bad[0])}: must hold integers (dtype {tr.dtype})")
    return PointingRecording(cols["subject"].astype(str), tr.astype(np.int64), num["time"],
                             np.stack([num[c] for c in _QCOLS], -1), cols["target"].astype(str), d=d, radius=radius,
                             source=path)


def _read_csv(path):
    text = read_text_file(input_file("path", path))
    meta = {"d": 1.0, "radius": float(np.pi / 12)}
    kept, lines = [], []
    for ln, raw in enumerate(text.splitlines(), 1):
        s = raw.strip()
        if not s:
            continue
        if s.startswith("#"):
            body = s.lstrip("#").strip()
            for key in meta:
                if body.startswith(key + "="):
                    try:
                        meta[key] = float(body[len(key) + 1:])
                    except ValueError as e:
                        raise ValueError(f"{path}:{ln}: bad comment {s!r} (expected '# {key}=<metres>')") from e
            continue
        kept.append(raw)
        lines.append(ln)
    if not kept:
        raise ValueError(f"{path}: empty file (no header, no samples)")
    rows = list(csv.reader(io.StringIO("\n".join(kept))))
    header = [h.strip().lower() for h in rows[0]]
    if len(set(header)) != len(header):
        raise ValueError(f"{path}:{lines[0]}: duplicate column names in header {header}")
    missing = [c for c in COLUMNS if c not in header]
    unknown = [c for c in header if c not in COLUMNS]
    if missing:
        raise ValueError(f"{path}:{lines[0]}: header line lacks column(s) {missing}"
                         + (f" and has unknown column(s) {unknown} (renamed?)" if unknown else "")
                         + f"; the columns are {', '.join(COLUMNS)}")
    if unknown:  # (lab exports carry extra columns: read on, but never silently)
        import warnings

        warnings.warn(f"{path}:{lines[0]}: column(s) {unknown} ignored (the format reads {', '.join(COLUMNS)})",
                      UserWarning, stacklevel=3)
    if len(rows) == 1:
        raise ValueError(f"{path}: header only, no samples")
    col = {c: header.index(c) for c in COLUMNS}
    body, lines = rows[1:], np.asarray(lines[1:])
    nf = np.fromiter((len(r) for r in body), int, len(body))
    if np.any(nf != len(header)):
        i = int(np.argmax(nf != len(header)))
        raise ValueError(f"{path}:{lines[i]}: expected {len(header)} fields, got {nf[i]}")
    table = list(zip(*body))  # columns of strings

    def numeric(c, kind):
        vals = table[col[c]]
        try:
            return np.array(vals, dtype=kind)
        except ValueError:
            for i, v in enumerate(vals):  # slow path only to locate the bad field
                try:
                    kind(v)
                except ValueError:
                    want = "an integer" if kind is int else "a number"
                    raise ValueError(f"{path}:{lines[i]}, column {c!r} (#{col[c] + 1}): expected {want}, "
                                     f"got {v!r}") from None
            raise

    subject = np.array([v.strip() for v in table[col["subject"]]])
    if np.any(subject == ""):
        i = int(np.argmax(subject == ""))
        raise ValueError(f"{path}:{lines[i]}, column 'subject' (#{col['subject'] + 1}): empty subject name")
    trial = numeric("trial", int)
    time = numeric("time", float)
    quat = np.stack([numeric(c, float) for c in _QCOLS], -1)
    target = np.array([v.strip().upper() for v in table[col["target"]]])
    return PointingRecording(subject, trial, time, quat, target, d=meta["d"], radius=meta["radius"], source=path,
                             line=lines)


# --- synthetic experiment ----------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class SyntheticPointing:
    """A synthetic pointing experiment (made by :func:`synthetic_pointing_experiment`).

    **Fields:**

    - ``recording``: the :class:`PointingRecording`.
    - ``donders``: the :class:`DondersRecording`, one Donders session per subject.
    - ``files``: paths written, by kind (``"pointing"``, ``"donders"``; empty without ``out``).
    - ``truth``: a dict of the generating values: ``subjects``, ``KJ`` (S, 3, 3), ``q_rest``
      (S, 3), ``labels`` (16,), ``T`` (S, 16) mean durations T_sj [s], ``tau0_ratio``/``tau_ratio``
      (S, 16) (τ0 = ratio·T_sj), ``tau0``/``tau`` (S, 16) [s] their nominal values, ``trial_label``
      (S, K, 16) label index of each movement of each trial, ``trial_T``, ``trial_tau0``,
      ``trial_tau`` (S, K, 16) the jittered values of each movement [s], ``trial_target``
      (S, K, 16, 2) the noisy end points, ``trial_q0`` (S, K, 16, 3) the start postures, ``onset``
      (S, K, 16) the simulation start time in the trial [s], ``params`` the options used.
    """

    recording: PointingRecording
    donders: DondersRecording
    files: dict
    truth: dict


def normalised_movements(KJ, q_rest, tau0_ratio, tau_ratio, q0, target, *, span, dt, d=1.0, pad=True,
                         solver="rk4"):
    """λ0-PMP movements in normalised time ``s = t/T`` (batched; one ``pmpjax.simulate`` call).

    With ``W = τ0 KJ`` (Eq 7) and ``k = b_max/τ0`` (Eq 10) every rate of the λ0-PMP is ``1/τ0``
    apart from the planner's ``K(t/τ)`` (Eq 8), so a movement with time constants ``(τ0, τ)``
    over ``t`` is the movement with ``(τ0/T, τ/T)`` over ``s = t/T``, for any ``T > 0``. All
    movements of an experiment, whatever their durations, then share one step count: ``span``
    and ``dt`` are in units of ``T``. Inputs (B, ...) flat; with ``pad`` the batch is padded to a
    power of two (>= 16) so that calls of similar size share one compilation. Works inside
    ``jit``/``vmap``/``grad`` (the RK4 stability check then does not run). ``solver`` as
    ``pmpjax.simulate``. Returns the Trajectory (``t`` is ``s``; ``xdot``, ``qdot`` are per unit
    ``s``: divide by ``T`` for physical rates).
    """
    B = np.shape(q0)[0]
    Bp = bucket(B, minimum=16) if pad else B
    args = (KJ, q_rest, tau0_ratio, tau_ratio, q0, target)
    xp = np if is_concrete(*args) else jnp  # (padding concrete inputs in NumPy compiles nothing)
    KJ, q_rest, r0, r, q0, target = (pad_rows(xp.asarray(a, float), Bp) for a in args)
    with without_unit_checks():  # (fitted values: an item out of range fails by its status, not the batch)
        model = Lambda0PMP(Wrist(d), KJ=KJ, q_rest=q_rest, W=r0[:, None, None] * KJ)
        tr = simulate(model, ArimotoPlanner(k=None, tau=r, tau0=r0), q0, target, duration=float(span),
                      dt=float(dt), solver=solver)
    return replace(tr, **{k: head_rows(getattr(tr, k), B)
                          for k in ("q", "x", "qdot", "xdot", "manipulability", "status")})


#: Default simulation grid of pointing movements, in units of the movement's duration T: the
#: 20 % offset of a model movement as slow as the data lies near s ≈ 1.1; 2.5 T leaves room for
#: slower models and the smoothing kernel's reach (and lets a synthetic movement settle).
MODEL_SPAN, MODEL_DT = 2.5, 0.01


def model_grid(ratios, *, settle: bool = False):
    """Static ``(span, dt)`` in units of T for time constants ``ratios`` = τ/T: the defaults
    (:data:`MODEL_SPAN`, :data:`MODEL_DT`: one compiled simulation serves most experiments),
    longer for slow movements (5 of the slowest time constant; 8 with ``settle``, for a movement
    that must come to rest), and RK4 steps halved until they are at most a tenth of the fastest
    time constant (relative error ~1e-5, far below IMU noise)."""
    rmax, rmin = float(np.max(ratios)), float(np.min(ratios))
    span = max(MODEL_SPAN, float(np.ceil((16.0 if settle else 10.0) * rmax) / 2))
    dt = MODEL_DT
    while dt > rmin / 10.0:
        dt /= 2
    return span, dt


def _hermite(s, x, v, sq):
    """Cubic Hermite interpolation of ``x`` (n, k) with derivatives ``v`` at increasing ``s`` (n,)."""
    i = np.clip(np.searchsorted(s, sq, side="right") - 1, 0, len(s) - 2)
    h = s[i + 1] - s[i]
    u = ((sq - s[i]) / h)[:, None]
    h00, h10, h01, h11 = 2 * u**3 - 3 * u**2 + 1, u**3 - 2 * u**2 + u, -2 * u**3 + 3 * u**2, u**3 - u**2
    return h00 * x[i] + h10 * h[:, None] * v[i] + h01 * x[i + 1] + h11 * h[:, None] * v[i + 1]


def _nullspace_direction(q):
    """Unit joint velocity (..., 3) that turns the hand about its pointing axis (the wrist's
    null space: the screen point stays put). Spatial joint axes of Eq 6: ``ω1 = −e_x``,
    ``ω2 = Rx(−q_PS) e_z``, ``ω3 = Rx(−q_PS) Rz(q_FE) e_y``; solve ``Σ q̇_i ω_i = R e_x``."""
    a, b, c = (q[..., i] for i in range(3))
    ca, sa, cb, sb, cc, sc = np.cos(a), np.sin(a), np.cos(b), np.sin(b), np.cos(c), np.sin(c)
    zero, one = np.zeros_like(a), np.ones_like(a)
    w1 = np.stack([-one, zero, zero], -1)
    w2 = np.stack([zero, sa, ca], -1)
    w3 = np.stack([-sb, ca * cb, -sa * cb], -1)
    u = np.stack([cb * cc, ca * sb * cc - sa * sc, -sa * sb * cc - ca * sc], -1)
    v = np.linalg.solve(np.stack([w1, w2, w3], -1), u[..., None])[..., 0]
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


@fast_compile_jit
def _imu_quaternions(q, eps):
    """Quaternions (N, 4) of ``R(q) exp(ε̂)``: postures ``q`` (N, 3) seen through IMU noise ``ε``."""
    return quat_from_matrix(wrist_rotation(q) @ matrix_from_rotvec(eps))


def synthetic_pointing_experiment(
    out=None,
    *,
    subjects=None,
    n_trials: int = 10,
    T=None,
    tau0_ratio=0.2,
    tau_ratio=0.2,
    target_spread: float = 0.1,
    duration_jitter: float = 0.05,
    param_jitter: float = 0.05,
    target_noise: float = 0.003,
    posture_noise_deg: float = 1.0,
    imu_noise_deg: float = 0.1,
    rate: float = 120.0,
    n_donders: int = 300,
    donders_noise_deg: float = 0.5,
    radius: float | None = None,
    d: float = 1.0,
    fmt: str = "csv",
    seed: int = 0,
) -> SyntheticPointing:
    """A seeded synthetic center-out experiment from the λ0-PMP, in the recording format.

    **Protocol** (as :func:`center_out_trials`): per subject ``n_trials`` trials, each
    visiting the 8 peripheral targets in a random order, each outbound movement followed by the
    inbound one (16 movements). A trial starts with the hand resting on the centre; at each cue
    the ``target`` column switches to the next target, the hand rests 0.2–0.3 s (reaction time),
    moves (λ0-PMP, ``W = τ0 KJ``, Arimoto ``K(t)`` with ``k = b_max/τ0``, Eqs 7–10, simulated
    until it has settled) and holds still at the target 0.25–0.4 s. Samples at ``rate`` [Hz].

    **Arguments:**

    - ``out``: folder to write ``pointing.<fmt>`` and ``donders.<fmt>`` into (created); None
      keeps everything in memory. ``fmt``: "csv" or "npz".
    - ``subjects``: Table 1–2 subjects (names or numbers, default all six: ``paper_subjects``).
    - ``T``: mean movement durations T_sj [s]: scalar, (S,) or (S, 16); default per subject
      uniform in [0.35, 0.55] s times a per-movement factor ``exp(target_spread·N(0, 1))``.
    - ``target_spread``: log-sd of that per-movement factor.
    - ``tau0_ratio``, ``tau_ratio``: τ0 = ratio·T_sj, τ = ratio·T_sj (scalar, (S,) or (S, 16));
      the paper's heuristic τ = τ0 = T/5 by default.
    - trial-to-trial variability, per movement: ``duration_jitter`` (log-sd of the movement's
      time scale), ``param_jitter`` (log-sd of each ratio), ``target_noise`` [m] (sd of the end
      point around the target: motor noise), ``posture_noise_deg`` (sd of the start posture
      along the null space, the redundant torsion; the hand stays on its screen point).
    - ``imu_noise_deg``: RMS angle of the white orientation noise of the IMU (random rotations in
      the hand frame), per sample.
    - ``n_donders``, ``donders_noise_deg``: the Donders session per subject
      (``synthetic_recordings``: steady postures over ±20°).
    - ``radius``: target distance [m] (default π/12, ``center_out``); ``d`` screen distance [m].
    - ``n_trials``: trials per subject; ``rate``: IMU sampling rate [Hz]; ``seed``: the seed of
      every random draw (the same seed gives the same experiment).

    **Returns:**

    A :class:`SyntheticPointing` (recording, Donders session, files, ground truth).

    **Raises:**

    ``ValueError`` naming the argument for unknown or repeated subjects, non-positive sizes,
    durations or rates, negative noise levels, a bad ``fmt`` or shapes of ``T`` and the ratios;
    ``RuntimeError`` if a simulated movement fails (it names the status).
    """
    if fmt not in ("csv", "npz"):
        raise ValueError(f"`fmt` must be 'csv' or 'npz', got {fmt!r}")
    check_positive_int("n_trials", n_trials)
    check_positive_int("n_donders", n_donders)
    for name, v in (("rate", rate), ("d", d)):
        if not (np.isfinite(v) and v > 0):
            raise ValueError(f"`{name}` must be positive, got {v}")
    for name, v in (("target_spread", target_spread), ("duration_jitter", duration_jitter),
                    ("param_jitter", param_jitter), ("target_noise", target_noise),
                    ("posture_noise_deg", posture_noise_deg), ("imu_noise_deg", imu_noise_deg),
                    ("donders_noise_deg", donders_noise_deg)):
        if not (np.isfinite(v) and v >= 0):
            raise ValueError(f"`{name}` must be >= 0, got {v}")
    r_t = target_radius(radius, d=d)
    names_all, KJ_all, qr_all = paper_subjects()
    if subjects is None:
        idx = list(range(len(names_all)))
    else:
        idx = []
        for s in subjects:
            key = str(s).lower().replace(" ", "")
            key = f"subj{key}" if key.isdigit() else key
            if key not in names_all:
                raise ValueError(f"`subjects`: unknown subject {s!r}; available: {', '.join(names_all)}")
            idx.append(names_all.index(key))
        if not idx or len(set(idx)) != len(idx):
            raise ValueError(f"`subjects` must name distinct Table subjects, got {subjects}")
    names = [names_all[i] for i in idx]
    KJ, q_rest = KJ_all[idx], qr_all[idx]
    S, K, L = len(names), int(n_trials), len(MOVEMENT_LABELS)
    rng = np.random.default_rng(seed)

    def per_movement(name, v, default=None):
        if v is None:
            return default
        a = np.asarray(v, dtype=float)
        if a.ndim == 1 and a.shape == (S,):
            a = a[:, None]
        try:
            a = np.broadcast_to(a, (S, L)).copy()
        except ValueError as e:
            raise ValueError(f"`{name}` must be a scalar, (S,) = ({S},) or (S, 16), got shape {a.shape}") from e
        if not np.all(np.isfinite(a) & (a > 0)):
            raise ValueError(f"`{name}` must be positive and finite")
        return a

    T_default = rng.uniform(0.35, 0.55, S)[:, None] * np.exp(target_spread * rng.normal(size=(S, L)))
    T_sj = per_movement("T", T, T_default)
    r0_sj = per_movement("tau0_ratio", tau0_ratio)
    r_sj = per_movement("tau_ratio", tau_ratio)

    # Movements of every trial: label index, jittered time scale and ratios, noisy end points.
    tg = center_out_targets(r_t)
    orders = np.stack([center_out_trials(K, seed=int(rng.integers(2**31)), radius=r_t)[0] for _ in range(S)])
    lab_index = {lab: i for i, lab in enumerate(MOVEMENT_LABELS)}
    trial_label = np.array([[[lab_index[f"{way}-{p}"] for p in row for way in ("out", "in")] for row in o]
                            for o in orders])  # (S, K, 16)
    ends_nominal = np.array([[[tg[p] if way == "out" else tg["C"] for p in row for way in ("out", "in")]
                              for row in o] for o in orders])  # (S, K, 16, 2)
    sidx = np.arange(S)[:, None, None]
    trial_T = T_sj[sidx, trial_label] * np.exp(duration_jitter * rng.normal(size=(S, K, L)))
    trial_r0 = r0_sj[sidx, trial_label] * np.exp(param_jitter * rng.normal(size=(S, K, L)))
    trial_r = r_sj[sidx, trial_label] * np.exp(param_jitter * rng.normal(size=(S, K, L)))
    ends = ends_nominal + target_noise * rng.normal(size=(S, K, L, 2))
    start0 = target_noise * rng.normal(size=(S, K, 2))  # resting on the centre before the first cue
    q_all = np.asarray(equilibrium_posture(Wrist(d), KJ[:, None, None], q_rest[:, None, None],
                                           np.concatenate([start0[:, :, None], ends], axis=2)).q)
    q_home, q_end = q_all[:, :, 0], q_all[:, :, 1:]
    q_settled = np.concatenate([q_home[:, :, None], q_end[:, :, :-1]], axis=2)  # where each movement starts
    # Redundant (null-space) posture noise: the hand keeps its screen point, the torsion varies.
    q0 = q_settled + np.deg2rad(posture_noise_deg) * rng.normal(size=(S, K, L, 1)) * _nullspace_direction(q_settled)

    span, dt = model_grid(np.concatenate([trial_r0.ravel(), trial_r.ravel()]), settle=True)
    B = S * K * L
    tr = normalised_movements(np.broadcast_to(KJ[:, None, None], (S, K, L, 3, 3)).reshape(B, 3, 3),
                              np.broadcast_to(q_rest[:, None, None], (S, K, L, 3)).reshape(B, 3),
                              trial_r0.reshape(B), trial_r.reshape(B), q0.reshape(B, 3), ends.reshape(B, 2),
                              span=span, dt=dt, d=d)
    s_grid = np.asarray(tr.t)
    q_sim = np.asarray(tr.q).reshape(S, K, L, -1, 3)
    qd_sim = np.asarray(tr.qdot).reshape(S, K, L, -1, 3)
    if not np.all(np.asarray(tr.status) == 0):
        raise RuntimeError("synthetic_pointing_experiment: a simulated movement failed (status "
                           f"{np.unique(np.asarray(tr.status)).tolist()}); check the parameters")

    # Trial timelines and 120 Hz samples.
    rows = dict(subject=[], trial=[], time=[], quat=[], target=[])
    onset = np.zeros((S, K, L))
    noise = np.deg2rad(imu_noise_deg) / np.sqrt(3.0)
    for s in range(S):
        for k in range(K):
            pre = rng.uniform(0.5, 0.8)
            rt = rng.uniform(0.2, 0.3, L)
            hold = rng.uniform(0.25, 0.4, L)
            win = span * trial_T[s, k]
            cue = pre + np.concatenate([[0.0], np.cumsum(rt + win + hold)[:-1]])
            onset[s, k] = cue + rt
            t_end = cue[-1] + rt[-1] + win[-1] + hold[-1]
            t = np.arange(0.0, t_end, 1.0 / rate)
            q = np.empty((t.size, 3))
            names_t = np.empty(t.size, dtype=object)
            names_t[:] = "C"
            seq = [p if way == "out" else "C" for p in orders[s, k] for way in ("out", "in")]
            prev_q = q_home[s, k]
            prev_end = 0.0
            for j in range(L):
                a, b = onset[s, k, j], onset[s, k, j] + win[j]
                names_t[t >= cue[j]] = seq[j]
                # Rest: blend from the last settled posture to this movement's start posture.
                m = (t >= prev_end) & (t < a)
                u = np.clip((t[m] - prev_end) / max(a - prev_end, 1e-9), 0, 1)
                w = u * u * (3 - 2 * u)
                q[m] = (1 - w)[:, None] * prev_q + w[:, None] * q0[s, k, j]
                m = (t >= a) & (t < b)
                q[m] = _hermite(s_grid, q_sim[s, k, j], qd_sim[s, k, j], (t[m] - a) / trial_T[s, k, j])
                prev_q, prev_end = q_sim[s, k, j, -1], b
            m = t >= prev_end
            q[m] = prev_q
            rows["subject"].append(np.full(t.size, names[s]))
            rows["trial"].append(np.full(t.size, k + 1))
            rows["time"].append(t)
            rows["quat"].append(q)
            rows["target"].append(names_t.astype(str))
    q = np.concatenate(rows["quat"])
    # (rows in padded chunks: experiments of any length share one compile)
    rows["quat"] = [row_chunks(_imu_quaternions, q, noise * rng.normal(size=q.shape), small=64, chunk=4096)]
    rec = PointingRecording(*(np.concatenate(rows[c]) for c in ("subject", "trial", "time", "quat", "target")),
                            d=float(d), radius=r_t, source="<synthetic>")
    donders = synthetic_recordings(KJ, q_rest, n_donders, noise_deg=donders_noise_deg,
                                   seed=int(rng.integers(2**31)), d=float(d), names=names)
    files = {}
    if out is not None:
        os.makedirs(out, exist_ok=True)
        files["pointing"] = os.path.join(os.fspath(out), f"pointing.{fmt}")
        files["donders"] = os.path.join(os.fspath(out), f"donders.{fmt}")
        write_pointing(files["pointing"], dataclasses.replace(rec, source=files["pointing"]))
        write_recordings(files["donders"], donders)
        rec = dataclasses.replace(rec, source=files["pointing"])
    truth = dict(
        subjects=tuple(names), KJ=KJ, q_rest=q_rest, labels=MOVEMENT_LABELS, T=T_sj,
        tau0_ratio=r0_sj, tau_ratio=r_sj, tau0=r0_sj * T_sj, tau=r_sj * T_sj, trial_label=trial_label,
        trial_T=trial_T, trial_tau0=trial_r0 * trial_T, trial_tau=trial_r * trial_T, trial_target=ends,
        trial_q0=q0, onset=onset,
        params=dict(n_trials=K, target_spread=target_spread, duration_jitter=duration_jitter,
                    param_jitter=param_jitter, target_noise=target_noise, posture_noise_deg=posture_noise_deg,
                    imu_noise_deg=imu_noise_deg, rate=rate, n_donders=n_donders,
                    donders_noise_deg=donders_noise_deg, radius=r_t, d=d, seed=seed, span=span, dt=dt),
    )
    return SyntheticPointing(rec, donders, files, truth)

