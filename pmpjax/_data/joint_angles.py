"""Joint-angle recordings of continuous trials: OpenSim ``.mot``/``.sto``, CSV, HuG-MP ``.mat``.

:func:`read_joint_angles` reads one recording (one continuous trial, several reaches) into a
:class:`JointRecording` (``t`` (T,) [s], ``q`` (T, n) [rad]); :func:`write_joint_angles` writes
``.mot``, ``.sto`` or ``.csv``. The format is chosen by the file's extension (any case).

**OpenSim** ``.mot`` / ``.sto`` (version-1 header, as inverse kinematics writes it)::

    Coordinates
    version=1
    nRows=3
    nColumns=3
    inDegrees=yes
    endheader
    time	shoulder_elv	elbow_flexion
    0.00	10.0	45.0

Header lines up to ``endheader``; ``key=value`` lines are read (``inDegrees``, ``nRows``,
``nColumns``, ``DataType``; others, and free text, are skipped). Then the column labels, the first
``time``, and one row per sample, fields separated by tabs or spaces. ``inDegrees=yes`` means
degrees (converted to radians), ``no`` radians. **Without an ``inDegrees`` line degrees are
assumed** (OpenSim's inverse kinematics writes its ``.mot`` output in degrees), with a warning when
every selected value lies within ±π (the data then look like radians); declared degrees (here or in
a CSV) whose every value lies within ±π degrees warn the same way. ``nRows``/``nColumns``
(the latter counting ``time``) are checked against the data when present; a ``DataType`` other
than ``double`` is refused. Columns named ``*_tx``, ``*_ty``, ``*_tz`` are OpenSim's translational
coordinates [m]: they are not angles, so ``joints=None`` leaves them out (listed in
``ignored_columns``) and naming one in ``joints`` is an error.

**CSV**: optional ``#`` comment lines, a header row with a ``time`` column (or ``t``; any case; a
``[s]``/``(s)``/``_s`` suffix allowed) and one column per joint, then one row per sample. Angles are
**radians unless declared degrees**, either for the whole file by a comment line before the header
``# units: deg`` (``degrees``; ``# units: rad`` says radians) or per column by a suffix ``_deg``,
``[deg]`` or ``(deg)`` (``_rad``, ``[rad]``, ``(rad)`` declare radians); a column's suffix wins over
the comment line, and suffixes are stripped for matching (``elbow_deg`` is the joint ``elbow``).
Empty fields and ``nan`` are missing samples. A radian column with a value beyond ±2π (degrees,
most likely) is refused with a hint naming the column and how to declare degrees; the same holds
for ``.mot``/``.sto`` files with ``inDegrees=no``.

**HuG-MP** ``.mat`` (the subject files ``S0i_trajs.mat``, read by :func:`pmpjax.load_hugmp`): a
subject file holds many separate motions (idle time removed, so they are not one continuous
trial); ``motion=(task, repetition, index)`` (1-based, as in ``HugmpSubject.motions``) picks one.
Its columns are ``q1`` … ``q4`` (the joints of ``pj.ShoulderElbowArm``, 100 Hz); the subject
defaults to the file's subject (``S01``) and the name is ``S01_task1_rep2_motion3``. The file must
keep its HuG-MP name ``S<nn>_trajs.mat``.

**Joints** (``joints=``): None keeps every angle column in file order; a name or a sequence of
names picks and orders columns, matched by exact name first, then case-insensitively; a pmpjax
chain with ``joint_names`` of which any is a column picks those columns in the chain's order (all
must then be found), and otherwise — a chain without names (``PlanarArm``, ``Wrist``,
``FunctionChain``, ``MjcfChain``), or whose names are display labels matching no column
(``ShoulderElbowArm``) — takes the file's angle columns in file order, **only when there are
exactly** ``chain.n`` of them (pass the names otherwise: the file's order is then trusted to be
the chain's joint order).
Columns not used are listed in ``ignored_columns``; requested joints that are missing raise a
``ValueError`` naming them, the file and its columns, with a did-you-mean suggestion.

**Checks** (each a ``ValueError`` naming the file, and the line and column, 1-based, where one
applies): time strictly increasing and evenly sampled (every step within ``sample_tol``, relative,
of the median step; the median step must be below 0.5 s — seconds, not milliseconds); at least 2
samples; rows with the header's number of fields and numeric fields (``inf`` refused). Missing
samples (NaN) are filled by linear interpolation in time when the valid samples on either side of
the gap are at most ``max_gap`` seconds apart (default 0.05 s: 4 missing samples at 100 Hz) and
reported in ``filled_gaps``; longer gaps, and gaps at the start or end of a column (nothing to
interpolate from), are refused, naming the column and the time span. Directories, empty files,
binary files (NUL bytes) and text that is not UTF-8 are refused as such.
"""

