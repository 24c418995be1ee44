"""HuG-MP recordings: loader, smoothing and differentiation, and arrays for IK-weight estimation.

**HuG-MP** (F. Bianchin et al., TUM-ITR/HuG-MP, MIT licence; bundled in ``pmpjax/data/hugmp``,
see its README): ``S0i_trajs.mat`` (MATLAB v5) holds ``tasks``, a repetitions × 6 cell of (M, 1)
cells of 4 × N joint-angle arrays [deg] at 100 Hz, on the 4-DoF shoulder–elbow arm ``pj.ShoulderElbowArm``.

**Smoothing** is ``scipy.signal.savgol_filter`` (cubic, ``mode='interp'``: polynomial fits at the
ends), called once for all motions of a call: stacked once aligned at their first sample (the
start fits and the interior are right) and once aligned at their last sample (the end fits are
right), two ``savgol_filter`` calls per derivative order; identical to the per-motion calls
(tested) and about 3× faster.
"""

from __future__ import annotations

import dataclasses
import os
from importlib import resources
from pathlib import Path

import numpy as np

from .._base import as_path, bucket, check_positive_int, fast_compile_jit, pad_rows
from .matlab import mat_version

HUGMP_TASKS = {
    1: ("R", "1", "12", "R", "4", "9", "R"),
    2: ("R", "2", "10", "R", "9", "11", "R"),
    3: ("R", "10", "2", "R", "11", "9", "R"),
    4: ("R", "1", "R", "3", "R", "9", "R", "11", "R"),
    5: ("K", "M", "R"),
    6: ("K", "S", "K"),
}


@dataclasses.dataclass
class HugmpSubject:
    """One HuG-MP subject's arm motions (made by :func:`load_hugmp`).

    **Fields:**

    - ``subject``: the name (``"S01"`` … ``"S04"``).
    - ``motions``: ``motions[task]`` a list of ``(repetition, index, q (N, 4) [rad])`` (1-based task
      numbers).
    - ``skipped``: ``(repetition, task, reason)`` of cells or motions that were not usable.
    - ``notes``: irregular but kept cells (e.g. extra motions).
    - ``fs``: sampling rate [Hz].
    """

    subject: str
    motions: dict
    skipped: list
    notes: list
    fs: float = 100.0


def hugmp_directory(directory=None) -> Path:
    """The HuG-MP directory: ``directory``, else ``$PMPJAX_HUGMP``, else the bundled copy."""
    if directory is not None:
        return as_path("directory", directory)
    env = os.environ.get("PMPJAX_HUGMP")
    if env:
        return Path(env)
    return Path(str(resources.files("pmpjax") / "data" / "hugmp"))


def _subject_name(subject) -> str:
    if isinstance(subject, bool) or not isinstance(subject, int | np.integer | str):
        raise TypeError(f"`subject` must be an int (1–4) or a name like 'S01', got {type(subject).__name__}")
    if isinstance(subject, str):
        if not (len(subject) == 3 and subject[0] == "S" and subject[1:].isdigit()):
            raise ValueError(f"`subject` name must look like 'S01', got {subject!r}")
        return subject
    if not 1 <= int(subject) <= 99:
        raise ValueError(f"`subject` must be a subject number in 1…99, got {subject}")
    return f"S{int(subject):02d}"


def load_hugmp(subject, directory=None, *, min_samples: int = 20) -> HugmpSubject:
    """Load a HuG-MP subject and survive its irregular cells.

    Empty cells and motions that are not finite 4 × N arrays with N ≥ ``min_samples`` are skipped and
    reported in ``skipped``; cells holding a number of motions other than the task lists are kept and
    reported in ``notes``. Angles are returned in radians.

    **Arguments:**

    - ``subject``: 1–4 or ``"S01"`` … ``"S04"``.
    - ``directory``: the folder of the ``S0i_trajs.mat`` files (default ``$PMPJAX_HUGMP``, else the
      bundled data set).
    - ``min_samples``: shortest usable motion (samples).

    **Returns:**

    A :class:`HugmpSubject`.

    **Raises:**

    - ``TypeError``/``ValueError`` naming ``subject`` for a bad subject; ``FileNotFoundError`` for a
      missing file; ``ValueError`` naming the file (and the variable ``tasks``) when it is malformed.
    """
    name = _subject_name(subject)
    min_samples = check_positive_int("min_samples", min_samples)
    path = hugmp_directory(directory) / f"{name}_trajs.mat"
    if not path.is_file():
        raise FileNotFoundError(f"HuG-MP file not found: {path} (set `directory` or $PMPJAX_HUGMP)")
    if mat_version(path) != "5":
        raise ValueError(f"{path}: HuG-MP files are MATLAB v5; got another format")
    import scipy.io

    try:
        tasks = scipy.io.loadmat(path).get("tasks")
    except (ValueError, OSError, TypeError) as e:
        raise ValueError(f"{path}: malformed MAT-file: {e}") from e
    if tasks is None:
        raise ValueError(f"{path}: no variable `tasks`")
    if tasks.dtype != object or tasks.ndim != 2 or tasks.shape[1] != 6:
        raise ValueError(f"{path}: variable `tasks` must be a repetitions × 6 cell array, "
                         f"got a {tasks.dtype} array of shape {tasks.shape}")
    motions = {t: [] for t in range(1, 7)}
    skipped, notes = [], []
    for r in range(tasks.shape[0]):
        for t in range(6):
            cell = tasks[r, t]
            if not isinstance(cell, np.ndarray) or cell.size == 0:
                skipped.append((r + 1, t + 1, "empty cell"))
                continue
            items = list(cell.reshape(-1)) if cell.dtype == object else [cell]
            expected = len(HUGMP_TASKS[t + 1]) - 1
            if len(items) != expected:
                notes.append((r + 1, t + 1, f"{len(items)} motions, task lists {expected}"))
            for i, mo in enumerate(items):
                a = np.asarray(mo) if isinstance(mo, np.ndarray) else None
                if a is None or a.dtype.kind not in "iuf" or a.ndim != 2 or a.shape[0] != 4:
                    skipped.append((r + 1, t + 1, f"motion {i + 1}: not a numeric 4 × N array"))
                elif a.shape[1] < min_samples:
                    skipped.append((r + 1, t + 1, f"motion {i + 1}: only {a.shape[1]} samples"))
                elif not np.all(np.isfinite(a)):
                    skipped.append((r + 1, t + 1, f"motion {i + 1}: NaN or inf"))
                else:
                    motions[t + 1].append((r + 1, i + 1, np.deg2rad(a.T.astype(float))))
    return HugmpSubject(subject=name, motions=motions, skipped=skipped, notes=notes)


