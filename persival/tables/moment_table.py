"""Per-muscle moment tables of the FE arm over (theta, a_m) (docs/theory.md, section 4).

Without muscle-muscle contact every muscle is its own FE body whose state, tension T and moment
about the hinge depend only on the elbow angle theta and its own activation a_m (docs/theory.md, 3.7), so
the joint equilibrium of any activation vector is the scalar equation
``sum_m M_m(theta, a_m) + M_gravity(theta) + M_passive_joint(theta) = 0`` with
``M_m = -(T_m dL_m/dtheta + dPi_c/dtheta)`` (flexion positive; the second term is the work of the
bones the muscle wraps over, persival.model.arm.muscle_unit). A table holds, per muscle and
activation level, the FE tension, moment and moment slope dM/dtheta at each angle, computed by
continuation along theta from a stretched start (:func:`persival.tables.continuation.sweep_muscle`,
also behind ``persival curves``), NaN where a solve fails. Between the tabulated angles the moment is a
cubic Hermite interpolant (slopes from the FE Schur complement); between activation levels it
is linear.

Files: one ``.npz``, arrays and a JSON header (model hash, profile, which columns are done),
written atomically after every (muscle, level) column: a killed build resumes without redoing
finished columns. :meth:`MomentTable.load` refuses another model's or profile's table.
"""

from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from persival.file_header import check_header
from persival.tables.continuation import sweep_muscle
from persival.vocabulary import MUSCLES

__all__ = ["MomentTable", "TableMismatchError", "build_moment_table", "empty_moment_table",
           "check_grids", "resumable", "FORMAT"]

FORMAT = "persival-moment-table"
VERSION = 2  # 2: moments and their slopes (with contact), no longer tension and axial stiffness
FINE_STEP_DEG = 0.25  # geometry, gravity and passive joint are stored this finely (exact, cheap)


class TableMismatchError(ValueError):
    """A table file that belongs to another model, profile or grid (or is no table at all)."""


