"""What every part of the model file's schema shares: strict, frozen pydantic models and the one
error a malformed or inconsistent file raises."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict

__all__ = ["ModelFileError", "Strict", "Vector"]

Vector = tuple[float, float, float]


class ModelFileError(ValueError):
    """A model file that is malformed or physically inconsistent."""


class Strict(BaseModel):
    """A schema entry: unknown keys are refused, a validated entry never changes."""

    model_config = ConfigDict(extra="forbid", frozen=True)
