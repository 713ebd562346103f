"""The packaged model file, and what the command line needs to know of it.

Kept apart from arm_file (which imports pydantic) so that building the CLI's help texts
(`persival --help`) reads the profile names without validating the whole model.
"""

from __future__ import annotations

import tomllib
from importlib import resources
from pathlib import Path

__all__ = ["default_model_path", "default_profile_names", "profiles_help"]


def default_model_path() -> Path:
    return Path(str(resources.files("persival.model").joinpath("default_arm.toml")))


def default_profile_names() -> tuple[str, ...]:
    """Mesh profiles of the packaged model, in file order (e.g. quick, paper, coarse)."""
    return tuple(tomllib.loads(default_model_path().read_text()).get("profiles", {}))


def profiles_help(prefix: str = "Mesh profile", model_option: bool = True) -> str:
    """Help text of a --profile option, listing the profiles the packaged model defines."""
    names = ", ".join(default_profile_names())
    return f"{prefix}: {names} (the built-in model; a --model file defines its own)." if model_option else f"{prefix}: {names}."
