"""The angle activation model that ships with the deployed model: the motion-and-load model at zero
velocity, acceleration and load (docs/theory.md, 6.4)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from persival.surrogate.activation_model import check_angles

if TYPE_CHECKING:
    from persival.surrogate.motion_model import MotionActivationModel

__all__ = ["RestAngleModel"]


class RestAngleModel:
    """Theta -> alpha of the motion model at zero velocity, acceleration and load: the angle
    activation model that ships with the deployed model, so that the angle and the motion
    requests of the contract give the same activations at no load (docs/theory.md, 6.4).

    ``predict(theta (n,)) -> activations (n, 5)``; ``torch_module()``: elbow_angle_deg [b, 1] -> activations [b, 5].
    """

    source = "motion model at zero velocity, acceleration and load (least effort on the deployed model's balance)"

    def __init__(self, motion: MotionActivationModel, range_deg: tuple[float, float]) -> None:
        self.motion = motion
        self.range_deg = (float(range_deg[0]), float(range_deg[1]))
        inside = (motion.theta >= self.range_deg[0]) & (motion.theta <= self.range_deg[1])
        self.knots = motion.theta[inside]  # where the map has its kinks (the motion grid's angles)
        self.branch_notes: list = []

    def _rows(self, theta_deg) -> np.ndarray:
        theta = check_angles(theta_deg, self.range_deg)
        return np.column_stack([theta, np.zeros((len(theta), 3))])

    def predict(self, theta_deg) -> np.ndarray:
        return self.motion.predict(self._rows(theta_deg))[0]

    def torch_module(self):
        import torch

        motion = self.motion.torch_module()

        class AtRest(torch.nn.Module):
            def __init__(self):
                super().__init__()
                self.motion = motion

            def forward(self, theta):
                zeros = torch.zeros_like(theta)
                return self.motion(torch.cat([theta, zeros, zeros, zeros], dim=1))[0]

        return AtRest()
