"""The main job's worker processes: spawned, each pinned to its share of the cores, ending with
the parent; their output goes to a log file per part, their log lines and progress bars to the
parent's display over a queue. Ctrl-C is the parent's to handle: it ends the workers."""

from __future__ import annotations

import contextlib
import os
import sys
import time
import traceback
from pathlib import Path

from .._base import json_safe
from .cache import enable_compilation_cache
from .parts import PartContext, as_part, portable, run_part

_WORKER: dict = {}


def _die_with_parent(parent: int) -> None:
    """End this spawned process when ``parent`` ends, however it ends (Linux: the kernel sends
    SIGTERM; elsewhere a no-op), so a killed command leaves no worker computing."""
    if not sys.platform.startswith("linux"):
        return
    import ctypes
    import signal

    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGTERM), 0, 0, 0)  # PR_SET_PDEATHSIG
    if os.getppid() != parent:  # the parent ended before prctl
        os._exit(1)


def _pin_to_share(slot: int, n_workers: int) -> None:
    """Restrict this worker to its share of the usable cores (the ``slot``-th of ``n_workers``
    disjoint shares; one core each when there are more workers than cores).

    XLA sizes its CPU thread pools by the cores a process may use, so unpinned workers each run
    as many threads as there are cores and the two workers of a 2-core run take turns on both
    (pinned, a cold ``--quick`` run took about 7 % less wall and CPU time). Linux only (elsewhere
    a no-op)."""
    if not hasattr(os, "sched_setaffinity"):
        return
    cores = sorted(os.sched_getaffinity(0))
    share = cores[slot::n_workers] if n_workers <= len(cores) else [cores[slot % len(cores)]]
    with contextlib.suppress(OSError):
        os.sched_setaffinity(0, share)


def _worker_init(queue, cache_dir, log_dir, parent=None, slot=None, n_workers=1) -> None:
    """Set up a spawned worker like the parent: float64, the compilation cache, Agg; its stdout and
    stderr (JAX, XLA and MuJoCo messages) go to ``log_dir/worker-PID.log`` (``PART.log`` while it
    runs a part), not the console; it ends with ``parent`` and ignores Ctrl-C (the parent, which
    gets it too, ends the workers); with a ``slot`` it runs on its share of the cores (set before
    JAX sizes its thread pools)."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if parent is not None:
        _die_with_parent(parent)
    if slot is not None:
        _pin_to_share(slot, n_workers)
    os.environ.setdefault("MPLBACKEND", "Agg")
    _WORKER["log_dir"] = Path(log_dir)
    _log_to(Path(log_dir) / f"worker-{os.getpid()}.log")
    import jax

    jax.config.update("jax_enable_x64", True)
    if cache_dir is not None:
        enable_compilation_cache(cache_dir)
    _WORKER["queue"] = queue


def _log_to(path: Path) -> None:
    """Send this process's stdout and stderr (Python's and the C libraries') to ``path``."""
    log = open(path, "a", buffering=1)  # noqa: SIM115
    sys.stdout.flush()
    sys.stderr.flush()
    os.dup2(log.fileno(), 1)
    os.dup2(log.fileno(), 2)
    old, sys.stdout = sys.stdout, log
    sys.stderr = log
    if old is not sys.__stdout__:
        old.close()


class _QueueConsole:
    """A worker's console: lines go to the parent's over the queue."""

    def __init__(self, queue):
        self._queue = queue

    def print(self, msg, **_):
        self._queue.put(("log", str(msg)))


def _queue_progress(queue, name):
    def factory(iterable, total=None, description=""):
        if total is None and hasattr(iterable, "__len__"):
            total = len(iterable)
        key = f"{name}/{id(iterable)}/{time.monotonic_ns()}"
        queue.put(("progress", key, name, description, 0, total))
        done = 0
        for item in iterable:
            yield item
            done += 1
            queue.put(("progress", key, name, description, done, total))
        queue.put(("progress_end", key))

    return factory


def _worker_run(name: str, part, out: str, quick: bool, seed: int) -> dict:
    queue = _WORKER["queue"]
    queue.put(("start", name, os.getpid()))
    console = _QueueConsole(queue)
    ctx = PartContext(name, Path(out), quick=quick, seed=seed, console=console,
                      progress_factory=_queue_progress(queue, name))
    _log_to(_WORKER["log_dir"] / f"{name}.log")
    try:
        entry = run_part(name, part, ctx)
    finally:
        _log_to(_WORKER["log_dir"] / f"worker-{os.getpid()}.log")
    return json_safe(entry)  # (plain data back to the parent)


_INTERRUPTED = []  # set when Ctrl-C ended this process's worker pools (see pools_interrupted)


def pools_interrupted() -> bool:
    """Whether Ctrl-C ended worker pools of this process (and clears that). The interpreter's exit
    would then join the pools' management threads (``concurrent.futures``), which can wait
    forever on the ended workers; the command line ends the process at once instead."""
    found = bool(_INTERRUPTED)
    _INTERRUPTED.clear()
    return found