from __future__ import annotations

import csv
import dataclasses
import difflib
import io
import os
import re
import warnings
from functools import partial
from pathlib import Path

import numpy as np

from .._base import as_path, check_positive, input_file, read_text_file
from .._chains import Chain

#: Extensions read (and written, but ``.mat``) by this module.
FORMATS = (".mot", ".sto", ".csv", ".mat")
_RAD_LIMIT = 2 * np.pi
_MAX_STEP = 0.5  # [s]: a median sample interval above this is not seconds (ms? frames?)
_CSV_UNIT = re.compile(r"^(?P<base>.*?)\s*(?:_(?P<a>deg|rad)|\[(?P<b>deg|rad)\]|\((?P<c>deg|rad)\))$", re.I)
_CSV_TIME = re.compile(r"^(time|t)\s*(?:\[s\]|\(s\)|_s)?$", re.I)
_TRANSLATION = re.compile(r"_t[xyz]$")
_UNIT_WORDS = {"deg": True, "degree": True, "degrees": True, "rad": False, "radian": False, "radians": False}


@dataclasses.dataclass(frozen=True, eq=False)
class JointRecording:
    """One continuous trial of joint angles (T samples, n joints).

    ``subject`` subject name; ``name`` the recording's name (the file's stem); ``t`` (T,) sample
    times [s], strictly increasing, evenly sampled; ``q`` (T, n) joint angles [rad], finite and
    within a full turn (±2π; larger values are degrees); ``joint_names`` (n,) names of the columns
    of ``q``; ``fs`` sampling rate [Hz] (default ``1 / median(diff(t))``); ``ignored_columns`` the
    file's columns not read; ``filled_gaps`` ``(joint, t_first, t_last)`` [s] of each run of
    missing samples that was filled by linear interpolation; ``source`` the file read
    (``"<memory>"`` when built from arrays).

    Build one from arrays as ``JointRecording(subject, name, t, q, joint_names)``; the fields are
    validated (``ValueError`` naming the field).
    """

    subject: str
    name: str
    t: np.ndarray
    q: np.ndarray
    joint_names: tuple[str, ...]
    fs: float | None = None
    ignored_columns: tuple[str, ...] = ()
    filled_gaps: tuple[tuple[str, float, float], ...] = ()
    source: str = "<memory>"

    def __post_init__(self):
        set_ = partial(object.__setattr__, self)
        where = f"JointRecording({self.source})"
        for field in ("subject", "name"):
            v = getattr(self, field)
            if not isinstance(v, str) or not v:
                raise ValueError(f"{where}: `{field}` must be a non-empty str, got {v!r}")
        try:
            t = np.array(self.t, dtype=np.float64)
            q = np.array(self.q, dtype=np.float64)
        except (TypeError, ValueError) as e:
            raise ValueError(f"{where}: `t` and `q` must be numeric arrays ({e})") from None
        if t.ndim != 1 or t.shape[0] < 2:
            raise ValueError(f"{where}: `t` must be a 1-D array of >= 2 sample times [s], got shape {t.shape}")
        if q.ndim != 2 or q.shape[0] != t.shape[0] or q.shape[1] == 0:
            raise ValueError(f"{where}: `q` must have shape (T, n) = ({t.shape[0]}, n >= 1) [rad], got {q.shape}")
        names = (self.joint_names,) if isinstance(self.joint_names, str) else tuple(self.joint_names)
        if len(names) != q.shape[1] or not all(isinstance(s, str) and s for s in names):
            raise ValueError(f"{where}: `joint_names` must be {q.shape[1]} non-empty names (one per column of "
                             f"`q`), got {list(names)}")
        if len(set(names)) != len(names):
            raise ValueError(f"{where}: `joint_names` must be unique, got {list(names)}")
        if not (np.all(np.isfinite(t)) and np.all(np.diff(t) > 0)):
            raise ValueError(f"{where}: `t` must be finite and strictly increasing")
        if not np.all(np.isfinite(q)):
            raise ValueError(f"{where}: `q` contains NaN or inf")
        if np.any(np.abs(q) > _RAD_LIMIT):
            k, j = np.unravel_index(int(np.argmax(np.abs(q) > _RAD_LIMIT)), q.shape)
            v = q[k, j]
            raise ValueError(f"{where}: `q` [rad] of joint '{names[j]}' is {v:.4g} at t = {t[k]:.4g} s, beyond a "
                             f"full turn (±2π): degrees? {v:.4g}° is {np.deg2rad(v):.4g} rad (np.deg2rad)")
        fs = 1.0 / float(np.median(np.diff(t))) if self.fs is None else self.fs
        if isinstance(fs, bool) or not isinstance(fs, int | float | np.number) or not (np.isfinite(fs) and fs > 0):
            raise ValueError(f"{where}: `fs` must be a positive sampling rate [Hz], got {fs!r}")
        set_("t", t)
        set_("q", q)
        set_("joint_names", names)
        set_("fs", float(fs))
        set_("ignored_columns", tuple(str(c) for c in self.ignored_columns))
        set_("filled_gaps", tuple((str(j), float(a), float(b)) for j, a, b in self.filled_gaps))
        set_("source", os.fspath(self.source))

    @property
    def n(self) -> int:
        """Number of joints."""
        return int(self.q.shape[1])


