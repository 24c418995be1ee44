"""MATLAB files (v5 and v7.3) and the IK paper's supporting-data layout.

**Reading and writing.** v5 files go through ``scipy.io``; v7.3 files are HDF5 and go through
``h5py`` with the MATLAB conventions (struct = group, scalar-struct fields as members, struct
arrays as groups of reference datasets, cell = dataset of object references into ``#refs#``,
column-major arrays stored transposed, ``MATLAB_class``/``MATLAB_empty`` attributes, a 512-byte
user block whose first 128 bytes are MATLAB's text header). ``read_mat`` returns the same Python
objects for both versions: structs -> dicts, cells and struct arrays -> lists (column-major
order), char -> str, numeric arrays squeezed as ``scipy.io.loadmat(simplify_cells=True)`` does.

Why h5py and not a v7.3 package: as fast as ``mat73`` (which only reads) and 5× faster than
``hdf5storage``, for about 60 lines here and no new dependency (h5py is already required). The
128-byte header is not forged: it is the text header MATLAB itself writes into the HDF5 user
block of a v7.3 file, which MATLAB checks before opening the HDF5 part.

**IK data-set layout** (after Khoramshahi et al. 2022, S1 Dataset; field names are ours): one
variable ``data``, a P×1 cell of participant structs. Each participant struct has one field per
condition (e.g. ``Natural``, ``Viscous``); each condition is a struct with fields ``Target1``…;
each target is a T×1 cell (or a 1×T struct array) of trial structs with ``q`` (S×n) [rad],
``dq`` (S×n) [rad/s], ``dx`` (S×m) [m/s] and ``J`` (m×n×S) per-step Jacobians; ``IK_data`` holds
per condition the concatenation over targets and trials ``dq`` (n×K), ``dx`` (m×K), ``J``
(m×n×K) (the input of Algorithm 1); an optional ``w_true`` struct holds known weights (synthetic
data). In Python a data set is ``{"participants": [{condition: {target: [trial dicts]}}],
"w_true": [{condition: (n,)}] or None}`` with trial dicts ``{"q", "qdot", "xdot", "J"}``
samples-first ((S, n), (S, n), (S, m), (S, m, n)).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from .._base import as_path, input_file

_MAT73_HEADER = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created by: pmpjax HDF5 schema 1.00 ."
_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,62}\Z")
# numeric MATLAB classes stored as plain HDF5 datasets in v7.3 files
_NUMERIC = {"double", "single", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64"}


# ---------------------------------------------------------------------------------------------
# reading: v5 (scipy.io) or v7.3 (h5py) into dicts / lists / arrays


def mat_version(path: Path) -> str:
    """``"5"`` or ``"7.3"`` from the file's header; ``ValueError`` naming the file otherwise."""
    with open(path, "rb") as fh:
        head = fh.read(128)
    if len(head) < 128:
        raise ValueError(f"{path}: not a MATLAB file (too short: {len(head)} bytes)")
    if head[:19] == b"MATLAB 7.3 MAT-file" or _is_hdf5(path):
        return "7.3"
    if head[:6] == b"MATLAB" and head[126:128] in (b"IM", b"MI"):
        return "5"
    raise ValueError(f"{path}: not a MATLAB v5 or v7.3 MAT-file (bad header {head[:20]!r})")


def _is_hdf5(path):
    import h5py

    try:
        return h5py.is_hdf5(path)
    except OSError:
        return False


def _from_v5(obj):
    """scipy.io (simplify_cells=True) output -> dicts, lists and arrays."""
    if isinstance(obj, dict):
        return {k: _from_v5(v) for k, v in obj.items() if not k.startswith("__")}
    if isinstance(obj, list):
        return [_from_v5(v) for v in obj]
    if isinstance(obj, np.ndarray) and obj.dtype == object:
        return [_from_v5(v) for v in obj.reshape(-1, order="F")]
    return obj


def _class(node) -> str:
    cls = node.attrs.get("MATLAB_class", b"")
    return cls.decode() if isinstance(cls, bytes) else str(cls)


def _refs(node):
    """Object references of a cell / struct-array field dataset, in MATLAB's column-major order."""
    return np.asarray(node[()]).T.reshape(-1, order="F")


