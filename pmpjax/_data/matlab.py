"""MATLAB data: the IK paper's supporting-data layout (v5 and v7.3) and the HuG-MP recordings.

**IK data set layout** (after Khoramshahi et al. 2022, S1 Dataset; field names are ours): one
variable ``data``, a P×1 cell of participant structs. Each participant struct has one field per
condition (e.g. ``Natural``, ``Viscous``); each condition is a struct with fields ``Target1``…;
each target is a T×1 cell of trial structs with ``q`` (S×n) [rad], ``dq`` (S×n) [rad/s], ``dx``
(S×m) [m/s] and ``J`` (m×n×S) per-step Jacobians; ``IK_data`` holds per condition the
concatenation over targets and trials ``dq`` (n×K), ``dx`` (m×K), ``J`` (m×n×K) (the input of
Algorithm 1); an optional ``w_true`` struct holds known weights (synthetic data). In Python a data
set is ``{"participants": [{condition: {target: [trial dicts]}}], "w_true": [{condition: (n,)}]}``
with trial dicts ``{"q", "qdot", "xdot", "J"}`` samples-first ((S, n), (S, n), (S, m), (S, m, n)).

**HuG-MP** (F. Bianchin et al., TUM-ITR/HuG-MP, MIT licence; bundled in ``pmpjax/data/hugmp``):
``S0i_trajs.mat`` holds ``tasks``, a repetitions × 6 cell of (M, 1) cells of 4 × N joint-angle
arrays [deg] at 100 Hz.
"""

from __future__ import annotations

import dataclasses
import functools
import os
from importlib import resources
from pathlib import Path

import jax
import numpy as np

_MAT73_HEADER = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created by: pmpjax HDF5 schema 1.00 ."

# ---------------------------------------------------------------------------------------------
# generic reading: v5 (scipy.io) or v7.3 (h5py) into dicts / lists / arrays


def _mat_version(path: Path) -> str:
    with open(path, "rb") as fh:
        head = fh.read(128)
    if len(head) < 128:
        raise ValueError(f"{path}: not a MATLAB file (too short: {len(head)} bytes)")
    if head[:19] == b"MATLAB 7.3 MAT-file" or _is_hdf5(path):
        return "7.3"
    if head[:6] == b"MATLAB" and head[126:128] in (b"IM", b"MI"):
        return "5"
    raise ValueError(f"{path}: not a MATLAB v5 or v7.3 MAT-file (bad header)")


def _is_hdf5(path):
    import h5py

    try:
        return h5py.is_hdf5(path)
    except OSError:
        return False


def _from_v5(obj):
    """scipy.io (simplify_cells=True) output -> dicts, lists and float arrays."""
    if isinstance(obj, dict):
        return {k: _from_v5(v) for k, v in obj.items() if not k.startswith("__")}
    if isinstance(obj, list):
        return [_from_v5(v) for v in obj]
    if isinstance(obj, np.ndarray) and obj.dtype == object:
        return [_from_v5(v) for v in obj.reshape(-1, order="F")]
    return obj


def _from_h5(f, node):
    import h5py

    cls = node.attrs.get("MATLAB_class", b"")
    cls = cls.decode() if isinstance(cls, bytes) else str(cls)
    if isinstance(node, h5py.Group):
        return {k: _from_h5(f, node[k]) for k in node.keys() if not k.startswith("#")}
    if node.attrs.get("MATLAB_empty", 0):
        return np.zeros((0,))
    if cls == "cell" or node.dtype == h5py.ref_dtype:
        refs = np.asarray(node[()]).T.reshape(-1, order="F")
        return [_from_h5(f, f[r]) for r in refs]
    if cls == "char":
        return "".join(chr(c) for c in np.asarray(node[()]).reshape(-1))
    return np.asarray(node[()], dtype=float).T