# ---------------------------------------------------------------------------------------------
# reading


def read_joint_angles(path, *, subject: str | None = None, joints=None, max_gap: float = 0.05,
                      sample_tol: float = 0.01, motion: tuple[int, int, int] | None = None) -> JointRecording:
    """Read one joint-angle recording (``.mot``, ``.sto``, ``.csv`` or HuG-MP ``.mat``).

    Formats, unit conventions and checks: see the module docstring.

    **Arguments:**

    - ``path``: the file; its extension picks the format.
    - ``subject``: subject name (default: the file's stem; for HuG-MP the file's subject, ``S01``).
    - ``joints``: None (every angle column, file order), a name or a sequence of column names
      (exact match, then case-insensitive), or a pmpjax chain (its ``joint_names`` when they name
      columns, else the file's angle columns in order when there are exactly ``chain.n`` of them).
    - ``max_gap``: longest span [s] between valid samples across which missing samples (NaN) are
      linearly interpolated (0 fills nothing).
    - ``sample_tol``: largest relative deviation of a sample interval from the median interval.
    - ``motion``: HuG-MP only, ``(task, repetition, index)`` (1-based), required for ``.mat``.

    **Returns:**

    A :class:`JointRecording`: ``t`` (T,) [s], ``q`` (T, n) [rad].

    **Raises:**

    ``ValueError`` naming the file (and line and column, 1-based) for unreadable or
    malformed files, bad time stamps, long gaps and joints not found; ``TypeError`` for arguments
    of the wrong type. A missing file raises an error that is both ``FileNotFoundError`` and
    ``ValueError``.
    """
    path = as_path("path", path)
    ext = path.suffix.lower()
    if path.is_dir():
        input_file("path", path)  # (a folder is refused as one, whatever its name)
    if ext not in FORMATS:
        raise ValueError(f"`path` must end in {', '.join(FORMATS)}, got {os.fspath(path)!r}")
    if subject is not None and (not isinstance(subject, str) or not subject):
        raise TypeError(f"`subject` must be a non-empty str (default: the file's stem), got {subject!r}")
    wanted = _wanted_joints(joints)
    if isinstance(max_gap, bool) or not isinstance(max_gap, int | float | np.floating | np.integer) \
            or not np.isfinite(max_gap) or max_gap < 0:
        raise ValueError(f"`max_gap` must be a duration >= 0 [s], got {max_gap!r}")
    check_positive("sample_tol", sample_tol)
    if ext != ".mat" and motion is not None:
        raise ValueError(f"`motion` picks a motion of a HuG-MP .mat file; {path.name} is a {ext} file")
    path = input_file("path", path)
    if ext == ".mat":
        return _read_hugmp(path, subject, wanted, motion)
    raw = path.read_bytes()
    if b"\x00" in raw:
        i = raw.index(b"\x00")
        line = raw[:i].count(b"\n") + 1
        raise ValueError(f"{path}: a binary file (NUL byte at byte {i}, line {line}), not a {ext} text file")
    text = read_text_file(path)  # (text in another encoding is refused by its first non-UTF-8 byte)
    table = _parse_opensim(path, text) if ext in (".mot", ".sto") else _parse_csv(path, text)
    return _build(path, table, subject or path.stem, path.stem, wanted, float(max_gap), float(sample_tol))


