"""One contract from FE to viewer (SPEC 5 and 9): `(angle, load_kg) -> activations` and
`(activations, load_kg) -> (positions, angle)` give the same numbers from the Python API, REST,
WebSocket and the page, and the angle asked for is the angle the deployed model shows.

The export is a real deployed model: the structured surrogate fitted to the coarse response-table
fixture (tests/data/response_table_coarse), its motion model solved on its own moment balance,
written by persival.deploy.export.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.slow  # fits the structured model on the coarse arm (make test-fast skips it)

ROOT = Path(__file__).resolve().parents[2]
N_REQUESTS = 200


@pytest.fixture(scope="module")
def structured_export(coarse_arm, coarse_table, tmp_path_factory) -> Path:
    from persival.campaign.arm_simulator import muscle_surface
    from persival.campaign.simulator import SurfaceTopology
    from persival.deploy.export import export_model
    from persival.surrogate.dataset import Dataset, Surfaces
    from persival.surrogate.motion_model import MotionActivationModel
    from persival.surrogate.structured.surrogate import StructuredSurrogate
    from persival.vocabulary import MUSCLES

    arm = coarse_arm
    surfaces = Surfaces.from_topologies([SurfaceTopology(n, arm.mesh.points[muscle_surface(arm, n)[0]],
                                                         muscle_surface(arm, n)[1]) for n in MUSCLES])
    empty = Dataset(np.zeros((0, 5)), np.zeros((0, surfaces.n_nodes, 3)), np.zeros(0), surfaces,
                    {"model_hash": arm.model_hash, "label": "FE arm (coarse)", "simulator": "arm"})
    deployed = StructuredSurrogate("coarse", tables=str(ROOT / "tests" / "data" / "response_table_coarse")).fit(empty)
    motion = MotionActivationModel.build(deployed.moments)
    folder = tmp_path_factory.mktemp("contract") / "export"
    export_model(deployed, folder, activation_model=motion.at_rest(), motion_model=motion)
    return folder


@pytest.fixture(scope="module")
def model(structured_export):
    from persival.deploy.artifacts import DeployedModel

    return DeployedModel(structured_export)


@pytest.fixture(scope="module")
def requests(model):
    from persival.deploy.contract import angle_requests

    return angle_requests(model, N_REQUESTS, seed=7)


@pytest.fixture(scope="module")
def client(structured_export):
    from fastapi.testclient import TestClient

    from persival.deploy.server import create_app

    return TestClient(create_app(structured_export))


def test_ninety_degrees_with_two_kilograms_over_rest_is_ninety_degrees(client):
    body = client.post("/api/predict", json={"angle_deg": 90, "load_kg": 2}).json()
    assert "elbow_angle_deg" in body, body
    assert body["elbow_angle_deg"] == pytest.approx(90.0, abs=0.5), body
    # the same activations without the load in the deformation model would flex the arm further
    unloaded = client.post("/api/predict", json={"activations": body["activations"]}).json()
    assert unloaded["elbow_angle_deg"] > 95.0
    loaded = client.post("/api/predict", json={"activations": body["activations"], "load_kg": 2}).json()
    assert loaded["elbow_angle_deg"] == pytest.approx(body["elbow_angle_deg"], abs=1e-4)


def test_python_api_holds_the_angle_asked_for(model, requests):
    from persival.deploy.contract import check_angle_contract

    result = check_angle_contract(model, requests)
    print(f"\n{result['requests']} requests, loads up to {result['max_load_kg']:.2f} kg: max "
          f"{result['max_angle_error_deg']:.3f} deg, mean {result['mean_angle_error_deg']:.4f} deg")
    assert result["max_angle_error_deg"] < 0.5
    assert result["max_load_kg"] > 1.0  # the requests do carry loads


def _python_answers(model, requests) -> tuple[np.ndarray, np.ndarray]:
    activations = np.stack([model.activations_for_angle(a, load) for a, load in requests])
    angles = np.array([model.predict(a, load_kg=load)[1][0] for a, (_, load) in zip(activations, requests)])
    return activations, angles


def test_rest_and_websocket_give_the_python_numbers(client, model, requests):
    activations, angles = _python_answers(model, requests)
    rest = [client.post("/api/predict", json={"angle_deg": float(a), "load_kg": float(load)}).json() for a, load in requests]
    with client.websocket_connect("/ws") as ws:
        socket = []
        for a, load in requests:
            ws.send_text(json.dumps({"angle_deg": float(a), "load_kg": float(load)}))
            socket.append(ws.receive_json())
    for answers in (rest, socket):
        assert np.abs(np.array([r["activations"] for r in answers]) - activations).max() < 1e-4
        assert np.abs(np.array([r["elbow_angle_deg"] for r in answers]) - angles).max() < 1e-3
    assert np.abs(angles - requests[:, 0]).max() < 0.5


def test_a_load_the_muscles_cannot_hold_is_refused_with_what_they_hold(client, model):
    held = float(model.holdable_load_kg([120.0])[0])
    refused = client.post("/api/predict", json={"angle_deg": 120, "load_kg": min(held + 1.0, model.max_load_kg)})
    assert refused.status_code == 422 and f"{held:.2f} kg" in refused.json()["error"]


CHROMIUM = os.environ.get("CHROMIUM", "/usr/bin/chromium")
WEB = ROOT / "persival" / "deploy" / "web"
browser_missing = not (Path(CHROMIUM).exists() and shutil.which("node") and (WEB / "dist" / "index.html").is_file()
                       and (WEB / "node_modules" / "playwright-core").is_dir())


@pytest.mark.skipif(browser_missing, reason="needs chromium, node and the built viewer (make web)")
def test_the_page_gives_the_python_numbers(structured_export, model, requests):
    from test_server import run_page_script


    result = run_page_script(structured_export, ROOT / "tests" / "viewer" / "contract_check.mjs",
                             json.dumps(requests.tolist()), timeout=300)
    assert result["consoleErrors"] == [] and result["pageErrors"] == []
    activations, angles = _python_answers(model, requests)
    page_a = np.array([r["activations"] for r in result["answers"]])
    page_angle = np.array([r["angle"] for r in result["answers"]])
    off = np.abs(page_angle - requests[:, 0])
    print(f"\npage vs Python: activations {np.abs(page_a - activations).max():.1e}, angle "
          f"{np.abs(page_angle - angles).max():.1e} deg; page vs request: max {off.max():.3f} deg")
    assert np.abs(page_a - activations).max() < 1e-4
    assert np.abs(page_angle - requests[:, 0]).max() < 0.5
    assert result["setAngle"]["elbowAngle"] == pytest.approx(requests[0, 0], abs=0.5)
