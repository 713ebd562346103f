"""Load and check an export folder (docs/deployment.md) and run its ONNX models.

The server and the load test only ever see a `DeployedModel`: everything that can be wrong
with a folder (missing file, corrupt ONNX, metadata that disagrees with the graphs) is found
here, once, at start-up, and reported as an `ArtifactError` naming the file and the field, so
that `persival serve` refuses to start instead of failing on the first request.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from persival.file_header import check_header
from persival.onnx_io import onnx_session
from persival.vocabulary import N_ACTIVATIONS, check_activation_vector

__all__ = ["ArtifactError", "DeployedModel", "FORMAT_NAME", "SUPPORTED_VERSIONS", "TIERS"]

FORMAT_NAME = "persival-export"
SUPPORTED_VERSIONS = (1,)
#: Model tiers in order of accuracy (the automatic mode steps down this list).
TIERS = ("float32", "float16", "int8")


class ArtifactError(RuntimeError):
    """An export folder that cannot be served; the message says what to fix."""


def _session(path: Path):
    if not path.is_file():
        raise ArtifactError(f"{path}: file missing (listed in metadata.json)")
    try:
        # One thread per session: the server answers many small requests concurrently, and a
        # thread pool per call would only add wake-up latency on a 2-core machine.
        return onnx_session(path, threads=1)
    except Exception as exc:  # onnxruntime raises its own Fail/InvalidGraph types
        raise ArtifactError(f"{path}: not a loadable ONNX model ({str(exc).splitlines()[0]})") from None


def _require(meta: dict, key: str, kind: type, where: str = "metadata.json"):
    if key not in meta:
        raise ArtifactError(f"{where}: missing field {key!r}")
    if not isinstance(meta[key], kind):
        raise ArtifactError(f"{where}: field {key!r} must be a {kind.__name__}")
    return meta[key]


def _io_shape(sess, name: str, inputs: bool) -> list:
    items = sess.get_inputs() if inputs else sess.get_outputs()
    for item in items:
        if item.name == name:
            return [d if isinstance(d, int) else None for d in item.shape]
    raise ArtifactError(f"model has no {'input' if inputs else 'output'} named {name!r} "
                        f"(it has {[i.name for i in items]})")


def _finite_number(value, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"{what} must be a number, got {type(value).__name__}")
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"{what} must be finite, got {value}")
    return value


def load_metadata(folder: Path) -> dict:
    path = folder / "metadata.json"
    if not folder.is_dir():
        raise ArtifactError(f"{folder}: no such artifact folder (run `persival export` first)")
    if not path.is_file():
        raise ArtifactError(f"{path}: missing; not an export folder")
    try:
        meta = json.loads(path.read_text())
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ArtifactError(f"{path}: not valid JSON ({exc})") from None
    return check_header(meta, path, "PerSival export", FORMAT_NAME, SUPPORTED_VERSIONS, ArtifactError,
                        version_key="format_version", advice="export it again with this version")


def _check_geometry(meta: dict) -> None:
    n_nodes = _require(meta, "n_nodes", int)
    surfaces = _require(meta, "surfaces", list)
    muscles = _require(meta, "muscles", list)
    if len(muscles) != N_ACTIVATIONS or [s.get("name") for s in surfaces] != muscles:
        raise ArtifactError("metadata.json: 'surfaces' must list the five muscles in the order of 'muscles'")
    start = 0
    for s in surfaces:
        if s.get("node_start") != start or not isinstance(s.get("node_count"), int) or s["node_count"] <= 0:
            raise ArtifactError(f"metadata.json: surface {s.get('name')!r}: node ranges must be contiguous")
        start += s["node_count"]
    if start != n_nodes:
        raise ArtifactError(f"metadata.json: surfaces cover {start} nodes, n_nodes is {n_nodes}")
    ref = np.asarray(_require(meta, "reference_points", list), dtype=np.float64)
    if ref.shape != (n_nodes, 3) or not np.isfinite(ref).all():
        raise ArtifactError(f"metadata.json: reference_points must be {n_nodes} x 3 finite numbers, got {ref.shape}")
    tris = np.asarray(_require(meta, "triangles", list))
    if tris.ndim != 2 or tris.shape[1] != 3 or tris.min() < 0 or tris.max() >= n_nodes:
        raise ArtifactError(f"metadata.json: triangles must be k x 3 node indices in [0, {n_nodes})")
    _require(meta, "skeleton", dict)


class DeployedModel:
    """One export folder: metadata, the deformation model (every tier) and the activation models."""

    def __init__(self, folder: str | Path) -> None:
        self.folder = Path(folder).resolve()
        self.metadata = meta = load_metadata(self.folder)
        _check_geometry(meta)
        self.n_nodes: int = meta["n_nodes"]
        self.muscles: list[str] = list(meta["muscles"])
        models = _require(meta, "models", dict)
        deformation = _require(models, "deformation", dict, "metadata.json: models")
        variants = _require(deformation, "variants", dict, "metadata.json: models.deformation")
        if "float32" not in variants:
            raise ArtifactError("metadata.json: models.deformation.variants has no 'float32'")
        self.sessions = {tier: self._deformation_session(tier, v) for tier, v in variants.items()}
        # Optional parts: an export may lack the angle output, the angle model or the motion model;
        # the requests that need them are refused then, the rest is served.
        self.has_angle = "elbow_angle_deg" in [o.name for o in self.sessions["float32"].get_outputs()]
        # an optional input backed by an initializer is listed among the overridable initializers
        float32 = self.sessions["float32"]
        self.takes_load = "load_kg" in [i.name for i in float32.get_inputs() + float32.get_overridable_initializers()]
        self.angle, self.angle_range = None, None
        if models.get("activation_angle"):
            self.angle_range = self._angle_model(models["activation_angle"])
        motion = models.get("activation_motion")
        self.motion = _session(self.folder / _require(motion, "file", str)) if motion else None
        self.max_load_kg = float(motion.get("max_load_kg", 0.0)) if motion else 0.0

    def _deformation_session(self, tier: str, variant: dict):
        sess = _session(self.folder / _require(variant, "file", str, f"variant {tier}"))
        try:
            if _io_shape(sess, "activations", True)[1:] != [N_ACTIVATIONS]:
                raise ArtifactError("input 'activations' must be [batch, 5]")
            if _io_shape(sess, "positions", False)[1:] not in ([self.n_nodes, 3], [None, None]):
                raise ArtifactError(f"output 'positions' is not [batch, {self.n_nodes}, 3] (metadata's n_nodes): "
                                    "model and metadata.json do not belong together")
        except ArtifactError as exc:
            raise ArtifactError(f"{variant['file']}: {exc}") from None
        out = sess.run(["positions"], {"activations": np.zeros((1, N_ACTIVATIONS), np.float32)})[0]
        if out.shape != (1, self.n_nodes, 3):
            raise ArtifactError(f"{variant['file']}: predicts {out.shape[1:]} positions, metadata says "
                                f"{self.n_nodes} nodes: model and metadata.json do not belong together")
        return sess

    def _angle_model(self, spec: dict) -> tuple[float, float]:
        self.angle = _session(self.folder / _require(spec, "file", str, "activation_angle"))
        lo, hi = (float(v) for v in _require(spec, "range_deg", list, "activation_angle"))
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise ArtifactError(f"metadata.json: activation_angle.range_deg must be [lo, hi], got {[lo, hi]}")
        return lo, hi

    @property
    def tiers(self) -> list[str]:
        return [t for t in TIERS if t in self.sessions]

    def check_activations(self, activations) -> np.ndarray:
        """(5,) float32 in [0, 1], or ValueError saying which entry is wrong."""
        if not isinstance(activations, (list, tuple, np.ndarray)) or len(activations) != N_ACTIVATIONS:
            raise ValueError(f"activations must be a list of {N_ACTIVATIONS} numbers ({', '.join(self.muscles)})")
        # JSON types first (a bool or a numeric string is a client bug, not an activation), then
        # the shared finite-and-in-[0, 1] check every stage applies.
        for i, v in enumerate(activations):
            if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)):
                raise ValueError(f"activations[{i}] ({self.muscles[i]}) must be a number, got {type(v).__name__}")
        return check_activation_vector(activations).astype(np.float32)

    def check_load(self, load_kg) -> float:
        """A load in the hand (kg) in [0, max_load_kg], or ValueError."""
        load = _finite_number(load_kg, "load_kg")
        if load and self.motion is None:
            raise ValueError("load_kg needs the motion model, which this export does not have")
        if not 0.0 <= load <= self.max_load_kg:
            raise ValueError(f"load_kg = {load} lies outside [0, {self.max_load_kg}]")
        return load

    def predict(self, activations, tier: str = "float32", load_kg=0.0) -> tuple[np.ndarray, np.ndarray]:
        """Positions (n, n_nodes, 3) mm and elbow angles (n,) deg for activations (5,) or (n, 5)
        and a load in the hand (kg): the deformation model solves the elbow's balance with it."""
        if tier not in self.sessions:
            raise ValueError(f"tier {tier!r} is not exported (have {self.tiers})")
        rows = activations.tolist() if isinstance(activations, np.ndarray) else activations
        if isinstance(rows, (list, tuple)) and rows and isinstance(rows[0], (list, tuple)):
            batch = np.stack([self.check_activations(r) for r in rows])
        else:
            batch = self.check_activations(rows)[None, :]
        load = self.check_load(load_kg)
        feeds = {"activations": batch}
        if load:
            if not self.takes_load:
                raise ValueError("this export's deformation model takes no load (load_kg): send activations alone")
            feeds["load_kg"] = np.full((1, 1), load, np.float32)
        if not self.has_angle:
            positions = self.sessions[tier].run(["positions"], feeds)[0]
            return positions, np.full(len(batch), np.nan, np.float32)
        positions, angle = self.sessions[tier].run(["positions", "elbow_angle_deg"], feeds)
        return positions, angle[:, 0]

    def activations_for_angle(self, angle_deg, load_kg=None) -> np.ndarray:
        """Least-effort activations (5,) that hold the elbow at an angle with a load in the hand (kg):
        the angle model without a load, the motion model with one; a load the muscles cannot hold
        there is refused with the load they can."""
        angle = _finite_number(angle_deg, "angle_deg")
        if self.angle is None:
            raise ValueError("this export has no activation model (activation_angle.onnx): send activations")
        lo, hi = self.angle_range
        if not lo <= angle <= hi:
            raise ValueError(f"angle_deg = {angle} lies outside the model's range [{lo:.2f}, {hi:.2f}]")
        load = 0.0 if load_kg is None else self.check_load(load_kg)
        if not load:
            return self.angle.run(None, {"elbow_angle_deg": np.array([[angle]], np.float32)})[0][0]
        activations, *deficit = self.motion.run(None, {"motion": np.array([[angle, 0.0, 0.0, load]], np.float32)})
        if deficit and deficit[0][0, 0] > 0:
            held = float(self.holdable_load_kg([angle])[0])
            raise ValueError(f"the muscles hold at most {held:.2f} kg at {angle:g} deg, not {load:g} kg")
        return activations[0]

    def holdable_load_kg(self, angles_deg, iterations: int = 40) -> np.ndarray:
        """The heaviest load (kg, at most max_load_kg) held at rest at each angle: bisection on the
        motion model's moment deficit (0 where the muscles hold the load)."""
        angles = np.asarray(angles_deg, dtype=np.float32).reshape(-1)
        if self.motion is None:
            return np.zeros(len(angles))
        lo, hi = np.zeros(len(angles)), np.full(len(angles), self.max_load_kg)
        for _ in range(iterations):
            mid = 0.5 * (lo + hi)
            rows = np.column_stack([angles, np.zeros((len(angles), 2)), mid]).astype(np.float32)
            held = self.motion.run(None, {"motion": rows})[1][:, 0] <= 0
            lo, hi = np.where(held, mid, lo), np.where(held, hi, mid)
        return lo

    def split(self, positions: np.ndarray) -> dict[str, np.ndarray]:
        """One state's (n_nodes, 3) positions cut into the muscles' node ranges."""
        return {s["name"]: positions[s["node_start"]: s["node_start"] + s["node_count"]]
                for s in self.metadata["surfaces"]}

    def files(self) -> dict[str, Path]:
        """The artifact files a client may download: metadata.json and every listed model (the
        deformation tiers, its required-load file if exported, the activation models)."""
        models = self.metadata["models"]
        names = ["metadata.json"] + [v["file"] for v in models["deformation"]["variants"].values()]
        if models["deformation"].get("load_variant"):
            names.append(models["deformation"]["load_variant"]["file"])
        names += [models[k]["file"] for k in ("activation_angle", "activation_motion") if models.get(k)]
        return {n: self.folder / n for n in names}