def read_mat(path) -> dict:
    """Read a MAT-file (v5 through scipy.io, v7.3 through h5py) into nested dicts/lists/arrays.

    Raises ``FileNotFoundError`` or ``ValueError`` (not a MAT-file, unreadable) naming the file.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"MAT-file not found: {path}")
    version = _mat_version(path)
    try:
        if version == "5":
            import scipy.io

            return _from_v5(scipy.io.loadmat(path, simplify_cells=True))
        import h5py

        with h5py.File(path, "r") as f:
            return {k: _from_h5(f, f[k]) for k in f.keys() if not k.startswith("#")}
    except (ValueError, OSError, TypeError, KeyError) as e:
        raise ValueError(f"{path}: malformed MATLAB v{version} file: {e}") from e


# ---------------------------------------------------------------------------------------------
# writing


def _to_v5(obj):
    if isinstance(obj, dict):
        return {k: _to_v5(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        cell = np.empty((len(obj), 1), dtype=object)
        for i, v in enumerate(obj):
            cell[i, 0] = _to_v5(v)
        return cell
    return np.asarray(obj, dtype=float)


def _write_h5(f, group, name, obj, counter):
    import h5py

    if isinstance(obj, dict):
        g = group.create_group(name)
        g.attrs["MATLAB_class"] = np.bytes_("struct")
        for k, v in obj.items():
            _write_h5(f, g, k, v, counter)
        return g
    if isinstance(obj, list | tuple):
        refs = f.require_group("#refs#")
        out = []
        for v in obj:
            counter[0] += 1
            out.append(_write_h5(f, refs, f"r{counter[0]}", v, counter).ref)
        # MATLAB stores an (N, 1) cell as an HDF5 (1, N) dataset (column-major -> transposed)
        ds = group.create_dataset(name, data=np.array(out, dtype=h5py.ref_dtype).reshape(1, -1))
        ds.attrs["MATLAB_class"] = np.bytes_("cell")
        return ds
    a = np.asarray(obj, dtype=float)
    if a.size == 0:
        ds = group.create_dataset(name, data=np.zeros(2, dtype=np.uint64))
        ds.attrs["MATLAB_empty"] = np.uint8(1)
    else:
        a2 = a.reshape(a.shape + (1,) * (2 - a.ndim)) if a.ndim < 2 else a
        ds = group.create_dataset(name, data=a2.T)
    ds.attrs["MATLAB_class"] = np.bytes_("double")
    return ds


def write_mat(path, variables: dict, *, version: str = "5") -> None:
    """Write nested dicts (structs), lists (N×1 cells) and arrays as a MAT-file v5 or v7.3."""
    path = Path(path)
    if version == "5":
        import scipy.io

        scipy.io.savemat(path, _to_v5(variables), do_compression=True, oned_as="column")
        return
    if version != "7.3":
        raise ValueError(f"`version` must be '5' or '7.3', got {version!r}")
    import h5py

    with h5py.File(path, "w", userblock_size=512) as f:
        counter = [0]
        for k, v in variables.items():
            _write_h5(f, f, k, v, counter)
    with open(path, "r+b") as fh:  # MATLAB's 128-byte text header inside the user block
        head = _MAT73_HEADER.ljust(116, b" ") + b"\x00" * 8 + b"\x00\x02IM"
        fh.write(head)


# ---------------------------------------------------------------------------------------------
# the IK data-set layout


def write_ik_dataset(path, dataset: dict, *, version: str = "5") -> None:
    """Write an IK data set (see module docstring) in the paper's layout, MAT v5 or v7.3."""
    parts = []
    for pi, part in enumerate(dataset["participants"]):
        ps, ik = {}, {}
        for cond, targets in part.items():
            cs, cat = {}, {"dq": [], "dx": [], "J": []}
            for tgt, trials in targets.items():
                cs[tgt] = [
                    {"q": tr["q"], "dq": tr["qdot"], "dx": tr["xdot"],
                     "J": np.moveaxis(np.asarray(tr["J"]), 0, -1)}
                    for tr in trials
                ]
                for tr in trials:
                    cat["dq"].append(np.asarray(tr["qdot"]).T)
                    cat["dx"].append(np.asarray(tr["xdot"]).T)
                    cat["J"].append(np.moveaxis(np.asarray(tr["J"]), 0, -1))
            ps[cond] = cs
            ik[cond] = {k: np.concatenate(v, axis=-1) for k, v in cat.items()}
        ps["IK_data"] = ik
        if dataset.get("w_true") is not None:
            ps["w_true"] = {c: np.asarray(v, float).reshape(1, -1) for c, v in dataset["w_true"][pi].items()}
        parts.append(ps)
    write_mat(path, {"data": parts}, version=version)


def _field(d, name, where):
    if not isinstance(d, dict):
        raise ValueError(f"{where}: expected a struct, got {type(d).__name__}")
    for k in d:
        if k.lower() == name.lower():
            return d[k]
    raise ValueError(f"{where}: missing field `{name}` (has {sorted(d)})")


def _mat2(a, where, name, cols=None):
    a = np.asarray(a, dtype=float)
    if a.ndim == 1:
        a = a[:, None]
    if a.ndim != 2 or (cols is not None and a.shape[1] != cols):
        raise ValueError(f"{where}: `{name}` must be an S×{cols or 'n'} matrix, got shape {a.shape}")
    return a


