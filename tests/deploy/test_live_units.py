"""The live modules' arithmetic (persival/deploy/web/src/live/, exercise.js) in Node, without a
browser: tests/viewer/live_units.mjs computes, this judges. Fast: no export, no Chromium."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
pytestmark = pytest.mark.skipif(shutil.which("node") is None, reason="needs node")


@pytest.fixture(scope="module")
def units():
    proc = subprocess.run(["node", str(ROOT / "tests" / "viewer" / "live_units.mjs")], capture_output=True, text=True,
                          timeout=60)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout)


def test_one_euro_filter(units):
    assert units["constant"] == 0 and units["stepMonotone"] and units["stepMax"] <= 100 + 1e-9  # no overshoot
    assert abs(units["stepFinal"] - 100) < 1e-6
    tracker, webcam = units["filter_tracker"], units["filter_webcam"]
    # the tracker's filter: within 1.5 deg of a 0-120-0 deg movement in 2 s (188 deg/s at its fastest)
    assert tracker["lagDeg"] < 1.5 and tracker["velocityErr"] < 40
    # noise on a still arm: less than half of it passes either filter
    for f in (tracker, webcam):
        assert f["stillRmsDeg"] < 0.5 * f["inputRmsDeg"]
    print(f"\nOne Euro on 0-120-0 deg in 2 s at 60 Hz: tracker settings lag at most {tracker['lagDeg']:.2f} deg, "
          f"velocity within {tracker['velocityErr']:.0f} deg/s, acceleration peak {tracker['accelerationPeak']:.0f} "
          f"(true {tracker['accelerationTrue']:.0f}) deg/s^2; webcam settings lag {webcam['lagDeg']:.2f} deg; "
          f"a still arm's noise rms {tracker['inputRmsDeg']:.2f} -> {tracker['stillRmsDeg']:.2f} / "
          f"{webcam['stillRmsDeg']:.2f} deg")


def test_elbow_angle_geometry(units):
    assert units["straight"] == 0 and abs(units["rightAngle"] - 90) < 1e-12 and units["degenerate"] is None
    assert max(abs(d) for d in units["quaternions"]) < 1e-9  # any upper arm, any forearm twist
    assert units["unit"] == [None, None, [1, 0, 0, 0], None]  # not unit, not 4 numbers, normalised, NaN


def test_tracker_messages(units):
    m = units["messages"]
    assert m["angle"] == {"angle": 87.5, "t": 12.5}
    assert abs(m["quaternions"]["angle"] - 60) < 1e-9 and abs(m["axis"]["angle"] - 60) < 1e-9
    for bad in ("notJson", "array", "string", "nan", "badTime", "notUnit", "badAxis", "neither", "relayError"):
        assert set(m[bad]) == {"error"}, bad
    assert m["status"] == {"status": {"type": "status", "publishers": 1}}


def test_repetitions_and_the_exercise_csv(units):
    reps = units["reps"]
    assert len(reps) == 3 and units["noReps"] == 0
    for r in reps:
        assert 2.5 < r["duration"] <= 3.0 and r["low"] < 23 and r["high"] > 109 and r["mean"] < r["peak"]
    assert [r["notHeld"] for r in reps] == [0, 5, 0]  # 4.0 to 4.2 s at 30 Hz, in the second curl
    csv = units["csv"]
    assert csv["header"] == "time_s,elbow_angle_deg,load_kg,target_deg,measured_deg"
    assert csv["column"] == "elbow_angle_deg" and csv["load"] == [1.5] * 10
    assert csv["angle"] == [20 + k for k in range(10)]
    assert csv["time"][0] == 0.1 and all(b > a for a, b in zip(csv["time"], csv["time"][1:]))
