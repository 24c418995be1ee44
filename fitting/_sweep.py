"""Parameter sweeps at scale: chunked, resumable, on every local device, or on a Dask cluster.

``sweep(fn, params, chunk_size=...)`` evaluates ``jax.vmap(fn)(params)`` chunk by chunk: each
chunk of ``chunk_size`` parameter rows is one call of one compiled kernel (the last chunk is
padded by repeating its last row, so every call has the same shape and there is exactly one
compilation); the kernel is ``jit(shard_map(vmap(fn)))`` over the local devices (rows split
evenly; on a CPU ``XLA_FLAGS=--xla_force_host_platform_device_count=2`` gives two devices), or,
with ``client=``, one Dask task per chunk on the cluster's workers. Chunks are dispatched two
ahead, so the store writes a finished chunk while the next ones compute (memory: at most three
chunks of ``fn``'s intermediates at once).

**Store** (``out=``), a directory::

    manifest.json                 format, fingerprint of the sweep, rows, chunk size, output leaves
    chunks/000017-<blake2b>.npz   chunk 17: its rows of every output leaf (o0, o1, ...)

The fingerprint is the sweep's identity: ``fn``'s name and source (or bytecode) hash, the hash of
its traced computation (jaxpr text and closed-over constants, so a changed captured constant is a
different sweep), the hash of the parameter table, the row count, the chunk size and the output
structure (tree, dtypes, trailing shapes). A store whose fingerprint differs is refused before any
work. Each shard is written atomically (temporary file, ``fsync``, ``os.replace``, ``fsync`` of
the directory), and its name carries the BLAKE2b checksum of its bytes, so a shard is either
absent or whole and self-verifying: on restart every shard is re-hashed and its arrays checked
against the manifest (leaf count, dtypes, shapes, rows); a truncated, corrupted or misnamed
shard is deleted and its chunk recomputed, and verified chunks are read, never rewritten.

**Why NPZ shards** (``python benchmarks/sweep.py --stores``): NPZ and Zarr write and read 10⁶
rows in seconds, Parquet 3–7× slower to write, all far below the minutes of compute the chunks
hold; NPZ wins on what is left: no dependency, and a chunk is one file, so one atomic rename makes
it durable and its checksummed name makes it self-verifying (Zarr writes each array's chunk in
place and would need checksum records of its own; Parquet needs list columns for shaped leaves).

**Failures**: a row whose outputs hold NaN/inf, or whose ``status`` leaf (an integer leaf named
``status``, codes of :class:`pmpjax.Status`) is non-zero, is marked ``failed`` with the reason;
the other rows are unaffected (each row is computed independently by ``vmap``).
"""

from __future__ import annotations

import collections
import csv
import dataclasses
import hashlib
import inspect
import io
import json
import math
import os
import re
import uuid
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import jax
import jax.extend.core
import numpy as np

from pmpjax import Status
from pmpjax.internal import check_positive_int, fast_compile_jit

FORMAT = "pmpjax sweep v1"
_SHARD = re.compile(r"^(\d{6,})-([0-9a-f]{32})\.npz$")
_TRACER_ERRORS = (
    jax.errors.ConcretizationTypeError,
    jax.errors.TracerArrayConversionError,
    jax.errors.TracerBoolConversionError,
    jax.errors.TracerIntegerConversionError,
    jax.errors.UnexpectedTracerError,
)


# --- result ---------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class SweepResult:
    """Outputs of a sweep over N parameter rows, in parameter-row order.

    ``outputs``: the pytree ``jax.vmap(fn)(params)`` returns, as NumPy arrays (N, ...);
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
        """Why ``row`` failed ('' when it did not)."""
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
        """One row per parameter set: parameter columns, output columns (trailing axes flattened
        as ``name[i]``/``name[i,j]``), ``failed`` and ``reason``. A dict of (N,) NumPy columns, or
        a ``pandas.DataFrame`` with ``pandas=True`` (needs the optional pandas extra)."""
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


# --- inputs ---------------------------------------------------------------------------------


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


def _source_hash(fn) -> str:
    """Hash of ``fn``'s source, else of its bytecode (functions made in notebooks/exec)."""
    h = hashlib.sha256()
    seen = set()

    def add(f):
        if id(f) in seen:
            return
        seen.add(id(f))
        if hasattr(f, "func") and hasattr(f, "args"):  # functools.partial
            add(f.func)
            h.update(repr((f.args, sorted(f.keywords.items()))).encode())
            return
        try:
            h.update(inspect.getsource(f).encode())
            return
        except (OSError, TypeError):
            pass
        code = getattr(f, "__code__", None) or getattr(getattr(f, "__call__", None), "__code__", None)
        if code is not None:
            h.update(code.co_code)
            h.update(repr(code.co_consts).encode())
            h.update(repr(code.co_names).encode())
        else:
            h.update(repr(type(f)).encode())

    add(fn)
    return h.hexdigest()


