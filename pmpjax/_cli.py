"""Command line: ``pmpjax reproduce`` (the main job) and subcommands for users' own files.

``pmpjax [reproduce] [--out DIR] [--quick] [--force] [--only PART ...] [--jobs N]``
(``python -m pmpjax`` does the same) runs every part of the main job on the embedded defaults and
writes PNG figures, CSV/JSON tables, ``results.json`` and a report (``report.html``,
self-contained, and ``report.md``). Results are written after every part, so an interruption
loses nothing; a re-run skips parts already finished (with the same ``--quick``) unless
``--force``; a failing part is reported and the others still run (exit status 1 when any part
failed). ``--jobs N`` (default: the usable cores) runs the parts in N spawned worker processes,
each on its share of the cores, longest first (the run is compile bound and XLA compiles on one
thread), a part that reuses another's compilations right after it on its worker (``FOLLOWS``);
``--jobs 1`` runs them in this process. Workers' own output (JAX, XLA, MuJoCo) goes to ``DIR/_logs/``, kept only if
not empty; their log lines and progress bars appear in this process's display.

Parts are built in (Figure 3, Figure 4, the postural primitives) or registered by installed packages under the
``pmpjax.jobs`` entry-point group (``fitting`` registers its fits there, so ``pmpjax`` never
imports ``fitting``). A part is ``part(ctx: PartContext) -> dict`` (JSON-able results); it
records its figures and tables with ``ctx.figure`` and ``ctx.table``; a ``converged`` entry
``[n_converged, n_total]`` in its results shows it as e.g. "ok, 0/12 converged" when not every
fit converged. Subcommands for users' files (``fit-donders``, ``analyze-pointing``, ...) are
registered the same way under ``pmpjax.commands``: ``command(subparsers) -> None`` adds a parser
whose ``func(args) -> int`` runs it. Bad input ends with a one-line message and exit status 2,
never a traceback.

JAX's persistent compilation cache is on for the command line (``$PMPJAX_CACHE_DIR``, default
``~/.cache/pmpjax/jax``; ``--no-cache`` turns it off), so a second run does not recompile.
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import dataclasses
import inspect
import json
import os
import sys
import time
import traceback
from collections.abc import Callable, Iterable
from pathlib import Path

from ._base.validate import output_dir

#: Order of the parts in a run and in the report (others follow alphabetically).
PART_ORDER = (
    "figure3", "donders_nio", "pointing", "ik_figures", "ik_synthetic", "ik_hugmp",
    "reaching", "sweeps", "figure4", "primitives",
)


@dataclasses.dataclass
class Artefact:
    """A file a part wrote: ``kind`` "figure" or "table", ``path`` relative to the output folder,
    ``caption`` what it shows, ``paper`` the paper's corresponding figure or number."""

    kind: str
    path: str
    caption: str
    paper: str = ""


