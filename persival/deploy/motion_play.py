"""A recorded movement through an export's models: `persival motion play` (docs/viewer.md).

Per frame of the prepared recording (:mod:`persival.deploy.recording`): the motion-and-load
model's activations for (angle, velocity, acceleration, load), whether the muscles can produce
the required moment (its ``moment_deficit_Nmm`` output is zero), and the arm drawn for the frame.
A deformation model without a load input is drawn at its own least-effort activations for the
target angle (``activation_angle.onnx``): fed the loaded activations, the unloaded arm would flex
further than the target (the "jump"). One that takes the load (``load_kg``: it solves the
elbow's equilibrium with the load in the hand) is fed the static effort (the motion model at
zero velocity and acceleration) and the load, and draws the loaded arm. The achieved angle is
the drawn state's elbow angle; its distance from the target is the model chain's own error, and
the activations reported are the motion model's, load and inertia included.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from persival.deploy.artifacts import DeployedModel
from persival.deploy.recording import PreparedMotion, Recording, prepare

__all__ = ["reachable_range", "play_motion", "play_recording", "write_outputs"]

_CHUNK = 256  # deformation rows per call: positions of 256 states of a large arm stay small


def reachable_range(model: DeployedModel) -> tuple[float, float]:
    """Angles every model of the export covers: the deformation's reachable range, the angle
    model's and the motion model's."""
    meta = model.metadata
    ranges = [meta.get("elbow_angle_range_deg"), model.angle_range,
              (meta["models"].get("activation_motion") or {}).get("range_deg")]
    ranges = [r for r in ranges if r]
    if not ranges:
        raise ValueError("this export has no elbow-angle range (no activation model): it cannot play a movement")
    lo, hi = max(float(r[0]) for r in ranges), min(float(r[1]) for r in ranges)
    if not lo < hi:
        raise ValueError(f"this export's models share no angle range ({ranges})")
    return lo, hi


def _motion_outputs(model: DeployedModel, motion: PreparedMotion) -> tuple[np.ndarray, np.ndarray]:
    """Activations (n, 5) and the moment deficit (n,) N mm (zeros when the graph has none)."""
    rows = np.column_stack([motion.target_deg, motion.velocity_deg_s, motion.acceleration_deg_s2,
                            motion.load_kg]).astype(np.float32)
    names = [o.name for o in model.motion.get_outputs()]
    wanted = ["activations"] + (["moment_deficit_Nmm"] if "moment_deficit_Nmm" in names else [])
    out = model.motion.run(wanted, {"motion": rows})
    deficit = out[1][:, 0] if len(out) > 1 else np.zeros(len(rows), np.float32)
    return out[0].astype(np.float64), deficit.astype(np.float64)


def _drawn_angles(model: DeployedModel, motion: PreparedMotion) -> np.ndarray:
    """The drawn states' elbow angles (see the module docstring), in chunks of _CHUNK frames."""
    session = model.sessions["float32"]
    # the contract says so in metadata.json (an optional input is an initializer too, which
    # onnxruntime does not list among the session's inputs)
    takes_load = model.motion is not None and "load_kg" in model.metadata["models"]["deformation"].get("inputs", {})
    if takes_load:
        static = PreparedMotion(motion.time_s, motion.target_deg, 0 * motion.target_deg, 0 * motion.target_deg,
                                motion.load_kg, motion.clamped, motion.sigma_s)
        drawn = _motion_outputs(model, static)[0]
    else:
        drawn = model.angle.run(None, {"elbow_angle_deg": motion.target_deg[:, None].astype(np.float32)})[0]
    drawn = np.clip(drawn, 0.0, 1.0).astype(np.float32)
    angles = []
    for k in range(0, len(drawn), _CHUNK):
        feeds = {"activations": drawn[k:k + _CHUNK]}
        if takes_load:
            feeds["load_kg"] = motion.load_kg[k:k + _CHUNK, None].astype(np.float32)
        angles.append(session.run(["elbow_angle_deg"], feeds)[0][:, 0])
    return np.concatenate(angles).astype(np.float64)


def play_motion(model: DeployedModel, motion: PreparedMotion) -> dict[str, np.ndarray]:
    """Every frame's activations, holdability, drawn state's angle (see the module docstring)."""
    if model.angle is None:
        raise ValueError("this export has no activation model (activation_angle.onnx): it cannot draw a movement")
    if not model.has_angle:
        raise ValueError("this export's deformation model has no elbow-angle output: it cannot draw a movement")
    if model.motion is not None:
        activations, deficit = _motion_outputs(model, motion)
    elif (motion.load_kg > 0).any():
        raise ValueError("a load needs the motion-and-load model, which this export does not have")
    else:  # static least effort: no velocity, acceleration or load term
        static = model.angle.run(None, {"elbow_angle_deg": motion.target_deg[:, None].astype(np.float32)})[0]
        activations, deficit = static.astype(np.float64), np.zeros(len(motion.time_s))
    return {"time_s": motion.time_s, "target_deg": motion.target_deg, "achieved_deg": _drawn_angles(model, motion),
            "activations": activations, "holds": deficit == 0.0, "deficit_Nmm": deficit, "clamped": motion.clamped,
            "velocity_deg_s": motion.velocity_deg_s, "acceleration_deg_s2": motion.acceleration_deg_s2,
            "load_kg": motion.load_kg}


