"""Figures of the evaluation stage: error hot-spot maps on the biceps, training histories, alpha_opt.

The hot-spot map (the paper's figure of where the network errs) colours every biceps surface
node by its mean error against the SG over the same random activations, one panel per network
(the paper net after a short and after its full training, the POD net), each panel on its own
colour scale (the panels' errors differ by orders of magnitude), drawn with off-screen
pyvista at the reference configuration; matplotlib's 3-D trisurf stands in if pyvista is not
installed or VTK cannot render (no off-screen OpenGL), and a warning says which and why.
"""

from __future__ import annotations

import shutil
import warnings
from pathlib import Path

import numpy as np

from persival.figures import save_figure

__all__ = ["biceps_surface", "hotspot_errors", "plot_hotspots", "collect_stage_figures"]


def biceps_surface(surfaces, name: str = "biceps") -> tuple[np.ndarray, np.ndarray]:
    """(points (n, 3), triangles (k, 3) local indices) of one muscle of concatenated surfaces."""
    k = surfaces.names.index(name)
    sl = surfaces.nodes_of(name)
    t0 = surfaces.triangle_starts[k]
    tri = surfaces.triangles[t0: t0 + surfaces.triangle_counts[k]] - sl.start
    return surfaces.reference_points[sl], tri


def hotspot_errors(predict, net_surfaces, sg, n: int = 500, seed: int = 7, muscle: str = "biceps") -> np.ndarray:
    """Mean over ``n`` random activations of each ``muscle`` node's error |x_net - x_SG| (mm)."""
    alpha = np.random.default_rng(seed).uniform(0.0, 1.0, (n, 5))
    total = np.zeros(sg.surfaces.node_counts[sg.surfaces.names.index(muscle)])
    for rows in np.array_split(np.arange(n), max(1, n // 100)):
        ref = sg.predict(alpha[rows])[:, sg.surfaces.nodes_of(muscle)]
        got = np.asarray(predict(alpha[rows]))[:, net_surfaces.nodes_of(muscle)]
        total += np.linalg.norm(got - ref, axis=2).sum(axis=0)
    return total / n


def _top(values: np.ndarray) -> float:
    """A panel's own colour-scale top: its largest node error (1 mm for an all-zero map)."""
    return float(np.max(values)) or 1.0


def _pyvista_panels(points, triangles, maps: dict[str, np.ndarray], path: Path) -> None:
    from persival.evaluate.render import headless_vtk

    headless_vtk()  # before pyvista: no "bad X server connection" on a machine without a display
    import pyvista as pv

    pv.OFF_SCREEN = True
    faces = np.column_stack([np.full(len(triangles), 3), triangles]).ravel()
    plotter = pv.Plotter(off_screen=True, shape=(1, len(maps)), window_size=(420 * len(maps), 640), border=False)
    for k, (label, values) in enumerate(maps.items()):
        plotter.subplot(0, k)
        mesh = pv.PolyData(np.asarray(points, dtype=float), faces)
        # each panel its own scale bar: pyvista shares a bar between meshes of one title, so the titles differ
        name = f"mean error (mm), {label}"
        mesh[name] = values
        plotter.add_mesh(mesh, scalars=name, cmap="inferno", clim=(0.0, _top(values)), smooth_shading=True,
                         scalar_bar_args={"title": "mean error (mm)" + " " * k, "vertical": False, "n_labels": 4,
                                          "fmt": "%.2g"})
        plotter.add_text(f"{label}\nmean {values.mean():.3f} mm, max {values.max():.3f} mm", font_size=10)
        plotter.view_vector((1.0, 0.0, 0.0), viewup=(0.0, 0.0, 1.0))
        plotter.reset_camera()
    plotter.screenshot(str(path))
    plotter.close()


def _matplotlib_panels(points, triangles, maps: dict[str, np.ndarray], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(4.2 * len(maps), 6))
    for k, (label, values) in enumerate(maps.items()):
        ax = fig.add_subplot(1, len(maps), k + 1, projection="3d")
        face_values = values[triangles].mean(axis=1)
        surf = ax.plot_trisurf(points[:, 0], points[:, 1], points[:, 2], triangles=triangles, cmap="inferno",
                               linewidth=0, antialiased=False)
        surf.set_array(face_values)
        surf.set_clim(0.0, _top(values))
        ax.set_title(f"{label}\nmean {values.mean():.3f} mm, max {values.max():.3f} mm", fontsize=9)
        ax.view_init(elev=0, azim=0)
        ax.set_axis_off()
        fig.colorbar(surf, ax=ax, shrink=0.5, label="mean error (mm)")
    save_figure(fig, path)


def plot_hotspots(points, triangles, maps: dict[str, np.ndarray], path: str | Path, skipped: dict | None = None) -> Path:
    """One panel per entry of ``maps`` (label -> per-node mean error, mm), each with its own colour
    scale from 0 to its largest error: a shared scale let one poorly trained net (tens of mm) turn
    the trained ones (a few mm) into one flat colour. Each panel's mean and max are in its title.

    Where pyvista cannot draw it, matplotlib does; the reason goes into a RuntimeWarning and,
    given the evaluation's ``skipped`` dict, into ``skipped["hotspots_pyvista"]``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        _pyvista_panels(points, triangles, maps, path)
        return path
    except ImportError as exc:  # pyvista is optional for this figure
        why = f"pyvista is not installed ({exc})"
    except Exception as exc:  # e.g. no off-screen OpenGL (no display, no EGL or OSMesa), or a VTK error
        why = f"pyvista could not render it ({type(exc).__name__}: {exc})"
    warnings.warn(f"hot-spot figure {path.name}: {why}; drawn with matplotlib instead", RuntimeWarning, stacklevel=2)
    if skipped is not None:
        skipped["hotspots_pyvista"] = f"{why}; {path.name} drawn with matplotlib instead"
    _matplotlib_panels(points, triangles, maps, path)
    return path


def collect_stage_figures(run, folder: Path) -> dict[str, Path]:
    """The training histories and alpha_opt(Theta) of the earlier stages, copied (or drawn) into ``folder``."""
    from persival.surrogate.plots import plot_activation_model, plot_training_history

    folder.mkdir(parents=True, exist_ok=True)
    out = {}
    for label, net in run.networks.items():
        target = folder / f"history_{label}.png"
        source = run.layout.network(label) / "history.png"
        if source.is_file():
            shutil.copyfile(source, target)
        elif net.history:
            plot_training_history(net.history, target, f"{label} network")
        else:
            continue
        out[f"history_{label}"] = target
    source = run.layout.activation_model.with_suffix(".png")
    target = folder / "activation_model.png"
    if source.is_file():
        shutil.copyfile(source, target)
        out["activation_model"] = target
    elif run.activation_model is not None:
        out["activation_model"] = plot_activation_model(run.activation_model, target, run.source_label)
    return out