# ---------------------------------------------------------------------------------------------
# smoothing and differentiation


def _window(fs, window):
    fs, window = float(fs), float(window)
    if not (np.isfinite(fs) and fs > 0):
        raise ValueError(f"`fs` must be a positive sampling rate [Hz], got {fs}")
    if not (np.isfinite(window) and window > 0):
        raise ValueError(f"`window` must be a positive duration [s], got {window}")
    return max(5, int(round(window * fs)) | 1)


def _savgol_all(qs, win, deriv, delta):
    """``scipy.signal.savgol_filter(q, win, 3, deriv, delta, axis=0)`` (mode 'interp') of every
    (N_i, d) array in ``qs`` (all N_i >= win), in two calls (see the module docstring)."""
    from scipy.signal import savgol_filter

    N = [q.shape[0] for q in qs]
    Nmax, d, half = max(N), qs[0].shape[1], win // 2
    head, tail = np.zeros((Nmax, len(qs), d)), np.zeros((Nmax, len(qs), d))
    for i, q in enumerate(qs):
        head[: N[i], i], tail[Nmax - N[i]:, i] = q, q
    yh = savgol_filter(head, win, 3, deriv=deriv, delta=delta, axis=0, mode="interp")
    yt = savgol_filter(tail, win, 3, deriv=deriv, delta=delta, axis=0, mode="interp")
    return [np.concatenate([yh[: n - half, i], yt[Nmax - half:, i]]) for i, n in enumerate(N)]


def _smooth_all(qs, fs, win, samples):
    """Smoothed angles and velocities of every motion, resampled to ``samples`` points (or not)."""
    qsm = _savgol_all(qs, win, 0, 1.0)
    qd = _savgol_all(qs, win, 1, 1.0 / fs)
    if samples is None:
        return qsm, qd
    t1 = np.linspace(0.0, 1.0, samples)

    def resample(a):
        t0 = np.linspace(0.0, 1.0, a.shape[0])
        return np.stack([np.interp(t1, t0, a[:, j]) for j in range(a.shape[1])], -1)

    return [resample(a) for a in qsm], [resample(a) for a in qd]


def _check_chain(chain, n=None):
    if not (hasattr(chain, "fk_jac_soa") and hasattr(chain, "n")):
        raise TypeError(f"`chain` must be a pmpjax chain (e.g. pj.ShoulderElbowArm()), got {type(chain).__name__}")
    if n is not None and int(chain.n) != n:
        raise ValueError(f"`chain` has {chain.n} joints, the data {n}")


