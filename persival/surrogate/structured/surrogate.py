"""The structured surrogate: per-muscle shape and moment models and the elbow's equilibrium.

The physics decomposes (docs/theory.md 7.7): each muscle's FE state depends
on the elbow angle and its own activation only, and the elbow angle is the stable root of one
scalar moment balance. So instead of learning the 5-D map alpha -> surfaces from a campaign, this
surrogate is fitted from the FE arm's response tables: five 2-D moment models, five 2-D shape
models (POD of each muscle's surfaces) and a root search. ``fit`` needs no campaign: the
dataset only names the surfaces to answer (and must come from the same model).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from persival.surrogate.base import Surrogate
from persival.surrogate.dataset import Dataset, Surfaces
from persival.surrogate.structured.moment_model import MomentModel
from persival.surrogate.structured.shape_model import MuscleShape, fit_muscle_shape
from persival.vocabulary import MUSCLES, check_activations

__all__ = ["StructuredSurrogate", "DEFAULT_TOLERANCE_MM", "FRAMES"]

# The POD truncation: 0.2 mm keeps the held-out error where 0.05 mm had it (quick run, 25 FE
# states: mean 0.042 against 0.033 mm, worst 1.005 against 0.993 mm, the worst set by the angle)
# with 61 modes (world frame) instead of 96 (own frame), which the exported graph reads once per
# state (docs/benchmarks.md)
DEFAULT_TOLERANCE_MM = 0.2
FRAMES = ("world", "own")

class StructuredSurrogate(Surrogate):
    """Surfaces and elbow angle of the FE arm from per-muscle models fitted to its response tables.

    ``profile``, ``model_file``, ``tables``: the arm and its table folder (default: the one
    ``persival tables`` builds); ``tolerance_mm``: the POD truncation (every tabulated state
    reproduced within it at every node); ``max_modes``: the most modes per muscle; ``frame``:
    where each muscle's surfaces are reduced, ``"world"`` (the default: the exported graph reads
    a surface with one product) or ``"own"`` (the muscle's frame, turned by Q(theta): fewer modes,
    one more product per muscle; docs/theory.md 7.7).
    """

    kind = "structured"
    has_angle = True
    # float32 only: a float16 or int8 graph would run the root search in reduced precision
    deploy_tiers = ("float32",)
    # ONNX runtime and PyTorch round the root search's float32 arithmetic differently: the angles
    # agree to about 1e-5 deg, which a 300 mm forearm turns into about 1e-4 mm
    export_tolerance_mm = 1e-3
    # the POD modes are stored in float16 and cast at load: folding at export would store float32
    export_constant_folding = False

    def __init__(self, profile: str = "quick", model_file: str | None = None, tables: str | None = None,
                 tolerance_mm: float = DEFAULT_TOLERANCE_MM, max_modes: int = 60, frame: str = "world") -> None:
        if frame not in FRAMES:
            raise ValueError(f"frame must be one of {FRAMES}, not {frame!r}")
        if not tolerance_mm > 0:
            raise ValueError(f"the POD tolerance must be positive, not {tolerance_mm} mm")
        self.frame = frame
        self.profile = profile
        self.model_file = None if model_file is None else str(model_file)
        self.tables = None if tables is None else str(tables)
        self.tolerance_mm = float(tolerance_mm)
        self.max_modes = int(max_modes)
        self.surfaces: Surfaces | None = None
        self.moments: MomentModel | None = None
        self.shapes: list[MuscleShape] = []
        self.metadata: dict = {}

    # ------------------------------------------------------------------ fit
    def fit(self, dataset: Dataset, progress=None) -> StructuredSurrogate:
        """Fit to the response tables of the arm that produced ``dataset``'s states, answering its surfaces."""
        from persival.campaign.arm_simulator import muscle_surface
        from persival.model.arm.arm_model import ArmModel
        from persival.tables.open import open_tables

        simulator = dataset.source.get("simulator")
        if simulator not in (None, "arm"):
            raise ValueError(f"the structured surrogate is fitted to the FE arm's response tables; the dataset holds "
                             f"states of the {simulator!r} simulator (use a campaign of the arm)")
        t0 = time.perf_counter()
        arm = ArmModel(self.model_file, self.profile)
        dataset.require_model(arm.model_hash)
        table = open_tables(arm, self.tables)
        moment_table = table.moment_table()
        self.moments = MomentModel.from_table(moment_table, arm.spec, arm.base_state().elbow_angle_deg)
        lo, hi = self.moments.range_deg
        angle_index = np.flatnonzero((table.angles_deg >= lo) & (table.angles_deg <= hi))
        shapes = []
        for i, (name, count) in enumerate(zip(dataset.surfaces.names, dataset.surfaces.node_counts)):
            if name not in MUSCLES:
                raise ValueError(f"the FE arm has no muscle {name!r} (dataset surfaces: {list(dataset.surfaces.names)})")
            nodes = muscle_surface(arm, name)[0]
            if len(nodes) != count:
                raise ValueError(f"surface {name!r}: the dataset has {count} nodes, the {self.profile} mesh {len(nodes)}: "
                                 "fit on states of the same mesh profile")
            local = np.searchsorted(arm.muscle_nodes[name], nodes)
            shapes.append(fit_muscle_shape(table, arm.units[name], name, local, angle_index, self.tolerance_mm,
                                           self.max_modes, world_frame=self.frame == "world"))
            if progress is not None:
                progress(i + 1, len(dataset.surfaces.names), name)
        self.shapes = shapes
        self.surfaces = dataset.surfaces
        self.metadata = {
            "kind": self.kind, "arch": "structured", "source": dataset.source, "profile": self.profile, "frame": self.frame,
            "model_hash": arm.model_hash,
            "tables": str(table.root), "muscles": list(dataset.surfaces.names),
            "grid": {"angles_deg": [lo, hi, len(angle_index)], "levels": table.levels.tolist()},
            "modes": {s.name: s.report["modes"] for s in shapes},
            "pod_worst_projection_error_mm": {s.name: round(s.report["worst_projection_error_mm"], 4) for s in shapes},
            "parameters": self.parameter_count, "fit_seconds": round(time.perf_counter() - t0, 2),
        }
        return self

    @property
    def parameter_count(self) -> int:
        arrays = [self.moments.data] + [a for s in self.shapes for a in (s.mean, s.modes, s.coefficient_data,
                                                                       s.rotation_data)]
        return int(sum(a.size for a in arrays))

    # ------------------------------------------------------------------ answers
    @property
    def fitted(self) -> bool:
        return self.moments is not None

    def predict_with_angle(self, activations, load_kg=0.0) -> tuple[np.ndarray, np.ndarray]:
        """Positions (m, N, 3) mm and elbow angles (m,) deg; activations (m, 5) or (5,), load in the hand (kg)."""
        self._require_fit()
        alpha = check_activations(activations)
        theta = self.moments.equilibrium(alpha, load_kg)
        return self.surfaces_at(theta, alpha), theta

    def surfaces_at(self, angles_deg, activations) -> np.ndarray:
        """Positions (m, N, 3) mm of the shape models at prescribed elbow angles (m,): the arm held
        at an angle, or the shape part of the error alone (at the FE state's own angle)."""
        self._require_fit()
        alpha = check_activations(activations)
        theta_w = self.moments.theta_basis.weights(np.broadcast_to(np.asarray(angles_deg, dtype=float), (len(alpha),)))
        parts = [s.positions(theta_w, self.moments.activation_basis.weights(alpha[:, s.muscle_index]))
                 for s in self.shapes]
        return np.concatenate(parts, axis=1)

    def predict_angle(self, activations) -> np.ndarray:
        self._require_fit()
        return self.moments.equilibrium(check_activations(activations))

    def deployable(self, dtype=None):
        """The exportable PyTorch graph (activations, load_kg) -> (positions, elbow_angle_deg)."""
        import torch

        from persival.surrogate.structured.graph import StructuredGraph

        self._require_fit()
        return StructuredGraph(self.moments, self.shapes, dtype or torch.float32)

    # ------------------------------------------------------------------ folder
    def save(self, path: str | Path) -> Path:
        self._require_fit()
        path = Path(path)
        path.mkdir(parents=True, exist_ok=True)
        self.surfaces.save(path / "surfaces.npz")
        arrays = self.moments.arrays()
        for s in self.shapes:
            for key in ("origin", "mean", "modes", "coefficient_data", "rotation_data"):
                arrays[f"{s.name}/{key}"] = getattr(s, key)
        np.savez(path / "structured.npz", **arrays)
        self.write_manifest(path, {
            "profile": self.profile, "model_file": self.model_file, "tables": self.tables, "tolerance_mm": self.tolerance_mm,
            "max_modes": self.max_modes, "frame": self.frame, "moments": self.moments.parameters(),
            "shapes": {s.name: s.report for s in self.shapes}, "metadata": self.metadata})
        return path

    @classmethod
    def load(cls, path: str | Path) -> StructuredSurrogate:
        path = Path(path)
        meta = cls.read_manifest(path)
        surrogate = cls(meta["profile"], meta.get("model_file"), meta.get("tables"), meta["tolerance_mm"], meta["max_modes"],
                        meta.get("frame", "own"))  # saved before the frame was a choice: the own frame
        with np.load(path / "structured.npz") as data:
            arrays = {k: data[k] for k in data.files}
        surrogate.moments = MomentModel.from_arrays(arrays, meta["moments"])
        surrogate.surfaces = Surfaces.load(path / "surfaces.npz")
        surrogate.shapes = [MuscleShape(name, *(arrays[f"{name}/{k}"] for k in ("origin", "mean", "modes", "coefficient_data",
                                                                            "rotation_data")), meta["shapes"][name])
                            for name in surrogate.surfaces.names]
        surrogate.metadata = meta["metadata"]
        return surrogate
