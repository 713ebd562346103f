"""Muscles lofted through outlines (persival.model.anatomy.muscle_sweep, the atlas variant): the centre line
runs through every outline's centre, the sections are its ellipses, the gmsh solid has their
volume, the shipped atlas layout overlaps nowhere at the check's levels, and bad layouts are
refused when the model file is read."""

from __future__ import annotations

import re

import numpy as np
import pytest

from persival.model.anatomy.schema_base import ModelFileError
from persival.model.arm.defaults import builtin_model_path
from persival.model.arm.kinematics import ArmKinematics
from persival.model.arm.model_file import load_model_file

ATLAS = builtin_model_path().parent / "variants" / "atlas_arm.toml"


@pytest.fixture(scope="module")
def atlas():
    return ArmKinematics(ATLAS)


def test_the_centre_line_runs_through_every_outline_and_the_sections_are_its_ellipses(atlas):
    for muscle in (m for m in atlas.spec.ordered_muscles() if m.outlines):
        sweep = atlas.sweep(muscle)
        line = sweep.line
        assert np.allclose(line[0], muscle.origin) and np.allclose(line[-1], atlas.body_end(muscle, muscle.mesh_angle_deg))
        step = np.linalg.norm(np.diff(line, axis=0), axis=1)
        assert step.max() / step.min() < 1.01  # stations equally spaced in arclength
        for outline in muscle.outlines:
            i = np.flatnonzero((line[:-1, 2] - outline.z) * (line[1:, 2] - outline.z) <= 0)[0]
            t = (outline.z - line[i, 2]) / (line[i + 1, 2] - line[i, 2])
            centre = line[i] + t * (line[i + 1] - line[i])
            # the spline passes the knot exactly; 33 straight chords miss it by their sagitta
            assert np.hypot(*(centre[:2] - outline.centre)) < 0.5, (muscle.name, outline.z)
            semi = sweep.semi_axes[i] + t * (sweep.semi_axes[i + 1] - sweep.semi_axes[i])
            if min(i, len(line) - 2 - i) > 6:  # away from the tendons' taper
                assert np.allclose(semi, outline.semi_axes, rtol=0.03), (muscle.name, outline.z, semi)
        tangent = np.gradient(line, axis=0)
        assert np.abs(np.einsum("ki,ki->k", sweep.major, tangent)).max() < 1e-9  # across the centre line
        assert np.all(sweep.semi_axes[:, 0] >= sweep.semi_axes[:, 1])


def test_the_lofted_ellipses_have_the_volume_of_their_sections(atlas):
    """gmsh's loft of the brachialis' ellipses against the sum of pi a b ds over its stations."""
    brachialis = atlas.spec.muscle("brachialis")
    sweep = atlas.sweep(brachialis)
    mesh = sweep.mesh(6.0)
    ds = np.linalg.norm(np.diff(sweep.line, axis=0), axis=1)
    area = np.pi * sweep.semi_axes[:, 0] * sweep.semi_axes[:, 1]
    assert mesh.volume() == pytest.approx(float(np.sum(0.5 * (area[1:] + area[:-1]) * ds)), rel=0.03)
    assert len(mesh.node_sets["origin"]) > 0 and len(mesh.node_sets["insertion"]) > 0


def test_the_atlas_layout_overlaps_nowhere_and_the_default_is_not_checked(atlas):
    from persival.model.arm.cross_sections import outline_overlaps

    assert outline_overlaps(atlas) == []
    assert len(outline_overlaps(ArmKinematics())) > 0  # spindles: read, not refused (no outlines in the file)


def _atlas_with(tmp_path, old: str, new: str):
    text = ATLAS.read_text()
    assert old in text
    path = tmp_path / "arm.toml"
    path.write_text(text.replace(old, new))
    return path


def test_overlapping_outlines_are_refused_naming_the_muscles_and_the_level(tmp_path):
    from persival.model.arm.cross_sections import OutlineOverlapError

    path = _atlas_with(tmp_path, "{ z = 81.7, centre = [-2.0, 21.0], semi_axes = [20.0, 9.0] }",
                       "{ z = 81.7, centre = [-2.0, 32.0], semi_axes = [20.0, 9.0] }")
    with pytest.raises(OutlineOverlapError, match=re.escape("brachialis in biceps at 30 % of the humerus (z = 81.7 mm")):
        ArmKinematics(path)
    bone = _atlas_with(tmp_path, "{ z = 144.7, centre = [0.0, -25.5], semi_axes = [24.0, 13.0] }",
                       "{ z = 144.7, centre = [0.0, -18.0], semi_axes = [24.0, 13.0] }")
    with pytest.raises(OutlineOverlapError, match=re.escape("triceps in humerus at 50 %")):
        ArmKinematics(bone)


@pytest.mark.parametrize("old, new, message", [
    ("semi_axes = [21.0, 15.0] }", "semi_axes = [15.0, 21.0] }", "the larger first"),
    ("semi_axes = [21.0, 15.0] }", "semi_axes = [21.0, 4.5] }", "thinner than its tendons"),
    ("{ z = 265.0, centre = [0.0, 33.0]", "{ z = 340.0, centre = [0.0, 33.0]", "does not lie between its ends"),
    ("mesh_angle_deg = 60.0\nbelly_radius = 20.0", "mesh_angle_deg = 60.0\nbow = 5.0\nbelly_radius = 20.0", "drop bow"),
])
def test_bad_outlines_are_refused(tmp_path, old, new, message):
    path = _atlas_with(tmp_path, old, new)
    with pytest.raises((ModelFileError, ValueError), match=message):
        load_model_file(path)
        ArmKinematics(path)


@pytest.mark.slow  # meshes the coarse arm (8 s): make test keeps it, the quick loop need not
def test_the_built_in_mesh_is_still_the_fixture_tables_mesh():
    """Meshed afresh (not from the cache), the built-in coarse arm has the fingerprint the response-
    table fixture was built on: a sweep change that moves one node would make the table tests skip."""
    import json
    from pathlib import Path

    from persival.model.arm.body import ArmBody
    from persival.tables.response_table import mesh_fingerprint

    header = json.loads((Path(__file__).parents[1] / "data" / "response_table_coarse" / "header.json").read_text())
    assert mesh_fingerprint(ArmBody.frame(None, "coarse")._build_mesh()) == header["mesh_fingerprint"]
