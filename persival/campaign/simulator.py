"""The simulator interface of a campaign, the picklable spec that names one, and the registry.

A campaign never ships a simulator object to its workers: it ships a `SimulatorSpec` (a kind and
json-able options) and every worker process builds the simulator itself, once, through the
registry. Heavy state (an FE mesh, a factorization, a model file) therefore stays where it is
used, and a worker that is restarted simply builds it again.
"""

from __future__ import annotations

import hashlib
import importlib
import json
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np

__all__ = [
    "SurfaceTopology",
    "ReferenceGeometry",
    "SimulationResult",
    "Simulator",
    "SimulatorSpec",
    "SimulationTimeout",
    "UnknownSimulatorError",
    "register_simulator",
    "registered_kinds",
    "simulator_factory",
    "make_simulator",
    "cached_simulator",
    "forget_cached_simulator",
]

@dataclass
class SurfaceTopology:
    """The display surface of one muscle in its reference configuration."""

    name: str
    reference_points: np.ndarray  # (n, 3) float64, mm
    triangles: np.ndarray  # (k, 3) int, linear display triangles into reference_points
    # Optional node set: index of each surface node in the simulator's full (volume) mesh.
    node_ids: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.reference_points = np.ascontiguousarray(self.reference_points, dtype=np.float64)
        self.triangles = np.ascontiguousarray(self.triangles, dtype=np.int64)
        n = len(self.reference_points)
        if self.node_ids is not None:
            self.node_ids = np.ascontiguousarray(self.node_ids, dtype=np.int64)
            if self.node_ids.shape != (n,):
                raise ValueError(f"surface {self.name!r}: node_ids must have shape ({n},), got "
                                 f"{self.node_ids.shape}")
        if self.reference_points.ndim != 2 or self.reference_points.shape[1] != 3 or n == 0:
            raise ValueError(f"surface {self.name!r}: reference_points must be (n, 3) with n > 0, "
                             f"got shape {self.reference_points.shape}")
        if not np.isfinite(self.reference_points).all():
            raise ValueError(f"surface {self.name!r}: reference_points are not all finite")
        if self.triangles.ndim != 2 or self.triangles.shape[1] != 3:
            raise ValueError(f"surface {self.name!r}: triangles must be (k, 3), got shape "
                             f"{self.triangles.shape}")
        if self.triangles.size and (self.triangles.min() < 0 or self.triangles.max() >= n):
            raise ValueError(f"surface {self.name!r}: triangle indices must lie in [0, {n})")

    @property
    def n_nodes(self) -> int:
        return len(self.reference_points)


@dataclass
class ReferenceGeometry:
    """Every surface a simulator reports, plus the provenance of the model behind them."""

    surfaces: dict[str, SurfaceTopology]  # ordered as the simulator lists its muscles
    model_hash: str  # sha256 of the model definition (provenance)
    description: dict = field(default_factory=dict)  # json-able: model name, profile, units

    def __post_init__(self) -> None:
        if not self.surfaces:
            raise ValueError("a reference geometry needs at least one surface")
        for name, surface in self.surfaces.items():
            if name != surface.name:
                raise ValueError(f"surface stored under {name!r} is named {surface.name!r}")

    @property
    def names(self) -> list[str]:
        return list(self.surfaces)


@dataclass
class SimulationResult:
    """One solved state."""

    elbow_angle_deg: float
    surfaces: dict[str, np.ndarray]  # current positions (n, 3) per surface, reference node order
    statistics: dict  # json-able: newton iterations, load steps, residuals, ...
    wall_time_s: float


@runtime_checkable
class Simulator(Protocol):
    """What a campaign needs from a simulator.

    ``simulate(activations, warm_start, attempt)``: activations are (5,) in [0, 1];
    ``warm_start`` is a token returned by an earlier ``simulate`` of the *same instance* (a
    nearby solved state) or None; ``attempt`` is 0 on the first try and 1, 2, ... on retries,
    where the simulator should take smaller load steps. Returns the result and a token for later
    warm starts (or None). Raising any exception marks the attempt as failed.

    A simulator may also define ``cancel()``: called from another thread when an attempt runs
    past the campaign's timeout; it must make the running ``simulate`` return or raise soon
    (the external-command simulator kills its process group). Without it the campaign abandons
    the hung attempt and, on dask, restarts the worker process.
    """

    name: str

    def reference(self) -> ReferenceGeometry: ...

    def simulate(
        self, activations: np.ndarray, warm_start: object | None = None, attempt: int = 0
    ) -> tuple[SimulationResult, object | None]: ...


class SimulationTimeout(RuntimeError):
    """An attempt ran past the campaign's time limit (recorded as failure reason 'timeout')."""


class UnknownSimulatorError(KeyError):
    def __str__(self) -> str:  # KeyError would print the message with quotes
        return str(self.args[0])


