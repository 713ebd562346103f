"""Tests of simulation campaigns: designs, the zarr store, the dask / in-process runner, the
external-command simulator with its importers, export and the CLI (issue 4, SPEC section 10)."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import typer
from typer.testing import CliRunner

from persival.campaign.analytic import AnalyticSimulator
from persival.campaign.design import Design, DesignError, chunks, solve_order
from persival.campaign.export import export_vtu
from persival.campaign.external import ExternalSimulator
from persival.campaign.importers import ResultImportError, parse_selector, read_surfaces
from persival.campaign.runner import run_campaign
from persival.campaign.simulator import (
    SimulatorSpec,
    UnknownSimulatorError,
    register_simulator,
)
from persival.campaign.store import (
    CampaignMismatchError,
    CampaignStore,
    StoreBusyError,
    StoreVersionError,
)
from persival.campaign.surface import boundary_triangles
from persival.vocabulary import MUSCLES

# A coarse analytic model keeps stores small and writes fast; the code paths are the same.
ANALYTIC = SimulatorSpec("analytic", {"mesh_size": 14.0})


def _cli() -> typer.Typer:
    from persival.cli import campaign as commands

    app = typer.Typer()
    bench = typer.Typer()
    app.add_typer(bench, name="bench")
    commands.register(app)
    return app


def _assert_same_states(a: CampaignStore, b: CampaignStore) -> None:
    np.testing.assert_array_equal(a.status_codes(), b.status_codes())
    np.testing.assert_array_equal(a.elbow_angles(), b.elbow_angles())
    for name in a.surface_names:
        np.testing.assert_array_equal(a.surface_positions(name), b.surface_positions(name))


# ---- designs ---------------------------------------------------------------------------------
def test_design_constructors_and_order(tmp_path):
    sg = Design.sparse_grid(1)
    assert sg.points.shape == (243, 5) and list(sg.ids) == list(range(243))
    rnd = Design.random(50, seed=3)
    np.testing.assert_array_equal(rnd.points, Design.random(50, seed=3).points)
    assert not np.array_equal(rnd.points, Design.random(50, seed=4).points)

    # CSV with a header (muscle columns in another order, explicit ids) and .npy round trip.
    csv_path = tmp_path / "d.csv"
    rnd.to_csv(csv_path)
    back = Design.from_file(csv_path)
    assert back.same_points(rnd)
    np.save(tmp_path / "d.npy", rnd.points)
    assert np.array_equal(Design.from_file(tmp_path / "d.npy").points, rnd.points)
    (tmp_path / "h.csv").write_text("triceps,id,biceps,brachialis,brachioradialis,anconeus\n"
                                    "0.5,7,0.1,0.2,0.3,0.9\n")
    h = Design.from_file(tmp_path / "h.csv")
    assert list(h.ids) == [7] and h.points.tolist() == [[0.1, 0.2, 0.3, 0.5, 0.9]]

    # The solve order is a permutation starting at alpha = 0 and much shorter than id order.
    order = solve_order(sg.points)
    assert sorted(order.tolist()) == list(range(243)) and np.all(sg.points[order[0]] == 0)
    length = lambda o: np.linalg.norm(np.diff(sg.points[o], axis=0), axis=1).sum()  # noqa: E731
    assert length(order) < 0.6 * length(np.arange(243))
    pieces = chunks(order, 7)
    assert len(pieces) == 7 and np.array_equal(np.concatenate(pieces), order)


@pytest.mark.parametrize("points, message", [
    ([[0.1, 0.2, 0.3, 0.4, 1.2]], "outside [0, 1]^5, first: row 0, anconeus = 1.2"),
    ([[0.1, -0.01, 0.3, 0.4, 0.5]], "brachialis = -0.01"),
    ([[0.1, np.nan, 0.3, 0.4, 0.5]], "not finite"),
    ([[0.1, 0.2, 0.3, 0.4]], "shape (n, 5)"),
    (np.zeros((0, 5)), "empty"),
])
def test_design_rejects_bad_points(points, message):
    with pytest.raises(DesignError, match=re.escape(message)):
        Design(np.asarray(points, dtype=float), np.arange(len(points)))


def test_design_rejects_bad_ids_and_files(tmp_path):
    with pytest.raises(DesignError, match="unique"):
        Design(np.zeros((2, 5)), [3, 3])
    (tmp_path / "bad.csv").write_text("0.1,0.2,0.3,0.4,0.5\n0.1,0.2,oops,0.4,0.5\n")
    with pytest.raises(DesignError, match="line 2"):
        Design.from_file(tmp_path / "bad.csv")
    with pytest.raises(DesignError, match="does not exist"):
        Design.from_file(tmp_path / "nope.csv")


# ---- end to end: level-1 sparse grid, LocalCluster vs in-process ------------------------------
@pytest.mark.slow
def test_level1_campaign_on_local_cluster_equals_in_process(tmp_path):
    design = Design.sparse_grid(1)
    inline = run_campaign(tmp_path / "inline.zarr", design, ANALYTIC, scheduler="inline",
                          progress=False)
    dask = run_campaign(tmp_path / "dask.zarr", design, ANALYTIC, n_workers=2, progress=False)
    for s in (inline, dask):
        assert (s["total"], s["done"], s["failed"], s["missing"]) == (243, 243, 0, 0)
    a, b = CampaignStore.open(tmp_path / "inline.zarr"), CampaignStore.open(tmp_path / "dask.zarr")
    _assert_same_states(a, b)

    # Read back through the Python API and check against the simulator itself.
    sim = AnalyticSimulator(**ANALYTIC.options)
    table = a.states()
    assert len(table) == 243 and set(table.status) == {"done"}
    assert np.all(table.wall_time_s > 0) and np.all(table.attempts == 1)
    for row in (0, 100, 242):
        res, _ = sim.simulate(design.points[row])
        assert a.elbow_angles()[row] == res.elbow_angle_deg
        for name in MUSCLES:
            np.testing.assert_array_equal(a.surface_positions(name, [row])[0], res.surfaces[name])
    ref = a.reference
    assert ref.names == list(MUSCLES) and ref.model_hash == sim.reference().model_hash
    prov = a.provenance
    assert prov["design_sha256"] == design.digest() and prov["persival_version"]
    # Warm starts were used along the path (chains of neighbouring states).
    assert sum(bool(s and s.get("warm_started")) for s in b.states().statistics) > 150
    # Rerunning a complete store computes nothing.
    again = run_campaign(tmp_path / "inline.zarr", design, ANALYTIC, scheduler="inline",
                         progress=False)
    assert again["this_run"]["computed"] == 0


# ---- kill -9 and resume ----------------------------------------------------------------------
_DRIVER = """
import sys
from persival.campaign.design import Design
from persival.campaign.runner import run_campaign
from persival.campaign.simulator import SimulatorSpec