def load_ik_dataset(path) -> dict:
    """Read an IK data set in the paper's layout (MAT v5 or v7.3) into the Python form.

    Returns ``{"participants": [...], "ik_data": [{cond: {"qdot" (K, n), "xdot" (K, m),
    "J" (K, m, n)}}], "w_true": [...] or None}``. Raises ``ValueError`` naming the participant,
    condition, target and trial of any malformed entry.
    """
    raw = read_mat(path)
    if "data" not in raw:
        raise ValueError(f"{path}: no variable `data` (found {sorted(raw)})")
    parts_raw = raw["data"]
    parts_raw = [parts_raw] if isinstance(parts_raw, dict) else parts_raw
    if not isinstance(parts_raw, list):
        raise ValueError(f"{path}: `data` must be a cell of participant structs")
    parts, ikd, wts = [], [], []
    for pi, praw in enumerate(parts_raw):
        where = f"{path}: participant {pi + 1}"
        if not isinstance(praw, dict):
            raise ValueError(f"{where}: expected a struct, got {type(praw).__name__}")
        part, ik, wt = {}, {}, None
        for cond, craw in praw.items():
            if cond in ("IK_data", "w_true"):
                continue
            if not isinstance(craw, dict):
                raise ValueError(f"{where}, condition {cond}: expected a struct of targets")
            part[cond] = {}
            for tgt, traw in craw.items():
                traw = [traw] if isinstance(traw, dict) else traw
                if not isinstance(traw, list):
                    raise ValueError(f"{where}, {cond}/{tgt}: expected a cell of trials")
                trials = []
                for ti, tr in enumerate(traw):
                    w2 = f"{where}, {cond}/{tgt}, trial {ti + 1}"
                    dq = _mat2(_field(tr, "dq", w2), w2, "dq")
                    n = dq.shape[1]
                    q = _mat2(_field(tr, "q", w2), w2, "q", n)
                    dx = _mat2(_field(tr, "dx", w2), w2, "dx")
                    Jm = np.asarray(_field(tr, "J", w2), dtype=float)
                    if Jm.ndim == 2:
                        Jm = Jm[:, :, None]
                    S = dq.shape[0]
                    if Jm.shape != (dx.shape[1], n, S) or q.shape[0] != S or dx.shape[0] != S:
                        raise ValueError(f"{w2}: inconsistent shapes q {q.shape}, dq {dq.shape}, "
                                         f"dx {dx.shape}, J {Jm.shape}")
                    trials.append({"q": q, "qdot": dq, "xdot": dx, "J": np.moveaxis(Jm, -1, 0)})
                part[cond][tgt] = trials
        if "IK_data" in praw:
            for cond, d in praw["IK_data"].items():
                w2 = f"{where}, IK_data/{cond}"
                Jm = np.asarray(_field(d, "J", w2), dtype=float)
                Jm = Jm[:, :, None] if Jm.ndim == 2 else Jm
                dq = np.atleast_2d(np.asarray(_field(d, "dq", w2), float))
                dx = np.atleast_2d(np.asarray(_field(d, "dx", w2), float))
                if Jm.shape != (dx.shape[0], dq.shape[0], dq.shape[1]) or dx.shape[1] != dq.shape[1]:
                    raise ValueError(f"{w2}: inconsistent shapes dq {dq.shape}, dx {dx.shape}, J {Jm.shape}")
                ik[cond] = {"qdot": dq.T, "xdot": dx.T, "J": np.moveaxis(Jm, -1, 0)}
        if "w_true" in praw:
            wt = {c: np.asarray(v, float).reshape(-1) for c, v in praw["w_true"].items()}
        parts.append(part)
        ikd.append(ik)
        wts.append(wt)
    return {"participants": parts, "ik_data": ikd,
            "w_true": wts if all(w is not None for w in wts) else None}


