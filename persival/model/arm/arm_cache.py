"""The arm's rest states and hanging arm in the on-disk state cache (persival.model.arm.state_cache).

Every muscle's rest state (its passive equilibrium at its mesh pose, docs/theory.md, 1.6) and the hanging
arm (all activations 0) are computed once per model file and mesh and kept on disk, keyed by
the model hash, the profile and the mesh; :class:`ArmStateCache` is the part of
:class:`~persival.model.arm.arm_model.ArmModel` that reads and writes them.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from persival.model.arm.arm_state import ArmState
from persival.model.arm.muscle_state import MuscleState
from persival.model.arm.progress import SolveTracker
from persival.model.arm.state_cache import load_states, model_cache_dir, save_states

__all__ = ["ArmStateCache"]


class ArmStateCache:
    """Rest states and hanging arm of an ArmModel (``units``, ``model_hash``, ``profile``, ``_base``) on disk."""

    def rest_states(self, tracker: SolveTracker | None = None, cache: bool = True) -> dict[str, MuscleState]:
        """Every muscle's passive equilibrium at its mesh length (the prestretch switched on,
        docs/theory.md, 1.6): the units' own when they have them, else from the state cache when there, else
        solved (20 s on the quick mesh) and, with ``cache``, written there without a hanging arm yet."""
        in_memory = all(getattr(unit, "_rest", None) is not None for unit in self.units.values())
        if not in_memory and not (cache and self.load_cached_rest_states()):
            tracker = tracker or SolveTracker(None, "rest state")
            rest = {name: unit.rest_state(tracker.muscle(name)) for name, unit in self.units.items()}
            if cache:
                save_states(self.cache_dir() / "rest_state.npz",
                            {"groups": ["rest"], "model_hash": self.model_hash, "profile": self.profile}, {"rest": rest})
        return {name: unit.rest_state() for name, unit in self.units.items()}

    def adopt_base_state(self, state: ArmState, cache: bool = True) -> None:
        """Take ``state`` (activations 0, a converged FE equilibrium) as the hanging arm, and
        with ``cache`` keep it in the state cache beside the rest states."""
        if np.any(state.activations):
            raise ValueError(f"the hanging arm has activations 0, not {list(state.activations)}")
        self._base = state
        if cache:
            self._save_cache(state)

    def has_cached_base(self) -> bool:
        """Whether the state cache holds this model's hanging arm (not only its rest states)."""
        return self._cached_base() is not None

    def _save_cache(self, hanging: ArmState) -> None:
        rest = self.rest_states()
        save_states(self.cache_dir() / "rest_state.npz",
                    {"groups": ["rest", "hanging"], "elbow_angle_deg": hanging.elbow_angle_deg,
                     "model_hash": self.model_hash, "profile": self.profile},
                    {"rest": rest, "hanging": hanging.muscle_states})

    def cache_dir(self) -> Path:
        """This model's and mesh's folder of the state cache (persival.model.arm.state_cache)."""
        return model_cache_dir(self)

    def load_cached_rest_states(self) -> bool:
        """Give every muscle its rest state from the state cache, if there; True if it was."""
        loaded = self._cached_groups()
        if loaded is not None:
            self._set_rest_states(loaded[1]["rest"])
        return loaded is not None

    def _set_rest_states(self, rest: dict[str, MuscleState]) -> None:
        for name, unit in self.units.items():
            unit._rest = rest[name]

    def _cached_groups(self):
        """(header, {group: {muscle: state}}) of this model's cache file, or None."""
        loaded = load_states(self.cache_dir() / "rest_state.npz", list(self.units))
        if loaded is None or loaded[0].get("model_hash") != self.model_hash or "rest" not in loaded[1]:
            return None
        return loaded

    def _cached_base(self):
        loaded = self._cached_groups()
        if loaded is None or "hanging" not in loaded[1]:
            return None
        header, groups = loaded
        # moment NaN: the states are re-converged (checked) by Newton, not taken as solved
        hanging = {name: replace(s, moment=float("nan")) for name, s in groups["hanging"].items()}
        return groups["rest"], hanging, float(header["elbow_angle_deg"])
