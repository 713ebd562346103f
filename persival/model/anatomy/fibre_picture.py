"""A picture of a muscle's fibre field: two orthogonal side views, arrows coloured by position.

Each view looks along one of the directions square to the muscle's line (origin to insertion):
along the hinge axis (the sagittal view of the arm) and square to both. The outline is the
mesh's boundary nodes in grey, arrows are the fibre directions at a sample of cell centroids
(coloured by their position along the muscle, 0 at the origin), the black line is the centre
line the tissue layout is measured along, and the attachment faces are marked (origin blue,
insertion red).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from persival.model.fe.mesh import Tet10Mesh

__all__ = ["draw_fibres"]

ARROWS = 400  # at most this many arrows per view


def draw_fibres(mesh: Tet10Mesh, centre_line: np.ndarray, name: str, path: Path, hinge_axis: np.ndarray) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from persival.figures import save_figure

    along = centre_line[-1] - centre_line[0]
    along /= np.linalg.norm(along)
    side = np.asarray(hinge_axis, dtype=float) - (np.asarray(hinge_axis, dtype=float) @ along) * along
    if np.linalg.norm(side) < 1e-6:  # a muscle along the hinge axis: any square direction
        side = np.cross(along, [0.0, 0.0, 1.0] if abs(along[2]) < 0.9 else [1.0, 0.0, 0.0])
    side /= np.linalg.norm(side)
    third = np.cross(along, side)
    centroids = mesh.points[mesh.cells[:, :4]].mean(axis=1)
    rng = np.random.default_rng(0)
    sample = rng.choice(mesh.n_cells, min(ARROWS, mesh.n_cells), replace=False)
    boundary = mesh.surface_nodes()
    extent = float(np.ptp(mesh.points @ along))
    fig, axes = plt.subplots(2, 1, figsize=(12, 5.5))  # one above the other: a muscle is long and thin
    for ax, (across, label) in zip(axes, ((third, "looking along the hinge axis"),
                                          (side, "turned 90 deg about the muscle"))):
        def plane(x, a=across, o=centre_line[0]):
            return np.column_stack([(x - o) @ along, (x - o) @ a])

        outline = plane(mesh.points[boundary])
        ax.scatter(outline[:, 0], outline[:, 1], s=2, c="0.6", lw=0)
        for nodes, colour in ((mesh.node_sets["origin"], "tab:blue"), (mesh.node_sets["insertion"], "tab:red")):
            face = plane(mesh.points[nodes])
            ax.scatter(face[:, 0], face[:, 1], s=6, c=colour, lw=0)
        base = plane(centroids[sample])
        arrows = plane(mesh.cell_data["fibre"][sample] + centre_line[0])
        colours = ax.quiver(base[:, 0], base[:, 1], arrows[:, 0], arrows[:, 1], mesh.cell_data["arclength"][sample],
                            cmap="viridis", angles="xy", scale_units="xy", scale=1.0 / (0.03 * extent), width=0.0015,
                            clim=(0.0, 1.0))
        line = plane(centre_line)
        ax.plot(line[:, 0], line[:, 1], "k-", lw=1)
        ax.set_aspect("equal")
        ax.set_xlabel("along the line origin -> insertion (mm)")
        ax.set_ylabel("across (mm)")
        ax.set_title(label, fontsize=9)
    fig.colorbar(colours, ax=axes, label="position along the muscle (0 origin, 1 insertion)", shrink=0.8)
    fig.suptitle(f"{name}: fibre directions ({mesh.n_cells} tet10, {mesh.n_nodes} nodes); attachment faces: origin blue, "
                 "insertion red", fontsize=10)
    return save_figure(fig, path)