def play_recording(model: DeployedModel, recording: Recording, load_kg: float | None = None) -> tuple[dict, dict]:
    """(frames, summary) of a recording through the export."""
    if load_kg is not None and model.motion is not None and load_kg > model.max_load_kg:
        raise ValueError(f"--load {load_kg:g} kg: the muscles hold at most {model.max_load_kg:.2f} kg anywhere "
                         "in the range (max_load_kg of the motion model)")
    lo, hi = reachable_range(model)
    motion = prepare(recording, (lo, hi), load_kg)
    frames = play_motion(model, motion)
    error = np.abs(frames["achieved_deg"] - frames["target_deg"])
    peak = frames["activations"].max(axis=0)
    summary = {
        "frames": int(len(motion.time_s)), "duration_s": float(motion.time_s[-1] - motion.time_s[0]),
        "rate_hz": float(1.0 / np.diff(motion.time_s[:2])[0]) if len(motion.time_s) > 1 else None,
        "frames_clamped": int(motion.clamped.sum()), "frames_not_holdable": int((~frames["holds"]).sum()),
        "range_deg": [lo, hi], "column": recording.column, "recording": recording.source,
        "input_frames": int(len(recording.time_s)),
        "smoothing": {"method": "Gaussian-weighted local linear regression on a uniform grid", "sigma_s": motion.sigma_s},
        "load_kg": {"min": float(motion.load_kg.min()), "max": float(motion.load_kg.max()),
                    "source": "--load" if load_kg is not None else recording.source.get("load_column") or "none (0 kg)"},
        "angle_error_deg": {"max": float(error.max()), "mean": float(error.mean())},
        "peak_activations": dict(zip(model.muscles, (float(v) for v in peak))),
        "models": {"motion": "activation_motion.onnx" if model.motion is not None else None,
                   "deformation": model.metadata["models"]["deformation"]["variants"]["float32"]["file"],
                   "export": str(model.folder)},
    }
    return frames, summary


def write_outputs(out: str | Path, frames: dict, summary: dict, muscles: list[str]) -> list[Path]:
    """OUT/activations.csv, OUT/motion.png, OUT/summary.json."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    columns = ["time_s", "target_deg", "achieved_deg", *muscles, "load_kg", "velocity_deg_s", "acceleration_deg_s2",
               "holds", "clamped"]
    table = np.column_stack([frames["time_s"], frames["target_deg"], frames["achieved_deg"], frames["activations"],
                             frames["load_kg"], frames["velocity_deg_s"], frames["acceleration_deg_s2"],
                             frames["holds"].astype(int), frames["clamped"].astype(int)])
    fmt = ["%.4f", "%.3f", "%.3f"] + ["%.5f"] * len(muscles) + ["%.3f", "%.3f", "%.2f", "%d", "%d"]
    np.savetxt(out / "activations.csv", table, fmt=fmt, delimiter=",", header=",".join(columns), comments="")
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    return [out / "activations.csv", plot_motion(frames, summary, muscles, out / "motion.png"), out / "summary.json"]


def plot_motion(frames: dict, summary: dict, muscles: list[str], path: Path) -> Path:
    """Target vs achieved angle (clamped frames shaded, frames that cannot be held marked) over the
    five activations."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from persival.figures import save_figure

    t = frames["time_s"]
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(10, 6.5), sharex=True, height_ratios=[1, 1.2])
    top.plot(t, frames["target_deg"], "k--", lw=1.2, label="target (recording, smoothed, clamped)")
    top.plot(t, frames["achieved_deg"], color="C0", lw=1.6, label="achieved (drawn arm)")
    for mask, colour, label in ((frames["clamped"], "0.85", "outside the reachable range: clamped"),
                                (~frames["holds"], "#f4a0a0", "the muscles cannot hold this")):
        if mask.any():
            top.fill_between(t, 0, 1, where=mask, color=colour, transform=top.get_xaxis_transform(), label=label, lw=0)
    lo, hi = summary["range_deg"]
    top.set(ylabel="elbow angle (deg)", ylim=(lo - 5, hi + 5),
            title=f"{Path(summary['recording']['file']).name}: {summary['frames']} frames, "
                  f"{summary['frames_clamped']} clamped, {summary['frames_not_holdable']} not holdable; "
                  f"load {summary['load_kg']['max']:g} kg")
    top.legend(fontsize=8, loc="best")
    colours = ["#e76f51", "#f4a261", "#e9c46a", "#2a9d8f", "#8ab17d"]  # the viewer's muscle colours
    for k, name in enumerate(muscles):
        bottom.plot(t, frames["activations"][:, k], color=colours[k % 5], lw=1.5, label=name)
    bottom.set(xlabel="time (s)", ylabel="activation", ylim=(-0.02, 1.02))
    bottom.legend(fontsize=8, ncol=5, loc="upper center")
    for ax in (top, bottom):
        ax.grid(alpha=0.3)
    fig.tight_layout()
    return save_figure(fig, path, dpi=110)