@dataclass
class MomentTable:
    """FE moment tables of the five muscles on an (angle, activation) grid."""

    angles_deg: np.ndarray  # (n_theta,)
    levels: np.ndarray  # (n_a,) activation levels, increasing, 0 first
    tension: np.ndarray  # (5, n_theta, n_a) N
    moments: np.ndarray  # (5, n_theta, n_a) M_m, N mm, flexion positive (docs/theory.md, 3.1)
    moment_slopes: np.ndarray  # (5, n_theta, n_a) dM/dtheta, N mm/rad
    done: np.ndarray  # (5, n_a) bool: column computed
    fine_deg: np.ndarray  # (n_fine,) fine angle grid of the exact geometry and loads
    fine_dL: np.ndarray  # (5, n_fine) dL/dtheta, mm/rad
    fine_gravity: np.ndarray  # (n_fine,) N mm, forearm + hand (ArmModel.gravity_moment)
    fine_joint: np.ndarray  # (n_fine,) N mm (ArmModel.passive_joint_moment)
    meta: dict = field(default_factory=dict)  # model_hash, profile, forearm, build times
    # (muscle, level) -> (M, dM, spline): a column's spline is rebuilt only when its values change
    # (builds fill the arrays in place; a root search calls level_moments some 40 times per state)
    _splines: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    # ------------------------------------------------------------------ derived arrays
    @property
    def complete(self) -> bool:
        return bool(self.done.all())

    def finite_range_deg(self) -> tuple[float, float]:
        """The widest run of table angles where every column is finite."""
        ok = np.isfinite(self.moments).all(axis=(0, 2))
        if not ok.any():
            raise ValueError("the table has no angle where every muscle converged at every level")
        edges = np.flatnonzero(np.diff(np.concatenate([[0], ok.astype(int), [0]])))  # run starts, ends + 1
        lo, hi = max(zip(edges[::2], edges[1::2] - 1), key=lambda r: r[1] - r[0])
        return float(self.angles_deg[lo]), float(self.angles_deg[hi])

    # ------------------------------------------------------------------ interpolation
    def gravity_moment(self, theta_deg) -> np.ndarray:
        """Forearm + hand gravity moment (N mm) at theta (tabulated from ArmModel.gravity_moment)."""
        return np.interp(theta_deg, self.fine_deg, self.fine_gravity)

    def passive_joint_moment(self, theta_deg) -> np.ndarray:
        return np.interp(theta_deg, self.fine_deg, self.fine_joint)

    def level_moments(self, muscle: str, theta_deg) -> np.ndarray:
        """(n, n_a): M_m(theta, a_j) at every activation level (Hermite in theta, docs/theory.md, 4.2)."""
        from scipy.interpolate import CubicHermiteSpline

        m = MUSCLES.index(muscle)
        theta = np.atleast_1d(np.asarray(theta_deg, dtype=float))
        rad = np.radians(self.angles_deg)
        out = np.full((len(theta), len(self.levels)), np.nan)
        for j in range(len(self.levels)):
            M, dM = self.moments[m, :, j], self.moment_slopes[m, :, j]
            ok = np.isfinite(M) & np.isfinite(dM)
            if ok.sum() < 2:
                continue
            kept = self._splines.get((m, j))
            if kept is None or not (np.array_equal(kept[0], M, equal_nan=True) and np.array_equal(kept[1], dM, equal_nan=True)):
                kept = (M.copy(), dM.copy(), CubicHermiteSpline(rad[ok], M[ok], dM[ok]))
                self._splines[(m, j)] = kept
            spline = kept[2]
            inside = (theta >= self.angles_deg[ok][0] - 1e-9) & (theta <= self.angles_deg[ok][-1] + 1e-9)
            out[inside, j] = spline(np.radians(theta[inside]))
        return out

    def moment(self, muscle: str, theta_deg, activation) -> np.ndarray:
        """M_m(theta, a) in N mm: Hermite in theta, linear in a between the levels (NaN outside)."""
        theta = np.atleast_1d(np.asarray(theta_deg, dtype=float))
        a = np.broadcast_to(np.asarray(activation, dtype=float), theta.shape)
        values = self.level_moments(muscle, theta)
        return np.array([np.interp(ai, self.levels, row) for ai, row in zip(a, values)])

    # ------------------------------------------------------------------ persistence
    def header(self) -> dict:
        return {"format": FORMAT, "version": VERSION, "muscles": list(MUSCLES), **self.meta}

    def save(self, path: str | Path) -> Path:
        """Write atomically (a kill leaves the previous file or the new one, never half of one)."""
        path = Path(path)
        tmp = path.with_name(f".{path.name}.writing.npz")
        np.savez(tmp, header=np.array(json.dumps(self.header(), default=float)), angles_deg=self.angles_deg,
                 levels=self.levels, tension=self.tension, moments=self.moments, moment_slopes=self.moment_slopes,
                 done=self.done,
                 fine_deg=self.fine_deg, fine_dL=self.fine_dL, fine_gravity=self.fine_gravity, fine_joint=self.fine_joint)
        os.replace(tmp, path)
        return path

    @classmethod
    def load(cls, path: str | Path, model_hash: str | None = None, profile: str | None = None,
             complete: bool = False) -> MomentTable:
        """Read a table; refuse one of another model (hash) or profile, or an unfinished one."""
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"{path}: no such moment table")
        try:
            with np.load(path, allow_pickle=False) as data:
                header = json.loads(str(data["header"]))
                arrays = {k: data[k] for k in data.files if k != "header"}
        except (OSError, ValueError, KeyError) as exc:
            raise TableMismatchError(f"{path} is not a moment table ({exc})") from None
        check_header(header, path, "moment table", FORMAT, VERSION, TableMismatchError, advice="rebuild it")
        meta = {k: v for k, v in header.items() if k not in ("format", "version", "muscles")}
        table = cls(meta=meta, **arrays)
        if model_hash is not None and meta.get("model_hash") != model_hash:
            raise TableMismatchError(f"{path} was built for another model: model hash {str(meta.get('model_hash'))[:12]}, "
                                     f"this model {model_hash[:12]}")
        if profile is not None and meta.get("profile") != profile:
            raise TableMismatchError(f"{path} was built for mesh profile {meta.get('profile')!r}, not {profile!r}")
        if complete and not table.complete:
            raise TableMismatchError(f"{path} is unfinished: {int(table.done.sum())} of {table.done.size} columns; "
                                     "rerun `persival moments` with the same --out to finish it")
        return table


