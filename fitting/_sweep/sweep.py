"""Parameter sweeps at scale: chunked, resumable, on every local device, or on a Dask cluster.

``sweep(fn, params, chunk_size=...)`` evaluates ``jax.vmap(fn)(params)`` chunk by chunk: each
chunk of ``chunk_size`` parameter rows is one call of one compiled kernel (the last chunk is
padded by repeating its last row, so every call has the same shape and there is exactly one
compilation), run on the local devices or on a Dask cluster (``engines``) and kept, resumably,
in a directory (``store``).

**Failures**: a row whose outputs hold NaN/inf, or whose ``status`` leaf (an integer leaf named
``status``, codes of :class:`pmpjax.Status`) is non-zero, is marked ``failed`` with the reason;
the other rows are unaffected (each row is computed independently by ``vmap``).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
import re
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import jax
import jax.extend.core
import numpy as np

from pmpjax import Status
from pmpjax.internal import check_positive_int

from .engines import _DaskEngine, _LocalEngine
from .store import FORMAT, _params_hash, _source_hash, _Store

_TRACER_ERRORS = (
    jax.errors.ConcretizationTypeError,
    jax.errors.TracerArrayConversionError,
    jax.errors.TracerBoolConversionError,
    jax.errors.TracerIntegerConversionError,
    jax.errors.UnexpectedTracerError,
)


@dataclasses.dataclass(frozen=True)
class SweepResult:
    """Outputs of a sweep over N parameter rows, in parameter-row order.

    ``outputs``: the pytree ``jax.vmap(fn)(params)`` returns, as NumPy arrays (N, ...), and
    ``leaf_names`` the names of its leaves;
    ``params``: ``{name: (N, ...)}`` the parameter table (label columns included); ``status``
    (N,) int, a :class:`pmpjax.Status` code per row (0 ok; ``NONFINITE`` for NaN/inf outputs;
    otherwise the first non-zero code of the ``status`` output leaf); ``failed`` (N,) bool;
    ``reasons`` (N,) str ('' for rows that did not fail); ``out``: the store directory or None;
    ``chunks_computed`` / ``chunks_reused``: chunks run now / read back verified from ``out``.
    """

    outputs: Any
    params: dict[str, np.ndarray]
    status: np.ndarray
    out: Path | None
    chunks_computed: int
    chunks_reused: int
    leaf_names: tuple[str, ...]
    _nonfinite: np.ndarray = dataclasses.field(repr=False)  # (N, L) bool: leaf has NaN/inf in row
    _status_counts: np.ndarray = dataclasses.field(repr=False)  # (N, 2) failing / total status entries

    @property
    def failed(self) -> np.ndarray:
        return self.status != 0

    @property
    def n_failed(self) -> int:
        return int(np.count_nonzero(self.status))

    @property
    def reasons(self) -> np.ndarray:
        """(N,) str: why each row failed ('' when it did not)."""
        out = np.full(self.status.shape, "", dtype=object)
        for i in np.flatnonzero(self.status):
            out[i] = self.reason(int(i))
        return out

    def reason(self, row: int) -> str:
        """Why a row failed.

        **Arguments:**

        - ``row``: the row index.

        **Returns:**

        The reason ('' when it did not fail).
        """
        code = int(self.status[row])
        if code == 0:
            return ""
        parts = []
        bad, total = self._status_counts[row]
        if bad:
            name = Status(code).name if code in Status._value2member_map_ else str(code)
            msg = Status(code).message if code in Status._value2member_map_ else "unknown status code"
            parts.append(f"status {name} ({msg}) in {bad} of {total} entries")
        leaves = [n for n, b in zip(self.leaf_names, self._nonfinite[row]) if b]
        if leaves:
            parts.append("non-finite values (NaN or inf) in output " + ", ".join(leaves))
        return "; ".join(parts)

    def table(self, *, pandas: bool = False):
        """One row per parameter set: parameter columns, output columns (trailing axes flattened as
        ``name[i]``/``name[i,j]``), ``failed`` and ``reason``.

        **Arguments:**

        - ``pandas``: return a ``pandas.DataFrame`` (needs the optional pandas extra).

        **Returns:**

        A dict of (N,) NumPy columns, or the DataFrame.

        **Raises:**

        - ``ImportError`` with ``pandas=True`` when pandas is not installed.
        """
        cols: dict[str, np.ndarray] = {}
        for name, a in self.params.items():
            cols.update(_columns(name, np.asarray(a)))
        for name, a in zip(self.leaf_names, jax.tree_util.tree_leaves(self.outputs)):
            for col, v in _columns(name, np.asarray(a)).items():
                cols[col if col not in cols else f"{col} (output)"] = v
        cols["failed"] = self.failed
        cols["reason"] = self.reasons
        if not pandas:
            return cols
        try:
            import pandas as pd
        except ImportError as e:  # pragma: no cover - depends on the environment
            raise ImportError("SweepResult.table(pandas=True) needs pandas: pip install 'pmpjax[pandas]'") from e
        return pd.DataFrame(cols)


def _columns(name, a):
    if a.ndim == 1:
        return {name: a}
    flat = a.reshape(a.shape[0], -1)
    idx = np.ndindex(*a.shape[1:])
    return {f"{name}[{','.join(map(str, i))}]": flat[:, k] for k, i in enumerate(idx)}


def _check_params(params) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray], int]:
    """Split ``params`` into numeric columns (passed to ``fn``) and string label columns."""
    if not isinstance(params, Mapping) or not params:
        raise TypeError(
            "`params` must be a non-empty dict {name: (N, ...) array} (see fitting.grid, "
            f"fitting.latin_hypercube, fitting.sobol, fitting.params_from_csv), got {type(params).__name__}"
        )
    numeric, labels, lengths = {}, {}, {}
    for name, v in params.items():
        if not isinstance(name, str):
            raise TypeError(f"`params` keys must be str, got {name!r}")
        a = np.asarray(v)
        if a.ndim == 0:
            raise ValueError(f"`params[{name!r}]` must have a leading row axis, got a scalar")
        lengths[name] = a.shape[0]
        if a.dtype.kind in "US" or (a.dtype.kind == "O" and all(isinstance(x, str) for x in a.reshape(-1))):
            if a.ndim != 1:
                raise ValueError(f"label column `params[{name!r}]` must be 1-D, got shape {a.shape}")
            labels[name] = a.astype(str)
        elif a.dtype.kind in "biuf":
            if a.dtype.kind == "f" and not np.all(np.isfinite(a)):
                row = int(np.argwhere(~np.isfinite(a.reshape(a.shape[0], -1)))[0, 0])
                raise ValueError(f"`params[{name!r}]` contains NaN or inf (first at row {row})")
            numeric[name] = a
        else:
            raise TypeError(f"`params[{name!r}]` must be numeric or str, got dtype {a.dtype}")
    if len(set(lengths.values())) != 1:
        raise ValueError(f"`params` columns must all have the same number of rows, got {lengths}")
    n = next(iter(lengths.values()))
    if n == 0:
        raise ValueError("`params` has no rows")
    if not numeric:
        raise ValueError("`params` has no numeric column to pass to `fn`")
    return numeric, labels, n


def _resolve_devices(devices):
    local = jax.local_devices()
    if devices is None:
        return list(local)
    if isinstance(devices, int | np.integer) and not isinstance(devices, bool):
        if not 1 <= devices <= len(local):
            raise ValueError(f"`devices` must be between 1 and {len(local)} (local devices), got {devices}")
        return list(local[: int(devices)])
    if isinstance(devices, Sequence) and devices and all(isinstance(d, jax.Device) for d in devices):
        if len(set(devices)) != len(devices) or any(d not in local for d in devices):
            raise ValueError(f"`devices` must be distinct local devices ({local}), got {list(devices)}")
        return list(devices)
    raise TypeError(f"`devices` must be None, a device count or a list of jax devices, got {devices!r}")


def _trace(fn, numeric, rows):
    """Trace ``vmap(fn)`` on ``rows`` abstract rows (a chunk): output structure, the computation's
    identity and its closed jaxpr (the one-device kernel replays it instead of tracing ``fn`` again:
    a row that fits or simulates takes seconds to trace)."""
    spec = {k: jax.ShapeDtypeStruct((rows,) + v.shape[1:], v.dtype) for k, v in numeric.items()}
    try:
        closed, shapes = jax.make_jaxpr(jax.vmap(fn), return_shape=True)(spec)
    except _TRACER_ERRORS as e:
        raise TypeError(
            f"`fn` is not jit-able (it must be a pure JAX function of one parameter row): {type(e).__name__}: "
            f"{str(e).splitlines()[0]}"
        ) from e
    except KeyError as e:
        raise ValueError(
            f"`fn` raised KeyError({e.args[0]!r}) on a parameter row; the row holds the numeric columns "
            f"{sorted(numeric)} (string columns are labels and are not passed to `fn`)"
        ) from e
    leaves, treedef = jax.tree_util.tree_flatten_with_path(shapes)
    if not leaves:
        raise TypeError("`fn` must return a pytree of arrays; it returned no arrays")
    out = []
    for path, s in leaves:
        if not isinstance(s, jax.ShapeDtypeStruct):
            raise TypeError(f"`fn` must return a pytree of arrays, got {type(s).__name__} at {path}")
        out.append((_leaf_name(path), np.dtype(s.dtype).str, tuple(s.shape[1:])))
    h = hashlib.sha256(re.sub(r"0x[0-9a-f]+", "0x", str(closed)).encode())
    for c in closed.consts:
        a = np.asarray(c)
        h.update(f"{a.dtype.str}{a.shape}".encode())
        h.update(np.ascontiguousarray(a).tobytes())
    return jax.tree_util.tree_structure(shapes), out, h.hexdigest(), closed


def _replay(closed, treedef):
    """``vmap(fn)`` as its traced jaxpr: ``{name: (rows, ...)} -> outputs``."""
    flat = jax.extend.core.jaxpr_as_fun(closed)
    return lambda args: jax.tree_util.tree_unflatten(treedef, flat(*jax.tree_util.tree_leaves(args)))


def _leaf_name(path) -> str:
    if not path:
        return "output"
    return jax.tree_util.keystr(path, simple=True, separator=".")


def sweep(
    fn: Callable,
    params,
    *,
    chunk_size: int,
    out=None,
    devices=None,
    client=None,
    progress=True,
) -> SweepResult:
    """Evaluate ``fn`` on every parameter row, in chunks, resumably; equals ``jax.vmap(fn)(params)``.

    **Arguments:**

    - ``fn``: a jit-able function of one parameter row (``{name: array}``, the numeric columns of
      ``params`` without their row axis) returning a pytree of arrays. An integer leaf named
      ``status`` holds :class:`pmpjax.Status` codes (non-zero marks the row failed).
    - ``params``: ``{name: (N, ...) array}``, one row per parameter set (``fitting.grid``,
      ``fitting.latin_hypercube``, ``fitting.sobol``, ``fitting.params_from_csv`` make them).
      String columns are labels: kept in ``params``/``table()``, not passed to ``fn``.
    - ``chunk_size``: rows per compiled call (memory: one chunk of ``fn``'s intermediates); the
      last chunk is padded, so every chunk reuses the one compilation.
    - ``out``: a directory for the resumable store (module docstring); ``None`` keeps everything
      in memory. Restarting with the same ``out`` reads the verified chunks and computes the rest.
    - ``devices``: local devices (``None`` = all, an int = the first k, or a list); each chunk's
      rows are split across them.
    - ``client``: a ``dask.distributed.Client``: run the chunks as Dask tasks on its workers
      (``fn`` must pickle with cloudpickle; pip install 'pmpjax[dask]'). Excludes ``devices``.
    - ``progress``: show a progress bar (rich) of the rows done; or a function ``progress(done,
      total)`` called with the rows done of all rows after each chunk (and once before the first).

    Each chunk runs ``jit(vmap(fn))`` compiled with ``pmpjax.internal.FAST_COMPILE`` (XLA:CPU's
    legacy loop emitters: rows that fit or simulate compile 15–55 % faster, pmpjax/_base/compile.py).

    **Returns:**

    A :class:`SweepResult`.

    **Raises:**

    Before any work: ``TypeError``/``ValueError`` for
    a non-callable or non-jit-able ``fn``, params of unequal lengths, NaN/inf or non-numeric
    params, a bad ``chunk_size``/``devices``/``client``, or an ``out`` that holds another sweep's
    store or unrelated files.
    """
    if not callable(fn):
        raise TypeError(f"`fn` must be callable, got {type(fn).__name__}")
    numeric, labels, n = _check_params(params)
    check_positive_int("chunk_size", chunk_size)
    if not isinstance(progress, bool) and not callable(progress):
        raise TypeError(f"`progress` must be True, False or a function progress(done, total), got {progress!r}")
    if client is not None:
        if devices is not None:
            raise ValueError("pass either `devices` (local run) or `client` (Dask), not both")
        try:
            from distributed import Client
        except ImportError as e:  # pragma: no cover - depends on the environment
            raise ImportError("`client=` needs dask.distributed: pip install 'pmpjax[dask]'") from e
        if not isinstance(client, Client):
            raise TypeError(f"`client` must be a dask.distributed.Client, got {type(client).__name__}")
    else:
        devs = _resolve_devices(devices)
    if out is not None and not isinstance(out, str | os.PathLike):
        raise TypeError(f"`out` must be a directory path or None, got {type(out).__name__}")
    chunk_rows = min(int(chunk_size), n)
    n_chunks = math.ceil(n / chunk_rows)

    # (traced at the chunk's length, which the fingerprint holds anyway, not at the device count's)
    treedef, leaves, computation, closed = _trace(fn, numeric, chunk_rows)
    fingerprint = {
        "fn": f"{getattr(fn, '__module__', '?')}.{getattr(fn, '__qualname__', type(fn).__name__)}",
        "fn_source": _source_hash(fn),
        "computation": computation,
        "params": _params_hash(numeric, labels),
        "n_rows": n,
        "chunk_size": chunk_rows,
        "outputs": [[name, dt, list(shape)] for name, dt, shape in leaves] + [str(treedef)],
    }
    manifest = {
        "format": FORMAT,
        "fingerprint": fingerprint,
        "n_rows": n,
        "chunk_size": chunk_rows,
        "n_chunks": n_chunks,
        "outputs": [[name, dt, list(shape)] for name, dt, shape in leaves],
        "params": {k: [v.dtype.str, list(v.shape[1:])] for k, v in {**numeric, **labels}.items()},
    }
    store = _Store.open(out, manifest) if out is not None else None
    ident = {k: fingerprint[k] for k in ("fn", "fn_source", "computation", "outputs")}
    kernel_key = hashlib.sha256(json.dumps(ident, sort_keys=True).encode()).hexdigest()

    results = [np.empty((n,) + shape, dtype=np.dtype(dt)) for _, dt, shape in leaves]
    reused = store.scan() if store is not None else {}
    for k, path in reused.items():
        for r, a in zip(results, store.read(k, path)):
            r[k * chunk_rows: k * chunk_rows + a.shape[0]] = a
    todo = [k for k in range(n_chunks) if k not in reused]

    def chunk_params(k, length):
        sl = slice(k * chunk_rows, min((k + 1) * chunk_rows, n))
        pad = length - (sl.stop - sl.start)
        return {name: np.concatenate([a[sl], np.repeat(a[sl.stop - 1: sl.stop], pad, 0)]) if pad else a[sl]
                for name, a in numeric.items()}

    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeElapsedColumn, TimeRemainingColumn

    bar = Progress("sweep rows", BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(), TimeRemainingColumn(),
                   disable=progress is not True, transient=False, console=Console(stderr=True))
    rows_done = [sum(min(chunk_rows, n - k * chunk_rows) for k in reused)]
    task = bar.add_task("sweep", total=n, completed=rows_done[0])
    report = progress if callable(progress) else None
    if report is not None:
        report(rows_done[0], n)
    bar.start()

    def done(k, arrays):
        rows = min(chunk_rows, n - k * chunk_rows)
        arrays = [np.ascontiguousarray(a[:rows]) for a in arrays]
        if store is not None:
            store.write(k, arrays)
        for r, a in zip(results, arrays):
            r[k * chunk_rows: k * chunk_rows + rows] = a
        bar.advance(task, rows)
        rows_done[0] += rows
        if report is not None:
            report(rows_done[0], n)

    try:
        if todo:
            engine = (_DaskEngine(fn, client, chunk_rows, kernel_key) if client is not None
                      else _LocalEngine(fn, devs, chunk_rows, kernel_key, _replay(closed, treedef)))
            engine.run(todo, chunk_params, done)
    finally:
        bar.stop()

    names = tuple(name for name, _, _ in leaves)
    status, nonfinite, counts = _failures(names, results)
    return SweepResult(
        outputs=jax.tree_util.tree_unflatten(treedef, results),
        params={**{k: np.asarray(v) for k, v in params.items()}},
        status=status,
        out=Path(out) if out is not None else None,
        chunks_computed=len(todo),
        chunks_reused=len(reused),
        leaf_names=names,
        _nonfinite=nonfinite,
        _status_counts=counts,
    )


def _failures(names, results):
    n = results[0].shape[0]
    nonfinite = np.zeros((n, len(names)), bool)
    status = np.zeros(n, np.int64)
    counts = np.zeros((n, 2), np.int64)
    for j, (name, a) in enumerate(zip(names, results)):
        flat = a.reshape(n, -1)
        if a.dtype.kind in "fc":
            nonfinite[:, j] = ~np.all(np.isfinite(flat), axis=1)
        elif name.split(".")[-1] == "status" and a.dtype.kind in "iu" and flat.shape[1]:
            bad = flat != 0
            first = flat[np.arange(n), np.argmax(bad, axis=1)]  # the first non-zero code of the row
            take = (status == 0) & bad.any(axis=1)  # the first failing status leaf names the reason
            status = np.where(take, first, status)
            counts[take] = np.stack([bad.sum(axis=1), np.full(n, flat.shape[1])], axis=1)[take]
    status = np.where((status == 0) & nonfinite.any(axis=1), int(Status.NONFINITE), status)
    return status, nonfinite, counts
