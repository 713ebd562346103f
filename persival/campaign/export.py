"""Exporting a campaign's states as a VTU series with a ParaView collection (.pvd).

Every file holds all muscle surfaces as one triangle mesh, with cell and point data
``surface_id`` (the index of the muscle in ``surfaces.json``) and point data ``displacement``
(current minus reference position). ``states.csv`` lists each exported state's id, activations,
elbow angle and file; ``surfaces.json`` gives the part selectors with which the external-command
simulator reads these files back, so an exported campaign is also a valid external result set.
"""

from __future__ import annotations

import csv
import json
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from persival.campaign.store import CampaignStore
from persival.vocabulary import MUSCLES

__all__ = ["export_vtu"]


def _mesh(ref, positions: dict[str, np.ndarray] | None):
    import meshio

    points, cells, cell_ids, point_ids, disp = [], [], [], [], []
    offset = 0
    for k, (name, surf) in enumerate(ref.surfaces.items()):
        cur = surf.reference_points if positions is None else positions[name]
        points.append(cur)
        disp.append(cur - surf.reference_points)
        cells.append(("triangle", surf.triangles + offset))
        cell_ids.append(np.full(len(surf.triangles), k, dtype=np.int32))
        point_ids.append(np.full(surf.n_nodes, k, dtype=np.int32))
        offset += surf.n_nodes
    return meshio.Mesh(
        np.concatenate(points), cells,
        point_data={"surface_id": np.concatenate(point_ids), "displacement": np.concatenate(disp)},
        cell_data={"surface_id": cell_ids},
    )


def export_vtu(store: CampaignStore | str | Path, out_dir: str | Path, states=None,
               progress: bool = False) -> dict:
    """Write ``reference.vtu``, one ``state_<id>.vtu`` per done state (or the given state rows),
    ``campaign.pvd``, ``states.csv`` and ``surfaces.json`` into ``out_dir``."""
    import meshio

    if not isinstance(store, CampaignStore):
        store = CampaignStore.open(store)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    ref = store.reference
    done = store.done_mask()
    rows = np.flatnonzero(done) if states is None else np.atleast_1d(np.asarray(states, dtype=np.int64))
    not_done = [int(r) for r in rows if not done[r]]
    if not_done:
        raise ValueError(f"states {not_done[:10]} are not done and cannot be exported")
    ids, acts, angles = store.ids, store.activations, store.elbow_angles()

    meshio.write(out / "reference.vtu", _mesh(ref, None))
    (out / "surfaces.json").write_text(json.dumps({
        "surfaces": ref.names,
        "selectors": {n: {"cell_data": "surface_id", "value": k} for k, n in enumerate(ref.names)},
    }, indent=1))
    collection = ET.Element("VTKFile", type="Collection", version="0.1")
    datasets = ET.SubElement(collection, "Collection")
    iterator = _tracked(rows, "export") if progress else rows
    # Read surfaces in blocks of states: one zarr call per surface and block.
    block = 64
    files = []
    with (out / "states.csv").open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["id", *MUSCLES, "elbow_angle_deg", "file"])
        cache: dict[int, dict[str, np.ndarray]] = {}
        for pos, r in enumerate(iterator):
            r = int(r)
            if r not in cache:
                chunk = rows[pos:pos + block]
                data = {n: store.surface_positions(n, chunk) for n in ref.names}
                cache = {int(c): {n: data[n][j] for n in ref.names} for j, c in enumerate(chunk)}
            name = f"state_{int(ids[r]):06d}.vtu"
            meshio.write(out / name, _mesh(ref, cache[int(r)]))
            ET.SubElement(datasets, "DataSet", timestep=str(int(ids[r])), part="0", file=name)
            w.writerow([int(ids[r]), *(repr(float(a)) for a in acts[r]), repr(float(angles[r])), name])
            files.append(name)
    ET.ElementTree(collection).write(out / "campaign.pvd", xml_declaration=True, encoding="utf-8")
    return {"out": str(out), "states": len(files), "files": files}


def _tracked(items, description: str):
    """``items`` one by one, advancing a progress bar (persival.progress)."""
    from persival.progress import progress_bar

    with progress_bar() as bar:
        task = bar.add_task(description, total=len(items))
        for item in items:
            yield item
            bar.advance(task)