def _from_h5(f, node, where: str):
    """One v7.3 node -> Python; ``where`` is the MATLAB-style path used in error messages."""
    import h5py

    cls = _class(node)
    if isinstance(node, h5py.Group):
        if cls not in ("", "struct"):
            raise ValueError(f"variable `{where}`: unsupported MATLAB class {cls!r} (objects are not read)")
        keys = [k for k in node.keys() if not k.startswith("#")]
        members = [node[k] for k in keys]
        is_array = keys and all(isinstance(m, h5py.Dataset) and m.dtype == h5py.ref_dtype and _class(m) != "cell"
                                for m in members)
        if not is_array:  # scalar struct: fields are members
            return {k: _from_h5(f, m, f"{where}.{k}") for k, m in zip(keys, members)}
        # struct array: each field holds one reference per element
        refs = {k: _refs(m) for k, m in zip(keys, members)}
        size = len(refs[keys[0]])
        if any(len(r) != size for r in refs.values()):
            raise ValueError(f"variable `{where}`: struct-array fields of different lengths")
        return [{k: _from_h5(f, f[refs[k][i]], f"{where}({i + 1}).{k}") for k in keys} for i in range(size)]
    if node.attrs.get("MATLAB_sparse", None) is not None:
        raise ValueError(f"variable `{where}`: sparse matrices are not supported")
    if node.attrs.get("MATLAB_empty", 0):
        return [] if cls == "cell" else np.zeros((0,))
    if cls == "cell" or node.dtype == h5py.ref_dtype:
        return [_from_h5(f, f[r], f"{where}{{{i + 1}}}") for i, r in enumerate(_refs(node))]
    data = np.asarray(node[()])
    if cls == "char":
        return "".join(chr(c) for c in data.T.reshape(-1, order="F"))
    if cls == "logical":
        return np.squeeze(data.T.astype(bool))
    if cls not in _NUMERIC and cls != "":
        raise ValueError(f"variable `{where}`: unsupported MATLAB class {cls!r}")
    if data.dtype.kind not in "iufb":
        raise ValueError(f"variable `{where}`: unsupported HDF5 data type {data.dtype}")
    return np.squeeze(data.T)


def read_mat(path) -> dict:
    """Read a MAT-file (v5 through scipy.io, v7.3 through h5py) into nested dicts, lists and arrays.

    Structs -> dicts, cells and struct arrays -> lists (column-major order), char -> str, numeric
    arrays squeezed (as ``scipy.io.loadmat(simplify_cells=True)``), for both versions.

    **Arguments:**

    - ``path``: the MAT-file.

    **Returns:**

    ``{variable: value}``.

    **Raises:**

    - ``ValueError`` naming the file and, where it applies, the variable
      (``data{2}.Natural.Target1{3}.dq``): no such file, a directory, empty, not a MAT-file,
      unreadable, unsupported content (objects, sparse matrices).
    """
    path = input_file("path", path)
    version = mat_version(path)
    try:
        if version == "5":
            import scipy.io

            return _from_v5(scipy.io.loadmat(path, simplify_cells=True))
        import h5py

        with h5py.File(path, "r") as f:
            return {k: _from_h5(f, f[k], k) for k in f.keys() if not k.startswith("#")}
    except (ValueError, OSError, TypeError, KeyError, NotImplementedError) as e:
        raise ValueError(f"{path}: malformed MATLAB v{version} file: {e}") from e


# ---------------------------------------------------------------------------------------------
# writing


def _check_value(obj, where):
    """Writable values: dicts with MATLAB field names (structs), lists/tuples (N×1 cells), str
    (char) and numeric arrays. ``TypeError``/``ValueError`` naming the variable otherwise."""
    if isinstance(obj, dict):
        for k, v in obj.items():
            if not isinstance(k, str) or not _NAME.match(k):
                raise ValueError(f"`{where}`: field name {k!r} is not a valid MATLAB name "
                                 "(a letter, then up to 62 letters, digits or underscores)")
            _check_value(v, f"{where}.{k}")
    elif isinstance(obj, list | tuple):
        for i, v in enumerate(obj):
            _check_value(v, f"{where}{{{i + 1}}}")
    elif not isinstance(obj, str):
        a = np.asarray(obj)
        if a.dtype.kind not in "iufb":
            raise TypeError(f"`{where}`: cannot write a {type(obj).__name__} (dtype {a.dtype}); use dicts, "
                            "lists, str or numeric arrays")


