"""Command line: ``pmpjax reproduce`` (the main job) and subcommands for users' own files.

``pmpjax [reproduce] [--out DIR] [--quick] [--force] [--only PART ...]`` (``python -m pmpjax``
does the same) runs every part of the main job on the embedded defaults and writes PNG figures,
CSV/JSON tables, ``results.json`` and a report (``report.html``, self-contained, and
``report.md``). Results are written after every part, so an interruption loses nothing; a
re-run skips parts already finished (with the same ``--quick``) unless ``--force``; a failing
part is reported and the others still run (exit status 1 when any part failed).

Parts are built in (Figure 3, Figure 4, the postural primitives) or registered by installed packages under the
``pmpjax.jobs`` entry-point group (``fitting`` registers its fits there, so ``pmpjax`` never
imports ``fitting``). A part is ``part(ctx: PartContext) -> dict`` (JSON-able results); it
records its figures and tables with ``ctx.figure`` and ``ctx.table``. Subcommands for users'
files (``fit-donders``, ``analyze-pointing``, ...) are registered the same way under
``pmpjax.commands``: ``command(subparsers) -> None`` adds a parser whose ``func(args) -> int``
runs it. Bad input ends with a one-line message and exit status 2, never a traceback.

JAX's persistent compilation cache is on for the command line (``$PMPJAX_CACHE_DIR``, default
``~/.cache/pmpjax/jax``; ``--no-cache`` turns it off), so a second run does not recompile.
"""

from __future__ import annotations

import argparse
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
        self._console.print(f"[bold cyan]{self.name}[/]: {msg}", highlight=False)

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
    return part.load() if hasattr(part, "load") else part


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


def reproduce(out: str | os.PathLike = "out", *, quick: bool = False, force: bool = False,
              only: Iterable[str] | None = None, seed: int = 0, progress: bool = True,
              cache: bool = True) -> dict:
    """Run the main job's parts into ``out``; returns the ``results.json`` content."""
    import jax

    from ._report import write_report

    jax.config.update("jax_enable_x64", True)
    if cache:
        enable_compilation_cache()
    parts = available_parts()
    names = list(parts) if not only else list(only)
    unknown = [n for n in names if n not in parts]
    if unknown:
        raise ValueError(f"unknown part(s) {unknown}; available: {list(parts)}")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    results_path = out / "results.json"
    results = json.loads(results_path.read_text()) if results_path.exists() else {}
    meta = results.setdefault("_meta", {})
    meta.update({"versions": _versions(), "seed": seed, "quick": quick})
    console, progress_factory, close = _ui(progress)
    try:
        for name in names:
            prev = results.get(name)
            if not force and _finished(prev, out, quick):
                console.print(f"[bold cyan]{name}[/]: finished earlier, skipped (--force to re-run)")
                continue
            ctx = PartContext(name, out, quick=quick, seed=seed, console=console,
                              progress_factory=progress_factory)
            t0 = time.perf_counter()
            entry = {"quick": quick}
            try:
                res = _call_part(_load(parts[name]), ctx)
                entry.update(status="ok", results=res)
            except Exception as e:  # a failing part is reported; the others still run
                (out / f"{name}.error.txt").write_text(traceback.format_exc())
                entry.update(status="failed", error=f"{type(e).__name__}: {e}")
                console.print(f"[bold red]{name}: FAILED[/] {type(e).__name__}: {e} "
                              f"(traceback in {out / (name + '.error.txt')})")
            entry["seconds"] = round(time.perf_counter() - t0, 2)
            entry["artefacts"] = [dataclasses.asdict(a) for a in ctx.artefacts]
            entry["doc"] = (inspect.getdoc(_load(parts[name])) or "").split("\n\n")[0]
            results[name] = entry
            # Written after every part so an interruption loses nothing already computed.
            _atomic_write(results_path, json.dumps(results, indent=2, default=_json_default))
            write_report(out, results)
    finally:
        close()
    console.print(f"results -> {results_path}; report -> {out / 'report.html'}")
    return results


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


def _ui(enabled: bool):
    """A rich console, a progress-bar factory for loops inside parts, and a closer."""
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    console = Console(stderr=True)
    if not enabled:
        return console, lambda it, total=None, description="": it, lambda: None
    prog = Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                    console=console, transient=True)
    prog.start()

    def factory(iterable, total=None, description=""):
        return prog.track(iterable, total=total, description=description)

    return console, factory, prog.stop


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
    rep.add_argument("--quick", action="store_true", help="small sizes (under a minute)")
    rep.add_argument("--force", action="store_true", help="re-run parts that finished before")
    rep.add_argument("--only", nargs="+", metavar="PART", help="run only these parts")
    rep.add_argument("--list", action="store_true", help="list the parts and exit")
    rep.add_argument("--seed", type=int, default=0, help="random seed of the synthetic data (default 0)")
    rep.add_argument("--no-progress", action="store_true", help="no progress display")
    rep.add_argument("--no-cache", action="store_true", help="no persistent JAX compilation cache")
    rep.set_defaults(func=_reproduce_cmd)
    from ._config import add_simulate_command

    add_simulate_command(sub)
    for name, ep in _commands().items():
        ep.load()(sub)
    return parser


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
                    progress=not args.no_progress, cache=not args.no_cache)
    failed = [k for k, v in res.items() if not k.startswith("_") and v.get("status") == "failed"]
    return 1 if failed else 0


def main(argv=None) -> int:
    os.environ.setdefault("MPLBACKEND", "Agg")
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser()
    commands = set(parser._subparsers._group_actions[0].choices)  # noqa: SLF001
    if not argv or (argv[0] not in commands and argv[0] not in ("-h", "--help")):
        argv = ["reproduce", *argv]  # `pmpjax --out out` is `pmpjax reproduce --out out`
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except (UserError, ValueError, FileNotFoundError, TypeError) as e:
        print(f"pmpjax {args.command}: error: {e}", file=sys.stderr)
        return 2
