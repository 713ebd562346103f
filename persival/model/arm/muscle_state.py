"""What a muscle's FE solve returns (MuscleState) and what it needs to know of the arm (MusclePath).

docs/theory.md, 3.3: each muscle is its own FE body whose state depends on the elbow angle theta and its
own activation only (persival.model.arm.muscle_unit).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["MusclePath", "MuscleState"]


@dataclass
class MuscleState:
    """Equilibrium of one muscle at elbow angle ``angle_deg`` and activation ``activation``."""

    angle_deg: float
    length: float  # mm, |I - O| at angle_deg
    activation: float
    displacement: np.ndarray  # (n_nodes, 3) mm, in the muscle's mesh-pose frame
    tension: float  # N, axial reaction of the insertion face: positive when the muscle pulls its ends together
    moment: float  # N mm about the hinge, flexion positive: -dPi*/dtheta (module docstring)
    moment_slope: float  # N mm/rad, dM/dtheta with the interior re-equilibrated (Schur complement)
    max_volume_change: float
    iterations: int = 0
    # du/dtheta (n_nodes, 3) mm/rad at fixed activation, the interior re-equilibrated: the slope of
    # the state along theta (cubic Hermite guesses between tabulated states); None if unknown
    sensitivity: np.ndarray | None = None
    contact_force: float = 0.0  # N, total normal force of the bones on the muscle
    max_penetration: float = 0.0  # mm, deepest muscle node inside a bone


@dataclass(frozen=True)
class MusclePath:
    """Where a muscle's ends and bones are at elbow angle theta (deg): the arm's kinematics.

    ``geometry(theta) -> (L, dL/dtheta, d2L/dtheta2)`` (mm, per radian); ``insertion(theta)``
    the world insertion point; ``bones(theta)`` the rigid obstacles (world frame) the muscle
    wraps over, with the penalty ``penalty`` (N/mm^3; docs/theory.md, 3.5); none: no contact.
    Surface points within ``attachment_mm`` of the muscle's two ends do not touch obstacles that
    spare them (the bones' shaped surfaces: the muscle is attached there).
    ``insertion_tie``: "line" (ball joints on the line of action) or "forearm" (the insertion
    face rigid with the forearm about ``hinge`` = (centre, axis)); persival.model.arm.insertion_ties.
    """

    origin: np.ndarray
    insertion: Callable[[float], np.ndarray]
    geometry: Callable[[float], tuple[float, float, float]]
    mesh_angle_deg: float
    bones: Callable[[float], Sequence] | None = None
    penalty: float = 0.0
    contact_smoothing_mm: float = 0.0  # mm over which the contact stiffness ramps up (docs/theory.md, 3.5)
    attachment_mm: float = 0.0
    insertion_tie: str = "line"
    hinge: tuple[np.ndarray, np.ndarray] | None = None