def motion_kinematics(q, chain, *, fs: float = 100.0, window: float = 0.15, samples: int | None = 100):
    """Smoothed joint angles, joint and task velocities and Jacobians of one motion.

    Savitzky–Golay smoothing and differentiation (cubic, ``window`` [s], ``scipy.signal``),
    optionally resampled to equally spaced points (time normalisation, as in the IK paper's
    100-sample trials; ``qdot`` stays in rad/s of real time). ``J`` from ``chain`` and ``ẋ = J q̇``.

    **Arguments:**

    - ``q``: (N, n) joint angles [rad].
    - ``chain``: a pmpjax chain with n joints (e.g. ``pj.ShoulderElbowArm()``).
    - ``fs``: sampling rate [Hz].
    - ``window``: smoothing window [s].
    - ``samples``: resample to this many points (None: keep the N samples).

    **Returns:**

    ``(q, qdot, xdot, J)``: (S, n) [rad], (S, n) [rad/s], (S, m), (S, m, n).

    **Raises:**

    - ``TypeError`` for a non-chain; ``ValueError`` naming the argument for a non-positive ``fs`` or
      ``window``, or a chain with another number of joints.
    """
    try:
        q = np.asarray(q, dtype=float)
    except (TypeError, ValueError) as e:
        raise ValueError(f"`q` must be a numeric (N, n) array, got {type(q).__name__}") from e
    if q.ndim != 2:
        raise ValueError(f"`q` must be an (N, n) array of joint angles, got shape {q.shape}")
    if not np.all(np.isfinite(q)):
        raise ValueError("`q` contains NaN or inf")
    _check_chain(chain, q.shape[1])
    win = _window(fs, window)
    if samples is not None:
        samples = check_positive_int("samples", samples)
    if q.shape[0] < win:
        raise ValueError(f"`q` has {q.shape[0]} samples, fewer than the smoothing window ({win} at fs = {fs} Hz)")
    (qs,), (qd,) = _smooth_all([q], float(fs), win, samples)
    J = _jacobians(chain, qs)
    return qs, qd, np.einsum("sij,sj->si", J, qd), J


@fast_compile_jit
def _jac_soa(chain, qc):
    return chain.fk_jac_soa(qc)[1]


def _jacobians(chain, q):
    """``chain.jacobian(q)`` (..., m, n) as a writable NumPy array, in one compiled call (eager
    op-by-op evaluation compiles ~100 small kernels per new shape)."""
    q = np.asarray(q, dtype=float)
    flat = q.reshape(-1, q.shape[-1])
    # pad the sample count to a power of two so that subjects of similar size share one compile
    N = flat.shape[0]
    qc = pad_rows(flat, bucket(N, minimum=1024), fill="zeros").T
    J = np.asarray(_jac_soa(chain, qc))[..., :N]
    return np.moveaxis(J, (0, 1), (-2, -1)).reshape(q.shape[:-1] + J.shape[:2]).copy()


def hugmp_arrays(subject: HugmpSubject, chain, *, samples: int = 100, window: float = 0.15):
    """Per task, pad a subject's motions into arrays for estimation (IK weights).

    Smoothing as :func:`motion_kinematics` at the subject's rate, one Jacobian evaluation for all
    motions; missing motions are masked (padded Jacobians are [I 0]).

    **Arguments:**

    - ``subject``: a :class:`HugmpSubject`.
    - ``chain``: a pmpjax chain with 4 joints (``pj.ShoulderElbowArm()``).
    - ``samples``: points per motion after resampling.
    - ``window``: smoothing window [s].

    **Returns:**

    ``dict(qdot (6, R, M, S, n), xdot (6, R, M, S, m), J (6, R, M, S, m, n), mask (6, R, M, S),
    q (6, R, M, S, n))`` with R repetitions and M motions per repetition.

    **Raises:**

    - ``TypeError`` for a non-subject or non-chain; ``ValueError`` naming the argument for fewer
      than 2 ``samples``, a chain with another number of joints, or motions too short for the
      smoothing window.
    """
    if not isinstance(subject, HugmpSubject):
        raise TypeError(f"`subject` must be a HugmpSubject (from pj.load_hugmp), got {type(subject).__name__}")
    samples = check_positive_int("samples", samples)
    if samples < 2:
        raise ValueError(f"`samples` must be at least 2, got {samples}")
    win = _window(subject.fs, window)
    items = [(t, r, i, q) for t, ms in subject.motions.items() for r, i, q in ms]
    n = items[0][3].shape[1] if items else 4
    _check_chain(chain, n)
    for t, r, i, q in items:
        if not 1 <= t <= 6:
            raise ValueError(f"`subject.motions`: task {t} outside 1…6")
        if q.ndim != 2 or q.shape[1] != n or q.shape[0] < win:
            raise ValueError(f"`subject.motions[{t}]`: repetition {r}, motion {i} must be (N >= {win}, {n}), "
                             f"got shape {q.shape}")
    R = max([r for _, r, _, _ in items] + [1])
    M = max([i for _, _, i, _ in items] + [1])
    shp = (6, R, M, samples)
    out = dict(qdot=np.zeros(shp + (n,)), q=np.zeros(shp + (n,)), mask=np.zeros(shp, bool))
    if items:
        qs, qd = _smooth_all([q for *_, q in items], float(subject.fs), win, samples)
        for (t, r, i, _), a, b in zip(items, qs, qd):
            sl = (t - 1, r - 1, i - 1)
            out["q"][sl], out["qdot"][sl] = a, b
            out["mask"][sl] = True
    J = _jacobians(chain, out["q"])
    m = J.shape[-2]
    J[~out["mask"]] = np.eye(m, n)
    out["J"] = J
    out["xdot"] = np.einsum("...ij,...j->...i", J, out["qdot"])
    return out
