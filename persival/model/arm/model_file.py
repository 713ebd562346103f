"""Reading the upper-limb model file (TOML): validation against its schema
(persival.model.anatomy.schema), the muscles' surface files and the model hash that keys every
store, table and cache (docs/theory.md, section 3).

The model is data: bones, the elbow hinge, the forearm's weight, passive joint limits, the
five muscles and mesh profiles. A muscle's surface path is resolved against the model file's
folder and its content is part of the model's hash.
"""

from __future__ import annotations

import hashlib
import tomllib
from pathlib import Path

from pydantic import ValidationError

from persival.model.anatomy.schema import ArmModelFile
from persival.model.anatomy.schema_base import ModelFileError
from persival.model.arm.defaults import packaged_models, resolve_model_path

# Bumped whenever the physics code changes the states a model file produces, so that stores,
# tables and caches keyed by the model hash are never reused across it. 2: the fibre reference
# lambda_0 moves the force-length curve only (docs/theory.md, 1.6).
PHYSICS_VERSION = 2


# Bumped whenever the code that turns a surface file into a mesh (repair, placement, meshing,
# Laplace fibres) changes what it gives, for the same reason as PHYSICS_VERSION.
# 3: cells with no Laplace gradient (past an attachment face) take the centre line's direction,
# not a leaked gradient or NaN; and a mesh cached with those NaN fibres must not be reused.
SURFACE_VERSION = 3  # 2: the Laplace centre line smoothed


def model_hash(text: str, surfaces: dict[str, bytes] | None = None) -> str:
    """sha256 of the model file's text and the physics version (provenance key of every store),
    and of the muscles' surface files where it has any (their content, not their names)."""
    digest = hashlib.sha256(f"persival-physics-{PHYSICS_VERSION}\n{text}".encode()).hexdigest()
    if not surfaces:
        return digest  # the built-in model's hash is the same as before surfaces existed
    lines = [digest, f"persival-surfaces-{SURFACE_VERSION}"]
    lines += [f"{name} {hashlib.sha256(data).hexdigest()}" for name, data in sorted(surfaces.items())]
    return hashlib.sha256("\n".join(lines).encode()).hexdigest()


def _where(data: dict, loc: tuple) -> str:
    """A validation error's place in the file, entries of a list named by their ``name``:
    ``muscles.3.matrix_prestretch`` -> ``muscles[triceps].matrix_prestretch``."""
    parts, node = [], data
    for key in loc:
        if isinstance(key, int) and isinstance(node, list) and key < len(node):
            node = node[key]
            name = node.get("name") if isinstance(node, dict) else None
            parts[-1] += f"[{name}]" if name and parts else f"[{key}]"
            continue
        node = node.get(key) if isinstance(node, dict) else None
        parts.append(str(key))
    return ".".join(parts) or "<file>"


def load_model_file(path: str | Path | None = None) -> tuple[ArmModelFile, str]:
    """Read and validate a model file: a path, or the name of a packaged model (the built-in arm
    when ``path`` is None; ``persival model list``).

    Returns the model and the sha256 of its text (provenance).
    """
    try:
        path = resolve_model_path(path)
    except FileNotFoundError as exc:  # $PERSIVAL_MODEL names nothing
        raise ModelFileError(str(exc)) from None
    try:
        text = path.read_text()
    except OSError as exc:
        names = ", ".join(packaged_models())
        raise ModelFileError(f"cannot read model file {path}: {(exc.strerror or str(exc)).lower()} (a path, or one of "
                             f"the packaged models: {names})") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ModelFileError(f"{path}: not valid TOML: {exc}") from exc
    try:
        model = ArmModelFile.model_validate(data)
    except ValidationError as exc:
        lines = [f"{_where(data, e['loc'])}: {e['msg']}" for e in exc.errors()]
        raise ModelFileError(f"{path}: invalid model file:\n  " + "\n  ".join(lines)) from None
    model, surfaces = _resolve_surfaces(model, path)
    return model, model_hash(text, surfaces)


def _resolve_surfaces(model: ArmModelFile, path: Path) -> tuple[ArmModelFile, dict[str, bytes]]:
    """The model with every muscle's surface as an absolute path (it is relative to the model
    file), and each surface file's bytes (part of the model's hash: a changed surface is a new model)."""
    muscles, surfaces = [], {}
    for muscle in model.muscles:
        if muscle.surface is not None:
            surface = (path.parent / muscle.surface).resolve()
            try:
                surfaces[muscle.name] = surface.read_bytes()
            except OSError as exc:
                raise ModelFileError(f"{path}: muscle {muscle.name!r}: cannot read its surface {surface}: "
                                     f"{(exc.strerror or str(exc)).lower()}") from None
            muscle = muscle.model_copy(update={"surface": str(surface)})
        muscles.append(muscle)
    return (model.model_copy(update={"muscles": muscles}) if surfaces else model), surfaces
