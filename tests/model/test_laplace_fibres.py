"""Laplace fibres (persival.model.anatomy.laplace_fibres) that are finite and unit on any repaired surface,
and the mesh-time check that refuses a muscle whose fibres are not."""

from __future__ import annotations

import numpy as np
import pytest
from surface_files import SPINDLE_LENGTH, model_with_surface, spindle, write_obj
from typer.testing import CliRunner

import persival.model.anatomy.surface_muscle as surface_muscle_module
from persival.cli import app
from persival.model.anatomy.laplace_fibres import laplace_fibres
from persival.model.anatomy.surface_muscle import check_fibres, surface_muscle
from persival.model.arm.body import ArmBody
from persival.model.fe.geometry import box_mesh
from persival.model.fe.mesh import MeshError

COARSE_BICEPS = 16.0  # mm, the coarse profile's biceps element size
INSET = 25.0  # mm from each tip to its end point: the attachment faces cut a tendon stub off behind them


def ring_stack(z, r, ring: int):
    """A closed surface of revolution about +z: a ring of ``ring`` vertices at each (z_i, r_i),
    a pole vertex 0.02 mm beyond each end ring; outward triangles."""
    t = np.linspace(0.0, 2.0 * np.pi, ring, endpoint=False)
    n = len(z)
    rings = np.column_stack([np.outer(r, np.cos(t)).ravel(), np.outer(r, np.sin(t)).ravel(), np.repeat(z, ring)])
    poles = np.array([[0.0, 0.0, z[0] - 0.02], [0.0, 0.0, z[-1] + 0.02]])
    i, j = (a.ravel() for a in np.meshgrid(np.arange(n - 1), np.arange(ring), indexing="ij"))
    a, b, c, d = i * ring + j, i * ring + (j + 1) % ring, (i + 1) * ring + (j + 1) % ring, (i + 1) * ring + j
    j = np.arange(ring)
    low, high = np.full(ring, n * ring), np.full(ring, n * ring + 1)
    faces = np.vstack([np.column_stack([a, b, c]), np.column_stack([a, c, d]),
                       np.column_stack([low, (j + 1) % ring, j]),
                       np.column_stack([high, (n - 1) * ring + j, (n - 1) * ring + (j + 1) % ring])])
    return np.vstack([rings, poles]), faces


def faulty_spindle(tendon: float = 1.5, belly: float = 20.0, ring: int = 16, stations: int = 120):
    """A segmentation's faults on a spindle with thin tendons (radius below the attachment faces'):
    slivers at the poles (a 0.05 mm ring 0.02 mm from each pole, then the tendon's ring), three
    holes in the belly, a repeated triangle and a fin (a third triangle on an edge, non-manifold)."""
    s = np.linspace(0.0, 1.0, stations)
    z = np.concatenate([[0.0], SPINDLE_LENGTH * s, [SPINDLE_LENGTH]])
    r = np.concatenate([[0.05], tendon + (belly - tendon) * np.sin(np.pi * s) ** 2, [0.05]])
    z[1], z[-2] = 0.02, SPINDLE_LENGTH - 0.02
    vertices, faces = ring_stack(z, r, ring)
    holes = [700, 900, 1100]  # on the belly's flanks
    edge = faces[holes[0] + 40, :2]
    fin_tip = vertices[edge].mean(axis=0) * [1.3, 1.3, 1.0]
    faces = np.vstack([np.delete(faces, holes, axis=0), faces[holes[0] + 60], [edge[0], edge[1], len(vertices)]])
    return np.vstack([vertices, fin_tip]), faces


def test_fibres_are_finite_unit_and_along_a_faulty_surface_with_stubs_behind_its_faces(tmp_path):
    """The end points 25 mm inside the tips of 1.5 mm tendons (faces of 4 and 5 mm): the faces wrap
    the tendon and cut the tips off, where phi is exactly 0 or 1 and the fibres were 0 / 0 (10 NaN
    cells on this surface before); they now run along the centre line."""
    write_obj(tmp_path / "faulty.obj", *faulty_spindle())
    model = model_with_surface(tmp_path / "m.toml", "faulty.obj", origin_point=(0.0, 0.0, INSET),
                               insertion_point=(0.0, 0.0, SPINDLE_LENGTH - INSET))
    body = ArmBody.frame(model, "coarse")
    repairs = body.surfaces["biceps"].surface.repairs
    assert repairs["closed small holes"] == 3 and repairs["removed repeated triangles"] == 1
    assert repairs["fixed non-manifold edges (triangles removed)"] == 1
    own = surface_muscle(body.spec.muscle("biceps"), body.surfaces["biceps"], COARSE_BICEPS)
    fibre, placed = own.mesh.cell_data["fibre"], own.placed
    assert np.all(np.isfinite(fibre)) and np.all(np.isfinite(own.mesh.cell_data["arclength"]))
    np.testing.assert_allclose(np.linalg.norm(fibre, axis=1), 1.0, atol=1e-12)
    axis = (placed.insertion - placed.origin) / np.linalg.norm(placed.insertion - placed.origin)
    assert np.abs(fibre @ axis).mean() > 0.9
    stub = own.fibres.fallback
    assert len(stub) > 0  # the tips behind the faces
    assert np.all(fibre[stub] @ axis > 0.99)  # the centre line's direction, origin -> insertion
    along = (own.mesh.points[own.mesh.cells[stub, :4]].mean(axis=1) - placed.origin) @ axis
    assert np.all((along < 5.0) | (along > np.linalg.norm(placed.insertion - placed.origin) - 5.0))  # at the ends only


