"""`persival anatomy`: overlap between bodies and bed gaps of solved arm states
(docs/design/arm_model_record.md, "Overlap between bodies").

Reads the FE stage's state directories (one VTU per muscle and bone at its deformed position)
or a campaign store of the FE arm (muscle surfaces per state; the bones are placed from the
model file at each state's elbow angle), turns every body into a closed triangle surface and
measures it with :mod:`persival.model.anatomy.overlap`. The muscles' ends (origin and the end of
the FE body at the state's angle) come from the model file, which must be the one the states
were computed with.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from persival.campaign.arm_simulator import display_triangles
from persival.model.anatomy.overlap import Body, bed_gaps, overlaps
from persival.model.arm.kinematics import ArmKinematics
from persival.model.arm.output import bone_surfaces
from persival.model.fe.mesh import Tet10Mesh
from persival.vocabulary import MUSCLES

__all__ = ["check_state_dirs", "check_store", "limit_text", "over_limit", "pair_limit_mm", "worst_cases", "write_json",
           "FUNCTIONAL_ARC_DEG", "MUSCLE_BONE_LIMIT_MM", "MUSCLE_MUSCLE_LIMIT_MM", "TRICEPS_BED_LIMIT_MM"]

# SPEC 3.3 (docs/arm_model.md, "How far bodies may reach into each other"): in the functional arc
# (elbow <= 130 deg; daily activities need 30-130 deg, Morrey et al. 1981) penetration muscle-bone
# <= 1 mm and muscle-muscle <= 2 mm; beyond it, where real flexion ends as soft tissue meets soft
# tissue, 2 mm and 5 mm. The triceps' belly (its middle 60 %) lies within 10 mm of the humerus.
FUNCTIONAL_ARC_DEG = 130.0
MUSCLE_BONE_LIMIT_MM = 1.0
MUSCLE_MUSCLE_LIMIT_MM = 2.0
_LIMITS_MM = {False: {2: MUSCLE_MUSCLE_LIMIT_MM, 1: MUSCLE_BONE_LIMIT_MM}, True: {2: 5.0, 1: 2.0}}
TRICEPS_BED_LIMIT_MM = 10.0


def _muscle_ends(kinematics: ArmKinematics, theta_deg: float) -> dict[str, np.ndarray]:
    out = {}
    for muscle in kinematics.spec.ordered_muscles():
        out[muscle.name] = np.array([muscle.origin, kinematics.body_end(muscle, theta_deg)], dtype=float)
    return out


def _tet10_surface(points: np.ndarray, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Surface nodes (mid-side included) and their linear triangles, numbered locally."""
    faces = Tet10Mesh(points, cells).boundary_faces()
    nodes = np.unique(faces)
    local = np.full(len(points), -1, dtype=np.int64)
    local[nodes] = np.arange(len(nodes))
    return points[nodes], display_triangles(local[faces])


def _check_model(found: str | None, kinematics: ArmKinematics, what: str) -> None:
    if found is not None and found != kinematics.model_hash:
        raise ValueError(f"{what} was computed from another model file (model hash {found[:12]}, the model given has "
                         f"{kinematics.model_hash[:12]}); pass its model file with --model")


def _measure(label: str, theta: float, activations, bodies: list[Body], attachment_mm: float) -> dict:
    return {"state": label, "elbow_angle_deg": float(theta),
            "activations": dict(zip(MUSCLES, map(float, activations))),
            "overlaps": overlaps(bodies, attachment_mm), "bed_gaps": bed_gaps(bodies)}


def check_state_dirs(directories, model_file=None, attachment_mm: float = 10.0) -> list[dict]:
    """Measure state directories written by the FE stage or ``persival simulate``."""
    import meshio

    from persival.evaluate.render import read_state_dir

    kinematics = ArmKinematics(model_file)
    results = []
    for directory in map(Path, directories):
        summary = read_state_dir(directory)
        _check_model(summary.get("model_hash"), kinematics, str(directory))
        theta = float(summary["elbow_angle_deg"])
        ends = _muscle_ends(kinematics, theta)
        bodies = []
        for name in MUSCLES:
            mesh = meshio.read(directory / f"{name}.vtu")
            points, triangles = _tet10_surface(np.asarray(mesh.points, dtype=float), mesh.cells_dict["tetra10"])
            bodies.append(Body(name, points, triangles, ends[name]))
        for path in sorted(directory.glob("bone_*.vtu")):
            mesh = meshio.read(path)
            bodies.append(Body(path.stem.removeprefix("bone_"), np.asarray(mesh.points, dtype=float),
                               mesh.cells_dict["triangle"]))
        results.append(_measure(directory.name, theta, summary["activations"].values(), bodies, attachment_mm))
    return results