def ik_dataset_arrays(dataset: dict, conditions=None, targets=None):
    """Pad a data set into arrays for vectorised estimation.

    Returns ``dict(qdot (P, C, T, R, S, n), xdot (P, C, T, R, S, m), J (P, C, T, R, S, m, n),
    mask (P, C, T, R, S), conditions, targets)``; missing trials are masked (zeros, ``J`` = [I 0]).
    """
    parts = dataset["participants"]
    conditions = list(conditions or parts[0].keys())
    targets = list(targets or parts[0][conditions[0]].keys())
    R = max(len(p[c][t]) for p in parts for c in conditions for t in targets)
    S = max(tr["qdot"].shape[0] for p in parts for c in conditions for t in targets for tr in p[c][t])
    tr0 = parts[0][conditions[0]][targets[0]][0]
    n, m = tr0["qdot"].shape[1], tr0["xdot"].shape[1]
    shp = (len(parts), len(conditions), len(targets), R, S)
    qd, xd = np.zeros(shp + (n,)), np.zeros(shp + (m,))
    J = np.broadcast_to(np.eye(m, n), shp + (m, n)).copy()
    mask = np.zeros(shp, bool)
    for a, p in enumerate(parts):
        for b, c in enumerate(conditions):
            for d, t in enumerate(targets):
                for r, tr in enumerate(p[c][t]):
                    k = tr["qdot"].shape[0]
                    ix = (a, b, d, r, slice(0, k))
                    qd[ix], xd[ix], J[ix] = tr["qdot"], tr["xdot"], tr["J"]
                    mask[a, b, d, r, :k] = True
    return dict(qdot=qd, xdot=xd, J=J, mask=mask, conditions=conditions, targets=targets)


# ---------------------------------------------------------------------------------------------
# HuG-MP

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
    """One HuG-MP subject: ``motions[task]`` a list of ``(repetition, index, q (N, 4) [rad])``
    (1-based task numbers); ``skipped`` lists ``(repetition, task, reason)`` of cells or motions
    that were not usable; ``notes`` lists irregular but kept cells (e.g. extra motions)."""

    subject: str
    motions: dict
    skipped: list
    notes: list
    fs: float = 100.0


def hugmp_directory(directory=None) -> Path:
    """The HuG-MP directory: ``directory``, else ``$PMPJAX_HUGMP``, else the bundled copy."""
    if directory is not None:
        return Path(directory)
    env = os.environ.get("PMPJAX_HUGMP")
    if env:
        return Path(env)
    return Path(str(resources.files("pmpjax") / "data" / "hugmp"))


def load_hugmp(subject, directory=None, *, min_samples: int = 20) -> HugmpSubject:
    """Load HuG-MP subject ``subject`` (1–4 or 'S01'…'S04') and survive its irregular cells.

    Empty cells and motions that are not finite 4 × N arrays with N ≥ ``min_samples`` are skipped
    and reported in ``skipped``; cells holding a number of motions other than the task lists are
    kept and reported in ``notes``. Angles are returned in radians.
    """
    name = f"S{int(subject):02d}" if isinstance(subject, int | np.integer) else str(subject)
    path = hugmp_directory(directory) / f"{name}_trajs.mat"
    if not path.is_file():
        raise FileNotFoundError(f"HuG-MP file not found: {path} (set `directory` or $PMPJAX_HUGMP)")
    if _mat_version(path) != "5":
        raise ValueError(f"{path}: HuG-MP files are MATLAB v5; got another format")
    import scipy.io

    try:
        tasks = scipy.io.loadmat(path).get("tasks")
    except (ValueError, OSError, TypeError) as e:
        raise ValueError(f"{path}: malformed MAT-file: {e}") from e
    if tasks is None or tasks.dtype != object or tasks.ndim != 2 or tasks.shape[1] != 6:
        raise ValueError(f"{path}: expected `tasks`, a repetitions × 6 cell array")
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
                if a is None or a.dtype == object or a.ndim != 2 or a.shape[0] != 4:
                    skipped.append((r + 1, t + 1, f"motion {i + 1}: not a 4 × N array"))
                elif a.shape[1] < min_samples:
                    skipped.append((r + 1, t + 1, f"motion {i + 1}: only {a.shape[1]} samples"))
                elif not np.all(np.isfinite(a)):
                    skipped.append((r + 1, t + 1, f"motion {i + 1}: NaN or inf"))
                else:
                    motions[t + 1].append((r + 1, i + 1, np.deg2rad(a.T.astype(float))))
    return HugmpSubject(subject=name, motions=motions, skipped=skipped, notes=notes)


@functools.lru_cache(maxsize=32)
def _savgol_operators(win, deriv, delta):
    """Cubic Savitzky–Golay filter of length ``win`` (SciPy's ``mode='interp'``) as linear maps:
    interior coefficients, and the edge maps (half, win) of the polynomial fits to the first and
    last ``win`` samples (the same for every signal, so fitted once instead of per motion)."""
    from scipy.signal import savgol_coeffs, savgol_filter

    edges = savgol_filter(np.eye(win), win, 3, deriv=deriv, delta=delta, axis=0, mode="interp")
    half = win // 2
    return savgol_coeffs(win, 3, deriv=deriv, delta=delta), edges[:half], edges[win - half:]


