"""The deployment contract measured (SPEC 5 and 9): the angle a user asks for, with a load in
the hand, is the angle the deployed model then shows.

``(angle, load) -> activations`` (the activation models) ``-> (positions, angle)`` (the
deformation model with the same load): on random requests over the model's range and the load
the muscles hold there, the achieved angle's distance from the request. The export stage
reports it; the tests compare the Python API, REST, WebSocket and the page on the same requests.
"""

from __future__ import annotations

import numpy as np

from persival.deploy.artifacts import DeployedModel

__all__ = ["angle_requests", "check_angle_contract"]


def angle_requests(model: DeployedModel, n: int, seed: int = 0) -> np.ndarray:
    """(n, 2) random (angle deg, load kg): angles uniform over the angle model's range, loads
    uniform between 0 and what the muscles hold at that angle (0 where the export has no motion
    model), a little inside it so that float32 rounding never tips a request over."""
    if model.angle_range is None:
        raise ValueError("this export has no activation model (activation_angle.onnx)")
    rng = np.random.default_rng(seed)
    angles = rng.uniform(*model.angle_range, n)
    held = model.holdable_load_kg(angles) if model.takes_load else np.zeros(n)
    return np.column_stack([angles, rng.uniform(0.0, 1.0, n) * 0.999 * held])


def check_angle_contract(model: DeployedModel, requests: np.ndarray) -> dict:
    """Per request the activations and the deployed model's angle; max and mean |achieved - asked|."""
    requests = np.asarray(requests, dtype=float)
    activations = np.stack([model.activations_for_angle(a, load) for a, load in requests])
    achieved = np.array([model.predict(a, load_kg=load)[1][0] for a, (_, load) in zip(activations, requests)])
    error = np.abs(achieved - requests[:, 0])
    worst = int(np.argmax(error))
    return {"requests": len(requests), "max_angle_error_deg": float(error.max()), "mean_angle_error_deg": float(error.mean()),
            "worst_request": {"angle_deg": float(requests[worst, 0]), "load_kg": float(requests[worst, 1]),
                              "achieved_deg": float(achieved[worst])},
            "angle_range_deg": list(model.angle_range), "max_load_kg": float(requests[:, 1].max())}