if __name__ == "__main__":
    run_campaign(sys.argv[1], Design.random(60, seed=11),
                 SimulatorSpec("analytic", {"mesh_size": 14.0, "delay_s": 0.05}),
                 n_workers=2, progress=False)
"""


@pytest.mark.slow
def test_killed_campaign_resumes_with_every_state_once(tmp_path):
    store_path = tmp_path / "killed.zarr"
    script = tmp_path / "driver.py"
    script.write_text(_DRIVER)
    # Own session = own process group: the driver, its nannies and its workers die together.
    proc = subprocess.Popen([sys.executable, str(script), str(store_path)],
                            start_new_session=True, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 60
        n_done = 0
        while time.monotonic() < deadline and n_done < 12:
            time.sleep(0.2)
            if (store_path / "zarr.json").exists():
                n_done = int(CampaignStore.open(store_path).done_mask().sum())
            assert proc.poll() is None, "the campaign ended before it could be killed"
        assert n_done >= 12, "the campaign made no progress"
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    before = CampaignStore.open(store_path)
    done_before = np.flatnonzero(before.done_mask())
    assert 12 <= len(done_before) < 60
    snap = {n: before.surface_positions(n, done_before) for n in before.surface_names}
    table_before = before.states()

    # Resume through the CLI with nothing but the store: design and simulator come from it.
    result = CliRunner().invoke(_cli(), ["campaign", "run", "--store", str(store_path),
                                         "--scheduler", "inline", "--no-progress"])
    assert result.exit_code == 0, result.output
    after = CampaignStore.open(store_path)
    table = after.states()
    assert len(table) == 60 and len(set(table.ids.tolist())) == 60
    assert set(table.status) == {"done"}
    assert after.summary()["missing"] == 0
    for n in after.surface_names:
        np.testing.assert_array_equal(after.surface_positions(n, done_before), snap[n])
    # Not recomputed at all: timing and statistics of the earlier states are untouched.
    np.testing.assert_array_equal(table.wall_time_s[done_before], table_before.wall_time_s[done_before])
    assert [table.statistics[i] for i in done_before] == [table_before.statistics[i] for i in done_before]
    # And what was computed after the kill equals an uninterrupted campaign.
    design = Design.random(60, seed=11)
    sim = AnalyticSimulator(mesh_size=14.0)
    for row in (0, 59):
        res, _ = sim.simulate(design.points[row])
        np.testing.assert_array_equal(after.surface_positions("biceps", [row])[0],
                                      res.surfaces["biceps"])


# ---- export, external command, importers ----------------------------------------------------
_FAKE_FE = """
import csv, json, os, shutil, sys, time
from pathlib import Path

