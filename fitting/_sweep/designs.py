"""Parameter tables (designs) for sweeps: full grids, Latin hypercubes, Sobol' points, CSV files."""

from __future__ import annotations

import csv
import io
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from pmpjax.internal import check_positive_int


def grid(**axes) -> dict[str, np.ndarray]:
    """Full factorial grid of parameter values, one row per combination.

    ``grid(a=[1, 2], b=[10, 20, 30])`` -> ``{a: (6,), b: (6,)}``; rows in C order (the first axis
    varies slowest), so outputs reshape to ``(len(a), len(b), ...)``.

    **Arguments:**

    - ``axes``: ``name=values``, each a non-empty 1-D sequence of finite numbers.

    **Returns:**

    ``{name: (N,) array}`` with N the product of the axes' lengths.

    **Raises:**

    - ``ValueError`` naming the axis for no axes, an empty or non-1-D axis, or NaN/inf.
    """
    if not axes:
        raise ValueError("`grid` needs at least one axis, e.g. grid(ratio=[1, 2, 4])")
    vals = {}
    for name, v in axes.items():
        a = np.asarray(v)
        if a.ndim != 1 or a.size == 0:
            raise ValueError(f"grid axis `{name}` must be a non-empty 1-D sequence, got shape {a.shape}")
        if a.dtype.kind == "f" and not np.all(np.isfinite(a)):
            raise ValueError(f"grid axis `{name}` contains NaN or inf")
        vals[name] = a
    mesh = np.meshgrid(*vals.values(), indexing="ij")
    return {name: m.reshape(-1) for name, m in zip(vals, mesh)}


def _check_bounds(bounds) -> tuple[list[str], np.ndarray, np.ndarray]:
    if not isinstance(bounds, Mapping) or not bounds:
        raise TypeError(f"`bounds` must be a non-empty dict {{name: (low, high)}}, got {bounds!r}")
    lo, hi = [], []
    for name, b in bounds.items():
        try:
            low, high = (float(x) for x in b)
        except (TypeError, ValueError) as e:
            raise ValueError(f"`bounds[{name!r}]` must be a (low, high) pair of numbers, got {b!r}") from e
        if not (np.isfinite(low) and np.isfinite(high) and low < high):
            raise ValueError(f"`bounds[{name!r}]` must be finite with low < high, got {b!r}")
        lo.append(low)
        hi.append(high)
    return list(bounds), np.asarray(lo), np.asarray(hi)


def latin_hypercube(bounds, n: int, *, seed: int = 0) -> dict[str, np.ndarray]:
    """Latin-hypercube samples of a box (``scipy.stats.qmc.LatinHypercube``, seeded): every axis
    split into n equal strata, one sample in each.

    **Arguments:**

    - ``bounds``: ``{name: (low, high)}``, finite with ``low < high``.
    - ``n``: number of samples.
    - ``seed``: the seed.

    **Returns:**

    ``{name: (n,) array}``.

    **Raises:**

    - ``TypeError``/``ValueError`` naming the argument for bad bounds or a non-positive ``n``.
    """
    from scipy.stats import qmc

    names, lo, hi = _check_bounds(bounds)
    check_positive_int("n", n)
    u = qmc.LatinHypercube(d=len(names), rng=np.random.default_rng(seed)).random(int(n))
    x = qmc.scale(u, lo, hi)
    return {name: x[:, i] for i, name in enumerate(names)}


def sobol(bounds, n: int, *, seed: int = 0, scramble: bool = True) -> dict[str, np.ndarray]:
    """Sobol' points in a box (``scipy.stats.qmc.Sobol``, scrambled and seeded).

    **Arguments:**

    - ``bounds``: ``{name: (low, high)}``, finite with ``low < high``.
    - ``n``: number of points, a power of two (the sequence's balance properties hold only for those).
    - ``seed``: the seed of the scrambling.
    - ``scramble``: scramble the sequence.

    **Returns:**

    ``{name: (n,) array}``.

    **Raises:**

    - ``TypeError``/``ValueError`` naming the argument for bad bounds or an ``n`` that is not a
      positive power of two.
    """
    from scipy.stats import qmc

    names, lo, hi = _check_bounds(bounds)
    check_positive_int("n", n)
    if int(n) & (int(n) - 1):
        raise ValueError(f"`n` must be a power of two for Sobol' points, got {n} (e.g. {1 << int(n).bit_length()})")
    engine = qmc.Sobol(d=len(names), scramble=scramble, rng=np.random.default_rng(seed))
    u = engine.random_base2(int(n).bit_length() - 1)
    x = qmc.scale(u, lo, hi)
    return {name: x[:, i] for i, name in enumerate(names)}


def params_from_csv(path, *, labels: Sequence[str] = ()) -> dict[str, np.ndarray]:
    """A parameter table from a CSV file with a header line (``#`` lines are comments), e.g. one
    row per subject.

    **Arguments:**

    - ``path``: the CSV file.
    - ``labels``: columns kept as str (e.g. ``labels=("subject",)``), not passed to the swept
      function; every other column is numeric (float64).

    **Returns:**

    ``{column: (N,) array}``, one row per data line.

    **Raises:**

    - ``ValueError`` naming the file, line and column for a missing/duplicate header, a row of the
      wrong length, an empty or non-numeric field, NaN/inf, or no data rows.
    """
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as e:
        raise ValueError(f"{path}: cannot read the parameter table ({e})") from e
    rows = [(i + 1, r) for i, r in enumerate(csv.reader(io.StringIO(text)))
            if r and not r[0].lstrip().startswith("#") and any(f.strip() for f in r)]
    if not rows:
        raise ValueError(f"{path}: empty parameter table (need a header line and data rows)")
    hline, header = rows[0]
    header = [h.strip() for h in header]
    if any(not h for h in header) or len(set(header)) != len(header):
        raise ValueError(f"{path}, line {hline}: header must name every column once, got {header}")
    missing = [lab for lab in labels if lab not in header]
    if missing:
        raise ValueError(f"{path}, line {hline}: label column(s) {missing} not in the header {header}")
    if len(rows) == 1:
        raise ValueError(f"{path}: the parameter table has a header but no data rows")
    cols: dict[str, list] = {h: [] for h in header}
    for line, r in rows[1:]:
        if len(r) != len(header):
            raise ValueError(f"{path}, line {line}: {len(r)} fields, the header has {len(header)}")
        for j, (h, f) in enumerate(zip(header, r)):
            f = f.strip()
            if h in labels:
                cols[h].append(f)
                continue
            try:
                v = float(f)
            except ValueError:
                v = None
            if v is None or not np.isfinite(v):
                what = "empty field" if not f else f"{f!r} is not a finite number"
                raise ValueError(f"{path}, line {line}, column {j + 1} ({h!r}): {what}")
            cols[h].append(v)
    return {h: np.asarray(v, dtype=str if h in labels else float) for h, v in cols.items()}
