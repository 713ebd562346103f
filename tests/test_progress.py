"""The progress of FE solves as the CLI shows it (persival.model.arm.progress), without solving."""

import io
import time

from rich.console import Console

from persival.model.arm.progress import ConsoleProgress, SolveTracker


def test_tracker_without_callback_is_silent():
    tracker = SolveTracker(None)
    assert tracker.muscle("biceps") is None  # the solver then runs exactly as without progress


def test_tracker_reports_every_load_step():
    reports = []
    tracker = SolveTracker(reports.append, "rest state")
    step = tracker.muscle("triceps", 0.6, 0.8)
    step(0.5)
    tracker.phase = "joint equilibrium"
    tracker.joint(2, 45.0, -1.5e3)
    tracker.muscle("biceps")(1.0)
    assert [r.load_steps for r in reports] == [1, 2]
    assert reports[0].load_fraction == 0.7 and "triceps, prestretch 70 %" in str(reports[0])
    assert str(reports[1]).startswith("joint iteration 2: trying elbow 45.0 deg (moment residual -1.5e+03 N mm before); biceps")


def test_lines_when_not_a_terminal_also_while_a_step_takes_long():
    out = io.StringIO()
    console = Console(file=out, force_terminal=False, width=200)
    with ConsoleProgress(console, None, "FE: hanging", every_s=0.4) as report:
        tracker = SolveTracker(report)
        time.sleep(0.45)
        tracker.muscle("biceps")(0.25)  # printed: 0.4 s since the start
        time.sleep(2.2)  # no report: the tick says how long the step has taken
    lines = out.getvalue().splitlines()
    assert lines[0].startswith("  FE: hanging: joint iteration 0") and "biceps load step t = 0.25" in lines[0]
    assert len(lines) >= 3 and all("s on the next step" in line for line in lines[1:])


def test_progress_bar_prints_lines_to_a_log_file_with_a_heartbeat():
    from persival.cli.progress import rich_progress_bar as progress_bar
    from persival.progress import LineProgress

    out = io.StringIO()
    console = Console(file=out, force_terminal=False, width=200)
    with progress_bar(console=console, interval_s=0.3) as bar:
        assert isinstance(bar, LineProgress)
        task = bar.add_task("campaign", total=4)
        bar.update(task, advance=1, info="1 done")  # the first update prints at once
        time.sleep(0.8)  # nothing happens: the heartbeat still prints
        bar.advance(task, 3)  # done: a last line
    lines = out.getvalue().splitlines()
    assert lines[0].startswith("  campaign: 1/4 1 done, 0:00 elapsed")
    assert len(lines) >= 3 and lines[-1].startswith("  campaign: 4/4")
    assert sum(line.startswith("  campaign: 1/4") for line in lines) >= 2  # heartbeat lines while stuck at 1
    terminal = Console(file=io.StringIO(), force_terminal=True)
    assert not isinstance(progress_bar(console=terminal), LineProgress)


def test_a_solve_still_setting_up_says_so_not_starting_then():
    """Before the first report (meshing, caches) a log shows the label and the time so far."""
    out = io.StringIO()
    console = Console(file=out, force_terminal=False, width=200)
    with ConsoleProgress(console, None, "FE: hanging", every_s=0.4):
        time.sleep(1.6)
    lines = out.getvalue().splitlines()
    assert lines and all(line.startswith("  FE: hanging: setting up, ") and line.endswith(" s so far") for line in lines)
    assert "starting" not in out.getvalue()
