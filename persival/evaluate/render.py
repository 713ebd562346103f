"""Pictures of solved arm states: muscles coloured by displacement magnitude, bones in grey.

Reads the state directories written by ``persival simulate`` (state.json + VTU files), so it
needs nothing from the model stage but its files. Each state is drawn off-screen by pyvista
(VTK) in a parallel projection of the sagittal plane, framed to the arm; matplotlib lays the
panels out with titles, muscle labels and one colour bar beside them (a VTK scalar bar sits on
top of the geometry).

The colour is the displacement from the hanging arm (all activations 0) when one of the
states is the hanging arm of the same model: the VTU files' own ``displacement`` is measured
from each muscle's stress-free mesh pose (60 or 90 deg), where a passive muscle that only rode
along with the forearm seems to have moved by centimetres.
"""

from __future__ import annotations

import ctypes.util
import json
import os
import textwrap
from pathlib import Path

import numpy as np

from persival.vocabulary import MUSCLES, check_muscle_names

__all__ = ["read_state_dir", "render_states", "headless_vtk"]

BONE_COLOUR = "#d8d2c4"
# labels left of the arm: the extensors lie behind the humerus, so in a view with flexion to the right
POSTERIOR = ("triceps", "anconeus")


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


def headless_vtk() -> None:
    """Pick VTK's off-screen window directly when there is no display.

    Without DISPLAY, VTK's default X window fails first and logs "bad X server connection"
    before it falls back to EGL; asking for EGL (or OSMesa) up front gives the same picture
    without the message. A user's own choice (VTK_DEFAULT_OPENGL_WINDOW) or a display is left alone.
    """
    if os.environ.get("DISPLAY") or os.environ.get("VTK_DEFAULT_OPENGL_WINDOW"):
        return
    for library, window in (("EGL", "vtkEGLRenderWindow"), ("OSMesa", "vtkOSOpenGLRenderWindow")):
        if ctypes.util.find_library(library):
            os.environ["VTK_DEFAULT_OPENGL_WINDOW"] = window
            return


def _load(directory: Path):
    import pyvista as pv

    summary = read_state_dir(directory)
    muscles = {name: pv.read(directory / f"{name}.vtu") for name in MUSCLES}
    bones = [pv.read(p) for p in sorted(directory.glob("bone_*.vtu"))]
    return summary, muscles, bones


def _reference(states) -> int | None:
    """Index of the hanging arm (all activations 0) among the states, if all share its mesh."""
    for k, (summary, muscles, _) in enumerate(states):
        if any(summary["activations"].values()):
            continue
        same = all(s.get("model_hash") == summary.get("model_hash")
                   and all(m[n].n_points == muscles[n].n_points for n in MUSCLES) for s, m, _ in states)
        return k if same else None
    return None


def _camera(bounds: np.ndarray, height_px: int):
    """Window size and camera of the sagittal view seen from +x (screen right = +y, up = +z) that
    shows exactly the (y, z) box ``bounds`` = [[ylo, zlo], [yhi, zhi]]."""
    (ylo, zlo), (yhi, zhi) = bounds
    width_px = int(round(height_px * (yhi - ylo) / (zhi - zlo)))
    centre = (0.0, 0.5 * (ylo + yhi), 0.5 * (zlo + zhi))
    position = [(centre[0] + 2000.0, centre[1], centre[2]), centre, (0.0, 0.0, 1.0)]
    return (width_px, height_px), position, 0.5 * (zhi - zlo)


