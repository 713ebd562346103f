"""The deployed model against held-out FE states, measured on the exported file itself.

The figure a user asks first ("how far is what runs on the device from the FE model?"): the
float32 ONNX graph, run by onnxruntime on the activations of the held-out states, against their
FE surfaces and elbow angles. Per state MaxAE (worst node) and MAE (mean node error) over all
exported muscles; the summary keeps the worst MaxAE, the mean MAE and the worst angle error
(docs/theory.md 8.1, 8.3).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["held_out_accuracy"]


def held_out_accuracy(model_file: str | Path, dataset) -> dict:
    """``{"states", "max_ae_mm", "mae_mm", "max_angle_error_deg"}`` of the ONNX model at
    ``model_file`` on ``dataset`` (its surfaces in the model's node order)."""
    import onnxruntime as ort

    options = ort.SessionOptions()
    options.log_severity_level = 3  # the optional load input is an initializer too: ORT warns about it
    session = ort.InferenceSession(str(model_file), options, providers=["CPUExecutionProvider"])
    outputs = [o.name for o in session.get_outputs()]
    got = session.run(None, {"activations": dataset.activations.astype(np.float32)})
    positions = got[outputs.index("positions")].astype(float)
    if positions.shape != dataset.positions.shape:
        raise ValueError(f"the model answers {positions.shape[1]} nodes, the held-out states have {dataset.positions.shape[1]}")
    errors = np.linalg.norm(positions - dataset.positions, axis=2)
    result = {"states": int(len(dataset)), "max_ae_mm": float(errors.max()), "mae_mm": float(errors.mean(axis=1).mean())}
    if "elbow_angle_deg" in outputs:
        angles = got[outputs.index("elbow_angle_deg")][:, 0].astype(float)
        result["max_angle_error_deg"] = float(np.abs(angles - dataset.elbow_angles).max())
    return result