def check_store(path, model_file=None, attachment_mm: float = 10.0, progress=None) -> list[dict]:
    """Measure every finished state of a campaign store of the FE arm."""
    from persival.campaign.store import CampaignStore

    with CampaignStore.open(path) as store:
        spec = store.spec
        if spec.kind != "arm":
            raise ValueError(f"{path}: a store of the {spec.kind!r} simulator; anatomy needs FE arm states (simulator arm)")
        kinematics = ArmKinematics(model_file if model_file is not None else spec.options.get("model_file"))
        _check_model(store.provenance.get("model_hash"), kinematics, str(path))
        reference = store.reference
        angles = store.elbow_angles()
        done = np.flatnonzero(np.isfinite(angles))
        positions = {name: store.surface_positions(name, done) for name in MUSCLES}
        activations, ids = store.activations, store.ids
    results = []
    for row, index in enumerate(done):
        theta = float(angles[index])
        ends = _muscle_ends(kinematics, theta)
        bodies = [Body(name, positions[name][row], reference.surfaces[name].triangles, ends[name]) for name in MUSCLES]
        bodies += [Body(name, p, t) for name, (p, t) in bone_surfaces(kinematics, theta).items()]
        results.append(_measure(f"{Path(path).stem}/{int(ids[index])}", theta, activations[index], bodies, attachment_mm))
        if progress is not None:
            progress(row + 1, len(done))
    return results


def pair_limit_mm(a: str, b: str, angle_deg: float | None = None) -> float | None:
    """The most one body may reach into the other at elbow angle ``angle_deg``: in the functional
    arc (or with no angle) 1 mm muscle-bone, 2 mm muscle-muscle; beyond it 2 and 5 mm; none for two bones."""
    muscles = (a in MUSCLES) + (b in MUSCLES)
    return _LIMITS_MM[angle_deg is not None and angle_deg > FUNCTIONAL_ARC_DEG].get(muscles)


def limit_text(a: str, b: str) -> str:
    """A pair's limits as a table cell: the functional arc's, then beyond it ("-" for two bones)."""
    inside, beyond = pair_limit_mm(a, b), pair_limit_mm(a, b, FUNCTIONAL_ARC_DEG + 1.0)
    return "-" if inside is None else f"{inside:g} ({beyond:g} beyond {FUNCTIONAL_ARC_DEG:g} deg)"


def over_limit(a: str, b: str, angle_deg: float, deepest_mm: float) -> bool:
    """Whether one body reaches deeper into the other than its limit at that angle."""
    limit = pair_limit_mm(a, b, angle_deg)
    return limit is not None and deepest_mm > limit


def worst_cases(results: list[dict]) -> dict:
    """Per pair and per muscle: the worst state (deepest overlap, largest gap) over all states."""
    pairs, gaps = {}, {}
    for state in results:
        for row in state["overlaps"]:
            key = (row["body"], row["inside"])
            entry = pairs.setdefault(key, {"body": key[0], "inside": key[1], "limit_mm": pair_limit_mm(*key), "states": 0,
                                           "most_nodes": 0, "of": row["of"], "deepest_mm": 0.0, "over_states": 0})
            entry["states"] += 1
            entry["over_states"] += over_limit(*key, state["elbow_angle_deg"], row["deepest_mm"])
            entry["most_nodes"] = max(entry["most_nodes"], row["nodes"])
            if row["deepest_mm"] > entry["deepest_mm"]:
                entry.update(deepest_mm=row["deepest_mm"], deepest_state=state["state"],
                             deepest_angle_deg=state["elbow_angle_deg"])
        for row in state["bed_gaps"]:
            entry = gaps.setdefault(row["muscle"], {"muscle": row["muscle"], "bed": row["bed"], "largest_gap_mm": -1.0})
            if row["largest_gap_mm"] > entry["largest_gap_mm"]:
                entry.update(largest_gap_mm=row["largest_gap_mm"], state=state["state"],
                             elbow_angle_deg=state["elbow_angle_deg"], at_fraction=row["at_fraction"])
    ordered = sorted(pairs.values(), key=lambda e: -e["deepest_mm"])
    return {"states": len(results), "overlaps": ordered, "bed_gaps": [gaps[m] for m in MUSCLES if m in gaps]}


def write_json(results: list[dict], out: Path, source: str, attachment_mm: float) -> None:
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"source": source, "attachment_mm": attachment_mm, "worst": worst_cases(results),
                               "states": results}, indent=1))


