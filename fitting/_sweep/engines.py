"""Where a sweep's chunks run: one compiled kernel over the local devices, or Dask tasks on a cluster.

The local kernel is ``jit(shard_map(vmap(fn)))`` over the local devices (rows split evenly; on a CPU
``XLA_FLAGS=--xla_force_host_platform_device_count=2`` gives two devices); with a Dask client each
chunk is one task on the cluster's workers. Chunks are dispatched two ahead, so the store writes a
finished chunk while the next ones compute (memory: at most three chunks of ``fn``'s intermediates).

**Stalled chunks**: a chunk whose computation has not finished while its process used almost no
CPU for :data:`STALL_SECONDS` raises ``RuntimeError`` (on a Dask worker: the task fails) instead
of waiting forever. XLA:CPU can deadlock that way with jax 0.10: its batched LAPACK kernels
(``eigh``, ``cholesky``, ``solve``, ``svd``, ... under ``vmap``, above roughly 200 000 flops
per call: 1 500 3×3 ``eigh``) split the batch over the intra-op thread pool and block their pool
thread until the pieces are done; when every pool thread does so at once (two such calls on a
2-core machine) nothing runs the pieces. The chunks finished before are in the store.
"""

from __future__ import annotations

import collections
import math
import threading
import time
import uuid
from typing import Any

import jax
import numpy as np

from pmpjax.internal import fast_compile_jit

#: Seconds a chunk may go unfinished while its process uses almost no CPU (below
#: :data:`IDLE_CPU_FRACTION` of one core) before it is reported as stalled.
STALL_SECONDS = 120.0
IDLE_CPU_FRACTION = 0.1  # an idle Dask worker (profiler, heartbeats) uses 3-4 %


def _wait_computed(leaves, chunk, stall_seconds=None):
    """Wait until the arrays ``leaves`` of a chunk (``chunk``: its name in the error) are computed;
    ``RuntimeError`` when the process stops computing for ``stall_seconds`` (default
    :data:`STALL_SECONDS`) before that.

    A helper thread blocks on the arrays (no polling delay); this one wakes up to look at the
    process's CPU time. Progress is CPU time, not wall time: on a loaded machine a slow chunk still
    uses CPU (its share), a deadlocked XLA:CPU none."""
    stall = STALL_SECONDS if stall_seconds is None else float(stall_seconds)
    leaves = list(leaves)
    if all(a.is_ready() for a in leaves if hasattr(a, "is_ready")):
        return leaves
    ready = threading.Event()

    def block():
        try:
            jax.block_until_ready(leaves)
        except Exception:  # noqa: BLE001 - device_get below raises it in the caller
            pass
        finally:
            ready.set()

    threading.Thread(target=block, name="pmpjax-sweep-wait", daemon=True).start()
    t0, cpu0 = time.monotonic(), time.process_time()
    while not ready.wait(min(1.0, stall / 4)):
        t, cpu = time.monotonic(), time.process_time()
        if t - t0 >= stall:
            if cpu - cpu0 < IDLE_CPU_FRACTION * (t - t0):
                raise RuntimeError(
                    f"{chunk} stalled: its computation has not finished and this process used "
                    f"{cpu - cpu0:.1f} s of CPU in the last {t - t0:.0f} s. XLA:CPU deadlocks this way with "
                    "jax 0.10 when batched LAPACK calls (eigh, cholesky, solve, svd, ... under vmap) occupy "
                    "every intra-op pool thread at once; this process (on Dask: its worker, `client.restart()`) "
                    "cannot run XLA:CPU computations any more. Run the sweep again in a new process (with "
                    "`out`, the finished chunks are kept), with a smaller `chunk_size` (fewer rows per LAPACK "
                    "call), or avoid LAPACK in `fn`.")
            t0, cpu0 = t, cpu
    return leaves


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
                done(*self._fetch(*pending.popleft()))
        while pending:
            done(*self._fetch(*pending.popleft()))

    @staticmethod
    def _fetch(k, out):
        leaves = _wait_computed(jax.tree_util.tree_leaves(out), f"sweep chunk {k}")
        return k, [np.asarray(a) for a in jax.device_get(leaves)]


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
    leaves = _wait_computed(jax.tree_util.tree_leaves(kernel(args)), "this sweep chunk")
    return [np.asarray(a)[:rows] for a in jax.device_get(leaves)]


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
