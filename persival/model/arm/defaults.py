"""The packaged model file, and what the command line needs to know of it.

Kept apart from arm_file (which imports pydantic) so that building the CLI's help texts
(`persival --help`) reads the profile names without validating the whole model.
"""

from __future__ import annotations

import os
import tomllib
from importlib import resources
from pathlib import Path

__all__ = ["MODEL_HELP", "MODEL_VARIABLE", "builtin_model_path", "default_model_path", "default_profile_names", "packaged_models",
           "profiles_help", "resolve_model_path"]

DEFAULT_MODEL_NAME = "default"
# the model every command uses when no --model is given: a packaged model's name or a file; unset, the
# built-in arm (a lab that works on its own arm sets it once instead of passing --model everywhere)
MODEL_VARIABLE = "PERSIVAL_MODEL"
MODEL_HELP = f"Model file (TOML) or a packaged model's name; default: ${MODEL_VARIABLE}, else the built-in arm."


def builtin_model_path() -> Path:
    """The built-in arm shipped with the package (persival/model/arm/default_arm.toml)."""
    return Path(str(resources.files("persival.model.arm").joinpath("default_arm.toml")))


def default_model_path() -> Path:
    """The model of a command without --model: $PERSIVAL_MODEL when set, else the built-in arm."""
    chosen = os.environ.get(MODEL_VARIABLE, "").strip()
    if not chosen:
        return builtin_model_path()
    path = _named_or_path(chosen)
    if not path.is_file():
        raise FileNotFoundError(f"{MODEL_VARIABLE}={chosen}: no such model file, nor a packaged model "
                                f"({', '.join(packaged_models())}); unset it for the built-in arm")
    return path


def packaged_models() -> dict[str, Path]:
    """The model files shipped with the package by name: the built-in arm ("default") and its
    variants (persival/model/arm/variants/NAME.toml), so that ``--model spindle_arm`` needs no path."""
    variants = Path(str(resources.files("persival.model.arm").joinpath("variants")))
    return {DEFAULT_MODEL_NAME: builtin_model_path(), **{p.stem: p for p in sorted(variants.glob("*.toml"))}}


def resolve_model_path(model: str | Path | None) -> Path:
    """The file a ``--model`` value names: an existing path as given, else a packaged model's name
    (``persival model list``), else the path as given (whose reading then fails with its own message);
    None: the default model (:func:`default_model_path`)."""
    return default_model_path() if model is None else _named_or_path(model)


def _named_or_path(model: str | Path) -> Path:
    path = Path(model)
    if path.exists() or path.suffix or len(path.parts) > 1:
        return path
    return packaged_models().get(str(model), path)


def default_profile_names() -> tuple[str, ...]:
    """Mesh profiles of the packaged model, in file order (e.g. quick, paper, coarse)."""
    try:
        path = default_model_path()
    except FileNotFoundError:  # the help texts still build; the command itself then names the variable
        path = builtin_model_path()
    return tuple(tomllib.loads(path.read_text()).get("profiles", {}))


def profiles_help(prefix: str = "Mesh profile", model_option: bool = True) -> str:
    """Help text of a --profile option, listing the profiles the packaged model defines."""
    names = ", ".join(default_profile_names())
    return f"{prefix}: {names} (the built-in model; a --model file defines its own)." if model_option else f"{prefix}: {names}."