@dataclasses.dataclass
class _Table:
    """A parsed text file: ``labels`` the matching names of the non-time columns; ``raw`` their
    header text; ``col`` their 0-based field index; ``degrees`` per column (None: undeclared);
    ``rows`` the data rows' fields; ``lines`` their 1-based line numbers; ``header_line``;
    ``time_col``; ``skip`` labels left out by default (translations); ``check`` nRows/nColumns."""

    labels: list
    raw: list
    col: list
    degrees: list
    rows: list
    lines: np.ndarray
    header_line: int
    time_col: int
    skip: set
    check: dict


def _wanted_joints(joints):
    """None, a tuple of names, or a chain (validated types)."""
    if joints is None or isinstance(joints, Chain):
        return joints
    if isinstance(joints, str):
        joints = (joints,)
    try:
        names = tuple(joints)
    except TypeError:
        raise TypeError(f"`joints` must be None, a sequence of joint names or a pmpjax chain, "
                        f"got {type(joints).__name__}") from None
    bad = [j for j in names if not isinstance(j, str) or not j.strip()]
    if bad or not names:
        raise TypeError(f"`joints` must hold non-empty joint names (str), got {list(names)}")
    dup = sorted({j for j in names if names.count(j) > 1})
    if dup:
        raise ValueError(f"`joints` names {dup} more than once")
    return names


def _parse_opensim(path, text) -> _Table:
    lines = text.splitlines()
    end = next((i for i, s in enumerate(lines) if s.strip().lower() == "endheader"), None)
    if end is None:
        raise ValueError(f"{path}: no 'endheader' line: not an OpenSim .mot/.sto file (header lines, then "
                         "'endheader', then the column labels)")
    meta = {}
    for ln, s in enumerate(lines[:end], 1):
        if "=" in s:
            key, _, value = s.partition("=")
            meta[key.strip().lower()] = (value.strip(), ln)
    check = {}
    if "indegrees" in meta:
        value, ln = meta["indegrees"]
        if value.lower() not in ("yes", "no", "true", "false"):
            raise ValueError(f"{path}: line {ln}: inDegrees must be 'yes' or 'no', got {value!r}")
        degrees = value.lower() in ("yes", "true")
    else:
        degrees = None
    for key, label in (("nrows", "nRows"), ("ncolumns", "nColumns")):
        if key in meta:
            value, ln = meta[key]
            try:
                check[label] = (int(value), ln)
            except ValueError:
                raise ValueError(f"{path}: line {ln}: {label} must be an integer, got {value!r}") from None
    if "datatype" in meta and meta["datatype"][0].lower() != "double":
        value, ln = meta["datatype"]
        raise ValueError(f"{path}: line {ln}: DataType={value}: only DataType=double (one number per column) "
                         "is read")
    body = [(ln, s) for ln, s in enumerate(lines[end + 1:], end + 2) if s.strip()]
    if not body:
        raise ValueError(f"{path}: no column labels after 'endheader' (line {end + 1})")
    header_line, header = body[0][0], body[0][1].split()
    if header[0].lower() != "time":
        raise ValueError(f"{path}: line {header_line}, column 1: the first column label must be 'time', "
                         f"got {header[0]!r}")
    labels = header[1:]
    _check_duplicates(path, header_line, labels)
    skip = {s for s in labels if _TRANSLATION.search(s)}
    rows = [s.split() for _, s in body[1:]]
    return _Table(labels, labels, list(range(1, len(header))), [degrees] * len(labels), rows,
                  np.array([ln for ln, _ in body[1:]], dtype=np.int64), header_line, 0, skip, check)


def _parse_csv(path, text) -> _Table:
    default, kept, numbers = None, [], []
    for ln, raw in enumerate(text.splitlines(), 1):
        s = raw.strip()
        if not s:
            continue
        if s.startswith("#"):
            if not kept:  # comments before the header may declare the units
                body = s.lstrip("#").strip()
                m = re.match(r"units?\s*[:=]\s*(\S+)\s*$", body, re.I)
                if m:
                    unit = m.group(1).lower()
                    if unit not in _UNIT_WORDS:
                        raise ValueError(f"{path}: line {ln}: unknown unit {m.group(1)!r} (write '# units: deg' or "
                                         "'# units: rad')")
                    default = _UNIT_WORDS[unit]
            continue
        kept.append(raw)
        numbers.append(ln)
    if not kept:
        raise ValueError(f"{path}: no header row (only comments or blank lines)")
    rows = list(csv.reader(io.StringIO("\n".join(kept))))
    header, header_line = [h.strip() for h in rows[0]], numbers[0]
    for i, h in enumerate(header):
        if not h:
            raise ValueError(f"{path}: line {header_line}, column {i + 1}: empty column name")
    times = [i for i, h in enumerate(header) if _CSV_TIME.match(h)]
    if len(times) != 1:
        what = "no time column" if not times else f"{len(times)} time columns {[header[i] for i in times]}"
        raise ValueError(f"{path}: line {header_line}: {what}; the header needs exactly one 'time' (or 't') "
                         f"column [s], got {header}")
    labels, raw_labels, col, degrees = [], [], [], []
    for i, h in enumerate(header):
        if i == times[0]:
            continue
        m = _CSV_UNIT.match(h)
        unit = m and (m.group("a") or m.group("b") or m.group("c"))
        labels.append(m.group("base") if unit and m.group("base") else h)
        raw_labels.append(h)
        col.append(i)
        degrees.append(_UNIT_WORDS[unit.lower()] if unit else (False if default is None else default))
    _check_duplicates(path, header_line, labels, raw_labels)
    return _Table(labels, raw_labels, col, degrees, rows[1:], np.array(numbers[1:], dtype=np.int64), header_line,
                  times[0], set(), {})


