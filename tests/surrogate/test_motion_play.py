"""`persival motion play`: a recorded elbow movement (CSV, OpenSim .mot / .sto) through an export.

The export is the small run's (SG -> POD net, its angle model) plus the coarse FE arm's
motion-and-load model (tests/conftest.py, `motion_export`). The recordings are written here.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from persival.cli import app
from persival.deploy.recording import prepare, read_recording

DURATION, RATE_FILE = 4.0, 50.0


def _cycle(lo: float, hi: float):
    """A flexion-extension cycle at rest at both ends (cosine), sampled at 50 Hz."""
    t = np.arange(0.0, DURATION + 1e-9, 1.0 / RATE_FILE)
    w = 2 * np.pi / DURATION
    return t, lo + (hi - lo) * 0.5 * (1 - np.cos(w * t))


def _write_csv(path, t, angle, load=None):
    cols, names = [t, angle], ["time_s", "elbow_angle_deg"]
    if load is not None:
        cols.append(np.full_like(t, load))
        names.append("load_kg")
    np.savetxt(path, np.column_stack(cols), delimiter=",", header=",".join(names), comments="", fmt="%.6f")
    return path


def _write_mot(path, t, angle_deg, in_degrees=True, names=("r_shoulder_elev", "r_elbow_flex", "l_elbow_flex")):
    """An OpenSim motion file: a header up to endheader, then tab-separated labelled columns."""
    values = angle_deg if in_degrees else np.radians(angle_deg)
    shoulder = 0.3 * values
    lines = ["Coordinates", "version=1", f"nRows={len(t)}", f"nColumns={1 + len(names)}",
             f"inDegrees={'yes' if in_degrees else 'no'}", "", "Units are S.I. units (second, meters, Newtons, ...)",
             "endheader", "\t".join(["time", *names])]
    lines += ["\t".join(f"{v:.8f}" for v in (a, s, b, 0.5 * b)) for a, s, b in zip(t, shoulder, values)]
    path.write_text("\n".join(lines) + "\n")
    return path


def _play(tmp_path, export, recording, *extra):
    out = tmp_path / "out"
    result = CliRunner().invoke(app, ["motion", "play", "--input", str(recording), "--out", str(out),
                                      "--artifacts", str(export), *extra])
    assert result.exit_code == 0, result.output
    table = np.genfromtxt(out / "activations.csv", delimiter=",", names=True)
    return table, json.loads((out / "summary.json").read_text()), result.output


def _chain_angle(export, target):
    """The export's own static chain, in Python: angle model -> deformation model -> elbow angle."""
    import onnxruntime as ort

    angle = ort.InferenceSession(str(export / "activation_angle.onnx"), providers=["CPUExecutionProvider"])
    deform = ort.InferenceSession(str(export / "deformation.onnx"), providers=["CPUExecutionProvider"])
    a = angle.run(None, {"elbow_angle_deg": np.asarray(target, np.float32)[:, None]})[0]
    return deform.run(["elbow_angle_deg"], {"activations": np.clip(a, 0, 1)})[0][:, 0]


