"""Per-muscle response tables of the FE arm over (theta, a_m): moments, forces and node states.

docs/theory.md, section 4. Without muscle-muscle contact every muscle is its own FE body whose
state depends on the elbow angle theta and its own activation a_m only, so a table of each
muscle's FE equilibria on a (theta, a) grid answers the whole arm: the joint equilibrium of any
activation vector is one scalar equation in the tabulated moments, and each muscle's shape at
the root is its table state there (:mod:`persival.tables.table_solve` uses the tables).

A column is one muscle at one activation level over every table angle, computed by continuation
along theta (:func:`~persival.tables.continuation.sweep_muscle`), each level continued from
the previous level's longest state (continuation along a). Layout of a table folder:

    header.json                  format, model hash, profile, mesh fingerprint, angles, levels
    columns/<muscle>-<j>.npz     tension (N), moment (N mm), moment_slope (N mm/rad), displacement
                                 (n_theta, n_nodes, 3) in the muscle's own frame and its slope
                                 du/dtheta (mm/rad, same shape; float32), NaN where a solve failed

Every column file is written to a temporary name and renamed when it is finished, so a killed
build keeps every finished column and resumes with the next; the columns of different muscles
are computed in parallel by dask worker processes (one task per muscle: its levels are a chain).
A folder of another model, profile, mesh or grid is refused with a message naming the mismatch.
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from persival.file_header import check_header
from persival.model.arm.muscle_state import MuscleState
from persival.model.arm.state_cache import mesh_fingerprint
from persival.tables.column_reuse import muscle_keys
from persival.tables.moment_table import MomentTable, TableMismatchError, check_grids, empty_moment_table
from persival.vocabulary import MUSCLES

__all__ = ["FORMAT", "VERSION", "DEFAULT_ANGLES", "DEFAULT_LEVELS", "ResponseTable", "TableMismatchError",
           "default_table_dir"]

FORMAT = "persival-response-table"
VERSION = 3  # 3: moments and du/dtheta (contact with the bones); 2: tension, stiffness and du/dL
# beyond the joint's limits (0, 160 deg) on both sides: strong extensors rest a few degrees
# below 0 and strong flexors press into the passive joint limit beyond 160 deg; a state whose
# equilibrium lies off the table is solved directly, at about 20 times the cost
DEFAULT_ANGLES = tuple(float(a) for a in np.arange(-10.0, 185.0 + 1e-9, 5.0))
# the levels of a level-2 sparse grid (and, every other one, of level 1): its states need no
# continuation in a, only the re-solve at the equilibrium angle; and below 0.25 four more, where
# a flexor goes from hanging slack to taut and its moment is far from linear in a (the biceps at
# 80 to 100 deg and a = 0.02 to 0.15: cubic interpolation over 0, 0.25, 0.5 missed its moment by
# 200 to 370 N mm, moving the elbow angle by up to 4.6 deg; docs/fe_tables.md); and above 0.25
# steps of 1/8: over steps of 1/4 a muscle's moment between levels was off by up to 51 N mm (the
# biceps at a = 0.33 and 125 deg, 200 exact states), 1.4 deg where the net moment is flat
DEFAULT_LEVELS = (0.0, 0.03125, 0.0625, 0.125, 0.1875, 0.25, 0.375, 0.5, 0.625, 0.75, 0.875, 1.0)


def default_table_dir(arm) -> Path:
    """Where the tables of this model and mesh live by default: beside its cached rest state, in a
    folder named after the default grid (a changed default grid starts a new table)."""
    grid = hashlib.sha256(json.dumps([DEFAULT_ANGLES, DEFAULT_LEVELS]).encode()).hexdigest()[:8]
    return arm.cache_dir() / f"response_table-v{VERSION}-{grid}"


@dataclass
class ResponseTable:
    """A table folder: its header, and its columns loaded on demand."""

    root: Path
    header: dict
    _columns: dict = field(default_factory=dict, repr=False)

    # ------------------------------------------------------------------ opening
    @classmethod
    def create_or_open(cls, root: str | Path, arm, angles=DEFAULT_ANGLES, levels=DEFAULT_LEVELS) -> ResponseTable:
        """The table at ``root`` for this arm and grid: opened if it exists (must match), else created."""
        refuse_touching_muscles(arm)
        angles, levels = check_grids(angles, levels)
        root = Path(root)
        if (root / "header.json").exists():
            table = cls.open(root, arm.model_hash, arm.profile, mesh_fingerprint(arm.mesh))
            if not (np.array_equal(table.angles_deg, angles) and np.array_equal(table.levels, levels)):
                raise TableMismatchError(f"{root} has angles {table.angles_deg.tolist()} and levels {table.levels.tolist()}; "
                                         f"asked for {angles.tolist()} and {levels.tolist()} (use another folder)")
            return table
        if root.exists() and any(root.iterdir()):
            raise TableMismatchError(f"{root} exists and is not a response table (no header.json); pick an empty folder")
        (root / "columns").mkdir(parents=True, exist_ok=True)
        geometry = empty_moment_table(arm, angles, levels)  # the exact geometry and loads on the fine grid
        muscles = arm.spec.ordered_muscles()
        header = {
            "format": FORMAT, "version": VERSION, "model_hash": arm.model_hash, "profile": arm.profile,
            "mesh_fingerprint": mesh_fingerprint(arm.mesh), "angles_deg": angles.tolist(), "levels": levels.tolist(),
            "muscles": list(MUSCLES), "n_nodes": {m.name: int(arm.units[m.name].mesh.n_nodes) for m in muscles},
            "forearm": geometry.meta["forearm"], "joint_limits_deg": geometry.meta["joint_limits_deg"],
            "fine_deg": geometry.fine_deg.tolist(),
            "fine_dL": geometry.fine_dL.tolist(), "fine_gravity": geometry.fine_gravity.tolist(),
            "fine_joint": geometry.fine_joint.tolist(),
            "lengths_mm": [[arm.muscle_length(m, t)[0] for t in angles] for m in muscles],
            # what each muscle's columns depend on: a table of another model with the same key has the same columns
            "muscle_keys": muscle_keys(arm, angles, levels, VERSION),
        }
        _write_atomic(root / "header.json", json.dumps(header).encode())
        return cls(root, header)

    @classmethod
    def open(cls, root: str | Path, model_hash: str | None = None, profile: str | None = None,
             mesh: str | None = None) -> ResponseTable:
        """Read a table folder; refuse one of another model (hash), profile or mesh."""
        root = Path(root)
        try:
            header = json.loads((root / "header.json").read_text())
        except FileNotFoundError:
            raise FileNotFoundError(f"{root}: no response table here (no header.json)") from None
        except (OSError, ValueError) as exc:
            raise TableMismatchError(f"{root}/header.json is not a response table header ({exc})") from None
        check_header(header, root, "response table", FORMAT, VERSION, TableMismatchError,
                     advice="build it again (`persival tables`)")
        if model_hash is not None and header["model_hash"] != model_hash:
            raise TableMismatchError(f"{root} was built for another model: model hash {header['model_hash'][:12]}, "
                                     f"this model {model_hash[:12]}")
        if profile is not None and header["profile"] != profile:
            raise TableMismatchError(f"{root} was built for mesh profile {header['profile']!r}, not {profile!r}")
        if mesh is not None and header["mesh_fingerprint"] != mesh:
            raise TableMismatchError(f"{root} was built on another mesh (fingerprint {header['mesh_fingerprint'][:12]}, "
                                     f"this mesh {mesh[:12]}: another gmsh version or mesh size)")
        return cls(root, header)

    # ------------------------------------------------------------------ grid and columns
    @property
    def angles_deg(self) -> np.ndarray:
        return np.asarray(self.header["angles_deg"], dtype=float)

    @property
    def levels(self) -> np.ndarray:
        return np.asarray(self.header["levels"], dtype=float)

    def lengths(self, muscle: str) -> np.ndarray:
        return np.asarray(self.header["lengths_mm"][MUSCLES.index(muscle)], dtype=float)

    def column_path(self, muscle: str, level: int) -> Path:
        return self.root / "columns" / f"{muscle}-{level}.npz"

    def is_done(self, muscle: str, level: int) -> bool:
        return self.column_path(muscle, level).is_file()

    @property
    def done(self) -> np.ndarray:
        """(5, n_levels) bool: column finished."""
        return np.array([[self.is_done(m, j) for j in range(len(self.levels))] for m in MUSCLES])

    @property
    def complete(self) -> bool:
        return bool(self.done.all())

    def column(self, muscle: str, level: int) -> dict:
        """tension, moment, moment_slope (n_theta,), displacement and sensitivity (n_theta, n_nodes, 3)
        float32, seconds."""
        key = (muscle, level)
        if key not in self._columns:
            with np.load(self.column_path(muscle, level), allow_pickle=False) as data:
                self._columns[key] = {k: data[k] for k in data.files}
        return self._columns[key]

    def column_summary(self, muscle: str, level: int) -> dict:
        """tension, moment, moment_slope and seconds of a column, without decompressing its node arrays
        (opening the tables for their moments reads every column: a warm ``simulate`` spent
        seconds on the node arrays it never used)."""
        keys = ("tension", "moment", "moment_slope", "seconds")
        if (muscle, level) in self._columns:
            return {k: self._columns[(muscle, level)][k] for k in keys}
        with np.load(self.column_path(muscle, level), allow_pickle=False) as data:  # reads only these keys
            return {k: data[k] for k in keys}

    def write_column(self, muscle: str, level: int, sweep: dict, seconds: float) -> None:
        n = self.header["n_nodes"][muscle]
        displacement = np.full((len(self.angles_deg), n, 3), np.nan, dtype=np.float32)
        sensitivity = displacement.copy()
        for k, state in enumerate(sweep["states"]):
            if state is not None:
                displacement[k] = state.displacement
                sensitivity[k] = state.sensitivity
        path = self.column_path(muscle, level)
        tmp = path.with_name(f".{path.name}.{os.getpid()}.writing.npz")
        np.savez_compressed(tmp, tension=sweep["tension_N"], moment=sweep["moment_Nmm"],
                            moment_slope=sweep["moment_slope_Nmm_per_rad"], displacement=displacement,
                            sensitivity=sensitivity, seconds=np.array(seconds))
        os.replace(tmp, path)

    def state(self, muscle: str, k: int, level: int) -> MuscleState | None:
        """The tabulated state of ``muscle`` at angle index k and level index j (None if it failed)."""
        col = self.column(muscle, level)
        if not np.isfinite(col["moment"][k]):
            return None
        return MuscleState(float(self.angles_deg[k]), float(self.lengths(muscle)[k]), float(self.levels[level]),
                           col["displacement"][k].astype(float), float(col["tension"][k]), float(col["moment"][k]),
                           float(col["moment_slope"][k]), 0.0, sensitivity=col["sensitivity"][k].astype(float))

    def moment_table(self) -> MomentTable:
        """The tables' moments as a :class:`MomentTable` (unfinished columns NaN, ``done`` False)."""
        n_theta, n_a = len(self.angles_deg), len(self.levels)
        tension, moment, slope = (np.full((5, n_theta, n_a), np.nan) for _ in range(3))
        done = self.done
        seconds = [[None] * n_a for _ in MUSCLES]
        for m, name in enumerate(MUSCLES):
            for j in range(n_a):
                if done[m, j]:
                    col = self.column_summary(name, j)
                    tension[m, :, j], moment[m, :, j], slope[m, :, j] = col["tension"], col["moment"], col["moment_slope"]
                    seconds[m][j] = float(col["seconds"])
        h = self.header
        meta = {"model_hash": h["model_hash"], "profile": h["profile"], "forearm": h["forearm"],
                "joint_limits_deg": h.get("joint_limits_deg"), "column_seconds": seconds}
        return MomentTable(self.angles_deg, self.levels, tension, moment, slope, done, np.asarray(h["fine_deg"]),
                           np.asarray(h["fine_dL"]), np.asarray(h["fine_gravity"]), np.asarray(h["fine_joint"]), meta)

    def build_seconds(self) -> float:
        """Sum of the finished columns' compute times (s)."""
        done = self.done
        return float(sum(float(self.column_summary(m, j)["seconds"]) for i, m in enumerate(MUSCLES)
                         for j in range(len(self.levels)) if done[i, j]))


def refuse_touching_muscles(arm) -> None:
    """A table holds each muscle over (theta, its own activation): muscles that touch each other
    (``[contact] touching``) depend on their group's activations, which it cannot hold."""
    groups = {" + ".join(group.names) for group in arm.groups.values()}
    if groups:
        raise ValueError(f"the response tables hold each muscle over (elbow angle, its own activation); this model's "
                         f"muscles {', '.join(sorted(groups))} touch each other and depend on each other's activations "
                         f"(docs/theory.md 3.5): solve it with `persival simulate --method direct` (or --option method=direct)")


def _write_atomic(path: Path, data: bytes) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}.writing")
    tmp.write_bytes(data)
    os.replace(tmp, path)
