"""The model file's schema: bones and their shapes, the elbow hinge, the forearm's weight, fascial
walls, contact, the muscles (lines of action, outlines, surfaces, tissue, fibre prestretch) and mesh
profiles, validated with pydantic (docs/theory.md, section 3; reading a file: persival.model.arm.model_file).

Coordinates in mm. Upper-arm points are in the fixed humerus frame; forearm points are given
in the forearm frame at theta = 0 (full extension, forearm hanging along -z) and rotate about
the hinge axis with the elbow angle (flexion positive). A muscle may take its shape from a surface
file (docs/own_anatomy.md, persival.model.anatomy.surface_import).
"""

from __future__ import annotations

from typing import Annotated, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from persival.vocabulary import MUSCLES

Vector = tuple[float, float, float]

class ModelFileError(ValueError):
    """A model file that is malformed or physically inconsistent."""


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class Joint(_Strict):
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


class Forearm(_Strict):
    mass: float = Field(1.6, gt=0, description="kg, forearm plus hand")
    centre_of_mass: float = Field(150.0, gt=0, description="mm from the elbow along the forearm")
    gravity: float = Field(9.81, ge=0, description="m/s^2, along -z")
    # Not in the default TOML on purpose: the FE states do not depend on it, and adding it there
    # would change the model hash that keys every campaign store. 330 mm: forearm (elbow to
    # wrist, about 255 mm here) plus about 40 % of a 190 mm hand, the centre of a grip.
    hand_distance: float = Field(330.0, gt=0, description="mm from the elbow to a load held in the hand (motion model)")


class HumerusShape(_Strict):
    """The humerus drawn and checked (persival.model.anatomy.bone_shapes; sources in docs/design/arm_model_record.md)."""

    kind: Literal["humerus"] = "humerus"
    length: float = Field(315.0, gt=0, description="mm, trochlea to the top of the head")
    epicondylar_width: float = Field(60.0, gt=0, description="mm, medial to lateral epicondyle")
    trochlea_width: float = Field(22.0, gt=0, description="mm along the hinge axis")
    trochlea_radius: float = Field(9.5, gt=0, description="mm, at the trochlear groove")
    capitulum_radius: float = Field(11.5, gt=0, description="mm, centred on the hinge axis")
    head_diameter: float = Field(44.0, gt=0, description="mm, humeral head")
    fossae_deg: tuple[float, float] = Field((0.0, 150.0), description="elbow angles whose forearm bones the fossae "
                                                                     "take in (a bony stop beyond)")


class UlnaShape(_Strict):
    kind: Literal["ulna"] = "ulna"
    joint_clearance: float = Field(1.0, gt=0, description="mm of cartilage between the notch and the trochlea")
    olecranon_angle_deg: float = Field(150.0, gt=0, lt=180, description="the olecranon's tip, from the forearm's "
                                                                          "distal direction towards posterior")
    coronoid_angle_deg: float = Field(10.0, ge=0, lt=90, description="the coronoid's tip, towards anterior")


class RadiusShape(_Strict):
    kind: Literal["radius"] = "radius"
    head_diameter: float = Field(22.5, gt=0, description="mm")
    head_height: float = Field(10.6, gt=0, description="mm along the radius")
    neck_length: float = Field(13.0, gt=0, description="mm, head to the tuberosity")


class TubeShape(_Strict):
    """A capped cylinder along start-end with the bone's radius (a bone without an anatomical shape)."""

    kind: Literal["tube"] = "tube"


BoneShape = Annotated[HumerusShape | UlnaShape | RadiusShape | TubeShape, Field(discriminator="kind")]


class Bone(_Strict):
    name: str
    segment: Literal["upper_arm", "forearm"]
    start: Vector
    end: Vector
    radius: float = Field(gt=0)
    # drawing and anatomy checks only: contact sees the capsule start-end-radius. Default: the
    # anatomical shape of a bone named humerus, ulna or radius, else a tube.
    shape: BoneShape | None = None

    def drawn_shape(self):
        """The shape this bone is drawn with (its own, or the default for its name)."""
        if self.shape is not None:
            return self.shape
        return {"humerus": HumerusShape, "ulna": UlnaShape, "radius": RadiusShape}.get(self.name, TubeShape)()


