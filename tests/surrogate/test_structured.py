"""The structured surrogate: per-muscle moment and shape models from the response tables, and the
elbow's equilibrium solved inside the exported graph.

Fitted to the coarse response-table fixture (tests/data/response_table_coarse, see
tests/tables/test_response_table.py); the root search is also checked on a synthetic balance with two
stable roots.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from persival.model.arm.external_moments import ExternalMoments
from persival.surrogate.structured.moment_model import MomentModel
from persival.vocabulary import MUSCLES

FIXTURE = Path(__file__).parents[1] / "data" / "response_table_coarse"


@pytest.fixture(scope="module")
def arm(coarse_arm):
    return coarse_arm


@pytest.fixture(scope="module")
def table(coarse_table):
    return coarse_table


@pytest.fixture(scope="module")
def surfaces(arm):
    from persival.campaign.arm_simulator import muscle_surface
    from persival.campaign.simulator import SurfaceTopology
    from persival.surrogate.dataset import Surfaces

    return Surfaces.from_topologies([SurfaceTopology(n, arm.mesh.points[muscle_surface(arm, n)[0]], muscle_surface(arm, n)[1])
                                     for n in MUSCLES])


@pytest.fixture(scope="module")
def fitted(arm, table, surfaces):
    from persival.surrogate.dataset import Dataset
    from persival.surrogate.structured.surrogate import StructuredSurrogate

    empty = Dataset(np.zeros((0, 5)), np.zeros((0, surfaces.n_nodes, 3)), np.zeros(0), surfaces,
                    {"model_hash": arm.model_hash, "label": "FE arm (coarse)"})
    return StructuredSurrogate("coarse", tables=str(FIXTURE)).fit(empty)


def test_table_states_are_reproduced_within_the_pod_tolerance(arm, table, fitted):
    """At a table angle and level the shape model returns the tabulated FE surface (world frame)."""
    from persival.campaign.arm_simulator import muscle_surface

    for k, j in ((2, 0), (5, 1), (7, 2)):
        theta, level = table.angles_deg[k], table.levels[j]
        alpha = np.full((1, 5), level)
        expected = []
        for name in MUSCLES:
            state = table.state(name, k, j)
            nodes = muscle_surface(arm, name)[0]
            local = np.searchsorted(arm.muscle_nodes[name], nodes)
            expected.append(arm.units[name].positions(state)[local])
        error = np.linalg.norm(fitted.surfaces_at([theta], alpha)[0] - np.concatenate(expected), axis=1).max()
        assert error <= fitted.tolerance_mm + 1e-6, (theta, level, error)


def test_both_frames_reproduce_the_tables_and_their_graphs_answer_as_numpy(arm, table, fitted, surfaces):
    """The default reduces the world positions (no turn in the graph); the own frame reduces the
    muscle's frame and turns it by Q(theta). Both reproduce a tabulated FE state within the POD
    tolerance, and both graphs (float64) give the numpy reference's surfaces and angles."""
    from persival.surrogate.dataset import Dataset
    from persival.surrogate.structured.surrogate import StructuredSurrogate

    empty = Dataset(np.zeros((0, 5)), np.zeros((0, surfaces.n_nodes, 3)), np.zeros(0), surfaces,
                    {"model_hash": arm.model_hash, "label": "FE arm (coarse)"})
    own = StructuredSurrogate("coarse", tables=str(FIXTURE), frame="own").fit(empty)
    alpha = np.random.default_rng(5).uniform(0.0, 1.0, (12, 5))
    for model, turned in ((fitted, False), (own, True)):
        graph = model.deployable(torch.float64)
        assert graph.turned == [turned] * 5
        with torch.no_grad():
            positions, angles = graph(torch.as_tensor(alpha), torch.zeros(12, 1, dtype=torch.float64))
        expected, expected_angles = model.predict_with_angle(alpha)
        assert np.abs(positions.numpy() - expected).max() < 1e-9 and np.abs(angles.numpy()[:, 0] - expected_angles).max() < 1e-9
    k, j = 4, 1
    theta, level = table.angles_deg[k], table.levels[j]
    truth = fitted.surfaces_at([theta], np.full((1, 5), level))
    assert np.linalg.norm(own.surfaces_at([theta], np.full((1, 5), level)) - truth, axis=2).max() <= 2 * own.tolerance_mm
    # the own frame needs fewer modes for the same tolerance: the turn carries the line of action
    assert sum(own.metadata["modes"].values()) < sum(fitted.metadata["modes"].values())
    with pytest.raises(ValueError, match="frame"):
        StructuredSurrogate("coarse", frame="muscle")


