"""Transverse sections of solved arm states: where muscles meet bones, seen along the humerus.

A side view cannot tell a belly lying on a bone from one passing through it; a section across
the upper arm can. Each state directory (``persival simulate``) becomes a panel with the
outlines of the chosen muscles' surfaces and of the bones (their shapes: the humerus widens to
its epicondyles) cut by the planes z = const (upper-arm frame: humerus along +z, anterior +y,
hinge axis +x), one colour per height (bones thick and pale) and one line style per muscle.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from persival.evaluate.render import headless_vtk, read_state_dir
from persival.vocabulary import check_muscle_names

__all__ = ["render_sections"]

STYLES = ("-", "--", ":", "-.", (0, (5, 1, 1, 1)))  # one per muscle, in vocabulary order


def _outline(surface, z: float) -> np.ndarray:
    """Segments (n, 2, 2) in the (y, x) plane where ``surface`` (pyvista PolyData) crosses z."""
    cut = surface.slice(normal="z", origin=(0.0, 0.0, z))
    if cut.n_points == 0:
        return np.zeros((0, 2, 2))
    lines = np.asarray(cut.lines).reshape(-1, 3)[:, 1:]  # [2, i, j] per segment
    points = np.asarray(cut.points)[:, [1, 0]]
    return points[lines]


def render_sections(directories: list[str | Path], heights_mm: list[float], out: str | Path,
                    muscles: list[str] | str | None = None) -> Path:
    """One panel per state: outlines of ``muscles`` (default all) and the bones at each height."""
    headless_vtk()
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import pyvista as pv
    from matplotlib.collections import LineCollection
    from matplotlib.lines import Line2D

    if not directories:
        raise ValueError("give at least one state directory")
    if not heights_mm or not all(np.isfinite(heights_mm)):
        raise ValueError(f"give one or more finite heights (mm along the humerus), got {heights_mm}")
    chosen = check_muscle_names(muscles, "muscles to draw")
    fig, axes = plt.subplots(1, len(directories), figsize=(5.4 * len(directories), 3.0), layout="constrained",
                             squeeze=False)
    for ax, directory in zip(axes[0], directories):
        directory = Path(directory)
        summary = read_state_dir(directory)
        bones = [pv.read(p) for p in sorted(directory.glob("bone_*.vtu"))]
        surfaces = [pv.read(directory / f"{name}.vtu").extract_surface(algorithm="dataset_surface") for name in chosen]
        for k, z in enumerate(heights_mm):
            colour = f"C{k}"
            for bone in bones:
                segments = _outline(bone.extract_surface(algorithm="dataset_surface"), z)
                # in the height's colour: a bone's outline changes with the height (the humerus's flare)
                ax.add_collection(LineCollection(segments, colors=colour, linewidths=3.5, alpha=0.3))
            for surface, style in zip(surfaces, STYLES):
                ax.add_collection(LineCollection(_outline(surface, z), colors=colour, linewidths=1.2, linestyles=style))
        ax.autoscale()
        ax.set_aspect("equal")
        ax.set_xlabel("y (mm, anterior)")
        ax.set_ylabel("x (mm, lateral)")
        held = " (held)" if "held_at_deg" in summary.get("newton", {}) else ""
        ax.set_title(f"{summary.get('model', '')}\nelbow {summary['elbow_angle_deg']:.1f} deg{held}", fontsize=8)
        keys = [Line2D([], [], color=f"C{k}", label=f"z = {z:g} mm") for k, z in enumerate(heights_mm)]
        if len(chosen) > 1:
            keys += [Line2D([], [], color="0.2", linestyle=style, label=name) for name, style in zip(chosen, STYLES)]
        keys.append(Line2D([], [], color="0.2", linewidth=3.5, alpha=0.3, label="bones"))
        ax.legend(handles=keys, fontsize=7, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    fig.suptitle(f"sections across the upper arm ({', '.join(chosen)})", fontsize=9)
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