def _check_duplicates(path, line, labels, raw=None):
    raw = labels if raw is None else raw
    seen = {}
    for lab, r in zip(labels, raw):
        if lab in seen:
            same = f"{seen[lab]!r} and {r!r}" if seen[lab] != r else f"{r!r} twice"
            raise ValueError(f"{path}: line {line}: duplicate column {lab!r} ({same})")
        seen[lab] = r


def _select(path, table: _Table, wanted) -> list[int]:
    """Indices into ``table.labels`` of the joints to read, in the order of ``wanted``."""
    labels = table.labels
    angles = [i for i, s in enumerate(labels) if s not in table.skip]
    if wanted is None:
        if not angles:
            raise ValueError(f"{_at(path, table)}: no joint-angle columns besides time "
                             f"(columns: {table.raw})")
        return angles
    whose = ""
    if isinstance(wanted, Chain):
        n = int(wanted.n)
        names = getattr(wanted, "joint_names", None)
        names = tuple(names) if names is not None and len(names) == n else None
        if not (names and _find(path, table, names)[0]):
            # no names, or display labels naming no column: the file's angle columns, in order
            if len(angles) == n:
                return angles
            named = f" (its joint_names {list(names)} are not columns)" if names else " and no joint names"
            raise ValueError(f"{_at(path, table)}: `joints` is a {type(wanted).__name__} with {n} "
                             f"joints{named}, but the file has {len(angles)} angle columns "
                             f"{[table.raw[i] for i in angles]}; pass joints=[the {n} column names in the chain's "
                             "joint order]")
        # some of the chain's names are columns: then all must be (never a silent reordering)
        wanted, whose = names, f" of {type(wanted).__name__}.joint_names"
    found, missing = _find(path, table, wanted)
    if missing:
        hints = []
        lower = {s.lower(): s for s in labels}
        for name in missing:
            near = difflib.get_close_matches(name.lower(), list(lower), n=1, cutoff=0.6)
            if near:
                hints.append(f"{name!r}: did you mean {lower[near[0]]!r}?")
        hint = f" ({'; '.join(hints)})" if hints else ""
        raise ValueError(f"{_at(path, table)}: joint(s) {missing}{whose} not found{hint}; the file's columns: "
                         f"{table.raw}")
    bad = [labels[i] for i in found if i not in angles]
    if bad:
        raise ValueError(f"{_at(path, table)}: column(s) {bad} are translational coordinates [m] "
                         "(OpenSim's *_tx, *_ty, *_tz), not joint angles")
    return found


def _chain_names_match(path, table, wanted) -> bool:
    """True when ``wanted`` is a chain whose ``joint_names`` are all columns of the table."""
    names = getattr(wanted, "joint_names", None) if isinstance(wanted, Chain) else None
    return names is not None and len(names) == int(wanted.n) and not _find(path, table, names)[1]


def _find(path, table: _Table, names):
    """(indices of ``names`` among the table's columns, names not found): exact match first (the
    matching name, then the header text), then case-insensitive."""
    labels, raw = table.labels, table.raw
    found, missing = [], []
    for name in names:
        if name in labels:
            found.append(labels.index(name))
            continue
        if name in raw:
            found.append(raw.index(name))
            continue
        ci = [i for i, s in enumerate(labels) if s.lower() == name.lower()]
        if len(ci) == 1:
            found.append(ci[0])
        elif len(ci) > 1:
            raise ValueError(f"{_at(path, table)}: joint {name!r} matches several columns case-insensitively: "
                             f"{[raw[i] for i in ci]}; give its exact name")
        else:
            missing.append(name)
    return found, missing


