"""rich's progress bars for the command line: installed as the library's progress factory
(persival.progress), and the bars the commands draw with their own columns. On a terminal a live
bar; written to a file (``make run > run.log``, CI) the library's plain lines, since rich draws
nothing there."""

from __future__ import annotations

from persival.progress import INTERVAL_S, LineProgress, set_progress_factory

__all__ = ["install", "rich_progress_bar"]


def rich_progress_bar(*columns, console=None, interval_s: float = INTERVAL_S, **kwargs):
    """rich's Progress(*columns) on a terminal (default columns: what, bar, count, info, rate,
    elapsed, ETA), a :class:`~persival.progress.LineProgress` elsewhere."""
    from rich.console import Console
    from rich.progress import Progress

    console = console or Console()
    if not console.is_terminal:
        return LineProgress(console, interval_s)
    return Progress(*(columns or _default_columns()), console=console, **kwargs)


def _default_columns() -> tuple:
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        ProgressColumn,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )
    from rich.text import Text

    class FieldsColumn(ProgressColumn):
        """A task's ``info`` field, and its rate where it names a ``rate_unit`` (e.g. states/h)."""

        def render(self, task):
            text = str(task.fields.get("info", "") or "")
            unit = task.fields.get("rate_unit")
            if unit:
                speed = task.finished_speed or task.speed
                per_hour = unit.endswith("/h")
                rate = f"{speed * (3600 if per_hour else 1):,.0f} {unit}" if speed else f"-- {unit}"
                text = f"{text} {rate}".strip()
            return Text(text, style="progress.data.speed")

    return (TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(), FieldsColumn(),
            TimeElapsedColumn(), TextColumn("ETA"), TimeRemainingColumn())


def install() -> None:
    """The library's long calls draw rich bars from now on (the command line calls this once)."""
    set_progress_factory(lambda console=None, interval_s=INTERVAL_S: rich_progress_bar(console=console,
                                                                                        interval_s=interval_s))
