"""Live input in the viewer, in real headless Chromium, driven by tests/viewer/live_tracker.mjs.

One browser for the module (starting Chromium costs seconds on 2 cores): bad input (no camera,
permission denied, a camera image with nobody in it, a tracker that sends garbage or stops), a
0-120-0 deg movement in 2 s at 60 Hz streamed through the server's relay by the documented
client (docs/examples/tracker_client.py), and an exercise followed through the tracker whose CSV
`persival motion play` reads back to the same activations. Screenshots go to
$PERSIVAL_VIEWER_SHOTS (or the test's tmp folder).
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import numpy as np
import pytest
from test_viewer import CHROMIUM, missing  # noqa: F401  (the same requirements as the viewer's tests)

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "tests" / "viewer" / "live_tracker.mjs"
CLIENT = ROOT / "docs" / "examples" / "tracker_client.py"
RATE_HZ, LO, HI, PERIOD_S = 60, 0.0, 120.0, 2.0
PLAN = {"lo": 25, "hi": 110, "period": 2, "reps": 2, "load": 1.0}

pytestmark = [pytest.mark.skipif(bool(missing), reason=f"needs {', '.join(missing)}"), pytest.mark.slow]


def blank_video(path: Path, width: int = 320, height: int = 240, frames: int = 10) -> Path:
    """A grey camera image (YUV 4:2:0, the fake camera's format): nobody in it."""
    with path.open("wb") as f:
        f.write(f"YUV4MPEG2 W{width} H{height} F10:1 Ip A1:1 C420jpeg\n".encode())
        for _ in range(frames):
            f.write(b"FRAME\n" + bytes([160]) * (width * height) + bytes([128]) * (width * height // 2))
    return path


@pytest.fixture(scope="module")
def live_run(motion_export, tmp_path_factory):
    from test_server import run_page_script


    shots = Path(os.environ.get("PERSIVAL_VIEWER_SHOTS") or tmp_path_factory.mktemp("live_shots"))
    shots.mkdir(parents=True, exist_ok=True)
    work = tmp_path_factory.mktemp("live")
    movement = ["--lo", str(LO), "--hi", str(HI), "--period", str(PERIOD_S), "--rate", str(RATE_HZ)]
    # the user follows the target a little short of it at both ends (the exercise starts with the first sample)
    exercise = ["--lo", str(PLAN["lo"] - 5), "--hi", str(PLAN["hi"] - 5), "--period", str(PLAN["period"]),
                "--cycles", str(PLAN["reps"]), "--rate", str(RATE_HZ)]
    config = {"video": str(blank_video(work / "blank.y4m")), "python": sys.executable, "client": str(CLIENT),
              "movement": movement, "movementMs": 1000 * PERIOD_S, "exercise": {"plan": PLAN, "client": exercise}}
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    result = run_page_script(motion_export, SCRIPT, str(shots), json.dumps(config), timeout=300, env=env)
    result["shots"], result["work"] = str(shots), work
    return result


def _chain(export: Path, target: np.ndarray) -> np.ndarray:
    """The drawn arm's angle for target angles: angle model, then deformation model (Python)."""
    import onnxruntime as ort

    angle = ort.InferenceSession(str(export / "activation_angle.onnx"), providers=["CPUExecutionProvider"])
    deform = ort.InferenceSession(str(export / "deformation.onnx"), providers=["CPUExecutionProvider"])
    a = angle.run(None, {"elbow_angle_deg": target.astype(np.float32)[:, None]})[0]
    return deform.run(["elbow_angle_deg"], {"activations": np.clip(a, 0, 1)})[0][:, 0].astype(float)


def test_bad_camera_input_says_so_and_nothing_breaks(live_run):
    r = live_run
    assert r["pageErrors"] == [] and r["consoleErrors"] == [], (r["pageErrors"], r["consoleErrors"])
    missing_camera, denied = r["camera"]["NotFoundError"], r["camera"]["NotAllowedError"]
    assert not missing_camera["ok"] and missing_camera["shown"] == "no camera found"
    assert not denied["ok"] and "permission was denied" in denied["shown"]
    assert missing_camera["source"] == denied["source"] == "off"  # back to off, nothing half-started
    # a camera that shows nobody: the tracker ran on its frames, found no one, said so; the arm stayed
    assert r["blank"]["ok"] and r["blankWebcam"]["counts"]["frames"] >= 3
    assert r["blankWebcam"]["counts"]["persons"] == 0
    assert r["blankMessage"].startswith("no person found in the camera image")
    assert abs(r["afterBlank"] - r["beforeBlank"]) < 1e-6
    print(f"\nno camera: {missing_camera['shown']!r}; denied: {denied['shown']!r}; blank camera "
          f"({r['blankWebcam']['counts']['frames']} frames tracked): {r['blankMessage']!r}; screenshots in {r['shots']}")


def test_tracker_movement_is_followed(live_run, motion_export):
    r = live_run
    log = r["log"]
    assert "sent: 121 samples" in r["clientOutput"]
    assert len(log) >= 0.6 * 121  # a sample that arrives while the page is busy gives way to the next
    measured = np.array([e["measured"] for e in log])
    target = np.array([e["target"] for e in log])
    achieved = np.array([e["achieved"] for e in log])
    models = json.loads((motion_export / "metadata.json").read_text())["models"]
    lo = max(models["activation_angle"]["range_deg"][0], models["activation_motion"]["range_deg"][0])
    hi = min(models["activation_angle"]["range_deg"][1], models["activation_motion"]["range_deg"][1])
    inside = (measured >= lo) & (measured <= hi)
    follow = np.abs(target[inside] - measured[inside])
    # the drawn state is the model chain's for the live angle, exactly (float32)
    chain = _chain(motion_export, target)
    assert np.abs(achieved - chain).max() < 0.05
    drawn_error = np.abs(achieved[inside] - _chain(motion_export, measured[inside]))
    # input to drawn frame: the tracker's send time to the end of the frame that showed it (one clock)
    latency = np.array([e["wallDrawn"] - 1000 * e["t"] for e in log])
    in_page = np.array([e["drawnAt"] - e["arrived"] for e in log])
    times = np.asarray(r["frameTimes"])
    fps = (len(times) - 1) / ((times[-1] - times[0]) / 1000)
    windows = [np.sum((times >= s) & (times < s + 500)) * 2 for s in np.arange(times[0], times[-1] - 500, 250)]
    print(f"\ntracker 0-120-0 deg in 2 s at 60 Hz through the relay: {len(log)} of 121 samples drawn; live angle vs "
          f"sent inside the range {lo:.0f}-{hi:.0f} deg: max {follow.max():.2f}, mean {follow.mean():.2f} deg; drawn "
          f"arm vs the model chain at the sent angle: max {drawn_error.max():.2f} deg; latency send -> drawn frame "
          f"median {np.median(latency):.1f} ms, p95 {np.percentile(latency, 95):.1f} ms (arrival -> frame median "
          f"{np.median(in_page):.1f}, p95 {np.percentile(in_page, 95):.1f}); {fps:.0f} fps while it played "
          f"(lowest half-second {min(windows):.0f}); clamped {r['afterMovement']['live']['counts']['clamped']}")
    assert follow.max() <= 2.0
    assert drawn_error.max() <= 2.0 + 0.05
    assert r["afterMovement"]["live"]["counts"]["clamped"] > 0  # 0 to 10 deg lies outside: counted
    assert fps >= 60


def test_tracker_garbage_and_silence(live_run):
    g = live_run["garbage"]
    assert all("cannot use" in s or "not a possible one" in s for s in g["shown"]), g["shown"]
    assert "not a possible one" in g["shown"][3]  # 1e9 deg: a number, but no elbow's
    assert abs(g["after"] - g["before"]) < 1e-6  # the arm held its last valid state
    assert g["counts"]["implausible"] == 1
    assert abs(g["quaternion"]["measured"] - 90.0) < 1e-3  # twist about the forearm does not enter
    assert "stopped sending" in g["silent"] and "no tracker is connected" in g["closed"]
    assert abs(g["end"] - g["after"]) > 1  # the quaternions moved it; nothing after them did
    print(f"\ngarbage: {g['shown'][0]!r}; silence: {g['silent']!r}; closed: {g['closed']!r}")


def test_exercise_csv_plays_back_to_the_same_activations(live_run, motion_export):
    from persival.deploy.artifacts import DeployedModel
    from persival.deploy.motion_play import play_recording
    from persival.deploy.recording import read_recording

    r = live_run
    assert r["exerciseStart"]["ok"] and r["ghost"] is not None and PLAN["lo"] <= r["ghost"] <= PLAN["hi"]
    ex = r["exercise"]
    assert ex["ok"], ex
    path = Path(r["work"]) / "exercise.csv"
    path.write_text(ex["csv"])
    frames, summary = play_recording(DeployedModel(motion_export), read_recording(path))
    page = np.asarray(ex["activations"], dtype=float).reshape(-1, 5)
    assert page.shape == frames["activations"].shape
    diff = np.abs(page - frames["activations"]).max()
    assert diff <= 1e-6
    assert np.abs(np.asarray(ex["target"]) - frames["target_deg"]).max() < 1e-6
    assert ex["framesNotHeld"] == summary["frames_not_holdable"] and ex["framesClamped"] == summary["frames_clamped"]
    # two repetitions found, each reaching about the streamed 20-105 deg, 2 s long
    reps = ex["reps"]
    assert len(reps) == PLAN["reps"] and r["exerciseTable"] == PLAN["reps"]
    for rep in reps:
        assert abs(rep["lowDeg"] - (PLAN["lo"] - 5)) < 3 and abs(rep["highDeg"] - (PLAN["hi"] - 5)) < 3
        assert abs(rep["duration"] - PLAN["period"]) < 0.3 and 0 < rep["meanEffort"] <= rep["peakEffort"] <= 5
    assert len(ex["liveReps"]) == PLAN["reps"]
    print(f"\nexercise CSV ({summary['frames']} frames) through persival motion play's reader: activations max |diff| "
          f"{diff:.1e}; reps: " + "; ".join(f"{x['lowDeg']:.0f}-{x['highDeg']:.0f} deg {x['duration']:.2f} s effort "
                                           f"{x['peakEffort']:.2f}/{x['meanEffort']:.2f} not held {x['framesNotHeld']}"
                                           for x in reps))
