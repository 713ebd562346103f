"""Shared fixtures: one small but real pipeline run (analytic campaign -> SG -> inverse -> data
-> networks -> export), built once per test session and shared by the pytest-xdist workers.

Real inputs, small sizes: a level-1 campaign of the analytic stand-in (243 states), the
activation model on a coarse knot spacing, 600 training states, a POD net and a paper net
trained for a few epochs. Tests assert properties that hold at this size (exactness of the
inverse solution, ONNX == PyTorch, SG vs itself, ...), not accuracy figures of a full run.
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import pytest

SEED_CACHE = Path(__file__).parent / "data" / "state_cache"
# the tests' shared helpers (surface_files.py) import from any test folder
sys.path.insert(0, str(Path(__file__).parent))


def pytest_configure(config):
    """The on-disk state cache (persival.model.arm.state_cache) of a test run is a fresh folder of
    that run, shared by its xdist workers (they inherit the variable; entries are keyed by model
    and mesh and written atomically), never the user's ~/.cache. It starts with the coarse arm's
    rest states and hanging arm (tests/data/state_cache, tests/data/README.md): every module that
    solves the coarse arm needs them, and each xdist worker solved them again (80 to 180 s of
    continuation from the mesh poses). A seed of another model or mesh sits under another key and
    is never read; a read one is re-converged, not trusted (ArmModel.base_state)."""
    if not os.environ.get("PERSIVAL_TEST_CACHE_SET"):
        import shutil
        import tempfile

        root = tempfile.mkdtemp(prefix="persival-test-cache-")
        if SEED_CACHE.is_dir():
            shutil.copytree(SEED_CACHE, root, dirs_exist_ok=True)
        os.environ["PERSIVAL_CACHE"] = root
        os.environ["PERSIVAL_TEST_CACHE_SET"] = "1"
    # The FE tests' small real input is the spindle arm on its coarse mesh (tests/data holds its
    # tables and rest states): the anatomical built-in arm costs several times more Newton
    # iterations per solve on its walls (docs/arm_model.md), which the 10-minute suite cannot carry.
    # Commands without --model take it through the variable (persival.model.arm.defaults), worker
    # processes included; the tests of the built-in arm's file name it (builtin_model_path).
    os.environ.setdefault("PERSIVAL_MODEL", "spindle_arm")


def _build_small_run(root: Path) -> Path:
    from persival.campaign.design import Design
    from persival.campaign.runner import INLINE, run_campaign
    from persival.campaign.simulator import SimulatorSpec
    from persival.deploy.export import export_model
    from persival.surrogate.activation_model import AngleActivationModel
    from persival.surrogate.build import fit_sparse_grid, make_training_data, train_network
    from persival.surrogate.inverse import InverseProblem
    from persival.surrogate.training import TrainingConfig

    spec = SimulatorSpec("analytic", {})
    run_campaign(root / "campaign" / "campaign.zarr", Design.sparse_grid(1), spec, scheduler=INLINE, progress=False)
    run_campaign(root / "campaign" / "held_out.zarr", Design.random(10, seed=1), spec, scheduler=INLINE, progress=False)
    sg = fit_sparse_grid(root / "campaign" / "campaign.zarr", root / "sg")
    model = AngleActivationModel.build(InverseProblem(sg, n_candidates=1024), spacing_deg=5.0, tolerance=1e-3)
    (root / "inverse").mkdir()
    model.save(root / "inverse" / "activation_model.json")
    make_training_data(root / "sg", root / "inverse" / "activation_model.json", root / "data", 600, seed=0)
    pod = train_network(root / "data", root / "networks" / "pod", TrainingConfig(arch="pod", folds=1, epochs=30))
    train_network(root / "data", root / "networks" / "paper", TrainingConfig(arch="paper", folds=1, epochs=10,
                                                                              activation="relu"), ["biceps"])
    export_model(pod, root / "export", activation_model=model)
    (root / "complete.json").write_text(json.dumps({"complete": True}))
    return root


@pytest.fixture(scope="session")
def small_run(tmp_path_factory) -> Path:
    """OUT of a small real run (layout of persival.pipeline), built once for all workers."""
    if not os.environ.get("PYTEST_XDIST_WORKER"):  # no xdist
        return _build_small_run(tmp_path_factory.mktemp("small_run"))
    from filelock import FileLock

    shared = tmp_path_factory.getbasetemp().parent / "small_run"
    with FileLock(str(shared) + ".lock"):
        if not (shared / "complete.json").exists():
            import shutil

            shutil.rmtree(shared, ignore_errors=True)
            shared.mkdir()
            _build_small_run(shared)
    return shared


def add_motion_model(export: Path, table: Path = Path(__file__).parent / "data" / "moments_coarse.npz") -> Path:
    """Give an export folder the motion-and-load model of a moment table (the coarse FE arm's by
    default), as `persival run` does: activation_motion.onnx and its metadata entry."""
    from persival.model.arm.model_file import load_model_file
    from persival.surrogate.motion_model import MotionActivationModel
    from persival.tables.moment_table import MomentTable

    spec, model_hash = load_model_file(None)
    model = MotionActivationModel.from_table(MomentTable.load(table, model_hash, complete=True), spec)
    entry = model.export_onnx(export)
    meta = json.loads((export / "metadata.json").read_text())
    meta["models"]["activation_motion"] = entry
    (export / "metadata.json").write_text(json.dumps(meta))
    return export


@pytest.fixture(scope="session")
def motion_export(small_run, tmp_path_factory) -> Path:
    """The small run's export (analytic arm: SG -> POD net, its angle model) plus the coarse FE
    arm's motion-and-load model: the models of a real export, two arms' physics (the tests check
    the chain's arithmetic and the refusals, not one arm's numbers)."""
    import shutil

    folder = tmp_path_factory.mktemp("motion_export") / "export"
    shutil.copytree(small_run / "export", folder)
    return add_motion_model(folder)


COARSE_TABLE = Path(__file__).parent / "data" / "response_table_coarse"


@pytest.fixture(scope="module")
def coarse_arm():
    """The built-in arm on the coarse mesh (meshed once per module)."""
    from persival.model.arm.arm_model import ArmModel

    return ArmModel(profile="coarse")


#: the commands that rebuild the coarse fixtures (tests/data/README.md)
REBUILD_TABLES = ("persival tables --profile coarse --angles 0:160:20 --levels 0,0.5,1 --out tests/data/response_table_coarse"
                  " --moments-out tests/data/moments_coarse.npz")


@pytest.fixture(scope="module")
def coarse_table(coarse_arm):
    """The coarse response-table fixture (tests/data/README.md); a failure naming the command that
    rebuilds it when the model or mesh changed since it was built (a skip would hide the tests it feeds)."""
    from persival.model.arm.state_cache import mesh_fingerprint
    from persival.tables.moment_table import TableMismatchError
    from persival.tables.response_table import ResponseTable

    try:
        return ResponseTable.open(COARSE_TABLE, coarse_arm.model_hash, "coarse", mesh_fingerprint(coarse_arm.mesh))
    except TableMismatchError as exc:
        pytest.fail(f"the fixture is of another model or mesh ({exc}); rebuild it: {REBUILD_TABLES}")