def run_in_workers(todo, parts, n_workers, *, out, quick, seed, cache_dir, ui, record) -> None:
    """Run ``todo`` (in that order) on ``n_workers`` spawned processes, one part at a time each,
    recording each entry as it arrives; a part that ``follows`` another runs right after it on
    its worker. A part whose worker crashes is re-run alone at the end (on a fresh worker,
    with nothing else running) and recorded as failed if it crashes again; its worker is replaced
    and the other parts go on."""
    import multiprocessing as mp
    import threading
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    from concurrent.futures.process import BrokenProcessPool
    from multiprocessing.managers import SyncManager

    from rich.markup import escape

    ctx = mp.get_context("spawn")
    log_dir = out / "_logs"
    log_dir.mkdir(exist_ok=True)
    manager = SyncManager(ctx=ctx)
    manager.start(_die_with_parent, (os.getpid(),))
    queue = manager.Queue()
    pump = threading.Thread(target=ui.pump, args=(queue,), daemon=True)
    pump.start()
    t_start: dict[str, float] = {}

    def worker(slot, n):
        """A one-process executor pinned to share ``slot`` of ``n`` (None: not pinned)."""
        return ProcessPoolExecutor(1, mp_context=ctx, initializer=_worker_init,
                                   initargs=(queue, cache_dir and str(cache_dir), str(log_dir), os.getpid(),
                                             slot, n))

    def failed(name, error, doc=""):
        """The entry of a part that ended without its worker's entry."""
        return {"quick": quick, "status": "failed", "error": error,
                "seconds": round(time.perf_counter() - t_start.get(name, time.perf_counter()), 2),
                "artefacts": [], "doc": doc}

    def crashed(name):
        log = log_dir / f"{name}.log"
        ui.console.print(f"[bold red]{name}: FAILED[/] its worker process crashed (messages in {escape(str(log))})")
        return failed(name, f"worker process crashed (messages in {log})", as_part(parts[name]).doc)

    def collect(fut, name) -> bool:
        """Record the part of a finished future; False if its worker crashed."""
        try:
            entry = fut.result()
        except BrokenProcessPool:
            ui.finished(name)
            return False
        except Exception as e:  # (the part could not be sent or its results not returned)
            with contextlib.suppress(OSError):
                (out / f"{name}.error.txt").write_text(traceback.format_exc())
            entry = failed(name, f"{type(e).__name__}: {e}")
            ui.console.print(f"[bold red]{name}: FAILED[/] {type(e).__name__}: {escape(str(e))}")
        ui.finished(name)
        record(name, entry)
        return True

    def send(pool, name):
        ui.submitted(name)
        t_start.setdefault(name, time.perf_counter())
        return pool.submit(_worker_run, name, portable(parts[name]), str(out), quick, seed)

    others = set(mp.active_children())  # (the manager's process; any of the caller's)
    pools = [worker(i, n_workers) for i in range(n_workers)]
    suspects: list[str] = []
    try:
        unsent = list(todo)
        follows = {n: as_part(parts[n]).follows for n in unsent}
        held = {f: lead for f, lead in follows.items() if lead in unsent}

        def take(after=None):
            """The next part: ``after``'s follower, else the first part not waiting for a leader."""
            name = next((f for f, lead in held.items() if lead == after), None) if after else None
            name = name or next((n for n in unsent if n not in held), None)
            if name is not None:
                held.pop(name, None)
                unsent.remove(name)
            return name

        running = {}  # future -> (part, worker index)
        for w in range(n_workers):
            if (name := take()) is not None:
                running[send(pools[w], name)] = (name, w)
        idle = [w for w in range(n_workers) if w not in {v[1] for v in running.values()}]
        while running:
            done, _ = wait(running, return_when=FIRST_COMPLETED)
            for fut in done:
                name, w = running.pop(fut)
                if not collect(fut, name):
                    suspects.append(name)
                    pools[w].shutdown(wait=False, cancel_futures=True)
                    pools[w] = worker(w, n_workers)
                for f in [f for f, lead in held.items() if lead == name][1:]:
                    held.pop(f)  # (the first follower runs next; further ones are released)
                if (nxt := take(after=name)) is not None:
                    running[send(pools[w], nxt)] = (nxt, w)
                else:
                    idle.append(w)
                while idle and (nxt := take()) is not None:
                    w2 = idle.pop(0)
                    running[send(pools[w2], nxt)] = (nxt, w2)
        for pool in pools:
            pool.shutdown()
        for name in suspects:  # alone, so that another part's crash or load cannot be the cause
            pool = worker(None, 1)
            if not collect(send(pool, name), name):
                record(name, crashed(name))
            pool.shutdown(wait=False, cancel_futures=True)
    except BaseException as e:  # (Ctrl-C, or the parent failed): a part still running must not hold up the exit
        if isinstance(e, KeyboardInterrupt):
            _INTERRUPTED.append(True)
        ours = set(mp.active_children()) - others
        for proc in ours:
            proc.terminate()
        for proc in ours:
            proc.join(timeout=2)
            if proc.is_alive():
                proc.kill()
        raise
    finally:
        for pool in pools:
            pool.shutdown(wait=False, cancel_futures=True)
        queue.put(None)
        pump.join(timeout=5)
        manager.shutdown()
        for log in log_dir.glob("*.log"):
            if log.stat().st_size == 0:
                log.unlink()
        with contextlib.suppress(OSError):
            log_dir.rmdir()  # (only if empty)
