"""The model file's muscles: line of action, outlines or a surface, tissue layout, fibre prestretch
and bulk moduli (docs/theory.md, section 3; the whole file: persival.model.anatomy.schema)."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, field_validator, model_validator

from persival.model.anatomy.schema_base import Strict, Vector


class Outline(Strict):
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


def distinct_heights(outlines: list[Outline], owner: str) -> None:
    heights = [o.z for o in outlines]
    if len(set(heights)) != len(heights):
        raise ValueError(f"{owner}: two outlines at the same height z")


class Muscle(Strict):
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
    matrix_prestretch: float = Field(1.0, ge=0.7, le=1.4, description="the muscle matrix's stress-free length "
                                     "over its mesh pose's, along the fibre, volume preserved (docs/theory.md 1.7)")
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
        distinct_heights(self.outlines, f"muscle {self.name!r}")
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