def test_a_stub_cut_off_behind_a_face_takes_the_centre_lines_direction():
    """A 60 x 4 x 4 mm bar whose origin face is a whole section 10 mm in: the 10 mm behind it is
    joined to the rest through fixed nodes only, phi there is exactly 0 and its gradient vanishes,
    smoothed or not (exactly the NaN of a real biceps before)."""
    mesh = box_mesh((12, 2, 2), size=(60.0, 4.0, 4.0))
    section = np.flatnonzero(np.isclose(mesh.points[:, 0], 10.0))
    fibres = laplace_fibres(mesh, section, mesh.node_sets["x1"])
    x = mesh.points[mesh.cells[:, :4]].mean(axis=1)[:, 0]
    behind = x < 10.0
    assert np.all(fibres.phi[behind] == 0.0)
    # the layer at the face still averages its neighbours' gradients; the one behind has none
    np.testing.assert_array_equal(fibres.fallback, np.flatnonzero(x < 5.0))
    gradient = x >= 5.0  # phi is linear in x from the face on: grad phi along the bar exactly
    np.testing.assert_allclose(fibres.fibre[gradient], np.tile([1.0, 0.0, 0.0], (gradient.sum(), 1)), atol=1e-9)
    # the centre line's slabs sit on the section's centroid to the Kuhn cells' lopsidedness
    np.testing.assert_allclose(fibres.fibre[~gradient], np.tile([1.0, 0.0, 0.0], ((~gradient).sum(), 1)), atol=1e-3)
    np.testing.assert_array_equal(fibres.position[behind], 0.0)


def test_the_check_names_the_cells_without_a_fibre():
    fibre = np.tile([0.0, 0.0, 1.0], (10, 1))
    position = np.linspace(0.0, 1.0, 10)
    check_fibres(fibre, position, "muscle 'biceps'")  # all fine: nothing raised
    fibre[[1, 4, 7]] = np.nan
    with pytest.raises(MeshError, match=r"muscle 'biceps': .* for 3 of 10 cells \(cells 1, 4, 7\)"):
        check_fibres(fibre, position, "muscle 'biceps'")
    fibre = np.tile([0.0, 0.0, 1.0], (100, 1))
    fibre[10:20] = 0.0  # zero length: no direction either
    with pytest.raises(MeshError, match=r"for 10 of 100 cells \(cells 10, 11, 12, 13, 14, \.\.\.\)"):
        check_fibres(fibre, np.zeros(100), "m")
    position[2] = np.nan
    with pytest.raises(MeshError, match=r"for 1 of 10 cells \(cells 2\)"):
        check_fibres(np.tile([0.0, 0.0, 1.0], (10, 1)), position, "m")


def test_persival_mesh_refuses_nan_fibres_and_writes_nothing(tmp_path, monkeypatch):
    """What the fallbacks cannot give a fibre to is one `error:` line, exit 2, naming the cells; the
    --out folder (here already there) stays empty."""
    write_obj(tmp_path / "spindle.obj", *spindle())
    model = model_with_surface(tmp_path / "m.toml", "spindle.obj")
    real = surface_muscle_module.laplace_fibres

    def broken(*args, **kwargs):
        fibres = real(*args, **kwargs)
        fibres.fibre[[3, 5]] = np.nan
        return fibres

    monkeypatch.setattr(surface_muscle_module, "laplace_fibres", broken)
    out = tmp_path / "mesh"
    out.mkdir()
    result = CliRunner().invoke(app, ["mesh", "--model", str(model), "--profile", "coarse", "--out", str(out)])
    assert result.exit_code == 2, result.output
    errors = [line for line in result.output.splitlines() if "error:" in line]
    assert len(errors) == 1 and "muscle 'biceps'" in errors[0] and "(cells 3, 5)" in errors[0]
    assert list(out.iterdir()) == []