def _at(path, table: _Table) -> str:
    """``file: line L`` of the column labels (just the file when it has no header line)."""
    return f"{path}: line {table.header_line}" if table.header_line else f"{path}"


def _column(path, table: _Table, field: int, name: str, allow_nan: bool) -> np.ndarray:
    """Floats of field ``field`` (0-based) of every row; missing fields ('', nan) are NaN when
    ``allow_nan``; a ``ValueError`` names file, line and column otherwise."""
    vals = [r[field] for r in table.rows]
    try:
        a = np.fromiter(map(float, vals), np.float64, len(vals))  # (Python's parser: 5x NumPy's on str)
    except ValueError:
        a = np.empty(len(vals))
        for k, v in enumerate(vals):  # slow path: missing fields, or locate the bad one
            s = v.strip()
            if allow_nan and (not s or s.lower().lstrip("+-").startswith("nan")):
                a[k] = np.nan
                continue
            try:
                a[k] = float(s)
            except ValueError:
                raise ValueError(f"{path}: line {table.lines[k]}, column {field + 1} ({name!r}): not a number: "
                                 f"{v!r}") from None
    bad = np.isinf(a) if allow_nan else ~np.isfinite(a)
    if bad.any():
        k = int(np.argmax(bad))
        what = "inf" if allow_nan else "NaN or inf (time must be given for every sample)"
        raise ValueError(f"{path}: line {table.lines[k]}, column {field + 1} ({name!r}): {what}: {vals[k]!r}")
    return a


def _build(path, table: _Table, subject, name, wanted, max_gap, sample_tol) -> JointRecording:
    if not table.rows:
        raise ValueError(f"{path}: no samples after the column labels (line {table.header_line})")
    nfield = len(table.labels) + 1
    counts = np.fromiter((len(r) for r in table.rows), np.int64, len(table.rows))
    if np.any(counts != nfield):
        k = int(np.argmax(counts != nfield))
        raise ValueError(f"{path}: line {table.lines[k]}: expected {nfield} fields (the columns of line "
                         f"{table.header_line}), got {counts[k]}")
    for label, (value, ln) in table.check.items():
        got = len(table.rows) if label == "nRows" else nfield
        if value != got:
            what = "data rows" if label == "nRows" else "columns (time included)"
            raise ValueError(f"{path}: line {ln}: {label}={value} but the file has {got} {what}")
    if len(table.rows) < 2:
        raise ValueError(f"{path}: only {len(table.rows)} sample: a recording needs at least 2")
    sel = _select(path, table, wanted)
    t = _column(path, table, table.time_col, "time", allow_nan=False)
    _check_time(path, table, t, sample_tol)
    q = np.stack([_column(path, table, table.col[i], table.raw[i], allow_nan=True) for i in sel], -1)
    degrees = [table.degrees[i] for i in sel]
    declared = [j for j, d in enumerate(degrees) if d is True]
    if declared and np.isfinite(q[:, declared]).any() and np.nanmax(np.abs(q[:, declared])) <= np.pi:
        peak = np.nanmax(np.abs(q[:, declared]))
        how, fix = (("'inDegrees=yes'", "set 'inDegrees=no' in the header") if path.suffix.lower() in (".mot", ".sto")
                    else ("'_deg' names or '# units: deg'", "declare radians ('_rad' names or '# units: rad')"))
        warnings.warn(f"{path}: the angles are declared in degrees ({how}), but every value lies within ±π "
                      f"degrees (largest {peak:.3g}°): radians? If so, {fix}", UserWarning, stacklevel=3)
    if any(d is None for d in degrees):  # OpenSim header without inDegrees: degrees assumed
        peak = np.nanmax(np.abs(q)) if np.isfinite(q).any() else np.nan
        if peak <= np.pi:
            warnings.warn(f"{path}: the header has no inDegrees line, so degrees are assumed (OpenSim inverse "
                          f"kinematics writes degrees), but every value lies within ±π (largest {peak:.3g}): "
                          "radians? Add 'inDegrees=no' to the header if so", UserWarning, stacklevel=3)
        degrees = [True if d is None else d for d in degrees]
    for j, (i, deg) in enumerate(zip(sel, degrees)):
        col = q[:, j]
        if not deg and np.isfinite(col).any() and np.nanmax(np.abs(col)) > _RAD_LIMIT:
            k = int(np.argmax(np.abs(col) > _RAD_LIMIT))  # (NaN compare False)
            how = ("set 'inDegrees=yes' in the header" if path.suffix.lower() in (".mot", ".sto") else
                   f"name the column {table.labels[i]}_deg (or {table.labels[i]} [deg]), or put '# units: deg' "
                   "before the header")
            raise ValueError(f"{path}: line {table.lines[k]}, column {table.col[i] + 1} ({table.raw[i]!r}): "
                             f"{float(col[k])!r} rad is beyond ±2π: these look like degrees; if they are, {how}")
    q = np.where(np.asarray(degrees)[None, :], np.deg2rad(q), q)
    if np.any(np.abs(q) > _RAD_LIMIT):  # (degrees beyond a full turn: radian columns are refused above)
        k, j = np.unravel_index(int(np.argmax(np.abs(q) > _RAD_LIMIT)), q.shape)
        raise ValueError(f"{path}: line {table.lines[k]}, column {table.col[sel[j]] + 1} ({table.raw[sel[j]]!r}): "
                         f"{np.rad2deg(q[k, j]):.6g}° is beyond a full turn (±360°), no joint angle")
    names = tuple(table.labels[i] for i in sel)
    if _chain_names_match(path, table, wanted):
        names = tuple(wanted.joint_names)
    filled = _fill_gaps(path, table, t, q, sel, max_gap)
    ignored = tuple(table.raw[i] for i in range(len(table.labels)) if i not in sel)
    return JointRecording(subject, name, t, q, names, ignored_columns=ignored, filled_gaps=filled,
                          source=os.fspath(path))