class PartContext:
    """What a part gets: ``out`` folder, ``quick`` (small sizes), ``seed``, ``log(msg)``,
    ``progress(iterable, total=None, description=...)`` and ``figure``/``table`` recorders."""

    def __init__(self, name: str, out: Path, *, quick: bool, seed: int, console, progress_factory):
        self.name, self.out, self.quick, self.seed = name, out, quick, seed
        self.artefacts: list[Artefact] = []
        self._console = console
        self._progress_factory = progress_factory

    def log(self, msg: str) -> None:
        from rich.markup import escape

        self._console.print(f"[bold cyan]{self.name}[/]: {escape(msg)}", highlight=False)

    def progress(self, iterable: Iterable, *, total: int | None = None, description: str = ""):
        return self._progress_factory(iterable, total=total, description=f"{self.name}: {description}")

    def figure(self, fig, filename: str, caption: str, paper: str = "", *, dpi: int = 110) -> Path:
        """Save a matplotlib figure (or record an existing PNG path) as ``filename``."""
        path = self.out / filename
        if isinstance(fig, str | Path):
            path = Path(fig)
        else:
            import matplotlib.pyplot as plt

            fig.savefig(path, dpi=dpi)
            plt.close(fig)
        self.artefacts.append(Artefact("figure", path.name, caption, paper))
        return path

    def table(self, rows: list[dict], filename: str, caption: str, paper: str = "") -> Path:
        """Write ``rows`` (list of dicts with the same keys) as CSV ``filename``."""
        path = self.out / filename
        if not rows:
            raise ValueError(f"table {filename!r} has no rows")
        with path.open("w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(rows[0]))
            w.writeheader()
            for r in rows:
                w.writerow({k: _fmt_cell(v) for k, v in r.items()})
        self.artefacts.append(Artefact("table", path.name, caption, paper))
        return path


def _fmt_cell(v):
    if isinstance(v, float):
        return f"{v:.6g}"
    return v


# ----------------------------------------------------------------------------- built-in parts


def figure3_part(ctx: PartContext) -> dict:
    """Figure 3 of Tommasino & Campolo (2017): λ0-PMP center-out paths, speeds and curvature."""
    import numpy as np

    from ._wrist.figure3 import figure3_data, plot_figure3

    data = figure3_data()
    ends = np.stack([data["targets"], np.zeros_like(data["targets"])], axis=1)
    final_err = float(abs(data["x"][:, :, -1] - ends).max())
    ctx.figure(plot_figure3(data), "figure3.png",
               "λ0-PMP center-out movements of the Figure 3 model (KJ = diag(0.5, 1.5, 2), τ = τ0 = 80 ms, "
               "k = 22.5): screen paths out and back, speed profiles and joint trajectories.",
               "Paper Figure 3: curved paths for diagonal targets, straight cardinal ones, bell-shaped speeds.")
    rows = [{"target": d, "A_net_out": float(data["A_net"][i, 0]), "A_net_in": float(data["A_net"][i, 1]),
             "A_hyst": float(data["A_hyst"][i]), "peak_speed_m_per_s": float(data["speed"][i].max())}
            for i, d in enumerate(data["directions"])]
    ctx.table(rows, "figure3_curvature.csv",
              "Curvature (A_net, normalised by (π/12)²) and hysteresis of the Figure 3 movements per target.",
              "Paper Figure 3A: diagonal paths curve, cardinal ones do not.")
    ctx.log(f"final task error {final_err:.2e} m")
    return {
        "parameters": {k: (v.tolist() if hasattr(v, "tolist") else v) for k, v in data["params"].items()},
        "max_final_task_error_m": final_err,
        "peak_speed_m_per_s": {d: float(data["speed"][i].max()) for i, d in enumerate(data["directions"])},
        "A_net_out": dict(zip(data["directions"], data["A_net"][:, 0].round(5).tolist())),
        "A_net_in": dict(zip(data["directions"], data["A_net"][:, 1].round(5).tolist())),
        "A_hyst": dict(zip(data["directions"], data["A_hyst"].round(5).tolist())),
        "all_ok": bool((data["status"] == 0).all()),
    }


def figure4_part(ctx: PartContext) -> dict:
    """Williamson (1996) Figure 4: two overlapping minimum-jerk set-point moves are summed."""
    import numpy as np

    from ._springy_arm.plots import plot_summed_moves
    from ._springy_arm.primitives import moves_from_targets, summed_moves

    # A move 0 → 1 (1 s) with a second move to 1.5 issued half-way.
    moves = moves_from_targets(np.zeros(1), np.array([[1.0], [1.5]]), np.array([0.0, 0.5]), 1.0)
    t = np.linspace(0.0, 2.0, 401)
    p, v = (np.asarray(a) for a in summed_moves(moves, np.zeros(1), t))
    ctx.figure(plot_summed_moves(moves, np.zeros(1), t), "figure4_summed_moves.png",
               "Set-point position and velocity of a move 0 → 1 (1 s) with a second move to 1.5 issued "
               "at 0.5 s: the velocities add, the set-point ends at 1.5 without a jump.",
               "Williamson (1996) Figure 4: summed minimum-jerk moves.")
    ctx.log(f"final set-point {p[-1, 0]:.6f}")
    return {"final_set_point": float(p[-1, 0]), "peak_velocity": float(v[:, 0].max()),
            "velocity_jump_max": float(np.abs(np.diff(v[:, 0])).max())}


def primitives_part(ctx: PartContext) -> dict:
    """Williamson (1996) beyond Figure 4: primitives under gravity, blends vs winner-take-all, reflexes.

    Gravity equilibria of the primitives and their blends vs winner-take-all (Figs 3, 5), the convergent
    force field of a posture (Fig 2), and the grasp, withdrawal and lead reflexes (Figs 8-10); forward
    rollouts on C MuJoCo."""
    from ._springy_arm.main_job import primitives_part as run

    return run(ctx)


# ----------------------------------------------------------------------------- running parts


def available_parts() -> dict[str, Callable]:
    """Built-in parts, then entry points of the ``pmpjax.jobs`` group, in ``PART_ORDER``."""
    from importlib.metadata import entry_points

    parts: dict[str, Callable] = {"figure3": figure3_part, "figure4": figure4_part, "primitives": primitives_part}
    for ep in entry_points(group="pmpjax.jobs"):
        parts.setdefault(ep.name, ep)
    rank = {n: i for i, n in enumerate(PART_ORDER)}
    return dict(sorted(parts.items(), key=lambda kv: (rank.get(kv[0], len(rank)), kv[0])))


def _load(part):
    """The part's function from an entry point, a ``module:attr`` string (workers) or itself."""
    if hasattr(part, "load"):
        return part.load()
    return _resolve(part)


def _call_part(fn, ctx: PartContext) -> dict:
    params = list(inspect.signature(fn).parameters)
    if params[:1] == ["ctx"]:
        return fn(ctx)
    # Older parts: job(out, log) -> dict; their new PNGs become figures captioned by the docstring.
    before = {p.name for p in ctx.out.glob("*.png")}
    res = fn(ctx.out, ctx.log)
    caption = (inspect.getdoc(fn) or ctx.name).split("\n\n")[0].replace("\n", " ")
    for p in sorted(ctx.out.glob("*.png")):
        if p.name not in before:
            ctx.artefacts.append(Artefact("figure", p.name, caption))
    return res


def _versions() -> dict:
    import importlib.metadata as md
    import platform

    out = {"python": platform.python_version(), "platform": platform.platform()}
    for pkg in ("pmpjax", "jax", "jaxlib", "numpy", "scipy", "matplotlib", "mujoco", "mujoco-mjx"):
        try:
            out[pkg] = md.version(pkg)
        except md.PackageNotFoundError:
            pass
    return out


def enable_compilation_cache(path: str | os.PathLike | None = None) -> Path:
    """Turn on JAX's persistent compilation cache at ``path`` (default ``$PMPJAX_CACHE_DIR`` or
    ``~/.cache/pmpjax/jax``) for every compiled function, however quick to compile."""
    import jax

    cache = Path(path or os.environ.get("PMPJAX_CACHE_DIR") or Path.home() / ".cache" / "pmpjax" / "jax")
    cache.mkdir(parents=True, exist_ok=True)
    jax.config.update("jax_compilation_cache_dir", str(cache))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    return cache


#: Wall seconds per part of idle cold runs, two parts at a time (``--jobs 2``, 2-core AMD EPYC Zen 4
#: KVM): the order in which parallel workers take the parts (longest first) when ``results.json``
#: has no times yet; ``--quick`` and the full run (``--no-cache``, pinned workers).
PART_SECONDS = {"pointing": 33, "reaching": 27, "sweeps": 16, "primitives": 8, "ik_figures": 8,
                "ik_hugmp": 8, "ik_synthetic": 8, "figure3": 4, "donders_nio": 3, "figure4": 1}
#: Parts that reuse another part's compilations (donders_nio's NIO fit has the shapes of
#: pointing's): with both to run, the follower waits for its leader and then runs on the worker that
#: ran it (in process, whether or not the compilation cache is on; 3 s instead of 12).
FOLLOWS = {"donders_nio": "pointing"}
PART_SECONDS_FULL = {"ik_hugmp": 73, "reaching": 46, "pointing": 33, "sweeps": 31, "ik_synthetic": 11,
                     "primitives": 8, "ik_figures": 8, "figure3": 3, "donders_nio": 2, "figure4": 1}


def default_jobs() -> int:
    """Worker processes of ``reproduce``: the cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # (macOS, Windows)
        return os.cpu_count() or 1


def reproduce(out: str | os.PathLike = "out", *, quick: bool = False, force: bool = False,
              only: Iterable[str] | None = None, seed: int = 0, progress: bool = True,
              cache: bool = True, jobs: int | None = 1) -> dict:
    """Run the main job's parts into ``out``; returns the ``results.json`` content.

    ``jobs`` > 1 (``None``: :func:`default_jobs`, the command line's default) spawns that many
    worker processes that run the parts, longest first (their previous ``seconds`` in
    ``results.json``, else :data:`PART_SECONDS` / :data:`PART_SECONDS_FULL`); XLA compiles mostly
    on one thread, so two parts compiling at once use two cores. ``jobs=1`` (the default here), or
    a single part to run, runs in this process. Parts given to workers must be importable
    (module-level functions or entry points); a worker that crashes fails its part, the others
    still run.

    Run times on two idle cores: the README (targets five minutes full, one minute ``--quick``);
    on cores shared with other jobs a second worker gains nothing.
    """
    import jax

    if jobs is None:
        jobs = default_jobs()
    if isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1:
        raise ValueError(f"jobs must be a positive integer, got {jobs!r}")
    jax.config.update("jax_enable_x64", True)
    cache_dir = enable_compilation_cache() if cache else None
    parts = available_parts()
    names = list(parts) if not only else list(only)
    unknown = [n for n in names if n not in parts]
    if unknown:
        raise ValueError(f"unknown part(s) {unknown}; available: {list(parts)}")
    out = Path(out)
    out = output_dir("--out", out)
    results_path = out / "results.json"
    results = json.loads(results_path.read_text()) if results_path.exists() else {}
    meta = results.setdefault("_meta", {})
    meta.update({"versions": _versions(), "seed": seed, "quick": quick})
    t_run = time.perf_counter()
    ui = _UI(progress)
    todo = []
    for name in names:
        if not force and _finished(results.get(name), out, quick):
            ui.console.print(f"[bold cyan]{name}[/]: finished earlier, skipped (--force to re-run)")
        else:
            todo.append(name)

    def record(name: str | None, entry: dict | None = None) -> None:
        if name is not None:
            results[name] = entry
            ui.part_done(name, entry)
        rank = {n: i for i, n in enumerate(parts)}
        ordered = {"_meta": meta, **dict(sorted(((k, v) for k, v in results.items() if k != "_meta"),
                                                key=lambda kv: (rank.get(kv[0], len(rank)), kv[0])))}
        results.clear()
        results.update(ordered)
        # Written after every part so an interruption loses nothing already computed.
        _atomic_write(results_path, json.dumps(results, indent=2, default=_json_default))
        write_report(out, results)

    n_workers = min(jobs, len(todo))
    meta["jobs"] = max(n_workers, 1)
    ui.begin(len(todo))
    from ._report import write_report

    try:
        if n_workers <= 1:
            for name in todo:
                ctx = PartContext(name, out, quick=quick, seed=seed, console=ui.console,
                                  progress_factory=ui.factory)
                with ui.running(name):
                    record(name, _run_part(name, parts[name], ctx))
        else:
            def estimate(n):
                prev = results.get(n) or {}
                return prev["seconds"] if prev.get("quick") == quick and "seconds" in prev \
                    else (PART_SECONDS if quick else PART_SECONDS_FULL).get(n, 10)

            todo.sort(key=estimate, reverse=True)
            _run_in_workers(todo, parts, n_workers, out=out, quick=quick, seed=seed, cache_dir=cache_dir,
                            ui=ui, record=record)
    finally:
        ui.close()
    meta["wall_seconds"] = round(time.perf_counter() - t_run, 2)
    if todo:
        record(None)  # (results.json and the report with the wall time)
    ui.console.print(f"results -> {results_path}; report -> {out / 'report.html'}")
    return results


def _run_part(name: str, part, ctx: PartContext) -> dict:
    """Run one part; its results.json entry (``status`` "ok" or "failed", ``seconds``, artefacts;
    ``converged`` [n, total] and ``all_converged`` when its results report the fits' convergence)."""
    from ._report import convergence

    t0 = time.perf_counter()
    entry: dict = {"quick": ctx.quick}
    doc = ""
    try:
        fn = _load(part)
        doc = (inspect.getdoc(fn) or "").split("\n\n")[0]
        res = _call_part(fn, ctx)
        entry["status"] = "ok"
        if (c := convergence(res)) is not None:
            entry.update(converged=list(c), all_converged=c[0] == c[1])
        entry["results"] = res
    except Exception as e:  # a failing part is reported; the others still run
        (ctx.out / f"{name}.error.txt").write_text(traceback.format_exc())
        entry.update(status="failed", error=f"{type(e).__name__}: {e}")
        from rich.markup import escape

        ctx._console.print(f"[bold red]{name}: FAILED[/] {type(e).__name__}: {escape(str(e))} "  # noqa: SLF001
                           f"(traceback in {ctx.out / (name + '.error.txt')})")
    entry["seconds"] = round(time.perf_counter() - t0, 2)
    entry["artefacts"] = [dataclasses.asdict(a) for a in ctx.artefacts]
    entry["doc"] = doc
    return entry


# ----------------------------------------------------------------------------- worker processes

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
    stderr (JAX, XLA and MuJoCo messages) go to ``log_dir/worker-PID.log``, not the console; it
    ends with ``parent``; with a ``slot`` it runs on its share of the cores (set before JAX sizes
    its thread pools)."""
    if parent is not None:
        _die_with_parent(parent)
    if slot is not None:
        _pin_to_share(slot, n_workers)
    os.environ.setdefault("MPLBACKEND", "Agg")
    log = open(Path(log_dir) / f"worker-{os.getpid()}.log", "a", buffering=1)  # noqa: SIM115
    sys.stdout.flush()
    sys.stderr.flush()
    os.dup2(log.fileno(), 1)
    os.dup2(log.fileno(), 2)
    sys.stdout = sys.stderr = log
    import jax

    jax.config.update("jax_enable_x64", True)
    if cache_dir is not None:
        enable_compilation_cache(cache_dir)
    _WORKER["queue"] = queue


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
    entry = _run_part(name, part, ctx)
    return json.loads(json.dumps(entry, default=_json_default))  # (plain data back to the parent)


def _portable(part):
    """A part as a worker can receive it: an entry point's ``module:attr`` string, or the function."""
    return part.value if hasattr(part, "load") else part


def _resolve(part):
    if isinstance(part, str):
        import importlib

        mod, _, attr = part.partition(":")
        obj = importlib.import_module(mod)
        for a in attr.split("."):
            obj = getattr(obj, a)
        return obj
    return part


def _run_in_workers(todo, parts, n_workers, *, out, quick, seed, cache_dir, ui, record) -> None:
    """Run ``todo`` (in that order) on ``n_workers`` spawned processes, one part at a time each,
    recording each entry as it arrives; a :data:`FOLLOWS` part runs right after its leader on the
    leader's worker. A part whose worker crashes is re-run alone at the end (on a fresh worker,
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
        ui.console.print(f"[bold red]{name}: FAILED[/] its worker process crashed (messages in {log_dir})")
        return failed(name, f"worker process crashed (messages in {log_dir})",
                      (inspect.getdoc(_resolve(_portable(parts[name]))) or "").split("\n\n")[0])

    def collect(fut, name) -> bool:
        """Record the part of a finished future; False if its worker crashed."""
        try:
            entry = fut.result()
        except BrokenProcessPool:
            ui.finished(name)
            return False
        except Exception as e:  # (the part could not be sent or its results not returned)
            (out / f"{name}.error.txt").write_text(traceback.format_exc())
            entry = failed(name, f"{type(e).__name__}: {e}")
            ui.console.print(f"[bold red]{name}: FAILED[/] {type(e).__name__}: {escape(str(e))}")
        ui.finished(name)
        record(name, entry)
        return True

    def send(pool, name):
        ui.submitted(name)
        t_start.setdefault(name, time.perf_counter())
        return pool.submit(_worker_run, name, _portable(parts[name]), str(out), quick, seed)

    pools = [worker(i, n_workers) for i in range(n_workers)]
    suspects: list[str] = []
    try:
        unsent = list(todo)
        held = {f: lead for f, lead in FOLLOWS.items() if f in unsent and lead in unsent}

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
    finally:
        for pool in pools:
            pool.shutdown(wait=False, cancel_futures=True)
        queue.put(None)
        pump.join(timeout=5)
        manager.shutdown()
        for log in log_dir.glob("worker-*.log"):
            if log.stat().st_size == 0:
                log.unlink()
        with contextlib.suppress(OSError):
            log_dir.rmdir()  # (only if empty)


def _finished(entry, out: Path, quick: bool) -> bool:
    if not entry or entry.get("status") != "ok" or entry.get("quick") != quick:
        return False
    return all((out / a["path"]).exists() for a in entry.get("artefacts", []))


def _atomic_write(path: Path, text: str) -> None:
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def _json_default(o):
    import numpy as np

    if isinstance(o, np.ndarray | np.generic):
        return o.tolist()
    if hasattr(o, "tolist"):
        return o.tolist()
    return str(o)


class _UI:
    """The parent's display: a rich console, one line per running part with its elapsed time, the
    parts done out of those to run, a line per finished part with its status, and the progress
    bars of loops inside parts (``ctx.progress``; from workers over a queue)."""

    def __init__(self, enabled: bool):
        import threading

        from rich.console import Console
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

        self.console = Console(stderr=True)
        self.enabled = enabled
        self._lock = threading.RLock()  # (the pump thread and the main thread both change the tasks)
        self._tasks: dict[str, object] = {}
        self._done: set[str] = set()  # (a late "start" from the queue must not bring back a finished part)
        self._inner: dict[str, tuple[str, object]] = {}
        self._n_parts, self._n_done, self._overall = 0, 0, None
        if enabled:
            self._prog = Progress(SpinnerColumn(), TextColumn("{task.description}"), BarColumn(),
                                  MofNCompleteColumn(), TimeElapsedColumn(), console=self.console, transient=True)
            self._prog.start()

    def begin(self, n_parts: int) -> None:
        """Count the parts to run."""
        with self._lock:
            self._n_parts, self._n_done = n_parts, 0
            if self.enabled and n_parts:
                self._overall = self._prog.add_task("[bold]parts done[/]", total=n_parts)

    def part_done(self, name: str, entry: dict) -> None:
        """A part has finished: its status (amber when not every fit converged) and the count."""
        from rich.markup import escape

        from ._report import part_status

        label, cls = part_status(entry)
        colour = {"ok": "green", "partial": "dark_orange"}.get(cls, "red")
        with self._lock:
            self._n_done += 1
            self.console.print(f"[bold cyan]{name}[/]: [{colour}]{escape(label)}[/] in {entry.get('seconds', '?')} s "
                               f"({self._n_done}/{self._n_parts} parts)", highlight=False)
            if self._overall is not None:
                self._prog.update(self._overall, completed=self._n_done)

    def factory(self, iterable, total=None, description=""):
        if not self.enabled:
            return iterable
        return self._prog.track(iterable, total=total, description=description)

    def submitted(self, name: str) -> None:
        with self._lock:
            self._done.discard(name)

    def started(self, name: str) -> None:
        with self._lock:
            if self.enabled and name not in self._tasks and name not in self._done:
                self._tasks[name] = self._prog.add_task(f"[bold cyan]{name}[/] running", total=None)

    def finished(self, name: str) -> None:
        if not self.enabled:
            return
        with self._lock:
            self._done.add(name)
            task = self._tasks.pop(name, None)
            if task is not None:
                self._prog.remove_task(task)
            for key in [k for k, (part, _) in self._inner.items() if part == name]:
                self._prog.remove_task(self._inner.pop(key)[1])

    @contextlib.contextmanager
    def running(self, name: str):
        self.submitted(name)
        self.started(name)
        try:
            yield
        finally:
            self.finished(name)

    def pump(self, queue) -> None:
        """Show the workers' messages until ``None`` arrives: ("start", part, pid), ("log", text),
        ("progress", key, part, description, done, total), ("progress_end", key)."""
        while True:
            try:
                msg = queue.get()
            except (EOFError, OSError):  # (the manager is gone)
                return
            if msg is None:
                return
            kind = msg[0]
            if kind == "start":
                self.started(msg[1])
                continue
            if kind == "log":
                self.console.print(msg[1], highlight=False)
                continue
            if not self.enabled:
                continue
            with self._lock:
                if kind == "progress":
                    key, part, description, done, total = msg[1:]
                    if part not in self._tasks:
                        continue  # (the part has finished meanwhile)
                    if key not in self._inner:
                        self._inner[key] = (part, self._prog.add_task(description, total=total))
                    self._prog.update(self._inner[key][1], completed=done)
                elif kind == "progress_end" and msg[1] in self._inner:
                    self._prog.remove_task(self._inner.pop(msg[1])[1])

    def close(self) -> None:
        if self.enabled:
            self._prog.stop()


# ----------------------------------------------------------------------------- entry point


class UserError(Exception):
    """Bad input from the command line: printed as one line, exit status 2."""


def _commands() -> dict:
    from importlib.metadata import entry_points

    return {ep.name: ep for ep in entry_points(group="pmpjax.commands")}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="pmpjax", description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    rep = sub.add_parser("reproduce", help="run every reproduced result of the three papers (the main job)",
                         description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    rep.add_argument("--out", default="out", help="output folder (created; default: out)")
    rep.add_argument("--quick", action="store_true",
                     help="small sizes (about 35 s with a warm compilation cache, under 2 min cold)")
    rep.add_argument("--force", action="store_true", help="re-run parts that finished before")
    rep.add_argument("--only", nargs="+", metavar="PART", help="run only these parts")
    rep.add_argument("--list", action="store_true", help="list the parts and exit")
    rep.add_argument("--seed", type=int, default=0, help="random seed of the synthetic data (default 0)")
    rep.add_argument("--no-progress", action="store_true", help="no progress display")
    rep.add_argument("--no-cache", action="store_true", help="no persistent JAX compilation cache")
    rep.add_argument("--jobs", "-j", type=_positive_int, default=None, metavar="N",
                     help=f"worker processes running parts at once (default: the usable cores, "
                          f"here {default_jobs()}; 1 runs in this process)")
    rep.set_defaults(func=_reproduce_cmd)
    from ._config import add_simulate_command

    add_simulate_command(sub)
    for name, ep in _commands().items():
        ep.load()(sub)
    return parser


def _positive_int(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}")
    return n


def _reproduce_cmd(args) -> int:
    if args.list:
        for name, part in available_parts().items():
            print(f"{name:16s} {(inspect.getdoc(_load(part)) or '').splitlines()[0]}")
        return 0
    parts = available_parts()
    if args.only:
        unknown = [n for n in args.only if n not in parts]
        if unknown:
            raise UserError(f"--only: unknown part(s) {', '.join(unknown)}; available: {', '.join(parts)}")
    res = reproduce(args.out, quick=args.quick, force=args.force, only=args.only, seed=args.seed,
                    progress=not args.no_progress, cache=not args.no_cache, jobs=args.jobs)
    failed = [k for k, v in res.items() if not k.startswith("_") and v.get("status") == "failed"]
    return 1 if failed else 0


def main(argv=None) -> int:
    os.environ.setdefault("MPLBACKEND", "Agg")
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser()
    commands = set(parser._subparsers._group_actions[0].choices)  # noqa: SLF001
    if not argv:  # a bare `pmpjax` says what it can do rather than start a long run in the current folder
        parser.print_help(sys.stderr)
        print("\npmpjax: give a command, or run the main job with `pmpjax --out DIR` (= pmpjax reproduce --out DIR)",
              file=sys.stderr)
        return 2
    if argv[0] not in commands and argv[0] not in ("-h", "--help"):
        argv = ["reproduce", *argv]  # `pmpjax --out out` is `pmpjax reproduce --out out`
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except (UserError, ValueError, FileNotFoundError, TypeError) as e:
        print(f"pmpjax {args.command}: error: {e}", file=sys.stderr)
        return 2
