"""Columns taken over from another model's response tables.

Each muscle is its own FE problem (docs/theory.md, 3.7): its columns depend on its own definition
and mesh, the bones, walls and contact settings it may meet, the joint's axis, the physics version
and the table's grid, and on nothing of the other muscles. A muscle whose key (a hash of exactly
those) is the same in another table's header has the same columns, so a model file with one
muscle changed rebuilds only that muscle's columns. The key is conservative: any change of a bone,
wall or the joint gives every muscle a new key.
"""

from __future__ import annotations

import hashlib
import json
import shutil
from collections.abc import Iterable
from pathlib import Path

from persival.cache_dir import cache_root
from persival.model.arm.model_file import PHYSICS_VERSION, SURFACE_VERSION
from persival.model.arm.state_cache import mesh_fingerprint

__all__ = ["muscle_keys", "reuse_columns", "table_headers"]


def muscle_keys(arm, angles, levels, table_version: int) -> dict[str, str]:
    """Each muscle's key: sha256 of what its columns depend on (module docstring)."""
    spec = arm.spec
    shared = {"physics": PHYSICS_VERSION, "surfaces": SURFACE_VERSION, "table_version": table_version,
              "profile": arm.profile, "joint": spec.joint.model_dump(mode="json"),
              "bones": [b.model_dump(mode="json") for b in spec.bones],
              "walls": [w.model_dump(mode="json") for w in spec.walls],
              "contact": spec.contact.model_dump(mode="json"),
              "angles": [float(a) for a in angles], "levels": [float(a) for a in levels]}
    keys = {}
    for muscle in spec.ordered_muscles():
        payload = {**shared, "muscle": muscle.model_dump(mode="json"),
                   "mesh_size": spec.mesh_size(arm.profile, muscle.name),
                   "mesh": mesh_fingerprint(arm.units[muscle.name].mesh)}
        keys[muscle.name] = hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()
    return keys


def table_headers(table_version: int, roots: Iterable[Path] | None = None) -> list[Path]:
    """Table folders to take columns from: ``roots`` as given, else every table of this format
    version in the cache (persival.cache_dir)."""
    if roots is not None:
        return [Path(r) for r in roots]
    return sorted(p.parent for p in cache_root().glob(f"*/response_table-v{table_version}-*/header.json"))


def reuse_columns(table, muscles: Iterable[str], roots: Iterable[Path]) -> dict[str, int]:
    """Copy into ``table`` the finished columns of ``muscles`` that another table in ``roots`` holds
    under the same muscle key; returns {muscle: columns copied}."""
    keys = table.header.get("muscle_keys", {})
    copied: dict[str, int] = {}
    for root in roots:
        if Path(root).resolve() == Path(table.root).resolve():
            continue
        try:
            other = json.loads((Path(root) / "header.json").read_text())
        except (OSError, ValueError):
            continue
        for muscle in muscles:
            if not keys.get(muscle) or other.get("muscle_keys", {}).get(muscle) != keys[muscle]:
                continue
            for level in range(len(table.header["levels"])):
                source = Path(root) / "columns" / f"{muscle}-{level}.npz"
                if source.is_file() and not table.is_done(muscle, level):
                    target = table.column_path(muscle, level)
                    shutil.copyfile(source, target.with_name(f".{target.name}.copying"))
                    target.with_name(f".{target.name}.copying").replace(target)
                    copied[muscle] = copied.get(muscle, 0) + 1
    return copied
