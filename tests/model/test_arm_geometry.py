"""The built-in arm's meshes (quick profile): five closed muscle surfaces, tissue layout, bones."""

import numpy as np
import pytest

from persival.campaign.arm_simulator import ArmSimulator
from persival.vocabulary import MUSCLES


@pytest.fixture(scope="module")
def simulator():
    return ArmSimulator(profile="quick", method="direct")  # geometry only: no response tables needed


@pytest.mark.slow
def test_reference_surfaces_are_closed_and_outward(simulator):
    reference = simulator.reference()
    assert list(reference.surfaces) == list(MUSCLES)
    for name, surface in reference.surfaces.items():
        tri = surface.triangles
        edges = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
        _, counts = np.unique(edges, axis=0, return_counts=True)
        assert np.all(counts == 2), f"{name}: surface not closed"
        p = surface.reference_points
        # enclosed volume by the divergence theorem: positive for outward normals
        volume = np.einsum("ij,ij->i", p[tri[:, 0]], np.cross(p[tri[:, 1]], p[tri[:, 2]])).sum() / 6.0
        body = simulator.arm.mesh
        cells = simulator.arm.muscle_cells[name]
        from persival.model.fe.mesh import Tet10Mesh

        nodes = simulator.arm.muscle_nodes[name]
        fe_volume = Tet10Mesh(body.points[nodes], body.cells[cells] - nodes[0]).volume()
        # faceted display triangles vs curved tet10 faces: a few per cent on coarse thin muscles
        assert volume == pytest.approx(fe_volume, rel=0.05), name


def test_tissue_layout_and_fibres(simulator):
    arm = simulator.arm
    gamma = arm.mesh.cell_data["muscle_fraction"]
    fibre = arm.mesh.cell_data["fibre"]
    assert np.allclose(np.linalg.norm(fibre, axis=1), 1.0)
    for name in MUSCLES:
        cells = arm.muscle_cells[name]
        s = arm.mesh.cell_data["arclength"][cells]
        # tendon (gamma = 0) at both ends, pure muscle in the middle of the belly
        assert gamma[cells][s < 0.01].max() < 0.5 and gamma[cells][s > 0.99].max() < 0.5, name
        assert gamma[cells][np.abs(s - 0.5) < 0.05].min() == pytest.approx(1.0), name


def test_bones_rotate_with_the_elbow(simulator):
    from persival.model.arm.output import bone_surfaces

    straight, flexed = bone_surfaces(simulator.arm, 0.0), bone_surfaces(simulator.arm, 90.0)
    assert np.allclose(straight["humerus"][0], flexed["humerus"][0])
    # the ulna points down (-z) in extension and forward (+y) at 90 deg
    tip0 = straight["ulna"][0][:, 2].min()
    tip90 = flexed["ulna"][0][:, 1].max()
    assert tip0 < -240 and tip90 > 240