@pytest.mark.slow
def test_csv_recording_with_a_load(motion_export, tmp_path):
    from persival.model.arm.model_file import load_model_file
    from persival.surrogate.motion_model import MotionActivationModel
    from persival.tables.moment_table import MomentTable

    meta = json.loads((motion_export / "metadata.json").read_text())
    lo, hi = meta["elbow_angle_range_deg"]  # 10 to 140.6 deg; the motion model covers 0 to 160
    t, angle = _cycle(lo - 10.0, hi + 5.0)  # starts at full extension, below the reachable range
    table, summary, output = _play(tmp_path, motion_export, _write_csv(tmp_path / "rec.csv", t, angle, 1.0))
    assert summary["frames"] == 401 and summary["duration_s"] == pytest.approx(DURATION)
    assert set(table.dtype.names) >= {"time_s", "target_deg", "achieved_deg", *meta["muscles"]}
    # clamping: the recording's frames outside [lo, hi] (the smoothing moves the edges by a frame at most)
    grid = np.arange(401) / 100.0
    raw = (lo - 10.0) + (hi + 5.0 - lo + 10.0) * 0.5 * (1 - np.cos(2 * np.pi * grid / DURATION))
    outside = int(((raw < lo) | (raw > hi)).sum())
    assert abs(summary["frames_clamped"] - outside) <= 2 and outside > 40
    assert table["target_deg"].min() >= lo - 1e-3 and table["target_deg"].max() <= hi + 1e-3  # csv: 3 decimals
    assert f"{summary['frames_clamped']} clamped" in output
    # velocity from the recording: the cosine's derivative where the arm is inside the range
    inside = (raw > lo + 5) & (raw < hi - 5)
    v_true = (hi + 5.0 - lo + 10.0) * 0.5 * (2 * np.pi / DURATION) * np.sin(2 * np.pi * grid / DURATION)
    assert np.abs(table["velocity_deg_s"][inside] - v_true[inside]).max() < 0.5
    # the activations are the motion model's for (angle, velocity, acceleration, 1 kg), float32 apart
    table_file = Path(__file__).parents[1] / "data" / "moments_coarse.npz"
    spec, model_hash = load_model_file(None)
    model = MotionActivationModel.from_table(MomentTable.load(table_file, model_hash, complete=True), spec)
    rows = np.column_stack([table["target_deg"], table["velocity_deg_s"], table["acceleration_deg_s2"],
                            np.ones(len(table))])
    expected, feasible = model.predict(rows)
    got = np.column_stack([table[m] for m in meta["muscles"]])
    assert np.abs(got - expected)[feasible].max() < 2e-3  # csv rounding of velocity / acceleration
    assert (table["holds"].astype(bool) == feasible).mean() > 0.99
    # 1 kg cannot be held near full flexion statically; the flexors rise with the angle there
    assert summary["frames_not_holdable"] == int((~feasible).sum())
    biceps = table["biceps"]
    assert biceps[np.argmax(table["target_deg"])] > biceps[np.argmin(table["target_deg"])] + 0.3
    # achieved = the drawn arm's angle: the export's static chain at the target, within its own error
    chain = _chain_angle(motion_export, table["target_deg"])
    assert np.abs(table["achieved_deg"] - chain).max() < 2e-3
    assert summary["angle_error_deg"]["max"] == pytest.approx(np.abs(chain - table["target_deg"]).max(), abs=2e-3)
    assert (tmp_path / "out" / "motion.png").stat().st_size > 20_000


def test_mot_in_radians_and_sto_with_a_chosen_column(motion_export, tmp_path):
    t, angle = _cycle(30.0, 120.0)
    csv_table, csv_summary, _ = _play(tmp_path / "csv", motion_export, _write_csv(tmp_path / "rec.csv", t, angle))
    mot = _write_mot(tmp_path / "rec.mot", t, angle, in_degrees=False)
    assert read_recording(mot).column == "r_elbow_flex"  # the right arm of the two elbow columns
    mot_table, mot_summary, _ = _play(tmp_path / "mot", motion_export, mot)
    assert mot_summary["column"] == "r_elbow_flex" and mot_summary["recording"]["angle_units"].startswith("rad")
    assert np.abs(mot_table["target_deg"] - csv_table["target_deg"]).max() < 1e-3
    assert mot_summary["frames_clamped"] == 0 == csv_summary["frames_clamped"]
    # .sto in degrees, OpenSim 4 names; --column picks the left arm (half the angle here)
    sto = _write_mot(tmp_path / "rec.sto", t, angle, names=("shoulder_elv_r", "elbow_flex_r", "elbow_flex_l"))
    assert read_recording(sto).column == "elbow_flex_r"
    left, summary, _ = _play(tmp_path / "sto", motion_export, sto, "--column", "elbow_flex_l", "--load", "0.5")
    assert summary["column"] == "elbow_flex_l" and summary["load_kg"]["source"] == "--load"
    assert np.abs(left["target_deg"] - np.clip(0.5 * csv_table["target_deg"], 10.0, None)).max() < 0.5
    assert np.all(left["load_kg"] == 0.5)


def test_resampling_smooths_noise_and_any_rate(tmp_path):
    """A 250 Hz recording with 1 deg of noise: 100 Hz frames, the noise smoothed out, no lag."""
    rng = np.random.default_rng(0)
    t = np.arange(0.0, 2.0, 0.004)
    clean = 60 + 30 * np.sin(2 * np.pi * 0.5 * t)
    path = _write_csv(tmp_path / "noisy.csv", t, clean + rng.normal(0, 1.0, len(t)))
    motion = prepare(read_recording(path), (0.0, 160.0))
    assert np.allclose(np.diff(motion.time_s), 0.01)
    truth = 60 + 30 * np.sin(2 * np.pi * 0.5 * motion.time_s)
    assert np.abs(motion.target_deg - truth)[10:-10].max() < 0.8  # the raw noise reaches +-3 deg
    assert np.abs(motion.target_deg - truth).mean() < 0.2