export = Path(sys.argv[1])
alpha, out = sys.argv[2], Path(sys.argv[3])
rows = {",".join(r[1:6]): r for r in csv.reader(open(export / "states.csv")) if r[0] != "id"}
row = rows[alpha]
state_id = int(row[0])
if state_id == 1:
    sys.stderr.write("solver diverged at load step 3\\n")
    sys.exit(3)
if state_id == 2:
    (export / "hang.pid").write_text(str(os.getpid()))
    time.sleep(600)
shutil.copy(export / row[7], out / "result.vtu")
json.dump({"elbow_angle_deg": float(row[6]), "statistics": {"newton_iterations": 4}},
          open(out / "result.json", "w"))
"""


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """A small finished analytic campaign and its VTU export."""
    base = tmp_path_factory.mktemp("export")
    design = Design.random(6, seed=5)
    run_campaign(base / "src.zarr", design, ANALYTIC, scheduler="inline", progress=False)
    res = export_vtu(base / "src.zarr", base / "vtu")
    assert res["states"] == 6
    (base / "fake_fe.py").write_text(_FAKE_FE)
    return base, design


def _external_spec(base: Path) -> SimulatorSpec:
    sel = json.loads((base / "vtu" / "surfaces.json").read_text())["selectors"]
    return SimulatorSpec("external", {
        "command": f"{sys.executable} {base / 'fake_fe.py'} {base / 'vtu'} {{alpha}} {{out}}",
        "reference": str(base / "vtu" / "reference.vtu"),
        "surfaces": sel,
    })


def test_export_writes_a_paraview_series(exported):
    base, _ = exported
    vtu = base / "vtu"
    pvd = (vtu / "campaign.pvd").read_text()
    assert pvd.count("<DataSet") == 6 and 'file="state_000000.vtu"' in pvd
    import meshio

    mesh = meshio.read(vtu / "state_000003.vtu")
    src = CampaignStore.open(base / "src.zarr")
    n_nodes = sum(s.n_nodes for s in src.reference.surfaces.values())
    assert mesh.points.shape == (n_nodes, 3)
    assert np.abs(mesh.point_data["displacement"]).max() > 1.0  # the muscles did move


def test_vtu_round_trip_and_external_failures(exported, tmp_path):
    base, design = exported
    spec = _external_spec(base)
    summary = run_campaign(tmp_path / "ext.zarr", design, spec, scheduler="inline",
                           timeout_s=3.0, progress=False)
    assert (summary["done"], summary["failed"], summary["missing"]) == (4, 2, 0)
    ext, src = CampaignStore.open(tmp_path / "ext.zarr"), CampaignStore.open(base / "src.zarr")
    table = ext.states()
    # The crash: retried, then recorded with the command's own words.
    assert table.status[1] == "failed" and table.attempts[1] == 3
    assert "status 3" in table.reason[1] and "solver diverged at load step 3" in table.reason[1]
    # The hang: killed at the timeout, recorded as such, not retried, process gone.
    assert table.status[2] == "failed" and table.reason[2].startswith("timeout")
    assert table.attempts[2] == 1 and 3.0 <= table.wall_time_s[2] < 20
    pid = int((base / "vtu" / "hang.pid").read_text())
    with pytest.raises(ProcessLookupError):
        os.kill(pid, 0)
    # Every other state imported from VTU reproduces the stored positions and angles exactly.
    ok = np.flatnonzero(ext.done_mask())
    assert ok.tolist() == [0, 3, 4, 5]
    np.testing.assert_array_equal(ext.elbow_angles()[ok], src.elbow_angles()[ok])
    for name in src.surface_names:
        np.testing.assert_array_equal(ext.surface_positions(name, ok), src.surface_positions(name, ok))
        np.testing.assert_array_equal(ext.reference.surfaces[name].triangles,
                                      src.reference.surfaces[name].triangles)
    assert table.statistics[0]["newton_iterations"] == 4
    # The node sets (indices into the result files) are kept: muscles follow each other there.
    offsets = np.cumsum([0] + [s.n_nodes for s in src.reference.surfaces.values()])
    for k, s in enumerate(ext.reference.surfaces.values()):
        np.testing.assert_array_equal(s.node_ids, np.arange(offsets[k], offsets[k + 1]))
    # Half-written states never show: failed states read as NaN.
    assert np.isnan(ext.surface_positions("biceps", [1, 2])).all()


def test_external_simulator_rejects_bad_templates(exported):
    base, _ = exported
    opts = _external_spec(base).options
    with pytest.raises(ValueError, match="unknown or malformed field"):
        ExternalSimulator(**{**opts, "command": "fe --alpha {alhpa}"})
    with pytest.raises(ValueError, match="surfaces"):
        ExternalSimulator(**{**opts, "surfaces": {}})


def _tet_cube(tmp_path):
    import gmsh

    gmsh.initialize(readConfigFiles=False, interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("cube")
        a = gmsh.model.occ.addBox(0, 0, 0, 1, 1, 1)
        b = gmsh.model.occ.addBox(1, 0, 0, 1, 1, 1)
        gmsh.model.occ.fragment([(3, a)], [(3, b)])
        gmsh.model.occ.synchronize()
        gmsh.model.addPhysicalGroup(3, [a], 11, name="left")
        gmsh.model.addPhysicalGroup(3, [b], 12, name="right")
        gmsh.option.setNumber("Mesh.MeshSizeMax", 0.34)
        gmsh.model.mesh.generate(3)
        path = tmp_path / "cubes.msh"
        gmsh.write(str(path))
    finally:
        gmsh.finalize()
    return path


def test_surface_of_tet_parts_from_xdmf(tmp_path):
    import meshio

    mesh = meshio.read(_tet_cube(tmp_path))
    tets = [(b.type, b.data) for b in mesh.cells if b.type == "tetra"]
    phys = [d for b, d in zip(mesh.cells, mesh.cell_data["gmsh:physical"]) if b.type == "tetra"]
    vol = meshio.Mesh(mesh.points, tets, cell_data={"material": phys})
    path = tmp_path / "cubes.xdmf"
    meshio.write(path, vol, data_format="XML")  # plain XML: no HDF5 needed
    parts = read_surfaces(path, {"left": parse_selector("cell_data:material=11"),
                                 "right": {"cell_data": "material", "value": 12}})
    for name, x0 in (("left", 0.0), ("right", 1.0)):
        p, tri = parts[name].points, parts[name].triangles
        # Every surface node lies on the boundary of its unit cube ...
        local = p - [x0, 0, 0]
        on_face = np.isclose(local, 0).any(axis=1) | np.isclose(local, 1).any(axis=1)
        assert on_face.all()
        # ... the triangles close it (area 6) and face outward (divergence theorem: volume 1).
        v0, v1, v2 = p[tri[:, 0]], p[tri[:, 1]], p[tri[:, 2]]
        cross = np.cross(v1 - v0, v2 - v0)
        assert np.isclose(0.5 * np.linalg.norm(cross, axis=1).sum(), 6.0)
        assert np.isclose(np.einsum("ij,ij->", v0, cross) / 6.0, 1.0)
    # The shared face is interior to the union: selecting both parts drops it.
    both = boundary_triangles([("tetra", np.concatenate([t for _, t in tets]))])
    assert len(both) == len(parts["left"].triangles) + len(parts["right"].triangles) \
        - 2 * int(np.isclose(parts["left"].points[:, 0], 1.0)[parts["left"].triangles].all(axis=1).sum())
    with pytest.raises(ResultImportError, match="no cell has material = 13"):
        read_surfaces(path, {"x": {"cell_data": "material", "value": 13}})
    with pytest.raises(ResultImportError, match="selects cell data 'mat'"):
        read_surfaces(path, {"x": {"cell_data": "mat", "value": 11}})


def test_d3plot_importer_on_a_lasso_written_file(tmp_path):
    dyna = pytest.importorskip(
        "lasso.dyna", reason="lasso-python is not installed (pip install 'persival[dyna]')")
    ArrayType, D3plot = dyna.ArrayType, dyna.D3plot
    # Written with lasso's own documented "new d3plot from scratch" API: two hexahedra
    # (part 7) and one tetrahedron in LS-DYNA's N1 N2 N3 N4 N4 N4 N4 N4 form (part 9).
    x = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0], [1, 1, 0], [2, 1, 0], [0, 0, 1],
                  [1, 0, 1], [2, 0, 1], [0, 1, 1], [1, 1, 1], [2, 1, 1], [3, 0, 0]], float)
    moved = x * [1.5, 1.0, 0.5] + [0.0, 0.25, 0.0]
    d3 = D3plot()
    d3.arrays[ArrayType.node_coordinates] = x
    d3.arrays[ArrayType.element_solid_node_indexes] = np.array(
        [[0, 1, 4, 3, 6, 7, 10, 9], [1, 2, 5, 4, 7, 8, 11, 10], [2, 12, 5, 8, 8, 8, 8, 8]])
    d3.arrays[ArrayType.element_solid_part_indexes] = np.array([0, 0, 1])
    d3.arrays[ArrayType.part_ids] = np.array([7, 9])
    d3.arrays[ArrayType.node_displacement] = np.stack([x, moved])
    path = tmp_path / "d3plot"
    d3.write_d3plot(str(path))

    sel = {"block": parse_selector("part:7"), "tip": {"part_id": 9}}
    cur = read_surfaces(path, sel)
    ref = read_surfaces(path, sel, reference=True)
    assert cur["block"].node_ids.tolist() == list(range(12))  # every node of a 2x1x1 block
    assert len(cur["block"].triangles) == 20  # 10 outer quads, the shared one dropped
    assert cur["tip"].node_ids.tolist() == [2, 5, 8, 12] and len(cur["tip"].triangles) == 4
    np.testing.assert_allclose(ref["block"].points, x[:12])
    np.testing.assert_allclose(cur["tip"].points, moved[[2, 5, 8, 12]], rtol=1e-6)  # float32 file
    with pytest.raises(ResultImportError, match="no solid or shell element of part id 8"):
        read_surfaces(path, {"x": {"part_id": 8}})


# ---- bad input: clear errors, nothing written ------------------------------------------------
def test_bad_input_changes_nothing(tmp_path):
    design = Design.random(5, seed=0)
    path = tmp_path / "s.zarr"
    run_campaign(path, design, ANALYTIC, scheduler="inline", progress=False)
    files_before = sorted((p.relative_to(path), p.stat().st_mtime_ns) for p in path.rglob("*")
                          if p.is_file() and p.name != "writer.lock")

    with pytest.raises(CampaignMismatchError, match="design: store has 5 points"):
        run_campaign(path, Design.random(5, seed=1), ANALYTIC, scheduler="inline", progress=False)
    with pytest.raises(CampaignMismatchError, match="simulator: store has"):
        run_campaign(path, design, SimulatorSpec("analytic", {"mesh_size": 10.0}),
                     scheduler="inline", progress=False)
    with pytest.raises(UnknownSimulatorError, match="unknown simulator kind 'nope'"):
        run_campaign(tmp_path / "new.zarr", design, SimulatorSpec("nope"), progress=False)
    assert not (tmp_path / "new.zarr").exists()

    # A second writer is refused while the first one lives.
    with CampaignStore.open_for_writing(path):
        with pytest.raises(StoreBusyError, match="another live process"):
            CampaignStore.open_for_writing(path)

    # Design files with bad points, through the CLI: exit code 2, a clear message, no store.
    bad = tmp_path / "bad.csv"
    bad.write_text("0.1,0.2,0.3,0.4,0.5\n0.1,0.2,1.5,0.4,0.5\n")
    r = CliRunner().invoke(_cli(), ["campaign", "run", "--store", str(tmp_path / "b.zarr"),
                                    "--design", str(bad), "--simulator", "analytic",
                                    "--scheduler", "inline", "--no-progress"])
    assert r.exit_code == 2 and "outside [0, 1]^5" in r.output and "brachioradialis = 1.5" in r.output
    assert not (tmp_path / "b.zarr").exists()
    files_after = sorted((p.relative_to(path), p.stat().st_mtime_ns) for p in path.rglob("*")
                         if p.is_file() and p.name != "writer.lock")
    assert files_after == files_before

    # A store of another format version is refused by readers, writers and the CLI.
    import zarr

    zarr.open_group(str(path), mode="r+").attrs["format_version"] = 99
    with pytest.raises(StoreVersionError, match="format version 99 .* reads version 1"):
        CampaignStore.open(path)
    with pytest.raises(StoreVersionError):
        run_campaign(path, design, ANALYTIC, scheduler="inline", progress=False)
    r = CliRunner().invoke(_cli(), ["campaign", "status", "--store", str(path)])
    assert r.exit_code == 2 and "format version 99" in r.output


# ---- an in-process simulator that crashes or hangs -------------------------------------------
class FlakySimulator(AnalyticSimulator):
    """Analytic model that raises on its first two attempts for a0 < 0.2 and never returns for
    a0 > 0.8 (without cancel(): only a thread or process restart stops it)."""

    name = "flaky"

    def simulate(self, activations, warm_start=None, attempt=0):
        if activations[0] > 0.8:
            time.sleep(3600)
        if activations[0] < 0.2 and attempt < 2:
            raise FloatingPointError(f"Newton diverged (attempt {attempt})")
        res, token = super().simulate(activations, warm_start, attempt)
        res.statistics["load_steps"] = 2 ** attempt
        return res, token


def _flaky_design() -> Design:
    pts = np.full((5, 5), 0.5)
    pts[:, 0] = [0.1, 0.5, 0.9, 0.6, 0.15]
    return Design(pts, np.arange(5))


def test_retries_and_hung_simulator_in_process(tmp_path):
    register_simulator("flaky", FlakySimulator)
    spec = SimulatorSpec("flaky", {"mesh_size": 14.0})
    s = run_campaign(tmp_path / "f.zarr", _flaky_design(), spec, scheduler="inline",
                     timeout_s=1.0, progress=False)
    assert (s["done"], s["failed"], s["missing"]) == (4, 1, 0)
    table = CampaignStore.open(tmp_path / "f.zarr").states()
    assert table.status[2] == "failed" and table.reason[2] == "timeout: attempt 0 ran longer than 1 s"
    # Retried with smaller load steps (attempt 2) and then solved, with the history kept.
    assert table.status[0] == "done" and table.attempts[0] == 3
    assert table.statistics[0]["load_steps"] == 4
    assert "Newton diverged (attempt 1)" in table.statistics[0]["failed_attempts"][1]


class GilHoggingSimulator(FlakySimulator):
    """FlakySimulator that, for 0.55 < a0 < 0.65, also spins in C code without releasing the
    GIL (catastrophic regex backtracking): not even its own worker process can answer then."""

    name = "gil-hog"

    def simulate(self, activations, warm_start=None, attempt=0):
        if 0.55 < activations[0] < 0.65:
            re.match(r"(a+)+$", "a" * 64 + "b")
        return super().simulate(activations, warm_start, attempt)


@pytest.mark.slow
def test_hung_and_unresponsive_workers_on_dask(tmp_path, monkeypatch):
    from persival.campaign import dask_chains

    # The driver's backstop (for workers that cannot even answer) at 3 x 1 s + 2 s.
    monkeypatch.setattr(dask_chains, "_BACKSTOP_GRACE_S", 2.0)
    register_simulator("gil-hog", GilHoggingSimulator)
    t0 = time.monotonic()
    s = run_campaign(tmp_path / "h.zarr", _flaky_design(), SimulatorSpec("gil-hog", {"mesh_size": 14.0}),
                     n_workers=2, timeout_s=1.0, progress=False)
    assert time.monotonic() - t0 < 45
    assert (s["done"], s["failed"], s["missing"]) == (3, 2, 0)
    table = CampaignStore.open(tmp_path / "h.zarr").states()
    # a0 = 0.9 sleeps: its worker's watchdog times out, the worker process is restarted.
    assert table.status[2] == "failed" and table.reason[2].startswith("timeout: attempt 0")
    # a0 = 0.6 holds the GIL: only the driver's backstop sees it.
    assert table.status[3] == "failed" and "worker unresponsive" in table.reason[3]
    assert table.status[0] == "done" and table.attempts[0] == 3


def test_failure_after_all_attempts_is_recorded(tmp_path):
    register_simulator("flaky", FlakySimulator)
    spec = SimulatorSpec("flaky", {"mesh_size": 14.0})
    s = run_campaign(tmp_path / "g.zarr", _flaky_design(), spec, scheduler="inline",
                     max_attempts=2, timeout_s=1.0, progress=False)
    table = CampaignStore.open(tmp_path / "g.zarr").states()
    assert table.status.tolist() == ["failed", "done", "failed", "done", "failed"]
    assert table.reason[0] == "FloatingPointError: Newton diverged (attempt 1) (after 2 attempts)"
    assert s["failure_reasons"]
    # --retry-failed recomputes exactly the failed states (still failing here) and no other.
    t_before = table.wall_time_s.copy()
    s2 = run_campaign(tmp_path / "g.zarr", _flaky_design(), spec, scheduler="inline",
                      max_attempts=3, timeout_s=1.0, retry_failed=True, progress=False)
    assert s2["this_run"]["computed"] == 3 and s2["done"] == 4
    after = CampaignStore.open(tmp_path / "g.zarr").states()
    np.testing.assert_array_equal(after.wall_time_s[[1, 3]], t_before[[1, 3]])


# ---- CLI -------------------------------------------------------------------------------------
def test_cli_run_status_export(tmp_path):
    app, runner = _cli(), CliRunner()
    store = tmp_path / "c.zarr"
    r = runner.invoke(app, ["campaign", "run", "--store", str(store), "--design", "random",
                            "--n-random", "4", "--seed", "2", "--simulator", "analytic",
                            "--option", "mesh_size=14", "--scheduler", "inline", "--no-progress"])
    assert r.exit_code == 0, r.output
    assert "4 done" in r.output
    r = runner.invoke(app, ["campaign", "status", "--store", str(store), "--json"])
    status = json.loads(r.output)
    assert (status["done"], status["missing"]) == (4, 0)
    assert status["simulator_spec"] == {"kind": "analytic", "options": {"mesh_size": 14}}
    r = runner.invoke(app, ["campaign", "export", "--store", str(store), "--out",
                            str(tmp_path / "vtu"), "--no-progress"])
    assert r.exit_code == 0 and len(list((tmp_path / "vtu").glob("state_*.vtu"))) == 4
    r = runner.invoke(app, ["campaign", "run", "--store", str(tmp_path / "x.zarr"),
                            "--simulator", "external", "--scheduler", "inline"])
    assert r.exit_code == 2 and "needs command, reference, surfaces" in r.output

