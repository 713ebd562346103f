"""The motion-and-load model as an ONNX graph (activation_motion.onnx), checked against Python on
random motions over its range, with the metadata entry the deployed export records."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from persival.onnx_io import export_graph, onnx_session

__all__ = ["export_motion_onnx", "motion_probe"]

_ONNX_NAME = "activation_motion.onnx"


def motion_probe(model, n: int = 512, seed: int = 0) -> np.ndarray:
    """Random motion rows over the range (loads 0-5 kg, accelerations +-500 deg/s^2)."""
    rng = np.random.default_rng(seed)
    return np.column_stack([rng.uniform(*model.range_deg, n), rng.uniform(-200, 200, n),
                            rng.uniform(-500, 500, n), rng.uniform(0.0, 5.0, n)])


def export_motion_onnx(model, folder: str | Path) -> dict:
    """folder/activation_motion.onnx (opset 17): motion [b, 4] -> activations [b, 5],
    moment_deficit_Nmm [b, 1]; checked against Python (1e-6 on feasible rows)."""
    import torch

    path = Path(folder) / _ONNX_NAME
    example = torch.tensor([[60.0, 0.0, 0.0, 1.0], [90.0, 0.0, 0.0, 2.0]], dtype=torch.float32)
    export_graph(model.torch_module(), example, path, "motion", ["activations", "moment_deficit_Nmm"])
    probe = motion_probe(model).astype(np.float32)
    got = onnx_session(path).run(None, {"motion": probe})[0]
    ref, feasible = model.predict(probe.astype(np.float64))
    diff = float(np.abs(got - ref)[feasible].max())
    if diff > 1e-6:
        raise RuntimeError(f"activation_motion.onnx differs from Python by {diff:.2e} (tolerance 1e-6)")
    holdable = model.holdable_load_kg(np.arange(np.ceil(model.range_deg[0] / 10) * 10, model.range_deg[1] + 1e-9, 10.0))
    finite = holdable[np.isfinite(holdable)]  # max_load_kg: the most held anywhere (at 10-degree steps)
    return {"file": _ONNX_NAME, "input": "motion", "output": "activations", "outputs": ["activations", "moment_deficit_Nmm"],
            "input_columns": ["angle_deg", "velocity_deg_s", "acceleration_deg_s2", "load_kg"],
            "range_deg": list(model.range_deg), "max_load_kg": float(finite.max()) if len(finite) else 0.0,
            "holdable_load_kg_per_10_deg": [None if not np.isfinite(h) else round(float(h), 3) for h in holdable],
            "max_abs_diff_vs_python": diff, **model.params}
