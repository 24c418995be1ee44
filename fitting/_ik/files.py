"""IK data files: the paper's ``.mat`` layout, NPZ and CSV, read into the arrays that
:func:`fitting.estimate_ik_weights` takes."""

from __future__ import annotations

import csv
import re
from pathlib import Path

import numpy as np

import pmpjax as pj
from pmpjax.internal import csv_floats, input_file, open_npz, read_text_file


def read_ik_file(path) -> dict:
    """Read IK data (the reader behind ``pmpjax ik-weights``): the paper's ``.mat`` layout, an NPZ
    with the arrays below, or a CSV (columns ``item``, ``qdot_1..n``, ``xdot_1..m``, ``J_r_c``
    row-major; one row per sample).

    **Arguments:**

    - ``path``: the file; its suffix (``.mat``, ``.npz``, ``.csv``) picks the format.

    **Returns:**

    ``{"qdot": (B, K, n) [rad/s], "xdot": (B, K, m), "J": (B, K, m, n), "mask": (B, K) bool,
    "labels": B item names}`` (a ``.mat`` file's items are participant × condition × target, trials
    pooled).

    **Raises:**

    ``ValueError`` naming the file (and line and column for CSV) for a missing file, an unknown
    suffix, missing arrays or columns, or malformed values.
    """
    path = input_file("path", path)
    suffix = path.suffix.lower()
    if suffix == ".mat":
        arr = pj.ik_dataset_arrays(pj.load_ik_dataset(path))
        lead = arr["qdot"].shape[:3]  # participants × conditions × targets; trials and samples pooled
        n, m = arr["qdot"].shape[-1], arr["xdot"].shape[-1]
        labels = [f"participant {a + 1} / {c} / target {t}" for a in range(lead[0])
                  for c in arr["conditions"] for t in arr["targets"]]
        return {"qdot": arr["qdot"].reshape(-1, np.prod(arr["qdot"].shape[3:5]), n),
                "xdot": arr["xdot"].reshape(-1, np.prod(arr["xdot"].shape[3:5]), m),
                "J": arr["J"].reshape(-1, np.prod(arr["J"].shape[3:5]), m, n),
                "mask": arr["mask"].reshape(-1, np.prod(arr["mask"].shape[3:5])), "labels": labels}
    if suffix == ".npz":
        with open_npz(path) as z:
            missing = [k for k in ("qdot", "xdot", "J") if k not in z.files]
            if missing:
                raise ValueError(f"{path}: missing array(s) {missing} (found {z.files})")
            qd, xd, J = (np.asarray(z[k], float) for k in ("qdot", "xdot", "J"))
            mask = np.asarray(z["mask"], bool) if "mask" in z.files else np.ones(qd.shape[:-1], bool)
        if qd.ndim == 2:
            qd, xd, J, mask = qd[None], xd[None], J[None], mask[None]
        return {"qdot": qd, "xdot": xd, "J": J, "mask": mask, "labels": [f"item {i}" for i in range(len(qd))]}
    if suffix == ".csv":
        return _read_ik_csv(path)
    raise ValueError(f"{path}: unknown format {suffix!r} (expected .mat, .npz or .csv)")


_IK_COLUMN = re.compile(r"(?:qdot|xdot)_(\d+)|J_(\d+)_(\d+)")


def _read_ik_csv(path: Path) -> dict:
    text = read_text_file(path)
    lines = [(i + 1, ln) for i, ln in enumerate(text.splitlines()) if ln.strip() and not ln.startswith("#")]
    if not lines:
        raise ValueError(f"{path}: empty file")
    header = [h.strip() for h in next(csv.reader([lines[0][1]]))]
    where = f"{path}: line {lines[0][0]}"
    # n joints and m task coordinates: the largest indices of the velocity and Jacobian columns
    index = {h: [int(g) for g in m.groups() if g] for h in header if (m := _IK_COLUMN.fullmatch(h))}
    unknown = [h for h in header if h != "item" and h not in index]
    n = max((i[-1] for h, i in index.items() if not h.startswith("xdot_")), default=0)
    m = max((i[0] for h, i in index.items() if not h.startswith("qdot_")), default=0)
    qcols, xcols = [f"qdot_{j + 1}" for j in range(n)], [f"xdot_{j + 1}" for j in range(m)]
    jcols = [f"J_{r + 1}_{c + 1}" for r in range(m) for c in range(n)]
    missing = [h for h in ["item", *qcols, *xcols, *jcols] if h not in header]
    if unknown:
        raise ValueError(f"{where}: unknown column(s) {', '.join(map(repr, unknown))}"
                         + (f" (missing: {', '.join(missing)})" if missing else "")
                         + "; the columns are item, qdot_1..n, xdot_1..m and J_r_c (r ≤ m, c ≤ n)")
    if not n or not m:
        raise ValueError(f"{where}: the header needs item, qdot_1..n, xdot_1..m and J_r_c columns; no "
                         + ("qdot_ or xdot_" if not n and not m else "qdot_" if not n else "xdot_") + " columns")
    if missing:
        raise ValueError(f"{where}: missing column(s) {', '.join(missing)} (qdot_1..{n}, xdot_1..{m} and every "
                         f"J_r_c of the {m}x{n} Jacobian)")
    extra = [h for h in header if h in index and h not in {*qcols, *xcols, *jcols}]
    if extra:
        raise ValueError(f"{where}: column(s) {', '.join(extra)} outside qdot_1..{n}, xdot_1..{m} and the {m}x{n} "
                         "Jacobian J_r_c")
    duplicated = sorted({h for h in header if header.count(h) > 1})
    if duplicated:
        raise ValueError(f"{where}: column(s) {', '.join(duplicated)} appear more than once")
    if len(lines) < 2:
        raise ValueError(f"{where}: no data rows after the header")
    idx = {h: header.index(h) for h in header}
    items: dict[str, list] = {}
    for lineno, ln in lines[1:]:
        cells = next(csv.reader([ln]))
        if len(cells) != len(header):
            raise ValueError(f"{path}: line {lineno}: {len(cells)} fields, header has {len(header)}")
        vals = csv_floats(path, lineno, cells, idx, (*qcols, *xcols, *jcols))
        items.setdefault(cells[idx["item"]], []).append(vals)
    K = max(len(v) for v in items.values())
    B = len(items)
    qd, xd, J = np.zeros((B, K, n)), np.zeros((B, K, m)), np.broadcast_to(np.eye(m, n), (B, K, m, n)).copy()
    mask = np.zeros((B, K), bool)
    for b, rows in enumerate(items.values()):
        a = np.asarray(rows)
        k = len(a)
        qd[b, :k], xd[b, :k], J[b, :k] = a[:, :n], a[:, n:n + m], a[:, n + m:].reshape(k, m, n)
        mask[b, :k] = True
    return {"qdot": qd, "xdot": xd, "J": J, "mask": mask, "labels": list(items)}
