"""Where PerSival keeps what it computes once per model and machine (meshes, bone fields, solved
states, response tables): $PERSIVAL_CACHE, else ~/.cache/persival."""

from __future__ import annotations

import os
from pathlib import Path


def cache_root() -> Path:
    """$PERSIVAL_CACHE, else ~/.cache/persival."""
    env = os.environ.get("PERSIVAL_CACHE")
    return Path(env) if env else Path.home() / ".cache" / "persival"
