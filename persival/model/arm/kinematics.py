"""The joint's kinematics of a model file, without a mesh: where forearm points, the muscles'
ends and their centre lines are at an elbow angle (docs/theory.md, 3.2)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from persival.model.anatomy.muscle_schema import Muscle
from persival.model.anatomy.muscle_sweep import Sweep, outlined_centre_line, sweep_sections
from persival.model.anatomy.wrapping import WrapCylinder
from persival.model.arm.cross_sections import check_outlines as refuse_overlaps
from persival.model.arm.model_file import load_model_file
from persival.model.fe.rotations import rotation_about


class ArmKinematics:
    """The joint's kinematics of a model file, without a mesh: where forearm points and the
    muscles' ends are at an elbow angle (enough to place bones and attachments)."""

    def __init__(self, model_file: str | Path | None = None, *, check_outlines: bool = True):
        """``check_outlines``: refuse a model file whose muscles' outlines overlap (only files that
        lay muscles out by outlines; ``persival anatomy --outlines`` reports them instead)."""
        self.spec, self.model_hash = load_model_file(model_file)
        joint = self.spec.joint
        self.axis = np.asarray(joint.axis, dtype=float) / np.linalg.norm(joint.axis)
        self.centre = np.asarray(joint.centre, dtype=float)
        if check_outlines and any(m.outlines for m in self.spec.muscles):
            # a layout drawn from an atlas is held to it: no outline overlaps another or the humerus
            # (persival.model.arm.cross_sections), before anything is meshed or written
            refuse_overlaps(self)

    def forearm_point(self, p: np.ndarray, theta_deg: float) -> np.ndarray:
        """A forearm-frame point (given at theta = 0) at elbow angle theta."""
        return self.centre + (np.asarray(p, dtype=float) - self.centre) @ rotation_about(self.axis, theta_deg).T

    def wrap_cylinder(self, muscle: Muscle) -> WrapCylinder:
        """The cylinder on the hinge axis the muscle's path wraps (radius 0: a straight path)."""
        return WrapCylinder(self.centre, self.axis, muscle.wrap_radius, 1 if muscle.action == "extensor" else -1)

    def muscle_length(self, muscle: Muscle, theta_deg: float) -> tuple[float, float, float]:
        """The muscle's length L (mm) and its derivatives dL/dtheta, d2L/dtheta2 (per radian).

        L is the origin-insertion path's length less the wrapped path's cable (``wrap_cable``):
        the length of the FE body between its end faces. The insertion turns about the hinge:
        I' = k x (I - c), I'' = k x I'. A wrapped path (docs/theory.md 3.4, :mod:`persival.model.anatomy.wrapping`)
        gains r per radian while it wraps.
        """
        insertion = self.forearm_point(muscle.insertion, theta_deg)
        v1 = np.cross(self.axis, insertion - self.centre)
        v2 = np.cross(self.axis, v1)
        L, dL, d2L = self.wrap_cylinder(muscle).geometry(np.asarray(muscle.origin, dtype=float), insertion, v1, v2)
        if L <= muscle.wrap_cable:
            raise ValueError(f"muscle {muscle.name!r}: wrap_cable {muscle.wrap_cable} mm is longer than its path "
                             f"({L:.1f} mm at {theta_deg} deg)")
        return L - muscle.wrap_cable, dL, d2L

    def body_end(self, muscle: Muscle, theta_deg: float) -> np.ndarray:
        """Where the muscle's FE body ends at theta: its insertion, or for a wrapped path the point
        ``L(theta) - wrap_cable`` along the path's first segment (the rest is cable)."""
        insertion = self.forearm_point(muscle.insertion, theta_deg)
        if muscle.wrap_radius == 0:
            return insertion
        origin = np.asarray(muscle.origin, dtype=float)
        cylinder = self.wrap_cylinder(muscle)
        if muscle.wrap_cable == 0 and not cylinder.wraps(origin, insertion):
            # exactly the insertion, not O + L d rounded: gmsh's loft meshes a centre line that
            # differs in the 14th digit differently (measured: 2548 against 1754 nodes)
            return insertion
        return origin + self.muscle_length(muscle, theta_deg)[0] * cylinder.first_direction(origin, insertion)


    def centre_line(self, muscle: Muscle, stations: int = 33) -> np.ndarray:
        """Stations along origin -> via points -> insertion in the muscle's mesh pose (through its
        outlines' centres when it has outlines: persival.model.anatomy.muscle_sweep)."""
        if muscle.outlines:
            return outlined_centre_line(muscle, np.asarray(muscle.origin, dtype=float),
                                        self.body_end(muscle, muscle.mesh_angle_deg), stations)
        knots = np.array([muscle.origin, *muscle.via, self.body_end(muscle, muscle.mesh_angle_deg)])
        seg = np.linalg.norm(np.diff(knots, axis=0), axis=1)
        if np.any(seg <= 0):
            raise ValueError(f"muscle {muscle.name!r}: consecutive centre-line points coincide")
        cum = np.concatenate([[0.0], np.cumsum(seg)])
        s = np.linspace(0.0, cum[-1], stations)
        line = np.column_stack([np.interp(s, cum, knots[:, k]) for k in range(3)])
        if muscle.bow > 0:
            # bowed away from the hinge in the plane normal to its axis: a slack muscle then
            # shortens by bending further, smoothly, instead of buckling at a bifurcation
            chord = knots[-1] - knots[0]
            normal = np.cross(self.axis, chord)
            normal /= np.linalg.norm(normal)
            if normal @ (0.5 * (knots[0] + knots[-1]) - self.centre) < 0:
                normal = -normal
            line += muscle.bow * np.sin(np.pi * s / cum[-1])[:, None] * normal
        return line

    def centre_line_length(self, muscle: Muscle) -> float:
        """Length (mm) of the muscle's centre line in its mesh pose: the scale of its tissue layout."""
        return float(np.linalg.norm(np.diff(self.centre_line(muscle), axis=0), axis=1).sum())

    def sweep(self, muscle: Muscle) -> Sweep:
        """The built-in muscle's solid: its centre line and the section at each station."""
        return sweep_sections(muscle, self.centre_line(muscle), self.centre_line_length(muscle))
