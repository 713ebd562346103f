"""Pictures of solved arm states: muscles coloured by displacement magnitude, bones in grey.

Reads the state directories written by ``persival simulate`` (state.json + VTU files), so it
needs nothing from the model stage but its files. Off-screen pyvista (VTK); one panel per state.
"""

from __future__ import annotations

import json
from pathlib import Path

from persival.vocabulary import MUSCLES


def read_state_dir(directory: str | Path) -> dict:
    """The summary (state.json) of a state directory, with a clear error if it is not one."""
    directory = Path(directory)
    summary = directory / "state.json"
    if not summary.is_file():
        raise FileNotFoundError(f"{directory} is not a state directory (no state.json; write one with `persival simulate`)")
    missing = [name for name in MUSCLES if not (directory / f"{name}.vtu").is_file()]
    if missing:
        raise FileNotFoundError(f"{directory}: missing muscle files {missing}")
    return json.loads(summary.read_text())


def render_states(directories: list[str | Path], out: str | Path, window: tuple[int, int] = (560, 720)) -> Path:
    """Render each state into its own panel, side by side, with one shared colour scale."""
    import numpy as np
    import pyvista as pv

    if not directories:
        raise ValueError("give at least one state directory")
    summaries = [read_state_dir(d) for d in directories]
    meshes = []
    for d in directories:
        d = Path(d)
        muscles = [pv.read(d / f"{name}.vtu").extract_surface(algorithm="dataset_surface") for name in MUSCLES]
        bones = [pv.read(p) for p in sorted(d.glob("bone_*.vtu"))]
        meshes.append((muscles, bones))
    everything = [m.points for muscles, bones in meshes for m in (*muscles, *bones)]
    lo = np.min([p.min(axis=0) for p in everything], axis=0)
    hi = np.max([p.max(axis=0) for p in everything], axis=0)
    top = max(float(np.max(m["displacement_magnitude"])) for muscles, _ in meshes for m in muscles)
    plotter = pv.Plotter(off_screen=True, shape=(1, len(directories)),
                         window_size=(window[0] * len(directories), window[1]), border=False)
    for k, ((muscles, bones), summary) in enumerate(zip(meshes, summaries)):
        plotter.subplot(0, k)
        for bone in bones:
            plotter.add_mesh(bone, color="#d8d2c4", smooth_shading=True)
        for muscle in muscles:
            plotter.add_mesh(
                muscle, scalars="displacement_magnitude", cmap="viridis", clim=(0.0, top), smooth_shading=True,
                scalar_bar_args={"title": "displacement (mm)", "vertical": False} if k == 0 else None,
                show_scalar_bar=(k == 0),
            )
        activations = ", ".join(f"{v:.2g}" for v in summary["activations"].values())
        plotter.add_text(f"elbow {summary['elbow_angle_deg']:.1f} deg\nactivations ({activations})", font_size=11)
        # the sagittal plane seen from +x (flexion to the right), every panel at the same scale
        centre = 0.5 * (lo + hi)
        distance = 1.15 * max(hi[1] - lo[1], hi[2] - lo[2]) / (2.0 * np.tan(np.radians(15.0)))
        plotter.camera_position = [(centre[0] + distance, centre[1], centre[2]), tuple(centre), (0.0, 0.0, 1.0)]
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    plotter.screenshot(out)
    plotter.close()
    return out