def test_moments_are_the_tables_at_their_grid_and_the_fe_root_nearby(fitted, table):
    moments = table.moment_table()
    for m, name in enumerate(MUSCLES):
        got = fitted.moments.muscle_moment(name, np.repeat(table.angles_deg, len(table.levels)),
                                           np.tile(table.levels, len(table.angles_deg)))
        assert np.allclose(got, moments.moments[m].ravel(), rtol=1e-9, atol=1e-6)
    angle = fitted.predict_angle(np.array([[0.5, 0, 0, 0, 0], [1.0, 1.0, 1.0, 0, 0]]))
    assert np.all(np.diff(angle) > 0) and 60 < angle[0] < angle[1] <= 160 + 1e-9


def test_slopes_of_a_smooth_column_are_kept_and_a_wall_s_kink_does_not_overshoot():
    """The FE slopes where they agree with the tabulated values (a smooth moment: every one kept);
    a column with a jump between 5 and 10 deg and a slope of -440 N mm/deg beside a flat run (the
    walls arm's biceps at a = 1/4) gets the monotone slope there, and its Hermite interpolant stays
    within the values, where the FE slopes overshoot by more than 400 N mm."""
    from scipy.interpolate import CubicHermiteSpline

    from persival.surrogate.structured.moment_model import consistent_slopes

    angles = np.arange(-10.0, 190.0, 5.0)
    smooth = 2000.0 * np.sin(np.radians(angles) * 0.9 + 0.3)[None, :, None]
    exact = (2000.0 * 0.9 * np.pi / 180.0 * np.cos(np.radians(angles) * 0.9 + 0.3))[None, :, None]
    assert np.array_equal(consistent_slopes(angles, smooth, exact), exact)

    walls = np.array([813.0, 790.0, 767.0, 745.0, 2499.0, 2498.0, 2485.0, 2463.0, 2452.0, 2434.0])
    fe_slopes = np.array([-5.0, -5.0, -4.0, -4.0, -440.0, -745.0, -485.0, -611.0, -989.0, -633.0])
    kept = consistent_slopes(angles[:10], walls[None, :, None], fe_slopes[None, :, None])[0, :, 0]
    assert np.array_equal(kept[:3], fe_slopes[:3])  # where the column is smooth
    fine = np.linspace(10.0, 35.0, 501)
    assert CubicHermiteSpline(angles[:10], walls, fe_slopes)(fine).min() < 2499.0 - 400.0
    limited = CubicHermiteSpline(angles[:10], walls, kept)(fine)
    assert limited.min() >= walls[4:].min() - 1e-9 and limited.max() <= walls[4:].max() + 1e-9


def test_in_graph_equilibrium_matches_a_scipy_root_of_the_same_model(fitted):
    rng = np.random.default_rng(7)
    alpha = rng.uniform(0.0, 1.0, (40, 5))
    load = rng.uniform(0.0, 3.0, (40, 1))
    graph = fitted.deployable(torch.float64)
    with torch.no_grad():
        _, in_graph = graph(torch.as_tensor(alpha), torch.as_tensor(load))
    reference = np.array([fitted.moments.reference_root(a, float(m)) for a, m in zip(alpha, load[:, 0])])
    assert np.abs(in_graph.numpy()[:, 0] - reference).max() < 1e-6
    assert np.abs(fitted.moments.equilibrium(alpha, load[:, 0]) - reference).max() < 1e-6
    residual = fitted.moments.residual(reference, alpha, load[:, 0])
    assert np.abs(residual).max() < 1e-6  # N mm: a root, not only the same number


