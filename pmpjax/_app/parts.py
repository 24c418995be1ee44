"""The main job's part protocol: a :class:`Part` (its function and the metadata the host
schedules it by), the :class:`PartContext` it writes through, and running one part.

A part is ``fn(ctx: PartContext) -> dict`` (JSON-able results) wrapped in a :class:`Part`;
installed packages register theirs under the ``pmpjax.jobs`` entry-point group (pmpjax's own
built-in parts included), so the host knows no part by name. A plain function is a part with
default metadata. A ``converged`` entry ``[n_converged, n_total]`` (or one flag per fit) in the
results shows the part as e.g. "ok, 0/12 converged" when not every fit converged.
"""

from __future__ import annotations

import csv
import dataclasses
import inspect
import time
import traceback
from collections.abc import Callable, Iterable
from pathlib import Path


@dataclasses.dataclass(frozen=True)
class Part:
    """A main-job part: ``fn(ctx) -> dict`` and how the host schedules it.

    ``seconds`` / ``seconds_full``: expected wall seconds of an idle cold ``--quick`` / full run
    on two workers (the order in which workers take parts, longest first, before ``results.json``
    has measured times); ``follows``: a part whose compilations this one reuses (with both to run,
    it waits for that part and runs on the same worker); ``order``: its place in ``results.json``
    and the report; ``title``: its section title in the report (else its name)."""

    fn: Callable[[PartContext], dict]
    seconds: float = 10.0
    seconds_full: float = 10.0
    follows: str | None = None
    order: int = 1000
    title: str = ""

    def __call__(self, ctx: PartContext) -> dict:
        return self.fn(ctx)

    @property
    def doc(self) -> str:
        """The first paragraph of the function's docstring."""
        return (inspect.getdoc(self.fn) or "").split("\n\n")[0]

    def expected_seconds(self, quick: bool) -> float:
        return self.seconds if quick else self.seconds_full


def available_parts() -> dict[str, object]:
    """Every part registered under the ``pmpjax.jobs`` entry-point group, by name, in their
    ``order`` (then alphabetically). Values are entry points; :func:`as_part` loads them."""
    from importlib.metadata import entry_points

    eps = {ep.name: ep for ep in entry_points(group="pmpjax.jobs")}
    return dict(sorted(eps.items(), key=lambda kv: (as_part(kv[1]).order, kv[0])))


def as_part(obj) -> Part:
    """A :class:`Part` from an entry point, a ``module:attr`` string (what workers receive), a
    Part or a plain function (default metadata)."""
    if hasattr(obj, "load"):
        obj = obj.load()
    elif isinstance(obj, str):
        obj = _resolve(obj)
    return obj if isinstance(obj, Part) else Part(obj)


def portable(part):
    """A part as a spawned worker can receive it: an entry point's ``module:attr`` string, or the
    object itself (a module-level function or Part)."""
    return part.value if hasattr(part, "load") else part


def _resolve(spec: str):
    """The object named by ``module:attr``."""
    import importlib

    mod, _, attr = spec.partition(":")
    obj = importlib.import_module(mod)
    for a in attr.split("."):
        obj = getattr(obj, a)
    return obj


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
    ``progress(iterable, total=None, description=...)``, ``counter(description=...)`` (a
    progress callback) and ``figure``/``table`` recorders."""

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

    def counter(self, *, description: str = ""):
        """A function ``advance(done, total)`` that shows ``done`` of ``total`` items of a loop the
        part does not drive itself (a library call's progress callback, e.g. ``fitting.sweep``'s
        ``progress``), on the same display as :meth:`progress`."""
        state: dict = {}

        def advance(done: int, total: int) -> None:
            if "items" not in state:
                state.update(items=iter(self.progress(range(total), total=total, description=description)), shown=0)
            items = state["items"]
            if done >= total:
                for _ in items:  # (the loop's end: its row is removed)
                    pass
                return
            while state["shown"] < int(done) + 1:  # (a loop counts an item when the next one is taken)
                next(items, None)
                state["shown"] += 1

        return advance

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


def run_part(name: str, part, ctx: PartContext) -> dict:
    """Run one part; its results.json entry (``status`` "ok" or "failed", ``seconds``, artefacts;
    ``converged`` [n, total] and ``all_converged`` when its results report the fits' convergence)."""
    from .report import convergence

    t0 = time.perf_counter()
    entry: dict = {"quick": ctx.quick}
    doc = ""
    try:
        part = as_part(part)
        doc = part.doc
        if part.title:
            entry["title"] = part.title
        res = part(ctx)
        entry["status"] = "ok"
        if (c := convergence(res)) is not None:
            entry.update(converged=list(c), all_converged=c[0] == c[1])
        entry["results"] = res
    except Exception as e:  # a failing part is reported; the others still run
        error_file = ctx.out / f"{name}.error.txt"
        try:
            error_file.write_text(traceback.format_exc())
            where = f"traceback in {error_file}"
        except OSError as write_error:
            where = f"its traceback could not be written: {write_error.strerror}"
        entry.update(status="failed", error=f"{type(e).__name__}: {e}")
        from rich.markup import escape

        ctx._console.print(f"[bold red]{name}: FAILED[/] {type(e).__name__}: {escape(str(e))} "  # noqa: SLF001
                           f"({escape(where)})")
    entry["seconds"] = round(time.perf_counter() - t0, 2)
    entry["artefacts"] = [dataclasses.asdict(a) for a in ctx.artefacts]
    entry["doc"] = doc
    return entry


