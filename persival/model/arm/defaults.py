"""The packaged model file, and what the command line needs to know of it.

Kept apart from arm_file (which imports pydantic) so that building the CLI's help texts
(`persival --help`) reads the profile names without validating the whole model.
"""

from __future__ import annotations

import tomllib
from importlib import resources
from pathlib import Path

__all__ = ["default_model_path", "default_profile_names", "packaged_models", "profiles_help", "resolve_model_path"]

DEFAULT_MODEL_NAME = "default"


def default_model_path() -> Path:
    return Path(str(resources.files("persival.model.arm").joinpath("default_arm.toml")))


def packaged_models() -> dict[str, Path]:
    """The model files shipped with the package by name: the built-in arm ("default") and its
    variants (persival/model/arm/variants/NAME.toml), so that ``--model atlas_walls`` needs no path."""
    variants = Path(str(resources.files("persival.model.arm").joinpath("variants")))
    return {DEFAULT_MODEL_NAME: default_model_path(), **{p.stem: p for p in sorted(variants.glob("*.toml"))}}


def resolve_model_path(model: str | Path | None) -> Path:
    """The file a ``--model`` value names: an existing path as given, else a packaged model's name
    (``persival model list``), else the path as given (whose reading then fails with its own message)."""
    if model is None:
        return default_model_path()
    path = Path(model)
    if path.exists() or path.suffix or len(path.parts) > 1:
        return path
    return packaged_models().get(str(model), path)


def default_profile_names() -> tuple[str, ...]:
    """Mesh profiles of the packaged model, in file order (e.g. quick, paper, coarse)."""
    return tuple(tomllib.loads(default_model_path().read_text()).get("profiles", {}))


def profiles_help(prefix: str = "Mesh profile", model_option: bool = True) -> str:
    """Help text of a --profile option, listing the profiles the packaged model defines."""
    names = ", ".join(default_profile_names())
    return f"{prefix}: {names} (the built-in model; a --model file defines its own)." if model_option else f"{prefix}: {names}."
