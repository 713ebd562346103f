"""Progress of an arm solve: what ``ArmModel.solve(..., progress=)`` reports, and a console reporter.

An arm state takes up to a minute and a half on the quick profile, most of it in the muscles'
load stepping. The natural heartbeat is the solver's accepted load step (a few Newton
iterations of one muscle, well under a second to a few seconds): the tracker turns it, the
joint iteration in theta and the rest-state continuation into one :class:`SolveProgress`.
Reporting never changes what is solved.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

__all__ = ["SolveProgress", "SolveTracker", "ConsoleProgress"]


@dataclass(frozen=True)
class SolveProgress:
    """One report of an arm solve in progress."""

    phase: str  # "rest state" (each muscle's prestretch switched on) or "joint equilibrium"
    muscle: str  # the muscle being solved
    load_fraction: float  # where that muscle's solve is: 0 -> 1 (prestretch share in the rest state)
    joint_iteration: int  # Newton iterations on the elbow angle so far
    theta_deg: float  # the elbow angle being tried
    moment_residual: float  # N mm at the last solved angle (nan before the first)
    load_steps: int  # accepted load steps of every muscle so far
    elapsed_s: float

    def __str__(self) -> str:
        if self.phase == "rest state":
            return (f"rest state of the mesh poses: {self.muscle}, prestretch {100 * self.load_fraction:.0f} % "
                    f"({self.load_steps} load steps, {self.elapsed_s:.0f} s)")
        residual = "" if math.isnan(self.moment_residual) else f" (moment residual {self.moment_residual:.1e} N mm before)"
        return (f"joint iteration {self.joint_iteration}: trying elbow {self.theta_deg:.1f} deg{residual}; "
                f"{self.muscle} load step t = {self.load_fraction:.2f} ({self.load_steps} load steps, {self.elapsed_s:.0f} s)")


class SolveTracker:
    """Collects the pieces of one solve and calls ``callback(SolveProgress)`` at every load step.

    Without a callback every method is a no-op and :meth:`muscle` returns None, so the solver
    is called exactly as without progress.
    """

    def __init__(self, callback: Callable[[SolveProgress], None] | None, phase: str = "joint equilibrium") -> None:
        self.callback = callback
        self.phase = phase
        self.joint_iteration, self.theta_deg, self.moment_residual = 0, math.nan, math.nan
        self.load_steps = 0
        self.t0 = time.perf_counter()

    def joint(self, iteration: int, theta_deg: float, moment_residual: float = math.nan) -> None:
        self.joint_iteration, self.theta_deg, self.moment_residual = iteration, float(theta_deg), float(moment_residual)

    def muscle(self, name: str, start: float = 0.0, end: float = 1.0) -> Callable[[float], None] | None:
        """The solver's ``progress(t)`` for one muscle solve; t is mapped onto [start, end]."""
        if self.callback is None:
            return None

        def step(t: float) -> None:
            self.load_steps += 1
            self.callback(SolveProgress(self.phase, name, start + t * (end - start), self.joint_iteration,
                                        self.theta_deg, self.moment_residual, self.load_steps,
                                        time.perf_counter() - self.t0))

        return step


class ConsoleProgress:
    """The CLI's progress callback, as a context manager around a solve::

        with console.status("FE: ...") as status, ConsoleProgress(console, status, "FE") as report:
            arm.solve(alpha, progress=report)

    Every report updates the rich ``status`` live. A load step can take longer than the 10 s a
    user should wait for a sign of life (its failed tries, cut and retried, report nothing), so
    a background tick adds the time spent since the last report. Where the output is not a
    terminal (a log file, CI) the live status is invisible: a line is printed at most every
    ``every_s`` seconds instead.
    """

    def __init__(self, console, status=None, label: str = "", every_s: float = 6.0) -> None:
        self.console, self.status, self.every_s = console, status, every_s
        self.prefix = f"{label}: " if label else ""
        self.text = None  # no report yet: the solve is still setting up (mesh, caches, the first load step)
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._since = self._printed = time.perf_counter()
        self._thread = threading.Thread(target=self._tick, daemon=True)

    def __enter__(self) -> ConsoleProgress:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()

    def __call__(self, progress: SolveProgress) -> None:
        with self._lock:
            self.text, self._since = f"{self.prefix}{progress}", time.perf_counter()
            self._show(self.text)

    def _tick(self) -> None:
        while not self._stop.wait(1.0):
            with self._lock:
                waited = time.perf_counter() - self._since
                if waited >= self.every_s / 2:
                    self._show(f"{self.prefix}setting up, {waited:.0f} s so far" if self.text is None
                               else f"{self.text}, then {waited:.0f} s on the next step")

    def _show(self, text: str) -> None:
        if self.status is not None:
            self.status.update(text.replace("[", "\\["))  # rich's escape: an activation list is not markup
        now = time.perf_counter()
        if (self.status is None or not self.console.is_terminal) and now - self._printed >= self.every_s:
            self.console.print(f"  {text}", highlight=False, markup=False, soft_wrap=True)  # a log line, not wrapped at 80
            self._printed = now