def _to_v5(obj):
    if isinstance(obj, dict):
        return {k: _to_v5(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        cell = np.empty((len(obj), 1), dtype=object)
        for i, v in enumerate(obj):
            cell[i, 0] = _to_v5(v)
        return cell
    if isinstance(obj, str):
        return obj
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
    if isinstance(obj, str):
        ds = group.create_dataset(name, data=np.array([ord(c) for c in obj], np.uint16).reshape(-1, 1))
        ds.attrs["MATLAB_class"] = np.bytes_("char")
        ds.attrs["MATLAB_int_decode"] = np.int32(2)
        return ds
    a = np.asarray(obj, dtype=float)
    if a.size == 0:
        ds = group.create_dataset(name, data=np.array(a.shape if a.ndim >= 2 else (0, 0), dtype=np.uint64))
        ds.attrs["MATLAB_empty"] = np.uint8(1)
    else:
        a2 = a.reshape(a.shape + (1,) * (2 - a.ndim)) if a.ndim < 2 else a
        ds = group.create_dataset(name, data=a2.T)
    ds.attrs["MATLAB_class"] = np.bytes_("double")
    return ds


def write_mat(path, variables: dict, *, version: str = "5") -> None:
    """Write nested dicts (structs), lists (N×1 cells), str (char) and numeric arrays (double) as a
    MAT-file v5 (``scipy.io.savemat``, compressed) or v7.3 (HDF5 with MATLAB's header).

    **Arguments:**

    - ``path``: the file to write.
    - ``variables``: a non-empty ``{name: value}`` dict of valid MATLAB names.
    - ``version``: ``"5"`` or ``"7.3"``.

    **Raises:**

    - ``ValueError``/``TypeError`` naming the variable or field that cannot be written, or a bad
      ``version``; ``FileNotFoundError`` when the target directory does not exist.
    """
    path = as_path("path", path)
    if version not in ("5", "7.3"):
        raise ValueError(f"`version` must be '5' or '7.3', got {version!r}")
    if not isinstance(variables, dict) or not variables:
        raise TypeError(f"`variables` must be a non-empty dict {{name: value}}, got {type(variables).__name__}")
    for k, v in variables.items():
        if not isinstance(k, str) or not _NAME.match(k):
            raise ValueError(f"`variables`: {k!r} is not a valid MATLAB variable name")
        _check_value(v, k)
    if not path.parent.is_dir():
        raise FileNotFoundError(f"directory of `path` does not exist: {path.parent}")
    if version == "5":
        import scipy.io

        scipy.io.savemat(path, _to_v5(variables), do_compression=True, oned_as="column")
        return
    import h5py

    with h5py.File(path, "w", userblock_size=512) as f:
        counter = [0]
        for k, v in variables.items():
            _write_h5(f, f, k, v, counter)
    with open(path, "r+b") as fh:  # MATLAB's 128-byte text header inside the user block
        fh.write(_MAT73_HEADER.ljust(116, b" ") + b"\x00" * 8 + b"\x00\x02IM")


# ---------------------------------------------------------------------------------------------
# the IK data-set layout


def _trial(q, qdot, xdot, J, where):
    """Samples-first float arrays of one trial, shapes checked: q, qdot (S, n), xdot (S, m),
    J (S, m, n). ``ValueError`` naming ``where`` and the field otherwise."""
    out = []
    for name, a, nd in (("q", q, 2), ("qdot", qdot, 2), ("xdot", xdot, 2), ("J", J, 3)):
        try:
            a = np.asarray(a, dtype=float)
        except (TypeError, ValueError) as e:
            raise ValueError(f"{where}: `{name}` is not numeric") from e
        if a.ndim != nd:
            raise ValueError(f"{where}: `{name}` must have {nd} dimensions, got shape {a.shape}")
        out.append(a)
    q, qd, xd, Jm = out
    S, n = qd.shape
    m = xd.shape[1]
    if q.shape != (S, n) or xd.shape[0] != S or Jm.shape != (S, m, n):
        raise ValueError(f"{where}: inconsistent shapes q {q.shape}, qdot {qd.shape}, xdot {xd.shape}, J {Jm.shape} "
                         "(expected (S, n), (S, n), (S, m), (S, m, n))")
    if not m < n:
        raise ValueError(f"{where}: need a redundant chain (m < n), got m = {m}, n = {n}")
    return {"q": q, "qdot": qd, "xdot": xd, "J": Jm}


def _participants(dataset, name="dataset"):
    if not isinstance(dataset, dict) or "participants" not in dataset:
        raise ValueError(f"`{name}` must be a dict with a 'participants' list (see pmpjax.load_ik_dataset)")
    parts = dataset["participants"]
    if not isinstance(parts, list | tuple) or not parts:
        raise ValueError(f"`{name}['participants']` must be a non-empty list of {{condition: {{target: trials}}}}")
    for pi, part in enumerate(parts):
        if not isinstance(part, dict) or not part:
            raise ValueError(f"`{name}`: participant {pi + 1} must be a non-empty dict of conditions")
        for cond, targets in part.items():
            if not isinstance(targets, dict) or not targets:
                raise ValueError(f"`{name}`: participant {pi + 1}, condition {cond!r} must be a dict of targets")
            for tgt, trials in targets.items():
                if not isinstance(trials, list | tuple):
                    raise ValueError(f"`{name}`: participant {pi + 1}, {cond}/{tgt} must be a list of trials")
    return parts


def write_ik_dataset(path, dataset: dict, *, version: str = "5") -> None:
    """Write an IK data set (see the module docstring) in the paper's layout, MAT v5 or v7.3.

    **Arguments:**

    - ``path``: the file to write.
    - ``dataset``: the Python form :func:`load_ik_dataset` returns (``participants``, optional
      ``w_true``).
    - ``version``: ``"5"`` or ``"7.3"``.

    **Raises:**

    - ``ValueError`` naming the participant, condition, target, trial and field of any malformed
      entry, or a bad ``version``.
    """
    path = as_path("path", path)
    if version not in ("5", "7.3"):
        raise ValueError(f"`version` must be '5' or '7.3', got {version!r}")
    parts_in = _participants(dataset)
    w_true = dataset.get("w_true")
    if w_true is not None and (not isinstance(w_true, list | tuple) or len(w_true) != len(parts_in)):
        raise ValueError(f"`dataset['w_true']` must be None or one {{condition: (n,)}} per participant "
                         f"({len(parts_in)}), got {type(w_true).__name__}")
    parts = []
    for pi, part in enumerate(parts_in):
        ps, ik = {}, {}
        for cond, targets in part.items():
            cs, cat = {}, {"dq": [], "dx": [], "J": []}
            for tgt, trials in targets.items():
                cs[tgt] = []
                for ti, tr in enumerate(trials):
                    where = f"`dataset`: participant {pi + 1}, {cond}/{tgt}, trial {ti + 1}"
                    if not isinstance(tr, dict) or not {"q", "qdot", "xdot", "J"} <= set(tr):
                        raise ValueError(f"{where}: a trial must be a dict with 'q', 'qdot', 'xdot', 'J'")
                    t = _trial(tr["q"], tr["qdot"], tr["xdot"], tr["J"], where)
                    Jm = np.moveaxis(t["J"], 0, -1)
                    cs[tgt].append({"q": t["q"], "dq": t["qdot"], "dx": t["xdot"], "J": Jm})
                    cat["dq"].append(t["qdot"].T)
                    cat["dx"].append(t["xdot"].T)
                    cat["J"].append(Jm)
            ps[cond] = cs
            if cat["dq"]:
                ik[cond] = {k: np.concatenate(v, axis=-1) for k, v in cat.items()}
        ps["IK_data"] = ik
        if w_true is not None:
            ps["w_true"] = {c: np.asarray(v, float).reshape(1, -1) for c, v in w_true[pi].items()}
        parts.append(ps)
    write_mat(path, {"data": parts}, version=version)


def _field(d, name, where):
    if not isinstance(d, dict):
        raise ValueError(f"{where}: expected a struct, got {type(d).__name__}")
    for k in d:
        if k.lower() == name.lower():
            return d[k]
    raise ValueError(f"{where}: missing field `{name}` (has {sorted(d)})")


def _mat2(a, where, name, S):
    """An S×k matrix (squeezed to 1-D when S = 1 or k = 1: restored)."""
    try:
        a = np.asarray(a, dtype=float)
    except (TypeError, ValueError) as e:
        raise ValueError(f"{where}: `{name}` is not numeric") from e
    if a.ndim == 1:
        a = a[None, :] if S == 1 else a[:, None]
    if a.ndim != 2:
        raise ValueError(f"{where}: `{name}` must be an S×k matrix, got shape {a.shape}")
    return a


def _jac(a, where, name="J"):
    try:
        a = np.asarray(a, dtype=float)
    except (TypeError, ValueError) as e:
        raise ValueError(f"{where}: `{name}` is not numeric") from e
    if a.ndim == 2:  # one sample (MATLAB drops the trailing singleton)
        a = a[:, :, None]
    if a.ndim != 3:
        raise ValueError(f"{where}: `{name}` must be an m×n×S array, got shape {a.shape}")
    return a


def _is_plain(v) -> bool:
    """A numeric array, number or char: not part of the conditions/targets/trials tree."""
    return isinstance(v, str | int | float | np.ndarray | np.generic)


def load_ik_dataset(path) -> dict:
    """Read an IK data set in the paper's layout (MAT v5 or v7.3) into the Python form.

    Trials may be a cell of structs or a struct array; numeric and char fields beside the
    conditions and targets are ignored.

    **Arguments:**

    - ``path``: the MAT-file.

    **Returns:**

    ``{"participants": [...], "ik_data": [{cond: {"qdot" (K, n) [rad/s], "xdot" (K, m), "J"
    (K, m, n)}}], "w_true": [...] or None}``.

    **Raises:**

    - ``ValueError`` naming the file, participant, condition, target, trial and field of any
      malformed entry.
    """
    path = as_path("path", path)
    raw = read_mat(path)
    if "data" not in raw:
        raise ValueError(f"{path}: no variable `data` (found {sorted(raw)})")
    parts_raw = raw["data"]
    parts_raw = [parts_raw] if isinstance(parts_raw, dict) else parts_raw
    if not isinstance(parts_raw, list) or not parts_raw:
        raise ValueError(f"{path}: `data` must be a non-empty cell of participant structs")
    parts, ikd, wts = [], [], []
    for pi, praw in enumerate(parts_raw):
        where = f"{path}: data{{{pi + 1}}}"
        if not isinstance(praw, dict):
            raise ValueError(f"{where}: expected a participant struct, got {type(praw).__name__}")
        part, ik, wt = {}, {}, None
        for cond, craw in praw.items():
            if cond in ("IK_data", "w_true") or _is_plain(craw):
                continue  # other numeric or char fields (e.g. the paper's estimated weights)
            if not isinstance(craw, dict):
                raise ValueError(f"{where}.{cond}: expected a struct of targets, got {type(craw).__name__}")
            part[cond] = {}
            for tgt, traw in craw.items():
                if _is_plain(traw):
                    continue
                traw = [traw] if isinstance(traw, dict) else traw
                if not isinstance(traw, list):
                    raise ValueError(f"{where}.{cond}.{tgt}: expected a cell of trial structs")
                trials = []
                for ti, tr in enumerate(traw):
                    w2 = f"{where}.{cond}.{tgt}{{{ti + 1}}} (participant {pi + 1}, {cond}/{tgt}, trial {ti + 1})"
                    Jm = _jac(_field(tr, "J", w2), w2)
                    S = Jm.shape[2]
                    dq, q, dx = (_mat2(_field(tr, k, w2), w2, k, S) for k in ("dq", "q", "dx"))
                    trials.append(_trial(q, dq, dx, np.moveaxis(Jm, -1, 0), w2))
                part[cond][tgt] = trials
        if "IK_data" in praw:
            if not isinstance(praw["IK_data"], dict):
                raise ValueError(f"{where}.IK_data: expected a struct of conditions")
            for cond, d in praw["IK_data"].items():
                w2 = f"{where}.IK_data.{cond}"
                Jm = _jac(_field(d, "J", w2), w2)
                # stored n×K and m×K: read as K×n, K×m matrices and transposed back
                dq, dx = (_mat2(np.transpose(_field(d, k, w2)), w2, k, Jm.shape[2]).T for k in ("dq", "dx"))
                if Jm.shape != (dx.shape[0], dq.shape[0], dq.shape[1]) or dx.shape[1] != dq.shape[1]:
                    raise ValueError(f"{w2}: inconsistent shapes dq {dq.shape} (n×K), dx {dx.shape} (m×K), "
                                     f"J {Jm.shape} (m×n×K)")
                ik[cond] = {"qdot": dq.T, "xdot": dx.T, "J": np.moveaxis(Jm, -1, 0)}
        if "w_true" in praw:
            if not isinstance(praw["w_true"], dict):
                raise ValueError(f"{where}.w_true: expected a struct of conditions")
            wt = {}
            for c, v in praw["w_true"].items():
                try:
                    wt[c] = np.asarray(v, float).reshape(-1)
                except (TypeError, ValueError) as e:
                    raise ValueError(f"{where}.w_true.{c}: not numeric") from e
        parts.append(part)
        ikd.append(ik)
        wts.append(wt)
    return {"participants": parts, "ik_data": ikd,
            "w_true": wts if all(w is not None for w in wts) else None}


def ik_dataset_arrays(dataset: dict, conditions=None, targets=None):
    """Pad a data set into arrays for vectorised estimation (``fitting.estimate_ik_weights``).

    Missing trials are masked (zeros, ``J`` = [I 0]).

    **Arguments:**

    - ``dataset``: the Python form of :func:`load_ik_dataset`.
    - ``conditions``, ``targets``: select and order them (default: those of the first participant).

    **Returns:**

    ``dict(qdot (P, C, T, R, S, n), xdot (P, C, T, R, S, m), J (P, C, T, R, S, m, n),
    mask (P, C, T, R, S), conditions, targets)`` for P participants, C conditions, T targets, R
    trials and S samples.

    **Raises:**

    - ``ValueError`` naming a participant that lacks a condition or target, or trials of other sizes
      n, m.
    """
    parts = _participants(dataset)
    conditions = list(parts[0].keys() if conditions is None else conditions)
    for c in conditions:
        if c not in parts[0]:
            raise ValueError(f"`conditions`: {c!r} is not a condition of participant 1 (has {list(parts[0])})")
    targets = list(parts[0][conditions[0]].keys() if targets is None else targets)
    trials = []
    for pi, p in enumerate(parts):
        for c in conditions:
            if c not in p:
                raise ValueError(f"`dataset`: participant {pi + 1} has no condition {c!r} (has {list(p)})")
            for t in targets:
                if t not in p[c]:
                    raise ValueError(f"`dataset`: participant {pi + 1}, condition {c!r} has no target {t!r}")
                for ri, tr in enumerate(p[c][t]):
                    where = f"`dataset`: participant {pi + 1}, {c}/{t}, trial {ri + 1}"
                    if not isinstance(tr, dict) or not {"q", "qdot", "xdot", "J"} <= set(tr):
                        raise ValueError(f"{where}: a trial must be a dict with 'q', 'qdot', 'xdot', 'J'")
                    trials.append((where, _trial(tr["q"], tr["qdot"], tr["xdot"], tr["J"], where)))
    if not trials:
        raise ValueError("`dataset` holds no trial for the selected conditions and targets")
    n, m = trials[0][1]["qdot"].shape[1], trials[0][1]["xdot"].shape[1]
    for where, tr in trials:
        if tr["J"].shape[1:] != (m, n):
            raise ValueError(f"{where}: J is {tr['J'].shape[1:]} per sample, other trials {(m, n)}")
    R = max(len(p[c][t]) for p in parts for c in conditions for t in targets)
    S = max(tr["qdot"].shape[0] for _, tr in trials)
    shp = (len(parts), len(conditions), len(targets), R, S)
    qd, xd = np.zeros(shp + (n,)), np.zeros(shp + (m,))
    J = np.broadcast_to(np.eye(m, n), shp + (m, n)).copy()
    mask = np.zeros(shp, bool)
    it = iter(trials)
    for a, p in enumerate(parts):
        for b, c in enumerate(conditions):
            for d, t in enumerate(targets):
                for r in range(len(p[c][t])):
                    tr = next(it)[1]
                    k = tr["qdot"].shape[0]
                    ix = (a, b, d, r, slice(0, k))
                    qd[ix], xd[ix], J[ix] = tr["qdot"], tr["xdot"], tr["J"]
                    mask[a, b, d, r, :k] = True
    return dict(qdot=qd, xdot=xd, J=J, mask=mask, conditions=conditions, targets=targets)