def _draw(muscles, bones, scalars, clim, window, camera, scale) -> np.ndarray:
    """One state as an RGB image of the framed sagittal view."""
    import pyvista as pv

    plotter = pv.Plotter(off_screen=True, window_size=window, border=False)
    plotter.set_background("white")
    for bone in bones:
        plotter.add_mesh(bone, color=BONE_COLOUR, smooth_shading=True)
    for name, mesh in muscles.items():
        mesh = mesh.copy()
        mesh.point_data["shown"] = scalars[name]
        plotter.add_mesh(mesh.extract_surface(algorithm="dataset_surface"), scalars="shown", cmap="viridis",
                         clim=clim, smooth_shading=True, show_scalar_bar=False)
    plotter.camera_position = camera
    plotter.enable_parallel_projection()
    plotter.camera.parallel_scale = scale
    image = plotter.screenshot(return_img=True)
    plotter.close()
    return image


def _label_muscles(ax, muscles, frame, fontsize: float) -> None:
    """Name every muscle in a column beside the arm (extensors left, flexors right), a thin
    leader line to the edge of its belly; labels kept apart vertically."""
    (ylo, zlo), (yhi, zhi) = frame
    gap, inset = 0.045 * (zhi - zlo), 0.04 * (yhi - ylo)
    for side in ("left", "right"):
        names = [n for n in muscles if (n in POSTERIOR) == (side == "left")]
        if not names:
            continue
        everything = np.vstack([np.asarray(muscles[n].points) for n in names])
        column = everything[:, 1].min() - inset if side == "left" else everything[:, 1].max() + inset
        rows = []
        for name in names:
            p = np.asarray(muscles[name].points)
            z0, z1 = np.percentile(p[:, 2], [35, 65])
            belly = p[(p[:, 2] >= z0) & (p[:, 2] <= z1)]
            tip = belly[np.argmin(belly[:, 1])] if side == "left" else belly[np.argmax(belly[:, 1])]
            rows.append((name, tip[1], tip[2]))
        rows.sort(key=lambda r: -r[2])
        levels = []
        for _, _, z in rows:  # top down, at least `gap` apart
            levels.append(min(z, levels[-1] - gap) if levels else z)
        for (name, y, z), level in zip(rows, levels):
            ax.annotate(name, xy=(y, z), xytext=(column, level), fontsize=fontsize, va="center",
                        ha="right" if side == "left" else "left", annotation_clip=False,
                        arrowprops={"arrowstyle": "-", "lw": 0.6, "color": "0.25", "shrinkA": 1, "shrinkB": 0})


def _shown_displacement(states, reference):
    """|u| per muscle node of every state: from the hanging arm if there is one, else the VTU's own."""
    if reference is None:
        return [{n: np.asarray(m[n]["displacement_magnitude"]) for n in MUSCLES} for _, m, _ in states]
    base = states[reference][1]
    return [{n: np.linalg.norm(np.asarray(m[n].points) - np.asarray(base[n].points), axis=1) for n in MUSCLES}
            for _, m, _ in states]


def render_states(directories: list[str | Path], out: str | Path, window: tuple[int, int] = (560, 720),
                  muscles: list[str] | str | None = None) -> Path:
    """Render each state into its own panel, side by side, with one shared colour scale.

    ``window[1]`` is the height of a panel's 3D view in pixels (its width follows the arm's
    extent); every panel shows the same box at the same scale. ``muscles``: draw only these
    (default all; e.g. one muscle that the others hide in the side view).
    """
    headless_vtk()
    if not directories:
        raise ValueError("give at least one state directory")
    drawn = check_muscle_names(muscles, "muscles to draw")
    states = [_load(Path(d)) for d in directories]
    reference = _reference(states)
    shown = _shown_displacement(states, reference)
    states = [(summary, {n: m[n] for n in drawn}, bones) for summary, m, bones in states]
    # framed to the muscles (the bones are cut at the frame): every panel has the same height
    # and scale, and its own width
    boxes = [np.array([[p[:, 1].min(), p[:, 2].min()], [p[:, 1].max(), p[:, 2].max()]])
             for p in (np.vstack([np.asarray(m.points) for m in muscles.values()]) for _, muscles, _ in states)]
    zlo, zhi = min(b[0, 1] for b in boxes), max(b[1, 1] for b in boxes)
    pad = 0.04 * (zhi - zlo)
    frames = [np.array([[b[0, 0] - pad, zlo - pad], [b[1, 0] + pad, zhi + pad]]) for b in boxes]
    top = max(1e-9, max(float(values[n].max()) for values, (_, drawn, _) in zip(shown, states) for n in drawn))
    images = []
    for (_, muscles, bones), values, frame in zip(states, shown, frames):
        images.append(_draw(muscles, bones, values, (0.0, top), *_camera(frame, window[1])))
    return _compose(states, images, frames, reference, top, Path(out))