def _check_time(path, table, t, sample_tol):
    step = np.diff(t)
    at = lambda k: f"{path}: line {table.lines[k]}, column {table.time_col + 1} ('time')"  # noqa: E731
    if np.any(step <= 0):
        k = int(np.argmax(step <= 0)) + 1
        raise ValueError(f"{at(k)}: time not strictly increasing ({float(t[k - 1])!r} then {float(t[k])!r})")
    med = float(np.median(step))
    if med > _MAX_STEP:
        raise ValueError(f"{at(1)}: median sample interval {med:.4g} s: time must be in seconds "
                         "(milliseconds? frame numbers?)")
    off = np.abs(step - med) > sample_tol * med
    if off.any():
        k = int(np.argmax(off)) + 1
        raise ValueError(f"{at(k)}: uneven sampling: interval {step[k - 1]:.6g} s ({float(t[k - 1])!r} to "
                         f"{float(t[k])!r}) differs from the median {med:.6g} s by more than "
                         f"sample_tol = {sample_tol:g} (relative): dropped or repeated samples?")


def _fill_gaps(path, table, t, q, sel, max_gap):
    """Fill runs of NaN in ``q`` (in place) by linear interpolation; returns the filled runs."""
    filled = []
    T = t.shape[0]
    for j, i in enumerate(sel):
        bad = np.isnan(q[:, j])
        if not bad.any():
            continue
        edges = np.diff(np.concatenate([[0], bad.astype(np.int8), [0]]))
        starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1
        where = f"{path}: column {table.col[i] + 1} ({table.raw[i]!r})"
        for s, e in zip(starts, ends):
            span = f"t = {float(t[s])!r} to {float(t[e])!r} s (lines {table.lines[s]}-{table.lines[e]})"
            if s == 0 or e == T - 1:
                end = "start" if s == 0 else "end"
                raise ValueError(f"{where}: missing values (NaN) from {span} at the {end} of the recording: "
                                 "nothing to interpolate from; trim the recording")
            bridge = t[e + 1] - t[s - 1]
            if bridge > max_gap * (1 + 1e-9):
                raise ValueError(f"{where}: missing values (NaN) from {span}: the gap between valid samples, "
                                 f"{bridge:.4g} s, is longer than max_gap = {max_gap:g} s")
            filled.append((table.labels[i], float(t[s]), float(t[e])))
        good = ~bad
        q[bad, j] = np.interp(t[bad], t[good], q[good, j])
    return tuple(filled)


