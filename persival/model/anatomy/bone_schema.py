"""The model file's bones (with their shapes), the fascial walls fixed to them and the contact
settings (docs/theory.md, section 3; the whole file: persival.model.anatomy.schema)."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, model_validator

from persival.model.anatomy.schema_base import Strict, Vector


class HumerusShape(Strict):
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


class UlnaShape(Strict):
    kind: Literal["ulna"] = "ulna"
    joint_clearance: float = Field(1.0, gt=0, description="mm of cartilage between the notch and the trochlea")
    olecranon_angle_deg: float = Field(150.0, gt=0, lt=180, description="the olecranon's tip, from the forearm's "
                                                                          "distal direction towards posterior")
    coronoid_angle_deg: float = Field(10.0, ge=0, lt=90, description="the coronoid's tip, towards anterior")


class RadiusShape(Strict):
    kind: Literal["radius"] = "radius"
    head_diameter: float = Field(22.5, gt=0, description="mm")
    head_height: float = Field(10.6, gt=0, description="mm along the radius")
    neck_length: float = Field(13.0, gt=0, description="mm, head to the tuberosity")


class TubeShape(Strict):
    """A capped cylinder along start-end with the bone's radius (a bone without an anatomical shape)."""

    kind: Literal["tube"] = "tube"


BoneShape = Annotated[HumerusShape | UlnaShape | RadiusShape | TubeShape, Field(discriminator="kind")]


class Bone(Strict):
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


class Wall(Strict):
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
    gives_mm: float = Field(0.0, ge=0, description="septum: mm it gives way (moves along its normal, away from the "
                            "muscle it holds) over gives_deg, a smoothstep in the angle (docs/theory.md 3.5)")
    gives_deg: tuple[float, float] = Field((120.0, 140.0), description="elbow angles (deg) over which a septum gives way")
    fades_deg: tuple[float, float] | None = Field(None, description="elbow angles (deg) over which the wall fades out "
                                                  "(its penetration scaled by a smoothstep from 1 to 0; docs/theory.md "
                                                  "3.5, 'Walls that fade with the elbow'); none: it holds at every angle")

    @model_validator(mode="after")
    def _complete(self):
        if self.gives_mm and self.kind != "septum":
            raise ValueError(f"wall {self.name!r}: only a septum gives way (gives_mm), not a {self.kind}")
        need = {"septum": ("point", "normal", "band"), "sleeve": ("start", "end", "radius")}[self.kind]
        missing = [k for k in need if getattr(self, k) is None]
        if missing:
            raise ValueError(f"wall {self.name!r}: a {self.kind} needs {', '.join(missing)}")
        if self.turns != 0 and self.pivot is None:
            raise ValueError(f"wall {self.name!r}: a wall that turns (turns = {self.turns:g}) needs a pivot")
        if not self.gives_deg[0] < self.gives_deg[1]:
            raise ValueError(f"wall {self.name!r}: gives_deg must rise (from, to), got {list(self.gives_deg)}")
        if self.fades_deg is not None and not self.fades_deg[0] < self.fades_deg[1]:
            raise ValueError(f"wall {self.name!r}: fades_deg must rise (from, to), got {list(self.fades_deg)}")
        if self.kind == "septum" and self.band[1] - self.band[0] < 2 * self.ramp:
            raise ValueError(f"wall {self.name!r}: its band must be at least two ramps ({2 * self.ramp:g} mm) long")
        return self


class Contact(Strict):
    penalty: float = Field(1.0, gt=0, description="N/mm^3: contact pressure per mm of penetration (docs/theory.md, 3.5)")
    smoothing_mm: float = Field(0.0, ge=0, description="mm of penetration over which the contact stiffness ramps up "
                                "from 0 to the penalty (a tangent without a jump where a point enters contact; "
                                "docs/theory.md 3.5); 0: the plain penalty")
    bone_surfaces: bool = Field(False, description="bones with a drawn shape touch the muscles that wrap them by "
                                "their shaped surfaces (a sampled distance field), not by their capsules")
    attachment_mm: float = Field(10.0, ge=0, description="mm: a muscle's surface this near its two ends (its "
                                 "attachments) does not touch the shaped surfaces")
    touching: list[list[str]] = Field(default_factory=list, description="groups of muscles that touch each other "
                                      "(frictionless penalty contact): each group is solved as one FE problem "
                                      "(persival.model.arm.muscle_group); a muscle in one group at most")