class Wall(_Strict):
    """A fascial wall (persival.model.anatomy.walls) that moves with its segment: a septum (a plane a
    muscle keeps to its side of, over a band of heights) or a sleeve (the inside of a capsule)."""

    name: str
    kind: Literal["septum", "sleeve"]
    segment: Literal["upper_arm", "forearm"] = "upper_arm"
    point: Vector | None = Field(None, description="septum: a point of the plane (mm)")
    normal: Vector | None = Field(None, description="septum: the plane's normal")
    along: Vector = Field((0.0, 0.0, 1.0), description="septum: the direction its band of heights is measured along")
    band: tuple[float, float] | None = Field(None, description="septum: heights (mm from point, along) where it acts")
    ramp: float = Field(10.0, gt=0, description="septum: mm over which it fades in and out at the band's ends")
    start: Vector | None = Field(None, description="sleeve: one end of its axis")
    end: Vector | None = Field(None, description="sleeve: the other end")
    radius: float | None = Field(None, gt=0, description="sleeve: mm from its axis")
    turns: float = Field(0.0, description="fraction of the elbow's flexion beyond turns_from_deg that the wall turns "
                         "by about an axis parallel to the hinge through pivot (positive: with the forearm; "
                         "docs/theory.md 3.5, 'Walls that turn with the elbow')")
    turns_from_deg: float = Field(60.0, description="deg: the elbow angle from which the wall turns (a smooth onset "
                                  "over about 10 deg)")
    pivot: Vector | None = Field(None, description="a point of the axis the wall turns about (mm; required with turns)")

    @model_validator(mode="after")
    def _complete(self):
        need = {"septum": ("point", "normal", "band"), "sleeve": ("start", "end", "radius")}[self.kind]
        missing = [k for k in need if getattr(self, k) is None]
        if missing:
            raise ValueError(f"wall {self.name!r}: a {self.kind} needs {', '.join(missing)}")
        if self.turns != 0 and self.pivot is None:
            raise ValueError(f"wall {self.name!r}: a wall that turns (turns = {self.turns:g}) needs a pivot")
        if self.kind == "septum" and self.band[1] - self.band[0] < 2 * self.ramp:
            raise ValueError(f"wall {self.name!r}: its band must be at least two ramps ({2 * self.ramp:g} mm) long")
        return self


class Contact(_Strict):
    penalty: float = Field(1.0, gt=0, description="N/mm^3: contact pressure per mm of penetration (docs/theory.md, 3.5)")
    bone_surfaces: bool = Field(False, description="bones with a drawn shape touch the muscles that wrap them by "
                                "their shaped surfaces (a sampled distance field), not by their capsules")
    attachment_mm: float = Field(10.0, ge=0, description="mm: a muscle's surface this near its two ends (its "
                                 "attachments) does not touch the shaped surfaces")
    touching: list[list[str]] = Field(default_factory=list, description="groups of muscles that touch each other "
                                      "(frictionless penalty contact): each group is solved as one FE problem "
                                      "(persival.model.arm.muscle_group); a muscle in one group at most")


class Outline(_Strict):
    """Where a muscle crosses the plane z = const of the upper-arm frame: an ellipse, as a
    cross-sectional atlas of the arm draws it (docs/design/arm_model_record.md, "Muscles lofted through outlines")."""

    z: float = Field(description="mm: height of the plane in the upper-arm frame (the hinge at 0)")
    centre: tuple[float, float] = Field(description="mm: x, y of the ellipse's centre in that plane")
    semi_axes: tuple[float, float] = Field(description="mm: the larger semi-axis (along angle_deg), then the smaller")
    angle_deg: float = Field(0.0, description="direction of the larger semi-axis, from +x towards +y")

    @model_validator(mode="after")
    def _ordered_axes(self):
        if min(self.semi_axes) <= 0 or self.semi_axes[0] < self.semi_axes[1]:
            raise ValueError(f"semi_axes must be positive, the larger first (along angle_deg), got {self.semi_axes}")
        return self


def _distinct_heights(outlines: list[Outline], owner: str) -> None:
    heights = [o.z for o in outlines]
    if len(set(heights)) != len(heights):
        raise ValueError(f"{owner}: two outlines at the same height z")