def _read_hugmp(path: Path, subject, wanted, motion) -> JointRecording:
    from .hugmp import load_hugmp

    m = re.fullmatch(r"(S\d\d)_trajs\.mat", path.name)
    if m is None:
        raise ValueError(f"{path}: a .mat file is read as a HuG-MP subject file, named S<nn>_trajs.mat "
                         f"(e.g. S01_trajs.mat); got {path.name!r}")
    data = load_hugmp(m.group(1), directory=path.parent)
    count = sum(len(v) for v in data.motions.values())
    if motion is None:
        raise ValueError(f"{path}: a HuG-MP file holds {count} separate motions; pick one with "
                         "motion=(task, repetition, index), e.g. motion=(1, 1, 1)")
    try:
        task, rep, idx = (int(v) for v in motion)
        if any(int(a) != a for a in motion):
            raise ValueError
    except (TypeError, ValueError):
        raise TypeError(f"`motion` must be (task, repetition, index), three integers, got {motion!r}") from None
    hit = [q for r, i, q in data.motions.get(task, []) if (r, i) == (rep, idx)]
    if not hit:
        why = [reason for r, tk, reason in data.skipped if (r, tk) == (rep, task)]
        reasons = f" (skipped by the loader: {'; '.join(why)})" if why else ""
        have = sorted({(tk, r, i) for tk, v in data.motions.items() for r, i, _ in v})
        raise ValueError(f"{path}: no motion (task {task}, repetition {rep}, index {idx}){reasons}; "
                         f"tasks 1-6, {len(have)} motions, e.g. {have[:3]}")
    q = hit[0]
    names = [f"q{k + 1}" for k in range(q.shape[1])]
    table = _Table(names, names, list(range(1, q.shape[1] + 1)), [False] * q.shape[1], [],
                   np.arange(1, q.shape[0] + 1), 0, 0, set(), {})
    sel = _select(path, table, wanted)
    out = tuple(names[i] for i in sel)
    if _chain_names_match(path, table, wanted):
        out = tuple(wanted.joint_names)
    t = np.arange(q.shape[0]) / data.fs
    return JointRecording(subject or data.subject, f"{data.subject}_task{task}_rep{rep}_motion{idx}", t,
                          q[:, sel], out, fs=data.fs,
                          ignored_columns=tuple(names[i] for i in range(len(names)) if i not in sel),
                          source=os.fspath(path))


# ---------------------------------------------------------------------------------------------
# writing


def write_joint_angles(path, recording: JointRecording, *, in_degrees: bool = True) -> Path:
    """Write a joint-angle recording as ``.mot``, ``.sto`` (OpenSim, version-1 header, tab
    separated) or ``.csv`` (``# units: deg|rad`` line, then ``time,<joint>,...``).

    Numbers are written with 17 significant digits, so :func:`read_joint_angles` reads back the
    same radians (to rounding of the degree conversion). To write arrays, build the recording:
    ``JointRecording(subject, name, t (T,) [s], q (T, n) [rad], joint_names)``.

    **Arguments:**

    - ``path``: the file; its extension picks the format.
    - ``recording``: the :class:`JointRecording`.
    - ``in_degrees``: write angles in degrees (``inDegrees=yes``; OpenSim's convention) or radians.

    **Returns:**

    The path written (``pathlib.Path``).

    **Raises:**

    ``TypeError`` for a non-recording; ``ValueError`` for another extension or joint names that
    the format cannot hold.
    """
    path = as_path("path", path)
    if not isinstance(recording, JointRecording):
        raise TypeError(f"`recording` must be a pmpjax.JointRecording, got {type(recording).__name__}")
    if not isinstance(in_degrees, bool | np.bool_):
        raise TypeError(f"`in_degrees` must be True or False, got {in_degrees!r}")
    ext = path.suffix.lower()
    if ext not in (".mot", ".sto", ".csv"):
        raise ValueError(f"`path` must end in .mot, .sto or .csv, got {os.fspath(path)!r}")
    names = recording.joint_names
    q = np.rad2deg(recording.q) if in_degrees else recording.q
    num = np.column_stack([recording.t, q])
    body = "\n".join(" ".join(f"{v:.17g}" for v in row) for row in num)
    if ext == ".csv":
        bad = [s for s in names if _CSV_TIME.match(s) or _CSV_UNIT.match(s)]
        if bad:
            raise ValueError(f"`recording`: joint name(s) {bad} would read as the time column or a unit suffix "
                             "in a CSV header")
        buf = io.StringIO()
        csv.writer(buf, lineterminator="\n").writerow(["time", *names])
        text = f"# units: {'deg' if in_degrees else 'rad'}\n{buf.getvalue()}{body.replace(' ', ',')}\n"
    else:
        bad = [s for s in names if not s or any(c.isspace() for c in s)]
        if bad:
            raise ValueError(f"`recording`: OpenSim column labels cannot hold whitespace: {bad}")
        header = (f"{recording.name}\nversion=1\nnRows={num.shape[0]}\nnColumns={num.shape[1]}\n"
                  f"inDegrees={'yes' if in_degrees else 'no'}\nendheader\n")
        text = header + "\t".join(["time", *names]) + "\n" + body.replace(" ", "\t") + "\n"
    path.write_text(text, encoding="utf-8")
    return path