def _canonical_json(obj: Any) -> str:
    try:
        return json.dumps(obj, sort_keys=True, separators=(",", ":"), allow_nan=False)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"simulator options must be json-able (no NaN): {exc}") from None


@dataclass(frozen=True)
class SimulatorSpec:
    """Names a simulator: ``kind`` from the registry and json-able ``options`` for its factory.

    Picklable and comparable; a campaign store records it, and resuming with a different spec is
    refused.
    """

    kind: str
    options: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not isinstance(self.kind, str) or not self.kind:
            raise ValueError(f"simulator kind must be a non-empty string, got {self.kind!r}")
        if not isinstance(self.options, dict):
            raise ValueError(f"simulator options must be a dict, got {type(self.options).__name__}")
        _canonical_json(self.options)

    def to_json(self) -> str:
        return _canonical_json({"kind": self.kind, "options": self.options})

    def digest(self) -> str:
        return hashlib.sha256(self.to_json().encode()).hexdigest()

    def __hash__(self) -> int:  # options is a dict, so the dataclass hash would fail
        return hash(self.to_json())


# --------------------------------------------------------------------------------------------
# Registry
# --------------------------------------------------------------------------------------------
Factory = Callable[..., Simulator]

# Kinds that live in modules not imported by default: "module:attribute" of the factory, imported
# on first use in whichever process needs it (the driver or a dask worker). "arm" is the built-in
# FE model (persival.model) wrapped by arm_simulator.
_LAZY: dict[str, str] = {
    "analytic": "persival.campaign.analytic:AnalyticSimulator",
    "external": "persival.campaign.external:ExternalSimulator",
    "arm": "persival.campaign.arm_simulator:ArmSimulator",
}
_REGISTRY: dict[str, Factory] = {}
_LOCK = threading.Lock()


def register_simulator(kind: str, factory: Factory | str) -> None:
    """Make ``kind`` buildable: ``factory(**options)`` returns a Simulator.

    ``factory`` may be a "module:attribute" string, imported on first use. For dask campaigns
    the factory must be importable by the workers (a module-level callable), because the runner
    ships it by reference.
    """
    if not isinstance(kind, str) or not kind:
        raise ValueError(f"simulator kind must be a non-empty string, got {kind!r}")
    with _LOCK:
        if isinstance(factory, str):
            _LAZY[kind] = factory
            _REGISTRY.pop(kind, None)
        elif callable(factory):
            _REGISTRY[kind] = factory
        else:
            raise TypeError(f"factory for {kind!r} must be callable or 'module:attribute'")


def registered_kinds() -> list[str]:
    return sorted(set(_REGISTRY) | set(_LAZY))


def simulator_factory(kind: str) -> Factory:
    """The factory registered for ``kind``; imports lazily registered kinds on first use."""
    with _LOCK:
        if kind in _REGISTRY:
            return _REGISTRY[kind]
        target = _LAZY.get(kind)
    if target is None:
        raise UnknownSimulatorError(
            f"unknown simulator kind {kind!r}; registered kinds: {', '.join(registered_kinds())}"
        )
    module_name, _, attr = target.partition(":")
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        if exc.name and module_name.startswith(exc.name):
            raise UnknownSimulatorError(
                f"simulator kind {kind!r} is not available in this installation: its module "
                f"{module_name} does not exist (yet)"
            ) from None
        raise
    try:
        factory = getattr(module, attr)
    except AttributeError:
        raise UnknownSimulatorError(
            f"simulator kind {kind!r}: {module_name} has no attribute {attr!r}"
        ) from None
    with _LOCK:
        _REGISTRY.setdefault(kind, factory)
        return _REGISTRY[kind]


def make_simulator(spec: SimulatorSpec, factory: Factory | None = None) -> Simulator:
    """A new simulator for ``spec`` (``factory`` overrides the registry lookup)."""
    factory = factory or simulator_factory(spec.kind)
    sim = factory(**spec.options)
    for attr in ("reference", "simulate"):
        if not callable(getattr(sim, attr, None)):
            raise TypeError(f"simulator kind {spec.kind!r} built an object without {attr}()")
    return sim


# One simulator per spec and process: workers keep their (possibly expensive) model between
# states, and a chain of neighbouring states can warm-start from each other.
_CACHE: dict[str, Simulator] = {}


def cached_simulator(spec: SimulatorSpec, factory: Factory | None = None) -> Simulator:
    key = spec.to_json()
    with _LOCK:
        sim = _CACHE.get(key)
    if sim is None:
        sim = make_simulator(spec, factory)
        with _LOCK:
            sim = _CACHE.setdefault(key, sim)
    return sim


def forget_cached_simulator(spec: SimulatorSpec) -> None:
    """Drop the cached instance (after a hung attempt that may still be using it)."""
    with _LOCK:
        _CACHE.pop(spec.to_json(), None)
