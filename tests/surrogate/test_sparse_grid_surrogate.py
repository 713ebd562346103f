"""The SG surrogate of a campaign store (SPEC 4) on a real small campaign (analytic simulator, level 1)."""

import numpy as np
import pytest

from persival.campaign.design import Design
from persival.campaign.runner import INLINE, run_campaign
from persival.campaign.simulator import SimulatorSpec, make_simulator
from persival.surrogate.sparse_grid_surrogate import SparseGridSurrogate


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    path = tmp_path_factory.mktemp("sg") / "campaign.zarr"
    run_campaign(path, Design.sparse_grid(1), SimulatorSpec("analytic", {}), scheduler=INLINE, progress=False)
    return path


@pytest.mark.slow
def test_interpolates_the_stored_states_and_generalizes(store, tmp_path):
    from persival.campaign.store import CampaignStore

    surrogate = SparseGridSurrogate("biceps").fit(store)
    with CampaignStore.open(store) as s:
        alpha = s.design.points
        stored, angles = s.surface_positions("biceps"), s.elbow_angles()
    positions, predicted_angles = surrogate.predict_with_angle(alpha)
    assert np.abs(positions - stored).max() < 1e-8  # interpolation property, in mm
    assert np.abs(predicted_angles - angles).max() < 1e-8
    simulator = make_simulator(SimulatorSpec("analytic", {}))
    rng = np.random.default_rng(1)
    errors = []
    for a in rng.uniform(0, 1, (10, 5)):
        truth, _ = simulator.simulate(a)
        x = surrogate.predict(a)
        errors.append(np.linalg.norm(x[0] - truth.surfaces["biceps"], axis=1).max())
    spread = np.ptp(stored, axis=0).max()
    print(f"held-out max node error {max(errors):.3f} mm (node motion range {spread:.1f} mm)")
    assert max(errors) < 0.2 * spread

    # gradients are the derivatives of predict
    a = rng.uniform(0.1, 0.9, (2, 5))
    dx, dtheta = surrogate.gradient(a)
    h = 1e-6
    for k in range(5):
        e = np.zeros(5)
        e[k] = h
        xp, tp = surrogate.predict_with_angle(a + e)
        xm, tm = surrogate.predict_with_angle(a - e)
        assert np.allclose((xp - xm) / (2 * h), dx[..., k], atol=1e-5)
        assert np.allclose((tp - tm) / (2 * h), dtheta[:, k], atol=1e-5)

    loaded = SparseGridSurrogate.load(surrogate.save(tmp_path / "sg"))
    assert np.array_equal(loaded.predict(a), surrogate.predict(a))
    assert loaded.triangles.shape == surrogate.triangles.shape


def test_bad_input(store):
    with pytest.raises(ValueError, match="no surface 'deltoid'"):
        SparseGridSurrogate("deltoid").fit(store)
    surrogate = SparseGridSurrogate().fit(store)
    with pytest.raises(ValueError):
        surrogate.predict([[0.5, 0.5, 0.5, 0.5, 1.5]])
    with pytest.raises(RuntimeError, match="fit"):
        SparseGridSurrogate().predict([[0.5] * 5])


def test_all_muscles_in_one_grid_and_the_angle_column(store, tmp_path):
    from persival.surrogate.dataset import Dataset
    from persival.surrogate.open import load_surrogate

    data = Dataset.from_store(store)
    assert data.surfaces.names == ("biceps", "brachialis", "brachioradialis", "triceps", "anconeus")
    assert data.source["simulator"] == "analytic" and data.source["states"] == 243
    surrogate = SparseGridSurrogate(None).fit(data)
    biceps = SparseGridSurrogate("biceps").fit(store)
    a = np.random.default_rng(3).uniform(0, 1, (4, 5))
    # the biceps block of the five-muscle fit is the biceps-only fit (same grid, same LU)
    np.testing.assert_allclose(surrogate.predict(a)[:, data.surfaces.nodes_of("biceps")], biceps.predict(a), atol=1e-9)
    np.testing.assert_allclose(surrogate.predict_angle(a), surrogate.predict_with_angle(a)[1], atol=1e-12)
    np.testing.assert_allclose(surrogate.angle_gradient(a), surrogate.gradient(a)[1], atol=1e-12)
    loaded = load_surrogate(surrogate.save(tmp_path / "sg5"))
    assert loaded.surfaces.ranges() == data.surfaces.ranges()
    assert loaded.metadata["simulator"] == "analytic"
