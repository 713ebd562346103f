"""Reading muscle surfaces out of external FE results: VTU / XDMF (meshio) and LS-DYNA d3plot
(lasso-python).

A *selector* picks one part of a result file, as a json-able dict:

- ``{"cell_data": NAME, "value": V}``: cells whose cell-data array NAME equals V (meshio; e.g.
  ``gmsh:physical``, a material id, PerSival's own ``surface_id``);
- ``{"cell_set": NAME}``: a named cell set (meshio; XDMF / Gmsh / Abaqus sets);
- ``{"part_id": P}``: an LS-DYNA part id (d3plot);
- ``{}``: every cell of the file.

The selected part's surface is extracted (``persival.campaign.surface``); its nodes are
numbered by increasing node index of the file, so every state of one FE model yields the same
node order as its reference.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from persival.campaign.surface import SurfaceError, boundary_triangles, compact

__all__ = ["ResultImportError", "PartSurface", "parse_selector", "read_surfaces", "MESHIO_SUFFIXES"]

MESHIO_SUFFIXES = (".vtu", ".xdmf", ".xmf", ".vtk", ".msh")


class ResultImportError(ValueError):
    """A result file that cannot be read as asked."""


@dataclass
class PartSurface:
    node_ids: np.ndarray  # (n,) node indices in the file
    points: np.ndarray  # (n, 3) positions in the file's state (or reference)
    triangles: np.ndarray  # (k, 3) into points


def parse_selector(text: str) -> dict:
    """Selector from its command-line form: ``cell_data:NAME=VALUE``, ``cell_set:NAME``,
    ``part:ID`` or ``all``."""
    text = text.strip()
    if text == "all":
        return {}
    kind, sep, rest = text.partition(":")
    if sep and kind == "cell_data" and "=" in rest:
        name, _, value = rest.rpartition("=")
        try:
            v: int | float | str = int(value)
        except ValueError:
            try:
                v = float(value)
            except ValueError:
                v = value
        return {"cell_data": name, "value": v}
    if sep and kind == "cell_set" and rest:
        return {"cell_set": rest}
    if sep and kind == "part":
        try:
            return {"part_id": int(rest)}
        except ValueError:
            pass
    raise ValueError(f"bad part selector {text!r}; use cell_data:NAME=VALUE, cell_set:NAME, "
                     "part:ID or all")


def _format_of(path: Path) -> str:
    name = path.name.lower()
    if name.startswith("d3plot") or path.suffix.lower() == ".d3plot":
        return "d3plot"
    if path.suffix.lower() in MESHIO_SUFFIXES:
        return "meshio"
    raise ResultImportError(f"{path}: unknown result format (expected d3plot or one of "
                       f"{', '.join(MESHIO_SUFFIXES)})")


def read_surfaces(path: str | Path, selectors: dict[str, dict], *, reference: bool = False,
                  displacement_field: str | None = None) -> dict[str, PartSurface]:
    """The surface of every selected part of one result file.

    ``reference``: read the undeformed geometry (d3plot: initial node coordinates; meshio: the
    file's points without displacement). ``displacement_field`` (meshio): a point-data array to
    add to the points, for codes that write the reference mesh plus displacements; without it
    the points are taken to be the current positions.
    """
    path = Path(path)
    if not path.exists():
        raise ResultImportError(f"result file {path} does not exist")
    if not selectors:
        raise ResultImportError("no parts selected")
    fmt = _format_of(path)
    try:
        if fmt == "d3plot":
            return _read_d3plot(path, selectors, reference)
        return _read_meshio(path, selectors, reference, displacement_field)
    except SurfaceError as exc:
        raise ResultImportError(f"{path}: {exc}") from None


# ---- meshio ----------------------------------------------------------------------------------
def _read_meshio(path, selectors, reference, displacement_field) -> dict[str, PartSurface]:
    import meshio

    try:
        mesh = meshio.read(path)
    except Exception as exc:  # meshio raises many types for malformed files
        raise ResultImportError(f"{path}: meshio could not read it ({type(exc).__name__}: {exc})") from None
    points = np.asarray(mesh.points, dtype=np.float64)
    if points.shape[1] == 2:
        points = np.column_stack([points, np.zeros(len(points))])
    if displacement_field and not reference:
        if displacement_field not in mesh.point_data:
            raise ResultImportError(f"{path}: no point data {displacement_field!r}; it has "
                               f"{sorted(mesh.point_data)}")
        points = points + np.asarray(mesh.point_data[displacement_field], dtype=np.float64)[:, :3]
    out = {}
    for name, sel in selectors.items():
        blocks = _meshio_select(mesh, sel, path, name)
        tris = boundary_triangles(blocks)
        nodes, local = compact(tris)
        out[name] = PartSurface(nodes, points[nodes], local)
    return out


def _meshio_select(mesh, sel: dict, path, name) -> list[tuple[str, np.ndarray]]:
    if not sel:
        return [(b.type, b.data) for b in mesh.cells]
    if "cell_data" in sel:
        key = sel["cell_data"]
        if key not in mesh.cell_data:
            raise ResultImportError(f"{path}: part {name!r} selects cell data {key!r}, the file has "
                               f"{sorted(mesh.cell_data) or 'none'}")
        blocks = []
        for block, values in zip(mesh.cells, mesh.cell_data[key]):
            mask = np.asarray(values).reshape(len(block.data), -1)[:, 0] == sel["value"]
            if mask.any():
                blocks.append((block.type, block.data[mask]))
        if not blocks:
            raise ResultImportError(f"{path}: part {name!r}: no cell has {key} = {sel['value']!r}")
        return blocks
    if "cell_set" in sel:
        key = sel["cell_set"]
        if key not in mesh.cell_sets:
            raise ResultImportError(f"{path}: part {name!r} selects cell set {key!r}, the file has "
                               f"{sorted(mesh.cell_sets) or 'none'}")
        blocks = []
        for block, idx in zip(mesh.cells, mesh.cell_sets[key]):
            if idx is not None and len(idx):
                blocks.append((block.type, block.data[np.asarray(idx)]))
        return blocks
    raise ResultImportError(f"part {name!r}: selector {sel} is not a meshio selector "
                       "(cell_data + value, or cell_set)")


# ---- LS-DYNA d3plot --------------------------------------------------------------------------
def _read_d3plot(path, selectors, reference) -> dict[str, PartSurface]:
    try:
        from lasso.dyna import ArrayType, D3plot, FilterType
    except ImportError:
        raise ResultImportError(
            "reading LS-DYNA d3plot files needs lasso-python: pip install 'persival[dyna]'"
        ) from None
    for name, sel in selectors.items():
        if set(sel) != {"part_id"}:
            raise ResultImportError(f"part {name!r}: d3plot parts are selected by part id "
                               f"({{'part_id': P}}), got {sel}")
    try:
        # Only the last state's positions are needed (lasso reads state data lazily by filter).
        d3 = D3plot(str(path), state_array_filter=[ArrayType.node_displacement],
                    state_filter={-1})
    except Exception as exc:
        raise ResultImportError(f"{path}: lasso could not read it ({type(exc).__name__}: {exc})") from None
    arrays = d3.arrays
    if reference or ArrayType.node_displacement not in arrays:
        if not reference:
            raise ResultImportError(f"{path}: the d3plot has no node displacements (states)")
        points = np.asarray(arrays[ArrayType.node_coordinates], dtype=np.float64)
    else:
        # lasso's "node_displacement" holds the current coordinates of every state.
        points = np.asarray(arrays[ArrayType.node_displacement][-1], dtype=np.float64)
    out = {}
    for name, sel in selectors.items():
        pid = int(sel["part_id"])
        blocks = []
        if ArrayType.element_solid_node_indexes in arrays:
            mask = d3.get_part_filter(FilterType.SOLID, [pid], for_state_array=False)
            blocks += _dyna_solids(np.asarray(arrays[ArrayType.element_solid_node_indexes])[mask])
        if ArrayType.element_shell_node_indexes in arrays:
            mask = d3.get_part_filter(FilterType.SHELL, [pid], for_state_array=False)
            blocks += _dyna_shells(np.asarray(arrays[ArrayType.element_shell_node_indexes])[mask])
        if not blocks:
            ids = arrays.get(ArrayType.part_ids)
            raise ResultImportError(f"{path}: part {name!r}: no solid or shell element of part id "
                               f"{pid} (part ids: {None if ids is None else np.asarray(ids).tolist()})")
        tris = boundary_triangles(blocks)
        nodes, local = compact(tris)
        out[name] = PartSurface(nodes, points[nodes], local)
    return out


def _dyna_solids(conn: np.ndarray) -> list[tuple[str, np.ndarray]]:
    """LS-DYNA stores every solid with 8 nodes: a tetrahedron as N1 N2 N3 N4 N4 N4 N4 N4."""
    if len(conn) == 0:
        return []
    conn = conn.astype(np.int64)
    tet = (conn[:, 3:] == conn[:, 3:4]).all(axis=1)
    hexa = (np.diff(np.sort(conn, axis=1), axis=1) != 0).all(axis=1)
    if not (tet | hexa).all():
        raise SurfaceError("the part has degenerate solids other than tetrahedra (wedges or "
                           "pyramids), which this importer does not handle")
    blocks = []
    if tet.any():
        blocks.append(("tetra", conn[tet, :4]))
    if hexa.any():
        blocks.append(("hexahedron", conn[hexa]))
    return blocks


def _dyna_shells(conn: np.ndarray) -> list[tuple[str, np.ndarray]]:
    """Shells have 4 nodes; a triangle repeats its third node."""
    if len(conn) == 0:
        return []
    conn = conn.astype(np.int64)
    tri = conn[:, 2] == conn[:, 3]
    blocks = []
    if tri.any():
        blocks.append(("triangle", conn[tri, :3]))
    if (~tri).any():
        blocks.append(("quad", conn[~tri]))
    return blocks