def _params_hash(numeric, labels) -> str:
    h = hashlib.sha256()
    for name in sorted({**numeric, **labels}):
        a = numeric[name] if name in numeric else labels[name]
        h.update(f"{name}|{a.dtype.str}|{a.shape}|".encode())
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


# --- store ----------------------------------------------------------------------------------


def _atomic_write(path: Path, data: bytes):
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    with open(tmp, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)
    fd = os.open(path.parent, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


class _Store:
    def __init__(self, out, manifest: dict):
        self.root = Path(out)
        self.chunks = self.root / "chunks"
        self.manifest = manifest
        self.leaves = [(np.dtype(d), tuple(s)) for _, d, s in manifest["outputs"]]

    @classmethod
    def open(cls, out, manifest: dict) -> _Store:
        """Open or create the store at ``out``; refuse one that holds another sweep."""
        root = Path(out)
        if root.exists() and not root.is_dir():
            raise ValueError(f"`out`={str(out)!r} is a file, not a sweep store directory")
        mpath = root / "manifest.json"
        if mpath.exists():
            try:
                old = json.loads(mpath.read_text())
            except (OSError, ValueError) as e:
                raise ValueError(f"`out`={str(out)!r}: manifest.json is unreadable ({e}); delete the store") from e
            if old.get("format") != FORMAT:
                raise ValueError(f"`out`={str(out)!r} is not a {FORMAT!r} store (format {old.get('format')!r})")
            theirs = old.get("fingerprint", {})
            diff = [k for k, v in manifest["fingerprint"].items() if theirs.get(k) != v]
            if diff:
                raise ValueError(
                    f"`out`={str(out)!r} holds another sweep's store (it differs in: {', '.join(diff)}); "
                    "pass a new `out` or delete that directory to start over"
                )
            return cls(root, old)
        if root.exists() and any(root.iterdir()):
            raise ValueError(
                f"`out`={str(out)!r} is a non-empty directory without a sweep manifest; pass a new or empty directory"
            )
        (root / "chunks").mkdir(parents=True, exist_ok=True)
        _atomic_write(mpath, json.dumps(manifest, indent=1).encode())
        return cls(root, manifest)

    def rows(self, k) -> int:
        n, c = self.manifest["n_rows"], self.manifest["chunk_size"]
        return min(c, n - k * c)

    def scan(self) -> dict[int, Path]:
        """Verified shards ``{chunk: path}``; temporary and invalid files are deleted."""
        good: dict[int, Path] = {}
        self.chunks.mkdir(parents=True, exist_ok=True)
        for p in sorted(self.chunks.iterdir()):
            m = _SHARD.match(p.name)
            k = int(m.group(1)) if m else -1
            if m and k < self.manifest["n_chunks"] and k not in good and self._verify(p, k, m.group(2)) is not None:
                good[k] = p
            else:
                p.unlink(missing_ok=True)
        return good

    def _verify(self, path: Path, k: int, digest: str):
        try:
            data = path.read_bytes()
            if hashlib.blake2b(data, digest_size=16).hexdigest() != digest:
                return None
            arrays = self._decode(data)
        except (OSError, ValueError, KeyError, EOFError, __import__("zipfile").BadZipFile):
            return None
        rows = self.rows(k)
        for a, (dt, shape) in zip(arrays, self.leaves):
            if a.dtype != dt or a.shape != (rows,) + shape:
                return None
        return arrays

    def _decode(self, data: bytes) -> list[np.ndarray]:
        with np.load(io.BytesIO(data), allow_pickle=False) as z:
            if sorted(z.files) != sorted(f"o{i}" for i in range(len(self.leaves))):
                raise ValueError("leaf names")
            return [z[f"o{i}"] for i in range(len(self.leaves))]

    def read(self, k: int, path: Path) -> list[np.ndarray]:
        return self._decode(path.read_bytes())

    def write(self, k: int, arrays: list[np.ndarray]):
        buf = io.BytesIO()
        np.savez(buf, **{f"o{i}": a for i, a in enumerate(arrays)})
        data = buf.getvalue()
        _atomic_write(self.chunks / f"{k:06d}-{hashlib.blake2b(data, digest_size=16).hexdigest()}.npz", data)


# --- engines --------------------------------------------------------------------------------


class _LocalEngine:
    """One compiled ``jit(shard_map(vmap(fn)))`` over the local devices; chunks dispatched ahead.

    Kernels are kept per (computation, devices, chunk length), so sweeps of the same ``fn`` with
    other parameters (or a restart in the same process) reuse the compilation."""

    _kernels: collections.OrderedDict = collections.OrderedDict()
    #: chunks dispatched beyond the one being stored (XLA's CPU client may run them concurrently)
    ahead = 2

    def __init__(self, fn, devices, chunk_rows, kernel_key, traced=None):
        """``traced``: ``vmap(fn)`` replayed from its jaxpr at ``chunk_rows`` rows (one device)."""
        from jax.sharding import Mesh, NamedSharding, PartitionSpec

        d = len(devices)
        self.length = math.ceil(chunk_rows / d) * d  # compiled rows per call (a multiple of the devices)
        if d == 1:
            self.sharding = jax.sharding.SingleDeviceSharding(devices[0])
        else:
            mesh = Mesh(np.asarray(devices), ("rows",))
            self.sharding = NamedSharding(mesh, PartitionSpec("rows"))
        key = (kernel_key, tuple(devices), self.length)
        self.kernel = self._kernels.pop(key, None)
        if self.kernel is None:
            if d == 1:
                self.kernel = fast_compile_jit(traced if traced is not None else jax.vmap(fn))
            else:
                spec = PartitionSpec("rows")
                self.kernel = fast_compile_jit(jax.shard_map(jax.vmap(fn), mesh=mesh, in_specs=spec, out_specs=spec,
                                                    check_vma=False))
        self._kernels[key] = self.kernel
        while len(self._kernels) > 8:
            self._kernels.popitem(last=False)

    def run(self, todo, chunk_params, done):
        pending = collections.deque()
        for k in todo:
            args = jax.device_put(chunk_params(k, self.length), self.sharding)
            pending.append((k, self.kernel(args)))  # asynchronous: runs while earlier chunks are stored
            if len(pending) > self.ahead:
                k0, o = pending.popleft()
                done(k0, [np.asarray(a) for a in jax.device_get(jax.tree_util.tree_leaves(o))])
        while pending:
            k0, o = pending.popleft()
            done(k0, [np.asarray(a) for a in jax.device_get(jax.tree_util.tree_leaves(o))])


_WORKER_KERNELS: dict[str, Any] = {}


def _dask_chunk(fn, key: str, x64: bool, args: dict, rows: int) -> list[np.ndarray]:
    """A Dask task: one chunk through ``jit(vmap(fn))``, compiled once per worker and computation."""
    if bool(jax.config.jax_enable_x64) != x64:
        jax.config.update("jax_enable_x64", x64)
    kernel = _WORKER_KERNELS.get(key)
    if kernel is None:
        if len(_WORKER_KERNELS) >= 8:
            _WORKER_KERNELS.pop(next(iter(_WORKER_KERNELS)))
        kernel = _WORKER_KERNELS[key] = fast_compile_jit(jax.vmap(fn))
    return [np.asarray(a)[:rows] for a in jax.device_get(jax.tree_util.tree_leaves(kernel(args)))]


class _DaskEngine:
    """The same chunks as Dask tasks (``client.submit``), at most two per worker thread in flight."""

    def __init__(self, fn, client, chunk_rows, key):
        self.fn, self.client, self.length, self.key = fn, client, chunk_rows, key
        self.x64 = bool(jax.config.jax_enable_x64)

    def run(self, todo, chunk_params, done):
        from distributed import as_completed

        limit = max(2, 2 * sum(self.client.nthreads().values()))
        todo = list(todo)
        nxt = 0

        def submit(k):
            return self.client.submit(_dask_chunk, self.fn, self.key, self.x64, chunk_params(k, self.length),
                                      self.length, key=f"pmpjax-sweep-{self.key[:12]}-{k}-{uuid.uuid4().hex[:8]}")

        futures = {}
        ac = as_completed()
        while nxt < len(todo) and len(futures) < limit:
            f = submit(todo[nxt])
            futures[f.key] = todo[nxt]
            ac.add(f)
            nxt += 1
        for f in ac:
            k = futures.pop(f.key)
            try:
                arrays = f.result()
            except Exception as e:
                for g in list(ac.futures):
                    g.cancel()
                raise RuntimeError(f"sweep chunk {k} failed on the Dask cluster: {e!r}") from e
            f.release()
            done(k, arrays)
            if nxt < len(todo):
                g = submit(todo[nxt])
                futures[g.key] = todo[nxt]
                ac.add(g)
                nxt += 1


# --- sweep ----------------------------------------------------------------------------------


def sweep(
    fn: Callable,
    params,
    *,
    chunk_size: int,
    out=None,
    devices=None,
    client=None,
    progress: bool = True,
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
    - ``progress``: show a progress bar (rich) of the rows done.

    Each chunk runs ``jit(vmap(fn))`` compiled with ``pmpjax.internal.FAST_COMPILE`` (XLA:CPU's
    legacy loop emitters: rows that fit or simulate compile 15–55 % faster, pmpjax/_base/compile.py).

    Returns a :class:`SweepResult`. **Raises** (before any work): ``TypeError``/``ValueError`` for
    a non-callable or non-jit-able ``fn``, params of unequal lengths, NaN/inf or non-numeric
    params, a bad ``chunk_size``/``devices``/``client``, or an ``out`` that holds another sweep's
    store or unrelated files.
    """
    if not callable(fn):
        raise TypeError(f"`fn` must be callable, got {type(fn).__name__}")
    numeric, labels, n = _check_params(params)
    check_positive_int("chunk_size", chunk_size)
    if not isinstance(progress, bool):
        raise TypeError(f"`progress` must be True or False, got {progress!r}")
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
                   disable=not progress, transient=False, console=Console(stderr=True))
    task = bar.add_task("sweep", total=n, completed=sum(min(chunk_rows, n - k * chunk_rows) for k in reused))
    bar.start()

    def done(k, arrays):
        rows = min(chunk_rows, n - k * chunk_rows)
        arrays = [np.ascontiguousarray(a[:rows]) for a in arrays]
        if store is not None:
            store.write(k, arrays)
        for r, a in zip(results, arrays):
            r[k * chunk_rows: k * chunk_rows + rows] = a
        bar.advance(task, rows)

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


# --- parameter tables -----------------------------------------------------------------------


def grid(**axes) -> dict[str, np.ndarray]:
    """Full factorial grid: ``grid(a=[1, 2], b=[10, 20, 30])`` -> ``{a: (6,), b: (6,)}``, rows in
    C order (the first axis varies slowest), so outputs reshape to ``(len(a), len(b), ...)``."""
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
    """``n`` Latin-hypercube samples (``scipy.stats.qmc.LatinHypercube``, seeded) of the box
    ``bounds = {name: (low, high)}``: every axis split into n equal strata, one sample in each."""
    from scipy.stats import qmc

    names, lo, hi = _check_bounds(bounds)
    check_positive_int("n", n)
    u = qmc.LatinHypercube(d=len(names), rng=np.random.default_rng(seed)).random(int(n))
    x = qmc.scale(u, lo, hi)
    return {name: x[:, i] for i, name in enumerate(names)}


def sobol(bounds, n: int, *, seed: int = 0, scramble: bool = True) -> dict[str, np.ndarray]:
    """``n`` Sobol' points (``scipy.stats.qmc.Sobol``, scrambled and seeded) in the box
    ``bounds = {name: (low, high)}``. ``n`` must be a power of two (the sequence's balance
    properties hold only for those)."""
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
    row per subject. Every column is numeric (float64) except those named in ``labels`` (kept
    as str, e.g. ``labels=("subject",)``, and not passed to ``fn``).

    **Raises** ``ValueError`` naming the file, line and column for a missing/duplicate header,
    a row of the wrong length, an empty or non-numeric field, NaN/inf, or no data rows.
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