def empty_moment_table(arm, angles: np.ndarray, levels: np.ndarray) -> MomentTable:
    """An empty table with the exact geometry and loads on the fine grid (docs/theory.md, 3.6)."""
    fine = np.arange(angles[0], angles[-1] + 1e-9, FINE_STEP_DEG)
    muscles = arm.spec.ordered_muscles()
    shape = (len(MUSCLES), len(angles), len(levels))
    fa = arm.spec.forearm
    meta = {"model_hash": arm.model_hash, "profile": arm.profile,
            "forearm": {"mass_kg": fa.mass, "centre_of_mass_mm": fa.centre_of_mass, "gravity_m_s2": fa.gravity,
                        "hand_distance_mm": fa.hand_distance},
            "joint_limits_deg": [float(v) for v in arm.spec.joint.limits_deg],
            "column_seconds": [[None] * len(levels) for _ in MUSCLES]}
    return MomentTable(
        angles_deg=angles, levels=levels, tension=np.full(shape, np.nan), moments=np.full(shape, np.nan),
        moment_slopes=np.full(shape, np.nan),
        done=np.zeros((len(MUSCLES), len(levels)), bool), fine_deg=fine,
        fine_dL=np.array([[arm.muscle_length(m, t)[1] for t in fine] for m in muscles]),
        fine_gravity=np.array([arm.gravity_moment(t) for t in fine]),
        fine_joint=np.array([arm.passive_joint_moment(t) for t in fine]), meta=meta)


def check_grids(angles, levels) -> tuple[np.ndarray, np.ndarray]:
    angles, levels = np.asarray(angles, dtype=float), np.asarray(levels, dtype=float)
    if angles.ndim != 1 or len(angles) < 2 or not np.isfinite(angles).all() or np.any(np.diff(angles) <= 0):
        raise ValueError(f"angles must be at least two finite increasing values (deg), got {angles.tolist()}")
    if levels.ndim != 1 or len(levels) < 2 or not np.isfinite(levels).all() or np.any(np.diff(levels) <= 0):
        raise ValueError(f"activation levels must be at least two increasing values, got {levels.tolist()}")
    if levels[0] != 0.0 or levels[-1] != 1.0:
        raise ValueError(f"activation levels must run from 0 to 1, got {levels.tolist()}")
    return angles, levels


def resumable(out, model_hash: str, profile: str, angles, levels) -> MomentTable | None:
    """The table at ``out`` if there is one to resume (same model, profile, grid), None if none;
    TableMismatchError for a file of another model, profile or grid."""
    if not Path(out).exists():
        return None
    table = MomentTable.load(out, model_hash, profile)
    angles, levels = np.asarray(angles, float), np.asarray(levels, float)
    if table.angles_deg.shape != angles.shape or not np.allclose(table.angles_deg, angles) or \
            table.levels.shape != levels.shape or not np.allclose(table.levels, levels):
        raise TableMismatchError(f"{out} has angles {table.angles_deg.tolist()} and levels {table.levels.tolist()}; "
                                 f"asked for {angles.tolist()} and {levels.tolist()} (use another --out)")
    return table


def build_moment_table(arm_or_profile, angles_deg, activations, progress=None, out: str | Path | None = None,
                       model_file: str | Path | None = None, muscles=None) -> MomentTable:
    """FE moment table of every muscle on ``angles_deg`` x ``activations`` (docs/theory.md, 4.5).

    ``arm_or_profile``: an :class:`~persival.model.arm.arm_model.ArmModel` or a profile name. With ``out``
    the table is saved after every (muscle, level) column and an existing file there is
    resumed: finished columns are kept (it must be of the same model, profile and grid).
    ``muscles``: compute only these muscles' columns (the others stay unfinished).
    ``progress(done, total, label)`` is called after every column (label says "skipped" for a
    resumed one).
    """
    angles, levels = check_grids(angles_deg, activations)
    arm = arm_or_profile
    if isinstance(arm_or_profile, str):
        from persival.model.arm.arm_model import ArmModel

        arm = ArmModel(model_file, profile=arm_or_profile)
    table = resumable(out, arm.model_hash, arm.profile, angles, levels) if out is not None else None
    table = table or empty_moment_table(arm, angles, levels)
    total, count, longest = table.done.size, 0, {}
    for m, muscle in enumerate(arm.spec.ordered_muscles()):
        for j, a in enumerate(levels):
            count += 1
            if muscles is not None and muscle.name not in muscles:
                continue
            if table.done[m, j]:
                if progress is not None:
                    progress(count, total, f"{muscle.name} a={a:g} (skipped: done)")
                continue
            t0 = time.perf_counter()
            sweep = sweep_muscle(arm, muscle, angles, float(a), start=longest.get(muscle.name))
            longest[muscle.name] = sweep["longest_state"]  # the next level continues from it
            table.tension[m, :, j], table.moments[m, :, j] = sweep["tension_N"], sweep["moment_Nmm"]
            table.moment_slopes[m, :, j] = sweep["moment_slope_Nmm_per_rad"]
            table.done[m, j] = True
            table.meta["column_seconds"][m][j] = time.perf_counter() - t0
            if out is not None:
                table.save(out)
            if progress is not None:
                progress(count, total, f"{muscle.name} a={a:g}")
    return table