def test_stable_root_nearest_the_hanging_arm_of_a_balance_with_two():
    """g(theta) = 300 sin(3 theta) (biceps at 1, no gravity) plus the joint's limit moments has two
    stable roots, at 60 deg and near 155 deg (the upper limit): the one nearest the hanging angle
    is taken, in numpy and in the graph."""
    angles = np.arange(0.0, 160.0 + 1e-9, 5.0)
    levels = np.array([0.0, 0.5, 1.0])
    rad = np.radians(angles)
    moments = np.zeros((5, len(angles), 3))
    slopes = np.zeros_like(moments)
    for j, a in enumerate(levels):
        moments[0, :, j] = a * 300.0 * np.sin(3 * rad)
        slopes[0, :, j] = a * 900.0 * np.cos(3 * rad)
    external = ExternalMoments(0.0, 150.0, 330.0, 9.81, 500.0, (0.0, 160.0), 10.0)
    alpha = np.array([[1.0, 0, 0, 0, 0]])
    found = {}
    for near in (50.0, 130.0):
        model = MomentModel(angles, levels, moments, slopes, external, near)
        theta = model.equilibrium(alpha)[0]
        assert model.slope(theta, alpha)[0] < 0 and abs(model.residual(theta, alpha)[0]) < 1e-6
        with torch.no_grad():
            _, in_graph = _moment_graph(model)(torch.as_tensor(alpha), torch.zeros(1, 1, dtype=torch.float64))
        assert abs(in_graph.item() - theta) < 1e-6
        found[near] = theta
    assert abs(found[50.0] - 60.0) < 0.5 and 150.0 < found[130.0] < 160.0


def test_a_balance_without_a_root_presses_to_its_end_in_float32_too():
    """Where the balance flexes (or extends) at every angle there is no stable root: the arm is
    pressed to the table's last (first) angle, in numpy, in the float64 graph and in the float32
    graph that ships (its fallback rank once lost the index in float32's rounding)."""
    angles = np.arange(-10.0, 160.0 + 1e-9, 5.0)
    levels = np.array([0.0, 0.5, 1.0])
    moments = np.zeros((5, len(angles), 3))
    slopes = np.zeros_like(moments)
    moments[0] = 1e5 * levels  # a biceps that out-pulls gravity and both limits
    moments[3] = -1e5 * levels  # a triceps that out-pushes them
    external = ExternalMoments(1.6, 150.0, 330.0, 9.81, 500.0, (0.0, 160.0), 10.0)
    model = MomentModel(angles, levels, moments, slopes, external, 30.0)
    alpha = np.array([[1.0, 0, 0, 0, 0], [0, 0, 0, 1.0, 0]])
    expected = np.array([160.0, -10.0])
    assert np.allclose(model.equilibrium(alpha), expected)
    for dtype in (torch.float64, torch.float32):
        graph = _moment_graph(model, dtype)
        with torch.no_grad():
            _, theta = graph(torch.as_tensor(alpha, dtype=dtype), torch.zeros(2, 1, dtype=dtype))
        assert np.allclose(theta[:, 0].numpy(), expected, atol=1e-3), (dtype, theta)


