"""Bring your own anatomy (docs/own_anatomy.md): the model file for editing, muscles from surfaces."""

from __future__ import annotations

import json

import numpy as np
import pytest
from surface_files import SPINDLE_LENGTH, model_with_surface, spindle, with_defects, write_obj, write_stl
from typer.testing import CliRunner

from persival.cli import app
from persival.model.anatomy.surface_mesh import volume_mesh
from persival.model.anatomy.surface_muscle import surface_muscle
from persival.model.arm.body import ArmBody
from persival.model.arm.defaults import builtin_model_path
from persival.model.arm.model_file import load_model_file

COARSE_BICEPS = 16.0  # mm, the coarse profile's biceps element size


def test_model_init_writes_the_built_in_model(tmp_path):
    out = tmp_path / "sub" / "my_arm.toml"
    result = CliRunner().invoke(app, ["model", "init", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert out.read_text() == builtin_model_path().read_text()
    assert load_model_file(out)[1] == load_model_file("default")[1]  # the same model, the same provenance


# -- muscles from surfaces -------------------------------------------------------------------------


def oriented(faces) -> set:
    """Triangles as (smallest vertex first) oriented triples: the same triangle however it is rotated."""
    out = set()
    for f in np.asarray(faces).tolist():
        k = f.index(min(f))
        out.add(tuple(f[k:] + f[:k]))
    return out


@pytest.fixture(scope="module")
def surfaces(tmp_path_factory):
    """The spindle as a clean STL, as an OBJ with duplicate vertices, a small hole and flipped
    triangles, and as an OBJ in metres; a model file for each."""
    root = tmp_path_factory.mktemp("surfaces")
    vertices, faces = spindle()
    write_stl(root / "spindle.stl", vertices, faces)
    write_obj(root / "defects.obj", *with_defects(vertices, faces))
    write_obj(root / "spindle_mm.obj", vertices, faces)
    write_obj(root / "spindle_m.obj", vertices / 1000.0, faces)
    models = {
        "stl": model_with_surface(root / "stl.toml", "spindle.stl"),
        "defects": model_with_surface(root / "defects.toml", "defects.obj"),
        "mm": model_with_surface(root / "mm.toml", "spindle_mm.obj"),
        "m": model_with_surface(root / "m.toml", "spindle_m.obj", units="m",
                                insertion_point=(0.0, 0.0, SPINDLE_LENGTH / 1000.0)),
    }
    return {"root": root, "vertices": vertices, "faces": faces, **models}


def test_repairs_are_counted_and_give_back_the_clean_spindle(surfaces):
    stl = ArmBody.frame(surfaces["stl"], "coarse").surfaces["biceps"]
    clean = ArmBody.frame(surfaces["mm"], "coarse").surfaces["biceps"]
    fixed = ArmBody.frame(surfaces["defects"], "coarse").surfaces["biceps"]
    n, m = len(surfaces["vertices"]), len(surfaces["faces"])
    # STL stores every triangle's corners apart: all but the spindle's own vertices merge
    assert stl.vertices_in == 3 * m and stl.surface.repairs["merged duplicate vertices"] == 3 * m - n
    assert sum(stl.surface.repairs.values()) == 3 * m - n and len(stl.surface.faces) == m
    assert sum(clean.surface.repairs.values()) == 0
    assert stl.surface.volume == pytest.approx(clean.surface.volume, rel=1e-6)  # STL: float32 coordinates
    repairs = fixed.surface.repairs
    assert fixed.vertices_in == n + 30 and repairs["merged duplicate vertices"] == 30
    assert repairs["closed small holes"] == 1 and repairs["triangles added (holes)"] == 2
    # winding made consistent with a seed triangle: the 40 flipped ones, or all the others (then all turned outward)
    assert repairs["reoriented triangles"] == 40 or (repairs["reoriented triangles"] == m - 2 - 40
                                                     and repairs["turned outward (triangles)"] == m)
    np.testing.assert_array_equal(fixed.surface.vertices, clean.surface.vertices)  # the user's vertices, in order
    np.testing.assert_array_equal(fixed.surface.source_vertex[:n], np.arange(n))
    kept = oriented(np.delete(surfaces["faces"], [100, 101], axis=0))
    assert kept <= oriented(fixed.surface.faces) and len(fixed.surface.faces) == m
    assert fixed.surface.volume == pytest.approx(clean.surface.volume, rel=2e-3) and fixed.surface.volume > 0


def test_the_surface_is_placed_by_the_minimal_rigid_motion(surfaces):
    body = ArmBody.frame(surfaces["stl"], "coarse")
    placed, muscle = body.surfaces["biceps"], body.spec.muscle("biceps")
    origin, target = np.array(muscle.origin), body.body_end(muscle, muscle.mesh_angle_deg)
    line = (target - origin) / np.linalg.norm(target - origin)
    np.testing.assert_allclose(placed.surface.vertices[-2], origin, atol=1e-9)  # origin_point -> origin
    np.testing.assert_allclose(placed.insertion, origin + SPINDLE_LENGTH * line, atol=1e-9)
    np.testing.assert_allclose(placed.rotation @ placed.rotation.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(placed.rotation) == pytest.approx(1.0)
    # minimal: the rotation axis is square to both lines (no twist about the muscle's line)
    angle_axis = np.array([placed.rotation[2, 1] - placed.rotation[1, 2], placed.rotation[0, 2] - placed.rotation[2, 0],
                           placed.rotation[1, 0] - placed.rotation[0, 1]])
    assert abs(angle_axis @ line) < 1e-9 and abs(angle_axis[2]) < 1e-9
    assert placed.scale == 1.0
    fitted = ArmBody.frame(model_with_surface(surfaces["root"] / "fit.toml", "spindle.stl", scale_to_fit=True), "coarse")
    fit = fitted.surfaces["biceps"]
    assert fit.scale == pytest.approx(np.linalg.norm(target - origin) / SPINDLE_LENGTH)
    np.testing.assert_allclose(fit.insertion, target, atol=1e-9)


def test_laplace_fibres_follow_the_spindle_from_origin_to_insertion(surfaces):
    body = ArmBody.frame(surfaces["defects"], "coarse")
    own = surface_muscle(body.spec.muscle("biceps"), body.surfaces["biceps"], COARSE_BICEPS)
    mesh, placed = own.mesh, own.placed
    line = (placed.insertion - placed.origin) / SPINDLE_LENGTH
    fibre = mesh.cell_data["fibre"]
    np.testing.assert_allclose(np.linalg.norm(fibre, axis=1), 1.0, atol=1e-12)
    along = fibre @ line
    assert along.min() > 0.95 and along.mean() > 0.99  # along the long axis, never backwards
    axial = (mesh.points[mesh.cells[:, :4]].mean(axis=1) - placed.origin) @ line / SPINDLE_LENGTH
    assert np.abs(mesh.cell_data["arclength"] - axial).max() < 0.02  # position: origin 0 -> insertion 1
    assert np.all(np.diff(mesh.cell_data["laplace"][np.argsort(axial)][::50]) > -0.05)
    assert own.fibres.length == pytest.approx(SPINDLE_LENGTH, rel=0.01)
    # the attachment faces: the caps (4 and 5 mm tendon radius: the whole cap of radius 4 and its rim)
    for nodes, point in ((mesh.node_sets["origin"], placed.origin), (mesh.node_sets["insertion"], placed.insertion)):
        assert np.linalg.norm(mesh.points[nodes] - point, axis=1).max() <= 5.0 + 1e-9 and len(nodes) >= 17
    assert own.volume.surface_kept and own.volume.vertices_kept == len(surfaces["vertices"])


def test_a_surface_in_metres_meshes_as_the_same_in_millimetres(surfaces):
    in_mm = ArmBody.frame(surfaces["mm"], "coarse").surfaces["biceps"]
    in_m = ArmBody.frame(surfaces["m"], "coarse").surfaces["biceps"]
    np.testing.assert_array_equal(in_m.surface.vertices, in_mm.surface.vertices)
    a, b = volume_mesh(in_mm.surface, COARSE_BICEPS).mesh, volume_mesh(in_m.surface, COARSE_BICEPS).mesh
    np.testing.assert_array_equal(a.cells, b.cells)
    np.testing.assert_array_equal(a.points, b.points)


def test_persival_mesh_writes_the_muscle_files_and_report(surfaces, tmp_path):
    import meshio
    import pyvista

    out = tmp_path / "mesh"
    result = CliRunner().invoke(app, ["mesh", "--model", str(surfaces["defects"]), "--profile", "coarse", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert "merged duplicate vertices 30" in result.output
    report = json.loads((out / "mesh_report.json").read_text())["muscles"]
    assert list(report) == ["biceps"]  # the muscles with their own surface
    entry = report["biceps"]
    n = len(surfaces["vertices"])
    assert entry["vertices_in"] == n + 30 and entry["vertices_kept_as_nodes"] == n and entry["surface_kept"]
    assert entry["repairs"]["triangles added (holes)"] == 2 and entry["scale"] == 1.0
    # straight-sided tet10 on the kept surface: the mesh's volume is the surface's, exactly
    assert entry["volume_mm3"] == pytest.approx(entry["surface_volume_mm3"], rel=1e-9)
    assert 35.0 <= entry["moment_arm_mm"]["90 deg"] <= 45.0  # SPEC 3.3's biceps range
    vtu = meshio.read(out / "biceps.vtu")
    assert vtu.cells[0].type == "tetra10" and len(vtu.cells[0].data) == entry["tetrahedra"]
    assert len(vtu.points) == entry["nodes_out"]
    assert {"fibre", "region", "laplace", "position", "muscle_fraction"} <= set(vtu.cell_data)
    assert set(np.unique(vtu.cell_data["region"][0])) == {0, 1, 2}  # tendon, blend and belly all present
    surface = pyvista.read(out / "biceps_surface.vtp")
    sources = np.asarray(surface.point_data["source_vertex"])
    assert sorted(sources[sources >= 0].tolist()) == list(range(n))  # every user vertex once, on a node
    assert (out / "biceps.png").stat().st_size > 10_000


@pytest.mark.slow
def test_a_biceps_from_a_surface_is_solved(surfaces):
    """The defects OBJ's biceps in the coarse arm: its FE unit pulls on the line of action (M = T r,
    r = -dL/dtheta exactly, the line tie), with the tension of its active belly."""
    from persival.model.arm.arm_model import ArmModel
    from persival.model.fe.material import MaterialParameters

    model = model_with_surface(surfaces["root"] / "solve.toml", "defects.obj", replace={"fibre_prestretch": "1.0"})
    arm = ArmModel(model, "coarse")
    unit, muscle = arm.units["biceps"], arm.spec.muscle("biceps")
    rest = unit.rest_state()
    assert abs(rest.tension) < 1e-6  # no prestretch: the mesh pose is stress free
    state = unit.solve(muscle.mesh_angle_deg, 0.3)
    assert state.moment == pytest.approx(state.tension * arm.line_moment_arm(muscle, muscle.mesh_angle_deg), rel=1e-9)
    # isometric at the mesh pose: at most what the belly's widest section pulls at the force-length's value there
    p = MaterialParameters()
    force_length = np.exp(-abs((1.0 / p.lambda_opt - 1.0) / p.dW_asc) ** p.nu_asc)
    widest = 0.3 * p.S_max * force_length * np.pi * 20.0**2
    assert 0.2 * widest < state.tension < widest and state.max_volume_change < 0.01


def test_a_fine_noisy_segmentation_is_remeshed_at_the_profiles_size(tmp_path):
    """A biceps-like surface at 1 mm triangles with voxel noise: remeshed (its vertices are not
    kept), about as fine as the built-in biceps of the profile, its volume kept, its fibres along
    its bend."""
    from surface_files import biceps_like

    vertices, faces, origin_end, insertion_end = biceps_like(ring=40, stations=240)
    write_obj(tmp_path / "biceps.obj", vertices, faces)
    model = model_with_surface(tmp_path / "m.toml", "biceps.obj", origin_point=tuple(origin_end + [0.5, -0.3, -1.0]),
                               insertion_point=tuple(insertion_end + [0.4, 0.2, 0.8]))
    body = ArmBody.frame(model, "coarse")
    own = surface_muscle(body.spec.muscle("biceps"), body.surfaces["biceps"], COARSE_BICEPS)
    mesh = own.mesh
    assert not own.volume.surface_kept and own.volume.vertices_kept < 0.01 * len(vertices)
    assert 300 < mesh.n_cells < 3000  # the built-in coarse biceps: about 1000; the surface's noise would give 10 times more
    assert mesh.volume() == pytest.approx(own.placed.surface.volume, rel=0.02)
    line = own.fibres.centre_line
    tangent = np.gradient(line, axis=0)
    tangent /= np.linalg.norm(tangent, axis=1)[:, None]
    arclength = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(line, axis=0), axis=1))])
    nearest = np.clip(np.searchsorted(arclength / arclength[-1], mesh.cell_data["arclength"]), 0, len(line) - 1)
    local = np.einsum("ij,ij->i", mesh.cell_data["fibre"], tangent[nearest])
    assert np.percentile(local, 5) > 0.95 and local.mean() > 0.98
    assert own.fibres.length == pytest.approx(345.0, rel=0.03)


def test_a_surface_that_one_feature_angle_cannot_reparametrize_is_remeshed_at_the_next(tmp_path):
    """The biceps-like surface at 1 mm with 40 duplicate vertices, 25 flipped triangles and a small
    hole, as PLY (float32 coordinates): repaired to a closed manifold (Euler 2) on which gmsh's
    split at 40 deg leaves a patch that is not a disk; the next feature angle remeshes it."""
    import gmsh
    import trimesh
    from surface_files import biceps_like

    from persival.model.anatomy.surface_import import read_surface
    from persival.model.anatomy.surface_mesh import CLASSIFY_ANGLES_DEG, _add_surface
    from persival.model.anatomy.surface_repair import repair_surface

    vertices, faces, _, _ = biceps_like()
    defective = with_defects(vertices, faces, duplicates=40, flips=25, hole=(2000, 2001), seed=5)
    trimesh.Trimesh(*defective, process=False).export(str(tmp_path / "biceps.ply"))
    repaired = repair_surface(*read_surface(tmp_path / "biceps.ply"), "biceps")
    gmsh.initialize(interruptible=False)
    try:
        gmsh.option.setNumber("General.Verbosity", 0)
        _add_surface(gmsh, repaired)
        with pytest.raises(Exception, match="topology"):  # the first angle alone fails on this surface
            gmsh.model.mesh.classifySurfaces(np.radians(CLASSIFY_ANGLES_DEG[0]), True, True, np.pi)
            gmsh.model.mesh.createGeometry()
        gmsh.model.remove()
        volume = volume_mesh(repaired, 10.0)
    finally:
        gmsh.finalize()
    assert not volume.surface_kept and volume.mesh.n_cells > 1000
    assert volume.mesh.volume() == pytest.approx(repaired.volume, rel=0.01)


def test_the_model_file_enters_the_digests_of_the_stages_that_read_it():
    """Built-in or given, the model file's hash is an input of the stages that read the arm (so an
    edited file reruns them), and of no other stage's settings (they see it through upstream)."""
    from persival.pipeline import RunConfig, _stage_inputs

    own = RunConfig(model="/data/my_arm.toml", model_hash="abc")
    assert _stage_inputs("campaign", own, {})["settings"]["model_hash"] == "abc"
    assert _stage_inputs("tables", RunConfig(model_hash="built-in"), {})["settings"]["model_hash"] == "built-in"
    assert "model_hash" not in _stage_inputs("sg", own, {})["settings"]


def test_the_run_fits_the_deployed_model_to_its_own_model_file(monkeypatch, tmp_path):
    """`persival run --model FILE`: the structured stage reads the tables of FILE's arm (it used the
    built-in arm's and refused the campaign's states as another model's)."""
    from rich.console import Console

    import persival.surrogate.build as stage
    from persival.pipeline import RunConfig, stages

    seen = {}

    def fit_structured(store, out, profile="quick", model_file=None, tables=None, tolerance_mm=0.05, progress=None):
        seen.update(profile=profile, model_file=model_file)
        raise RuntimeError("fitted")

    monkeypatch.setattr(stage, "fit_structured", fit_structured)
    with pytest.raises(RuntimeError, match="fitted"):
        stages.structured(tmp_path, RunConfig(profile="coarse", model="/data/my_arm.toml"), Console(quiet=True))
    assert seen == {"profile": "coarse", "model_file": "/data/my_arm.toml"}


def test_a_fin_on_an_edge_is_removed_and_counted():
    """A stray triangle on an edge of the surface (three triangles on one edge: non-manifold) goes,
    not one of the surface's own; what is left is the clean spindle."""
    from persival.model.anatomy.surface_repair import repair_surface

    vertices, faces = spindle()
    a, b = faces[200][:2]
    fin = np.array([[a, b, len(vertices)]])
    apex = 0.5 * (vertices[a] + vertices[b]) + [0.0, 0.0, 30.0]
    for position in (0, len(faces)):  # the fin first in the file, and last
        repaired = repair_surface(np.vstack([vertices, apex]), np.insert(faces, position, fin, axis=0))
        assert repaired.repairs["fixed non-manifold edges (triangles removed)"] == 1
        assert oriented(repaired.faces) == oriented(faces) and len(repaired.vertices) == len(vertices)
