"""The on-disk store of a sweep (manifest and checksummed NPZ shards) and the hashes behind its fingerprint.

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
"""

from __future__ import annotations

import hashlib
import inspect
import io
import json
import os
import re
from pathlib import Path

import numpy as np

from pmpjax.internal import output_dir

FORMAT = "pmpjax sweep v1"
_SHARD = re.compile(r"^(\d{6,})-([0-9a-f]{32})\.npz$")


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
        output_dir("out", root)  # (created and writable: a store that cannot be written fails before any work)
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