def _moment_graph(model, dtype=torch.float64):
    """The graph of a moment model with a one-node 'surface' per muscle (nothing to shape)."""
    from persival.surrogate.structured.graph import StructuredGraph
    from persival.surrogate.structured.shape_model import MuscleShape

    n_t2, n_a = model.data.shape[1], len(model.levels)
    eye = np.tile(np.eye(3).ravel(), (n_t2 // 2, 1))
    rotation = np.concatenate([eye, np.zeros_like(eye)])
    shapes = [MuscleShape(name, np.zeros(3), np.zeros(3), np.zeros((1, 3)), np.zeros((n_t2, n_a, 1)), rotation, {})
              for name in MUSCLES]
    return StructuredGraph(model, shapes, dtype)


def test_export_runs_in_onnxruntime_with_and_without_the_load(fitted, tmp_path):
    import onnx
    import onnxruntime as ort

    from persival.deploy.export import export_model
    from persival.surrogate.open import load_surrogate

    again = load_surrogate(fitted.save(tmp_path / "structured"))
    assert again.kind == "structured"
    alpha = np.random.default_rng(1).uniform(0.0, 1.0, (16, 5))
    positions, angles = fitted.predict_with_angle(alpha)
    p2, a2 = again.predict_with_angle(alpha)
    assert np.array_equal(p2, positions) and np.array_equal(a2, angles)
    meta = export_model(again, tmp_path / "export")
    deformation = meta["models"]["deformation"]
    assert list(deformation["variants"]) == ["float32"] and deformation["optional_inputs"] == {"load_kg": 0.0}
    options = ort.SessionOptions()
    options.log_severity_level = 3
    session = ort.InferenceSession(str(tmp_path / "export" / "deformation.onnx"), options, providers=["CPUExecutionProvider"])
    got, got_angle = session.run(None, {"activations": alpha.astype(np.float32)})
    assert got.shape == positions.shape and np.abs(got - positions).max() < 0.05  # POD modes stored in float16
    assert np.abs(got_angle[:, 0] - angles).max() < 1e-3
    loaded, loaded_angle = session.run(None, {"activations": alpha.astype(np.float32),
                                              "load_kg": np.full((16, 1), 2.0, np.float32)})
    heavy_positions, heavy = fitted.predict_with_angle(alpha, 2.0)
    assert np.abs(loaded_angle[:, 0] - heavy).max() < 1e-3 and np.abs(loaded - heavy_positions).max() < 0.05
    assert np.all(heavy <= angles + 1e-9)  # a load in the hand never flexes the elbow further
    # the same graph with the load a required input, for onnxruntime-web (it cannot feed the optional one)
    variant = deformation["load_variant"]
    path = tmp_path / "export" / variant["file"]
    assert variant["file"] == "deformation_load.onnx" and variant["bytes"] == path.stat().st_size
    assert variant["inputs"] == {"activations": [None, 5], "load_kg": [None, 1]}
    assert variant["max_abs_diff_vs_torch"]["positions"] <= again.export_tolerance_mm
    required = ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
    assert [i.name for i in required.get_inputs()] == ["activations", "load_kg"]
    assert "load_kg" not in {init.name for init in onnx.load(str(path)).graph.initializer}  # no default: required
    with pytest.raises(Exception, match="load_kg"):
        required.run(None, {"activations": alpha.astype(np.float32)})
    fed, fed_angle = required.run(None, {"activations": alpha.astype(np.float32), "load_kg": np.full((16, 1), 2.0, np.float32)})
    assert np.abs(fed - loaded).max() <= 1e-5 and np.abs(fed_angle - loaded_angle).max() <= 1e-5


def test_states_of_another_model_are_refused(surfaces):
    from persival.surrogate.dataset import Dataset
    from persival.surrogate.structured.surrogate import StructuredSurrogate

    other = Dataset(np.zeros((0, 5)), np.zeros((0, surfaces.n_nodes, 3)), np.zeros(0), surfaces, {"model_hash": "0" * 64})
    with pytest.raises(ValueError, match="same arm"):
        StructuredSurrogate("coarse", tables=str(FIXTURE)).fit(other)
    with pytest.raises(RuntimeError, match="fit"):
        StructuredSurrogate().predict(np.zeros(5))