@pytest.mark.parametrize("text, message", [
    ("time_s,shoulder\n0,1\n1,2\n", "which column is the elbow angle"),
    ("time_s,elbow_angle_deg\n0,10\n1,20\n0.5,30\n", "time does not increase at frame 3"),
    ("time_s,elbow_angle_deg\n0,10\n1,nan\n", "not a finite number"),
    ("time_s,elbow_angle_deg\n0,10\n1,abc\n", "is not a number"),
    ("elbow_angle_deg\n10\n20\n", "no time column"),
    ("time_s,elbow_angle_deg\n0,10\n", "at least 2"),
    ("time_s,elbow_angle_deg,load_kg\n0,10,1\n1,20,-1\n", "negative"),
])
def test_bad_recordings_are_refused(tmp_path, text, message):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(ValueError, match=message):
        read_recording(path)


def test_mot_without_endheader_and_no_frame_in_range(tmp_path):
    path = tmp_path / "bad.mot"
    path.write_text("Coordinates\ninDegrees=yes\ntime\tr_elbow_flex\n0\t10\n")
    with pytest.raises(ValueError, match="endheader"):
        read_recording(path)
    t, angle = _cycle(150.0, 170.0)
    with pytest.raises(ValueError, match="no frame lies inside the model's reachable range 10.0 to 140.0"):
        prepare(read_recording(_write_mot(tmp_path / "far.mot", t, angle)), (10.0, 140.0))


def _with_load_input(export: Path, folder: Path, kg_to_deg: float = -3.0) -> Path:
    """A copy of the export whose deformation graph takes `load_kg` (as a model that solves the
    elbow's equilibrium with the load does): here its angle simply shifts by kg_to_deg per kg."""
    import shutil

    import onnx
    from onnx import TensorProto, helper, numpy_helper

    shutil.copytree(export, folder)
    model = onnx.load(folder / "deformation.onnx")
    graph = model.graph
    for node in graph.node:
        node.output[:] = ["angle_unloaded" if o == "elbow_angle_deg" else o for o in node.output]
    graph.input.append(helper.make_tensor_value_info("load_kg", TensorProto.FLOAT, ["batch", 1]))
    # optional, as the exported structured model's: an initializer of the input's name is its default (0 kg)
    graph.initializer.extend([numpy_helper.from_array(np.zeros((1, 1), np.float32), "load_kg"),
                              numpy_helper.from_array(np.array([[kg_to_deg]], np.float32), "kg_to_deg")])
    graph.node.extend([helper.make_node("Mul", ["load_kg", "kg_to_deg"], ["shift"], name="load_shift"),
                       helper.make_node("Add", ["angle_unloaded", "shift"], ["elbow_angle_deg"], name="load_add")])
    onnx.save(model, folder / "deformation.onnx")
    meta = json.loads((folder / "metadata.json").read_text())
    meta["models"]["deformation"]["inputs"]["load_kg"] = [None, 1]
    meta["models"]["deformation"]["variants"] = {"float32": meta["models"]["deformation"]["variants"]["float32"]}
    (folder / "metadata.json").write_text(json.dumps(meta))
    return folder


def test_a_deformation_model_that_takes_the_load_draws_the_loaded_arm(motion_export, tmp_path):
    import onnxruntime as ort

    export = _with_load_input(motion_export, tmp_path / "export")
    t, angle = _cycle(40.0, 100.0)
    table, summary, _ = _play(tmp_path, export, _write_csv(tmp_path / "rec.csv", t, angle), "--load", "2")
    # drawn: the static effort (motion model at zero velocity and acceleration, 2 kg) and the load
    motion = ort.InferenceSession(str(export / "activation_motion.onnx"), providers=["CPUExecutionProvider"])
    rows = np.column_stack([table["target_deg"], 0 * table["target_deg"], 0 * table["target_deg"],
                            np.full(len(table), 2.0)]).astype(np.float32)
    static = np.clip(motion.run(["activations"], {"motion": rows})[0], 0, 1)
    original = ort.InferenceSession(str(motion_export / "deformation.onnx"), providers=["CPUExecutionProvider"])
    expected = original.run(["elbow_angle_deg"], {"activations": static})[0][:, 0] - 6.0
    assert np.abs(table["achieved_deg"] - expected).max() < 2e-3
    assert summary["models"]["deformation"] == "deformation.onnx"
