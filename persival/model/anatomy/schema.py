"""The model file's schema: bones and their shapes, the elbow hinge, the forearm's weight, fascial
walls, contact, the muscles (lines of action, outlines, surfaces, tissue, fibre prestretch) and mesh
profiles, validated with pydantic (docs/theory.md, section 3; reading a file: persival.model.arm.model_file).

Coordinates in mm. Upper-arm points are in the fixed humerus frame; forearm points are given
in the forearm frame at theta = 0 (full extension, forearm hanging along -z) and rotate about
the hinge axis with the elbow angle (flexion positive). A muscle may take its shape from a surface
file (docs/own_anatomy.md, persival.model.anatomy.surface_import).
"""

from __future__ import annotations

import numpy as np
from pydantic import Field, field_validator, model_validator

from persival.model.anatomy.bone_schema import Bone, Contact, Wall
from persival.model.anatomy.muscle_schema import Muscle, Outline, distinct_heights
from persival.model.anatomy.schema_base import ModelFileError, Strict, Vector
from persival.vocabulary import MUSCLES


class Joint(Strict):
    centre: Vector = (0.0, 0.0, 0.0)
    axis: Vector = (1.0, 0.0, 0.0)
    limits_deg: tuple[float, float] = (0.0, 160.0)
    limit_moment: float = Field(500.0, gt=0, description="N mm: passive moment at a limit")
    limit_width_deg: float = Field(10.0, gt=0, description="deg: e-folding width of the limit moment")

    @field_validator("axis")
    @classmethod
    def _nonzero_axis(cls, v):
        if np.linalg.norm(v) == 0:
            raise ValueError("joint axis must be non-zero")
        return v

    @model_validator(mode="after")
    def _ordered_limits(self):
        lo, hi = self.limits_deg
        if not lo < hi:
            raise ValueError("joint limits must satisfy lower < upper")
        return self


class Forearm(Strict):
    mass: float = Field(1.6, gt=0, description="kg, forearm plus hand")
    centre_of_mass: float = Field(150.0, gt=0, description="mm from the elbow along the forearm")
    gravity: float = Field(9.81, ge=0, description="m/s^2, along -z")
    # Not in the default TOML on purpose: the FE states do not depend on it, and adding it there
    # would change the model hash that keys every campaign store. 330 mm: forearm (elbow to
    # wrist, about 255 mm here) plus about 40 % of a 190 mm hand, the centre of a grip.
    hand_distance: float = Field(330.0, gt=0, description="mm from the elbow to a load held in the hand (motion model)")




class Profile(Strict):
    mesh_size: float = Field(gt=0, description="default element size (mm)")
    muscle_mesh_size: dict[str, float] = Field(default_factory=dict)

    @field_validator("muscle_mesh_size")
    @classmethod
    def _positive_sizes(cls, v):
        for name, h in v.items():
            if h <= 0:
                raise ValueError(f"mesh size of {name!r} must be positive")
        return v


class ArmModelFile(Strict):
    name: str
    description: str = ""
    joint: Joint = Joint()
    forearm: Forearm = Forearm()
    contact: Contact = Contact()
    bones: list[Bone]
    walls: list[Wall] = Field(default_factory=list)
    muscles: list[Muscle]
    # The upper arm's skin where it crosses planes z = const (persival.model.arm.cross_sections): a model
    # file that gives it has every muscle's outline checked to lie inside it, as an atlas draws them.
    skin: list[Outline] = Field(default_factory=list, description="the upper arm's outline at heights z (ellipses, "
                                                                  "upper-arm frame); between them interpolated")
    profiles: dict[str, Profile]

    @model_validator(mode="after")
    def _consistent(self):
        names = [m.name for m in self.muscles]
        missing = [n for n in MUSCLES if n not in names]
        extra = [n for n in names if n not in MUSCLES]
        if missing or extra or len(names) != len(set(names)):
            raise ValueError(
                f"the model needs exactly the muscles {', '.join(MUSCLES)}; "
                f"missing: {missing or 'none'}, "
                f"unknown or repeated: {extra or [n for n in names if names.count(n) > 1] or 'none'}"
            )
        lo, hi = self.joint.limits_deg
        for m in self.muscles:
            if not lo <= m.mesh_angle_deg <= hi:
                raise ValueError(f"muscle {m.name!r}: mesh_angle_deg {m.mesh_angle_deg} lies outside the joint limits "
                                 f"{self.joint.limits_deg}")
        for bone in self.bones:
            if bone.segment != "upper_arm":
                continue
            for m in self.muscles:
                if m.wraps and bone.name not in m.wraps:
                    continue  # a bone the muscle does not touch (no contact with it)
                d = _distance_to_segment(np.array(m.origin), np.array(bone.start), np.array(bone.end))
                if d < 0.9 * bone.radius:
                    raise ValueError(
                        f"muscle {m.name!r}: origin {m.origin} lies inside bone {bone.name!r} "
                        f"({d:.1f} mm from its axis, radius {bone.radius} mm)"
                    )
        centre, axis = np.array(self.joint.centre), np.array(self.joint.axis) / np.linalg.norm(self.joint.axis)
        for m in (m for m in self.muscles if m.wrap_radius > 0):
            for end in ("origin", "insertion"):
                q = np.array(getattr(m, end)) - centre
                d = float(np.linalg.norm(q - (q @ axis) * axis))
                if d <= m.wrap_radius:
                    raise ValueError(f"muscle {m.name!r}: its {end} lies {d:.1f} mm from the hinge axis, inside its "
                                     f"wrap cylinder (wrap_radius {m.wrap_radius} mm)")
        bone_names = [b.name for b in self.bones] + [w.name for w in self.walls]
        if len(set(bone_names)) != len(bone_names):
            raise ValueError(f"bones and walls need distinct names, got {bone_names}")
        for m in self.muscles:
            unknown = [b for b in m.wraps if b not in bone_names]
            if unknown:
                raise ValueError(f"muscle {m.name!r} wraps over unknown bone(s) or wall(s) {unknown}; the bones and "
                                 f"walls are {bone_names}")
        grouped = [n for group in self.contact.touching for n in group]
        if any(len(group) < 2 for group in self.contact.touching) or len(grouped) != len(set(grouped)) \
                or not set(grouped) <= set(names):
            raise ValueError(f"[contact] touching must list groups of two or more known muscles, each muscle in one "
                             f"group at most; got {self.contact.touching} (muscles: {', '.join(names)})")
        distinct_heights(self.skin, "skin")
        if not self.profiles:
            raise ValueError("at least one mesh profile is required")
        return self

    def bone(self, name: str) -> Bone:
        for b in self.bones:
            if b.name == name:
                return b
        raise KeyError(name)

    def wall(self, name: str) -> Wall:
        for w in self.walls:
            if w.name == name:
                return w
        raise KeyError(name)

    def muscle(self, name: str) -> Muscle:
        for m in self.muscles:
            if m.name == name:
                return m
        raise KeyError(name)

    def ordered_muscles(self) -> list[Muscle]:
        return [self.muscle(n) for n in MUSCLES]

    def profile(self, name: str) -> Profile:
        if name not in self.profiles:
            raise ModelFileError(f"unknown profile {name!r}; the model defines {sorted(self.profiles)}")
        return self.profiles[name]

    def mesh_size(self, profile: str, muscle: str) -> float:
        p = self.profile(profile)
        return p.muscle_mesh_size.get(muscle, p.mesh_size)


def _distance_to_segment(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    d = b - a
    t = np.clip((p - a) @ d / (d @ d), 0.0, 1.0)
    return float(np.linalg.norm(p - (a + t * d)))
