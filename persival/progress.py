"""Progress of long library calls, and a console for calls made outside the command line.

The library says what it is doing through :func:`progress_bar` (rich's Progress calls:
``add_task``, ``update``, ``advance``, ``tasks``, ``start``/``stop``, context manager); how it is
drawn is the caller's. The command line installs rich's bars for a terminal
(:func:`set_progress_factory`, persival.cli.progress); everywhere else (a log file, CI, the Python
API) a :class:`LineProgress` prints one line per unfinished task at least every ``interval_s``
seconds (a heartbeat thread, so a task that takes minutes per step still shows it is alive) and a
last line when it ends. No library module imports rich.
"""

from __future__ import annotations

import re
import threading
import time
from contextlib import contextmanager
from types import SimpleNamespace

__all__ = ["INTERVAL_S", "LineProgress", "PlainConsole", "progress_bar", "set_progress_factory"]

INTERVAL_S = 30.0


_FACTORY = None


def set_progress_factory(factory) -> None:
    """``factory(console=..., interval_s=...)`` -> a progress object: what :func:`progress_bar` returns."""
    global _FACTORY
    _FACTORY = factory


def progress_bar(*, console=None, interval_s: float = INTERVAL_S):
    """The installed factory's progress (the command line's rich bars), else a :class:`LineProgress`."""
    if _FACTORY is not None:
        return _FACTORY(console=console, interval_s=interval_s)
    return LineProgress(console or PlainConsole(), interval_s)


class PlainConsole:
    """The console of a library call made outside the command line: rich-style markup
    (``[dim]...[/dim]``) left out, one line per print, flushed."""

    is_terminal = False
    _TAG = re.compile(r"(?<!\\)\[/?[a-z#@][^\[\]]*\]")

    def _plain(self, text) -> str:
        return self._TAG.sub("", str(text)).replace("\\[", "[")

    def print(self, *objects, markup: bool = True, **_) -> None:
        text = " ".join(self._plain(o) if markup else str(o) for o in objects)
        print(text, flush=True)

    def rule(self, title: str = "", **_) -> None:
        print(f"--- {self._plain(title)} ---", flush=True)

    @contextmanager
    def status(self, text: str = "", **_):
        self.print(text)
        yield SimpleNamespace(update=lambda *args, **kwargs: None)


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
