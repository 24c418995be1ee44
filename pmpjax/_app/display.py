"""The main job's display: a rich console with the running parts, the parts done out of those
to run, each finished part's status and the progress bars of loops inside parts."""

from __future__ import annotations

import contextlib


def _DoneOfTotal():  # noqa: N802 - a rich column, built when rich is imported
    """Rich's "done/total" column that shows nothing for a task without a total (a running part
    whose own loops show their counts), instead of "0/?"."""
    from rich.progress import ProgressColumn
    from rich.text import Text

    class DoneOfTotal(ProgressColumn):
        def render(self, task):
            if task.total is None:
                return Text("")
            return Text(f"{int(task.completed)}/{int(task.total)}", style="progress.download")

    return DoneOfTotal()


class Display:
    """The parent's display: a rich console, one line per running part with its elapsed time, the
    parts done out of those to run, a line per finished part with its status, and the progress
    bars of loops inside parts (``ctx.progress``; from workers over a queue)."""

    def __init__(self, enabled: bool):
        import threading

        from rich.console import Console
        from rich.progress import BarColumn, Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

        self.console = Console(stderr=True)
        if not self.console.is_terminal:  # (a log file or a pipe: one line per message, however long)
            self.console.soft_wrap = True
        self.enabled = enabled
        self._lock = threading.RLock()  # (the pump thread and the main thread both change the tasks)
        self._tasks: dict[str, object] = {}
        self._done: set[str] = set()  # (a late "start" from the queue must not bring back a finished part)
        self._inner: dict[str, tuple[str, object]] = {}
        self._n_parts, self._n_done, self._overall = 0, 0, None
        if enabled:
            self._prog = Progress(SpinnerColumn(), TextColumn("{task.description}"), BarColumn(),
                                  _DoneOfTotal(), TimeElapsedColumn(), console=self.console, transient=True)
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

        from .report import part_status

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
