"""Simulate one FE state of the arm: biceps half active, every other muscle at rest.

The spindle arm (the packaged variant the tests use) on the coarse mesh, solved by the exact path
of docs/theory.md, 4.3: the joint equilibrium on the per-muscle response tables, then every muscle
re-solved by Newton there. Its coarse tables ship with the tests (tests/data/response_table_coarse),
so nothing is built first; `persival tables --profile quick` builds the tables of the built-in arm
on the default mesh (long: 40 min on 2 cores).

    python docs/examples/simulate_state.py [OUT]

Prints the elbow angle. Without PERSIVAL_CACHE set, the state cache (meshes, rest states) goes
to OUT/cache, seeded with the coarse arm's rest states from tests/data/state_cache.
"""

import os
import shutil
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(tempfile.mkdtemp(prefix="persival-example-"))
if "PERSIVAL_CACHE" not in os.environ:
    os.environ["PERSIVAL_CACHE"] = str(out / "cache")
    shutil.copytree(REPO / "tests" / "data" / "state_cache", out / "cache", dirs_exist_ok=True)

from persival.model.arm.arm_model import ArmModel  # noqa: E402  (after the cache is chosen)
from persival.model.arm.output import write_state  # noqa: E402
from persival.model.arm.state_cache import mesh_fingerprint  # noqa: E402
from persival.tables.response_table import ResponseTable  # noqa: E402
from persival.tables.table_solve import TableSolver  # noqa: E402

arm = ArmModel("spindle_arm", profile="coarse")  # meshes once (gmsh), then from the cache
table = ResponseTable.open(REPO / "tests" / "data" / "response_table_coarse", arm.model_hash, "coarse",
                           mesh_fingerprint(arm.mesh))
state = TableSolver(arm, table).solve([0.5, 0, 0, 0, 0])  # biceps, brachialis, brachioradialis, triceps, anconeus
write_state(arm, state, out / "biceps_half")  # state.json + one VTU per muscle, for ParaView
print(f"moment residual: {state.moment_residual:.1e} N mm, max |J - 1|: {100 * state.max_volume_change:.2f} %")
print(f"elbow angle: {state.elbow_angle_deg:.2f} deg")
