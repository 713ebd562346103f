"""What a solve of the arm returns (ArmState): one equilibrium, or a held state, of the five muscles."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from persival.model.arm.muscle_state import MuscleState
from persival.vocabulary import MUSCLES

__all__ = ["ArmState"]


@dataclass
class ArmState:
    """One equilibrium of the arm (also the warm-start token for nearby solves)."""

    activations: np.ndarray  # (5,) biceps, brachialis, brachioradialis, triceps, anconeus
    elbow_angle_deg: float
    displacement: np.ndarray  # (n_nodes, 3) mm, all muscles, world frame
    moment_residual: float  # N mm at convergence
    muscle_moments: dict[str, float]  # N mm about the hinge axis (flexion positive)
    muscle_forces: dict[str, float]  # N, tension of each muscle (negative: pushing, slack)
    external_moment: float  # N mm, gravity + passive joint
    max_volume_change: float
    muscle_states: dict[str, MuscleState] = field(default_factory=dict, repr=False)
    statistics: dict = field(default_factory=dict)
    wall_time_s: float = 0.0

    def summary(self) -> dict:
        return {
            "activations": {n: float(a) for n, a in zip(MUSCLES, self.activations)},
            "elbow_angle_deg": self.elbow_angle_deg,
            "moment_residual_Nmm": self.moment_residual,
            "muscle_moments_Nmm": self.muscle_moments,
            "muscle_forces_N": self.muscle_forces,
            "external_moment_Nmm": self.external_moment,
            "max_abs_J_minus_1": self.max_volume_change,
            "newton": self.statistics,
            "wall_time_s": self.wall_time_s,
        }
