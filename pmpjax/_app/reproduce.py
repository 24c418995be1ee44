"""``pmpjax reproduce``: run the main job's parts into a folder, recording ``results.json`` and the
report after every part, in this process or in worker processes."""

from __future__ import annotations

import json
import os
import time
from collections.abc import Iterable
from pathlib import Path

from .._base import json_text, output_dir
from .cache import enable_compilation_cache
from .display import Display
from .parts import PartContext, as_part, available_parts, run_part


def _versions() -> dict:
    """Versions of Python, the platform and the packages behind the results."""
    import importlib.metadata as md
    import platform

    out = {"python": platform.python_version(), "platform": platform.platform()}
    for pkg in ("pmpjax", "jax", "jaxlib", "numpy", "scipy", "matplotlib", "mujoco", "mujoco-mjx"):
        try:
            out[pkg] = md.version(pkg)
        except md.PackageNotFoundError:
            pass
    return out


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
    ``results.json``, else each :class:`Part`'s expected seconds); XLA compiles mostly
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
    try:
        results = json.loads(results_path.read_text()) if results_path.exists() else {}
        if not isinstance(results, dict):
            raise ValueError("not a JSON object")
    except ValueError as e:
        raise ValueError(f"{results_path}: not a results file of pmpjax ({e}); delete it or use another "
                         "--out") from None
    meta = results.setdefault("_meta", {})
    meta.update({"versions": _versions(), "seed": seed, "quick": quick})
    t_run = time.perf_counter()
    ui = Display(progress)
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
        _atomic_write(results_path, json_text(results, indent=2))
        write_report(out, results)

    # The report must not link an earlier run's traceback or messages of a part that runs again.
    stale = [p for name in todo for p in (out / f"{name}.error.txt", out / "_logs" / f"{name}.log")]
    for path in stale + (list((out / "_logs").glob("worker-*.log")) if todo else []):
        path.unlink(missing_ok=True)
    n_workers = min(jobs, len(todo))
    meta["jobs"] = max(n_workers, 1)
    ui.begin(len(todo))
    from .report import write_report

    try:
        if n_workers <= 1:
            for name in todo:
                ctx = PartContext(name, out, quick=quick, seed=seed, console=ui.console,
                                  progress_factory=ui.factory)
                with ui.running(name):
                    record(name, run_part(name, parts[name], ctx))
        else:
            def estimate(n):
                prev = results.get(n) or {}
                return prev["seconds"] if prev.get("quick") == quick and "seconds" in prev \
                    else as_part(parts[n]).expected_seconds(quick)

            todo.sort(key=estimate, reverse=True)
            from .workers import run_in_workers

            run_in_workers(todo, parts, n_workers, out=out, quick=quick, seed=seed, cache_dir=cache_dir,
                           ui=ui, record=record)
    finally:
        ui.close()
    meta["wall_seconds"] = round(time.perf_counter() - t_run, 2)
    if todo:
        record(None)  # (results.json and the report with the wall time)
    ui.console.print(f"results -> {results_path}; report -> {out / 'report.html'}")
    return results


def _finished(entry, out: Path, quick: bool) -> bool:
    if not entry or entry.get("status") != "ok" or entry.get("quick") != quick:
        return False
    return all((out / a["path"]).exists() for a in entry.get("artefacts", []))


def _atomic_write(path: Path, text: str) -> None:
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)
