"""On-disk cache of an arm's solved states, keyed by the model and its mesh (issues 11 and 17).

The hanging arm (all activations 0) costs a minute or more on the quick mesh (every muscle
continued from its mesh pose, then the joint equilibrium), yet it is the same for every run of
the same model file and mesh. It is solved once and kept under the cache directory:

    $PERSIVAL_CACHE (default ~/.cache/persival)/<key>/rest_state.npz

The arm's mesh is cached the same way (gmsh takes 11 s for the coarse profile, profiled), under
``meshes/``, keyed by the model hash, the profile and the gmsh version.

``key`` = sha256 of the model hash (file text plus the physics version, see arm_file), the mesh
profile and the mesh itself (points and cells: a different gmsh that meshes differently gets its
own entry). A cached state is not trusted blindly: loading re-runs the joint equilibrium from it,
which converges in one Newton iteration per muscle when the cache is right (ArmModel.base_state).
Files are written to a temporary name and renamed, so a kill never leaves half a file.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import numpy as np

from persival.cache_dir import cache_root
from persival.model.arm.muscle_state import MuscleState

__all__ = ["model_cache_dir", "mesh_fingerprint", "save_states", "load_states", "cached_mesh"]

FORMAT = "persival-state-cache"



def mesh_fingerprint(mesh) -> str:
    """sha256 of the mesh's points (to 1e-9 mm) and cells."""
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(np.round(mesh.points, 9)).tobytes())
    h.update(np.ascontiguousarray(mesh.cells, dtype=np.int64).tobytes())
    return h.hexdigest()


def model_cache_dir(arm) -> Path:
    """The cache folder of this model file, profile and mesh (not created here)."""
    key = hashlib.sha256(f"{arm.model_hash}\n{arm.profile}\n{mesh_fingerprint(arm.mesh)}".encode()).hexdigest()
    return cache_root() / f"{arm.spec.name}-{arm.profile}-{key[:16]}"


def _state_arrays(prefix: str, state: MuscleState) -> dict:
    arrays = {f"{prefix}/displacement": state.displacement,
              f"{prefix}/scalars": np.array([state.angle_deg, state.length, state.activation, state.tension, state.moment,
                                             state.moment_slope, state.max_volume_change, state.iterations], dtype=float)}
    if state.sensitivity is not None:
        arrays[f"{prefix}/sensitivity"] = state.sensitivity
    return arrays


def _state(data, prefix: str) -> MuscleState:
    angle, length, activation, tension, moment, moment_slope, max_j, iterations = data[f"{prefix}/scalars"]
    slope = np.array(data[f"{prefix}/sensitivity"]) if f"{prefix}/sensitivity" in data.files else None
    return MuscleState(float(angle), float(length), float(activation), np.array(data[f"{prefix}/displacement"]),
                       float(tension), float(moment), float(moment_slope), float(max_j), int(iterations), slope)


def save_states(path: Path, header: dict, groups: dict[str, dict[str, MuscleState]]) -> Path:
    """Write ``groups`` ({group: {muscle: state}}) and a JSON header atomically."""
    path.parent.mkdir(parents=True, exist_ok=True)
    arrays = {"header": np.array(json.dumps({"format": FORMAT, **header}, default=float))}
    for group, states in groups.items():
        for name, state in states.items():
            arrays.update(_state_arrays(f"{group}/{name}", state))
    tmp = path.with_name(f".{path.name}.{os.getpid()}.writing.npz")
    np.savez(tmp, **arrays)
    os.replace(tmp, path)
    return path


def load_states(path: Path, muscles) -> tuple[dict, dict[str, dict[str, MuscleState]]] | None:
    """Header and {group: {muscle: state}} from ``path``; None if there is no readable cache file."""
    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as data:
            header = json.loads(str(data["header"]))
            if header.get("format") != FORMAT:
                return None
            groups = {g: {m: _state(data, f"{g}/{m}") for m in muscles} for g in header["groups"]}
    except (OSError, ValueError, KeyError):
        return None  # unreadable or of an older layout: solved again and overwritten
    return header, groups


def cached_mesh(model_hash: str, name: str, profile: str, build):
    """The mesh ``build()`` makes for this model and profile, from the cache when there
    (a Tet10Mesh: points, cells, node sets, cell data)."""
    import gmsh

    from persival.model.fe.mesh import Tet10Mesh

    key = hashlib.sha256(f"{model_hash}\n{profile}\ngmsh {gmsh.__version__}".encode()).hexdigest()
    path = cache_root() / "meshes" / f"{name}-{profile}-{key[:16]}.npz"
    if path.is_file():
        try:
            with np.load(path, allow_pickle=False) as data:
                sets = {k[len("set/"):]: data[k] for k in data.files if k.startswith("set/")}
                cells = {k[len("cell/"):]: data[k] for k in data.files if k.startswith("cell/")}
                return Tet10Mesh(data["points"], data["cells"], node_sets=sets, cell_data=cells)
        except (OSError, ValueError, KeyError):
            pass  # unreadable: meshed again and overwritten
    mesh = build()
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.writing.npz")
    np.savez(tmp, points=mesh.points, cells=mesh.cells, **{f"set/{k}": v for k, v in mesh.node_sets.items()},
             **{f"cell/{k}": v for k, v in mesh.cell_data.items()})
    os.replace(tmp, path)
    return mesh