def _savgol(q, win, deriv, delta):
    """``scipy.signal.savgol_filter(q, win, 3, deriv, delta, axis=0)`` (mode 'interp') of (N, d) ``q``."""
    from scipy.ndimage import convolve1d

    coeffs, head, tail = _savgol_operators(win, deriv, delta)
    y = convolve1d(q, coeffs, axis=0, mode="constant")
    half = win // 2
    y[:half] = head @ q[:win]
    y[q.shape[0] - half:] = tail @ q[q.shape[0] - win:]
    return y


def _smooth(q, fs, window, samples):
    q = np.asarray(q, dtype=float)
    win = max(5, int(round(window * fs)) | 1)
    if q.shape[0] < win:
        raise ValueError(f"`q` has {q.shape[0]} samples, fewer than the smoothing window ({win})")
    qs, qd = _savgol(q, win, 0, 1.0), _savgol(q, win, 1, 1.0 / fs)
    if samples is not None:
        t0 = np.linspace(0.0, 1.0, q.shape[0])
        t1 = np.linspace(0.0, 1.0, samples)
        qs = np.stack([np.interp(t1, t0, qs[:, j]) for j in range(q.shape[1])], -1)
        qd = np.stack([np.interp(t1, t0, qd[:, j]) for j in range(q.shape[1])], -1)
    return qs, qd


def motion_kinematics(q, chain, *, fs: float = 100.0, window: float = 0.15, samples: int | None = 100):
    """Smoothed joint angles -> ``q`` (S, n), ``qdot`` (S, n), ``xdot`` (S, m), ``J`` (S, m, n).

    Savitzky–Golay smoothing and differentiation (cubic, ``window`` [s]) of ``q`` (N, n) [rad]
    sampled at ``fs`` [Hz]; optionally resampled to ``samples`` equally spaced points (time
    normalisation, as in the IK paper's 100-sample trials). ``J`` from ``chain`` and ``ẋ = J q̇``.
    """
    qs, qd = _smooth(q, fs, window, samples)
    J = np.asarray(chain.jacobian(qs))
    return qs, qd, np.einsum("sij,sj->si", J, qd), J


@jax.jit
def _jac_soa(chain, qc):
    return chain.fk_jac_soa(qc)[1]


def _jacobians(chain, q):
    """``chain.jacobian(q)`` (..., m, n) as a writable NumPy array, in one compiled call (eager
    op-by-op evaluation compiles ~100 small kernels per new shape)."""
    q = np.asarray(q, dtype=float)
    flat = q.reshape(-1, q.shape[-1])
    # pad the sample count to a power of two so that subjects of similar size share one compile
    N = flat.shape[0]
    P = max(1024, 1 << (N - 1).bit_length())
    qc = np.concatenate([flat, np.zeros((P - N, q.shape[-1]))]).T
    J = np.asarray(_jac_soa(chain, qc))[..., :N]
    return np.moveaxis(J, (0, 1), (-2, -1)).reshape(q.shape[:-1] + J.shape[:2]).copy()


def hugmp_arrays(subject: HugmpSubject, chain, *, samples: int = 100, window: float = 0.15):
    """Per task, pad the subject's motions into arrays for estimation.

    Returns ``dict(qdot (6, R, M, S, 4), xdot (6, R, M, S, 3), J (6, R, M, S, 3, 4),
    mask (6, R, M, S), q (6, R, M, S, 4))`` with R repetitions and M motions per repetition
    (missing ones masked; padded Jacobians are [I 0]); one Jacobian evaluation for all motions.
    """
    R = max([r for t in subject.motions.values() for r, _, _ in t] + [1])
    M = max([i for t in subject.motions.values() for _, i, _ in t] + [1])
    shp = (6, R, M, samples)
    out = dict(qdot=np.zeros(shp + (4,)), q=np.zeros(shp + (4,)), mask=np.zeros(shp, bool))
    for t, items in subject.motions.items():
        for r, i, q in items:
            sl = (t - 1, r - 1, i - 1)
            out["q"][sl], out["qdot"][sl] = _smooth(q, subject.fs, window, samples)
            out["mask"][sl] = True
    J = _jacobians(chain, out["q"])
    J[~out["mask"]] = np.eye(3, 4)
    out["J"] = J
    out["xdot"] = np.einsum("...ij,...j->...i", J, out["qdot"])
    return out
