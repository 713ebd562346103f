"""A cheap closed-form simulator: five capsule-shaped "muscles" that contract, bulge and follow a
flexing elbow.

It exists so that campaigns, stores, exports and surrogates can be exercised end to end in
seconds. Every output is a smooth nonlinear function of the activations (tanh of polynomial
torques for the flexion angle; activation-dependent shortening, volume-keeping bulging and a
smooth rotation about the elbow axis for the nodes), so a surrogate fitted to it has something
real to approximate. The surfaces are gmsh triangulations of capsules. It is not a physical
model of the arm: use the "arm" kind for that.

Geometry: shoulder at the origin, humerus along -z, elbow axis parallel to y through
(0, 0, -300) mm. The reference configuration is the straight arm; ``elbow_angle_deg`` is the
flexion angle (0 = straight).
"""

from __future__ import annotations

import hashlib
import json
import threading
import time
from functools import lru_cache

import numpy as np

from persival.campaign.simulator import ReferenceGeometry, SimulationResult, SurfaceTopology
from persival.vocabulary import MUSCLES, check_activation_vector

__all__ = ["AnalyticSimulator"]

_ELBOW_Z = -300.0
# name -> (centre xyz, radius, overall length) of a capsule, mm; biceps, brachialis and triceps
# lie on the upper arm, brachioradialis and anconeus cross the elbow, so the flexion bends them.
_MUSCLE_SHAPES = {
    "biceps": ((22.0, 0.0, -170.0), 15.0, 240.0),
    "brachialis": ((10.0, 0.0, -235.0), 12.0, 140.0),
    "brachioradialis": ((18.0, 12.0, -330.0), 9.5, 180.0),
    "triceps": ((-22.0, 0.0, -160.0), 16.0, 240.0),
    "anconeus": ((-12.0, 8.0, -315.0), 6.0, 50.0),
}
# The rotation about the elbow is blended in over this z band (mm below the shoulder), so
# muscles that cross the joint bend smoothly instead of tearing.
_BLEND = (-280.0, -325.0)
_MODEL_VERSION = 1
_GMSH_LOCK = threading.Lock()  # gmsh has one global state per process


@lru_cache(maxsize=4)
def _capsule_surfaces(mesh_size: float) -> tuple[tuple[str, np.ndarray, np.ndarray], ...]:
    """gmsh surface triangulations of the five capsules (cached per process).

    Capsules (a cylinder fused with two spheres) rather than scaled spheres: gmsh meshes an
    affinely stretched OCC sphere erratically (5x the nodes for a 5 % change of one axis),
    a capsule reliably; the activation-dependent bulge then makes it spindle-shaped.
    """
    import gmsh

    out = []
    with _GMSH_LOCK:
        owner = not gmsh.isInitialized()
        if owner:
            # interruptible=False: no signal handler, so this also works in a dask worker thread.
            gmsh.initialize(readConfigFiles=False, interruptible=False)
        try:
            gmsh.option.setNumber("General.Terminal", 0)
            gmsh.option.setNumber("General.NumThreads", 1)  # deterministic node order
            for name in MUSCLES:
                (cx, cy, cz), radius, length = _MUSCLE_SHAPES[name]
                half = 0.5 * length - radius  # half-length of the cylindrical part
                gmsh.model.add(f"persival-analytic-{name}")
                occ = gmsh.model.occ
                cyl = occ.addCylinder(0.0, 0.0, -half, 0.0, 0.0, 2.0 * half, radius)
                caps = [(3, occ.addSphere(0.0, 0.0, z, radius)) for z in (-half, half)]
                occ.fuse([(3, cyl)], caps)
                gmsh.model.occ.synchronize()
                gmsh.option.setNumber("Mesh.MeshSizeMin", mesh_size)
                gmsh.option.setNumber("Mesh.MeshSizeMax", mesh_size)
                gmsh.model.mesh.generate(2)
                node_tags, coords, _ = gmsh.model.mesh.getNodes()
                _, tri_nodes = gmsh.model.mesh.getElementsByType(2)
                gmsh.model.remove()
                coords = coords.reshape(-1, 3) + np.array([cx, cy, cz])
                tri_tags = tri_nodes.astype(np.int64).reshape(-1, 3)
                # Keep only nodes used by triangles (gmsh also lists seam/geometry points),
                # numbered in order of their gmsh tag.
                used = np.unique(tri_tags)
                lookup = np.full(int(node_tags.max()) + 1, -1, dtype=np.int64)
                lookup[node_tags.astype(np.int64)] = np.arange(len(node_tags))
                points = coords[lookup[used]]
                renumber = np.full(int(used.max()) + 1, -1, dtype=np.int64)
                renumber[used] = np.arange(len(used))
                out.append((name, points, renumber[tri_tags]))
        finally:
            if owner:
                gmsh.finalize()
    return tuple(out)