class Muscle(_Strict):
    name: str
    action: Literal["flexor", "extensor"]
    origin: Vector
    insertion: Vector
    wraps: list[str] = Field(default_factory=list, description="bones and walls the muscle slides over (frictionless "
                                                               "contact)")
    via: list[Vector] = Field(default_factory=list, description="centre-line points, upper-arm frame")
    wrap_radius: float = Field(0.0, ge=0, description="mm: the path wraps a cylinder of this radius on the hinge axis "
                                                      "(0: a straight path; persival.model.anatomy.wrapping)")
    wrap_cable: float = Field(0.0, ge=0, description="mm of the wrapped path that is inextensible cable, not FE body")
    insertion_tie: Literal["line", "forearm"] = Field(
        "line", description="line: both end faces ball joints on the line of action; forearm: the insertion face "
                            "rigid with the forearm, the origin face with the humerus (persival.model.arm.insertion_ties)")
    mesh_angle_deg: float = Field(description="elbow angle of the stress-free mesh pose")
    bow: float = Field(0.0, ge=0, description="mm: sagitta of a sine bow of the centre line away from the hinge")
    belly_radius: float = Field(gt=0)
    tendon_radius: tuple[float, float] = Field(description="proximal, distal (mm)")
    tendon_length: tuple[float, float] = Field(description="proximal, distal pure tendon (mm, mesh pose)")
    transition_length: float = Field(gt=0, description="muscle-tendon blend zone (mm)")
    fibre_prestretch: float = Field(1.0, gt=0.5, lt=2.0)
    bulk_modulus: tuple[float, float] = Field((100.0, 1000.0), description="muscle, tendon (MPa)")
    # Own anatomy (docs/own_anatomy.md): the muscle's shape from a closed surface
    # instead of the swept solid; belly_radius and bow then play no part.
    surface: str | None = Field(None, description="surface file (STL, OBJ, PLY, VTK, VTP), relative to the model file")
    surface_units: Literal["mm", "cm", "m"] = "mm"
    origin_point: Vector | None = Field(None, description="near the origin end, in the surface's coordinates")
    insertion_point: Vector | None = Field(None, description="near the insertion end, in the surface's coordinates")
    scale_to_fit: bool = Field(False, description="uniform scale so the two points span origin to insertion")
    # The belly's sections from an atlas (persival.model.anatomy.muscle_sweep): the centre line runs through
    # the outlines' centres and the sections are their ellipses; belly_radius and bow play no part.
    outlines: list[Outline] = Field(default_factory=list, description="the belly's sections at heights of the "
                                                                      "upper arm, in the humerus frame")

    @field_validator("tendon_radius", "tendon_length", "bulk_modulus")
    @classmethod
    def _positive_pair(cls, v, info):
        if min(v) <= 0:
            raise ValueError(f"{info.field_name} must be positive, got {v}")
        return v

    @model_validator(mode="after")
    def _wrap_is_complete(self):
        if self.wrap_radius > 0 and self.via:
            raise ValueError(f"muscle {self.name!r}: a wrapped path (wrap_radius) takes no via points")
        if self.wrap_cable > 0 and self.wrap_radius == 0:
            raise ValueError(f"muscle {self.name!r}: wrap_cable needs a wrap_radius")
        if self.insertion_tie == "forearm" and self.wrap_radius > 0:
            raise ValueError(f"muscle {self.name!r}: a forearm-tied insertion face rides the forearm, not a wrapped "
                             "path's end (drop wrap_radius or use insertion_tie = \"line\")")
        return self

    @model_validator(mode="after")
    def _surface_keys_complete(self):
        surface_keys = {"surface_units", "origin_point", "insertion_point", "scale_to_fit"} & self.model_fields_set
        if self.surface is None and surface_keys:
            raise ValueError(f"muscle {self.name!r}: {', '.join(sorted(surface_keys))} given without a surface")
        if self.surface is not None and (self.origin_point is None or self.insertion_point is None):
            raise ValueError(f"muscle {self.name!r}: a surface needs origin_point and insertion_point (in the surface's "
                             "coordinates, near its two ends)")
        return self

    @model_validator(mode="after")
    def _outlines_alone(self):
        if not self.outlines:
            return self
        clash = [k for k, on in (("surface", self.surface is not None), ("via", bool(self.via)), ("bow", self.bow > 0)) if on]
        if clash:
            raise ValueError(f"muscle {self.name!r}: outlines place its belly; drop {', '.join(clash)}")
        _distinct_heights(self.outlines, f"muscle {self.name!r}")
        thin = [o.z for o in self.outlines if o.semi_axes[1] <= max(self.tendon_radius)]
        if thin:
            raise ValueError(f"muscle {self.name!r}: the outline at z = {thin[0]:g} mm is thinner than its tendons "
                             f"(smaller semi-axis at most {max(self.tendon_radius):g} mm)")
        return self

    @model_validator(mode="after")
    def _belly_thicker_than_tendons(self):
        if self.belly_radius <= max(self.tendon_radius):
            raise ValueError(f"muscle {self.name!r}: belly_radius must exceed the tendon radii")
        return self


class Profile(_Strict):
    mesh_size: float = Field(gt=0, description="default element size (mm)")
    muscle_mesh_size: dict[str, float] = Field(default_factory=dict)

    @field_validator("muscle_mesh_size")
    @classmethod
    def _positive_sizes(cls, v):
        for name, h in v.items():
            if h <= 0:
                raise ValueError(f"mesh size of {name!r} must be positive")
        return v


class ArmModelFile(_Strict):
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
        _distinct_heights(self.skin, "skin")
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