def _title(summary: dict, is_reference: bool, with_model: bool) -> str:
    """A panel's title: the model where the panels differ in it, the activations, the angle, and
    for a held state (``persival simulate --angle``) the brace's moment."""
    alpha = ", ".join(f"{v:.2g}" for v in summary["activations"].values())
    lines = [summary.get("model", "")] if with_model else []
    lines += [f"alpha = ({alpha})", f"elbow {summary['elbow_angle_deg']:.1f} deg{' (reference)' if is_reference else ''}"]
    if "held_at_deg" in summary.get("newton", {}):
        lines.append(f"held: brace {summary['newton']['brace_moment_Nmm']:.0f} N mm")
    return "\n".join(lines)


def _compose(states, images, frames, reference, top, out: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize

    dpi, height_px = 110, images[0].shape[0]
    scale = height_px / (frames[0][1, 1] - frames[0][0, 1])  # pixels per mm, the same in every panel
    # text scaled with the panels, and panels at least as wide as their titles (small pictures)
    fontsize = float(np.clip(9.0 * height_px / 600.0, 6.5, 9.0))
    titles = [_title(summary, k == reference, len({s.get("model") for s, _, _ in states}) > 1)
              for k, (summary, _, _) in enumerate(states)]
    longest = max(len(line) for title in titles for line in title.split("\n"))
    least = (longest + 2) * 0.6 * fontsize * dpi / 72.0 / scale
    spans = [max(f[1, 0] - f[0, 0], least) for f in frames]
    margin = 0.3 * max(spans)  # room for the muscle labels either side of the first panel
    widths = [spans[0] + 2 * margin, *spans[1:], 0.04 * sum(spans)]
    fig, axes = plt.subplots(1, len(states) + 1, figsize=(scale * sum(widths) / dpi + 1.2, images[0].shape[0] / dpi + 0.9),
                             gridspec_kw={"width_ratios": widths}, layout="constrained")
    for k, (ax, (_, muscles, _), image, frame, title) in enumerate(zip(axes, states, images, frames, titles)):
        (ylo, zlo), (yhi, zhi) = frame
        ax.imshow(image, extent=(ylo, yhi, zlo, zhi), interpolation="antialiased")
        half = 0.5 * widths[k]
        ax.set_xlim(0.5 * (ylo + yhi) - half, 0.5 * (ylo + yhi) + half)
        ax.set_ylim(zlo, zhi)
        ax.set_axis_off()
        ax.set_title(title, fontsize=fontsize)
        if k == 0:
            _label_muscles(ax, muscles, frame, fontsize - 1)
    origin = "the hanging arm (alpha = 0)" if reference is not None else "the muscles' mesh poses"
    bar = fig.colorbar(ScalarMappable(Normalize(0.0, top), "viridis"), cax=axes[-1])
    bar.set_label(f"displacement (mm)\nfrom {origin}", fontsize=fontsize)
    bar.ax.tick_params(labelsize=fontsize)
    profile = states[0][0].get("profile")
    title = (f"FE arm{f' ({profile} profile)' if profile else ''}, side view, flexion to the right; "
             f"alpha = activations of ({', '.join(MUSCLES)})")
    fig.suptitle(textwrap.fill(title, max(40, int(fig.get_figwidth() * 72 / (0.55 * fontsize)))), fontsize=fontsize)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=dpi)
    plt.close(fig)
    return out
