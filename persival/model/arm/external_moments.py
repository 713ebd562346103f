"""The hinge's external load: gravity on forearm, hand and a held load, and the passive joint
moment (docs/theory.md, 3.6). One implementation, used by the FE arm's joint equilibrium, the
response tables, the deployed model's moment balance and the activation models, so that every
tier balances the same moments.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

__all__ = ["ExternalMoments"]


@dataclass(frozen=True)
class ExternalMoments:
    """Gravity on forearm, hand and load, and the passive joint moment (N mm, flexion positive)."""

    mass_kg: float
    centre_of_mass_mm: float
    hand_distance_mm: float
    gravity_m_s2: float
    limit_moment: float
    limits_deg: tuple[float, float]
    limit_width_deg: float

    @classmethod
    def of_arm(cls, spec) -> ExternalMoments:
        """From a model file's forearm and joint (an ``ArmModelFile``)."""
        fa, j = spec.forearm, spec.joint
        return cls(fa.mass, fa.centre_of_mass, fa.hand_distance, fa.gravity, j.limit_moment,
                   (float(j.limits_deg[0]), float(j.limits_deg[1])), j.limit_width_deg)

    def as_dict(self) -> dict:
        return {**asdict(self), "limits_deg": list(self.limits_deg)}

    @classmethod
    def from_dict(cls, data: dict) -> ExternalMoments:
        return cls(**{**data, "limits_deg": tuple(data["limits_deg"])})

    def lever(self, load_kg=0.0) -> np.ndarray:
        """g (m r_com + load d): gravity's moment is -lever sin(theta) (N mm)."""
        return self.gravity_m_s2 * (self.mass_kg * self.centre_of_mass_mm + np.asarray(load_kg) * self.hand_distance_mm)

    def gravity(self, theta_deg, load_kg=0.0) -> np.ndarray:
        """M_g + M_load = -g (m r + load d) sin(theta) (docs/theory.md, 3.6 and 6.4)."""
        return -self.lever(load_kg) * np.sin(np.radians(theta_deg))

    def joint(self, theta_deg) -> np.ndarray:
        """M_p = K [exp((theta_min - theta)/w) - exp((theta - theta_max)/w)] (docs/theory.md, 3.6)."""
        lo, hi = self.limits_deg
        w = self.limit_width_deg
        return self.limit_moment * (np.exp((lo - np.asarray(theta_deg)) / w) - np.exp((np.asarray(theta_deg) - hi) / w))

    def value(self, theta_deg, load_kg=0.0) -> np.ndarray:
        """M_ext = M_g + M_load + M_p (N mm)."""
        return self.gravity(theta_deg, load_kg) + self.joint(theta_deg)

    def slope(self, theta_deg, load_kg=0.0) -> np.ndarray:
        """dM_ext/dtheta, N mm per degree."""
        lo, hi = self.limits_deg
        w = self.limit_width_deg
        theta = np.asarray(theta_deg)
        joint = -self.limit_moment / w * (np.exp((lo - theta) / w) + np.exp((theta - hi) / w))
        return -self.lever(load_kg) * np.cos(np.radians(theta)) * (np.pi / 180.0) + joint
