"""Progress that a log file shows.

rich draws its bars only on a terminal; written to a file (``make run > run.log``, CI) a long
stage is silent for minutes. :func:`progress_bar` returns rich's ``Progress`` on a terminal and
otherwise a :class:`LineProgress` with the same calls (``add_task``, ``update``, ``advance``,
``tasks``, context manager) that prints one line per unfinished task at least every
``interval_s`` seconds (a heartbeat thread, so a task that takes minutes per step still shows
it is alive) and a last line when it ends.
"""

from __future__ import annotations

import threading
import time
from types import SimpleNamespace

__all__ = ["progress_bar", "LineProgress", "INTERVAL_S"]

INTERVAL_S = 30.0


def progress_bar(*columns, console=None, interval_s: float = INTERVAL_S, **kwargs):
    """rich's Progress(*columns) on a terminal, a :class:`LineProgress` elsewhere."""
    from rich.console import Console
    from rich.progress import Progress

    console = console or Console()
    if console.is_terminal:
        return Progress(*columns, console=console, **kwargs)
    return LineProgress(console, interval_s)


def _clock(seconds: float) -> str:
    m, s = divmod(int(seconds), 60)
    return f"{m}:{s:02d}"


class LineProgress:
    """A plain-text stand-in for rich's Progress (the calls PerSival makes)."""

    def __init__(self, console, interval_s: float = INTERVAL_S) -> None:
        self.console = console
        self.interval_s = float(interval_s)
        self.tasks: list[SimpleNamespace] = []
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    # ------------------------------------------------------------------ rich's calls
    def add_task(self, description: str, total: float | None = None, completed: float = 0, **fields) -> int:
        with self._lock:
            task = SimpleNamespace(id=len(self.tasks), description=description, total=total, completed=completed,
                                   fields=fields, started=time.perf_counter(), printed=0.0, finished=False)
            self.tasks.append(task)
        return task.id

    def update(self, task_id: int, *, advance: float | None = None, completed: float | None = None,
               total: float | None = None, description: str | None = None, **fields) -> None:
        with self._lock:
            task = self.tasks[task_id]
            if total is not None:
                task.total = total
            if completed is not None:
                task.completed = completed
            if advance is not None:
                task.completed += advance
            if description is not None:
                task.description = description
            task.fields.update(fields)
            done = task.total is not None and task.completed >= task.total
        if done:
            self._finish(task)
        elif time.perf_counter() - task.printed >= self.interval_s:
            self._print(task)

    def advance(self, task_id: int, advance: float = 1) -> None:
        self.update(task_id, advance=advance)

    def start(self) -> None:
        if self._thread is None:
            self._thread = threading.Thread(target=self._heartbeat, name="progress-lines", daemon=True)
            self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=1.0)
            self._thread = None
        for task in list(self.tasks):
            self._finish(task)

    def __enter__(self) -> LineProgress:
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    # ------------------------------------------------------------------ lines
    def line(self, task) -> str:
        count = f"{task.completed:g}/{task.total:g}" if task.total else f"{task.completed:g}"
        info = " ".join(str(v) for v in task.fields.values() if v not in (None, ""))
        return f"  {task.description}: {count}{' ' + info if info else ''}, {_clock(time.perf_counter() - task.started)} elapsed"

    def _print(self, task) -> None:
        task.printed = time.perf_counter()
        self.console.print(self.line(task), highlight=False, markup=False)

    def _finish(self, task) -> None:
        with self._lock:
            if task.finished:
                return
            task.finished = True
        self._print(task)

    def _heartbeat(self) -> None:
        while not self._stop.wait(min(1.0, self.interval_s / 3)):
            now = time.perf_counter()
            for task in list(self.tasks):
                if not task.finished and now - task.printed >= self.interval_s:
                    self._print(task)