def flexion_angle_deg(activations: np.ndarray) -> float:
    """Closed-form elbow flexion: tanh of flexor minus extensor torque (polynomials in alpha)."""
    a0, a1, a2, a3, a4 = (float(v) for v in activations)
    flexor = 1.0 * a0 + 0.35 * a0 * a0 + 0.7 * a1 + 0.5 * a2 * a2 + 0.15 * a0 * a1
    extensor = 1.1 * a3 + 0.25 * a4 + 0.2 * a4 * a4 + 0.1 * a3 * a4
    return 70.0 + 65.0 * np.tanh(1.4 * (flexor - extensor))


def _deform(name: str, points: np.ndarray, activation: float, theta_deg: float) -> np.ndarray:
    (cx, cy, cz), _, length = _MUSCLE_SHAPES[name]
    rz = 0.5 * length
    theta = np.deg2rad(theta_deg)
    # Active shortening along the muscle axis, more when the elbow is flexed.
    s = 1.0 - 0.18 * activation * (1.0 + 0.3 * np.sin(theta))
    zeta = (points[:, 2] - cz) / rz
    # Volume-keeping radial growth 1/sqrt(s), plus a belly bulge that peaks mid-muscle.
    radial = (1.0 + 0.06 * activation**2 * (1.0 - zeta**2)) / np.sqrt(s)
    out = np.empty_like(points)
    out[:, 0] = cx + radial * (points[:, 0] - cx)
    out[:, 1] = cy + radial * (points[:, 1] - cy)
    out[:, 2] = cz + s * (points[:, 2] - cz)
    # Rotation about the elbow axis (y through z = _ELBOW_Z), blended in with a smoothstep.
    t = np.clip((out[:, 2] - _BLEND[0]) / (_BLEND[1] - _BLEND[0]), 0.0, 1.0)
    phi = theta * t * t * (3.0 - 2.0 * t)
    x, d = out[:, 0].copy(), out[:, 2] - _ELBOW_Z
    out[:, 0] = x * np.cos(phi) - d * np.sin(phi)
    out[:, 2] = _ELBOW_Z + x * np.sin(phi) + d * np.cos(phi)
    return out


class AnalyticSimulator:
    """Closed-form stand-in for an FE model (kind "analytic").

    Options: ``mesh_size`` (mm, gmsh target edge length; 8 gives about 1500 surface nodes in
    all) and ``delay_s`` (sleep per state, to emulate an expensive solve in demos and tests of
    the campaign machinery). Warm starts are accepted and reported in the statistics but cannot
    change the result: the outputs are closed-form, so a state is bit-identical however it was
    reached.
    """

    name = "analytic"

    def __init__(self, mesh_size: float = 8.0, delay_s: float = 0.0) -> None:
        mesh_size, delay_s = float(mesh_size), float(delay_s)
        if not (np.isfinite(mesh_size) and 1.0 <= mesh_size <= 50.0):
            raise ValueError(f"mesh_size must be in [1, 50] mm, got {mesh_size}")
        if not (np.isfinite(delay_s) and delay_s >= 0.0):
            raise ValueError(f"delay_s must be >= 0, got {delay_s}")
        self.mesh_size = mesh_size
        self.delay_s = delay_s
        self._surfaces = _capsule_surfaces(mesh_size)

    def reference(self) -> ReferenceGeometry:
        surfaces = {
            name: SurfaceTopology(name, points.copy(), tris.copy())
            for name, points, tris in self._surfaces
        }
        definition = {"model": "analytic", "version": _MODEL_VERSION, "mesh_size": self.mesh_size,
                      "shapes": _MUSCLE_SHAPES, "elbow_z": _ELBOW_Z, "blend": _BLEND}
        h = hashlib.sha256(json.dumps(definition, sort_keys=True).encode())
        for _, points, tris in self._surfaces:  # the mesh is part of the model
            h.update(points.tobytes())
            h.update(tris.tobytes())
        return ReferenceGeometry(
            surfaces=surfaces,
            model_hash=h.hexdigest(),
            description={"model": "analytic", "mesh_size_mm": self.mesh_size, "units": "mm, deg",
                         "elbow_angle": "flexion angle, 0 = straight arm"},
        )

    def simulate(self, activations, warm_start=None, attempt: int = 0):
        t0 = time.perf_counter()
        alpha = check_activation_vector(activations)
        if self.delay_s:
            time.sleep(self.delay_s)
        theta = float(flexion_angle_deg(alpha))
        positions = {
            name: _deform(name, points, float(alpha[i]), theta)
            for i, (name, points, _) in enumerate(self._surfaces)
        }
        stats = {"model": "analytic", "attempt": int(attempt), "warm_started": warm_start is not None}
        if warm_start is not None:
            stats["warm_start_distance"] = float(np.linalg.norm(alpha - np.asarray(warm_start)))
        result = SimulationResult(theta, positions, stats, time.perf_counter() - t0)
        return result, alpha.copy()
