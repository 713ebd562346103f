"""Train a small POD network (docs/theory.md, 7.3) and export it to ONNX (7.6).

The network learns the states of a level-1 campaign of the analytic stand-in directly (the main
job trains on 4000 sparse-grid states instead, `persival data` + `persival train`), for a few
epochs, then the export writes three ONNX tiers and metadata.json; onnxruntime runs the float32
tier as the server does (`persival.deploy.artifacts.DeployedModel`).

    python docs/examples/train_export.py [OUT]

Prints the POD rank, the file size and the largest difference between the ONNX model and the
network in PyTorch.
"""

import sys
import tempfile
from pathlib import Path

import numpy as np

from persival.campaign.design import Design
from persival.campaign.runner import INLINE, run_campaign
from persival.campaign.simulator import SimulatorSpec
from persival.deploy.artifacts import DeployedModel
from persival.deploy.export import export_model
from persival.surrogate.dataset import Dataset
from persival.surrogate.network_surrogate import NetworkSurrogate
from persival.surrogate.training import TrainingConfig

out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(tempfile.mkdtemp(prefix="persival-example-"))
run_campaign(out / "campaign.zarr", Design.sparse_grid(1), SimulatorSpec("analytic"), scheduler=INLINE, progress=False)
data = Dataset.from_store(out / "campaign.zarr")

net = NetworkSurrogate(TrainingConfig(arch="pod", folds=1, epochs=15)).fit(data, out / "pod")
export_model(net, out / "export")

alpha = np.random.default_rng(0).uniform(0.0, 1.0, (8, 5))
onnx_file = out / "export" / "deformation.onnx"
positions, angles = DeployedModel(out / "export").predict(alpha)  # onnxruntime, float32 tier: (8, nodes, 3) mm
print(f"POD rank {net.net.config['rank']}, {onnx_file.stat().st_size / 1e6:.2f} MB float32, "
      f"best validation loss {net.metadata['training']['best']['val_loss']:.3g} mm^2")
fit_error = np.linalg.norm(net.predict(data.activations) - data.positions, axis=2).mean()
print(f"mean node error on its training states: {fit_error:.2f} mm (15 epochs; the main job trains 5 x 100)")
print(f"ONNX vs PyTorch: {np.abs(positions - net.predict(alpha)).max():.2e} mm")
