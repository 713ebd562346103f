"""Serve an exported model over HTTP and ask it for one state (docs/deployment.md, docs/viewer.md).

A small export is made first (a POD network trained for a few epochs on 40 states of the analytic
stand-in); `persival serve --artifacts DIR` serves the same folder with uvicorn, the web viewer
included. Here the FastAPI app runs in-process under its test client: the same routes, no port.

    python docs/examples/serve.py [OUT]

Prints the server's health reply, the elbow angle of one predicted state, and how far it lies
from the same network run in Python.
"""

import sys
import tempfile
from pathlib import Path

from fastapi.testclient import TestClient

from persival.campaign.design import Design
from persival.campaign.runner import INLINE, run_campaign
from persival.campaign.simulator import SimulatorSpec
from persival.deploy.export import export_model
from persival.deploy.server import create_app
from persival.surrogate.dataset import Dataset
from persival.surrogate.network_surrogate import NetworkSurrogate
from persival.surrogate.training import TrainingConfig

out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(tempfile.mkdtemp(prefix="persival-example-"))
run_campaign(out / "states.zarr", Design.random(40, seed=0), SimulatorSpec("analytic"), scheduler=INLINE, progress=False)
net = NetworkSurrogate(TrainingConfig(arch="pod", folds=1, epochs=5)).fit(Dataset.from_store(out / "states.zarr"))
export_model(net, out / "export")

with TestClient(create_app(out / "export")) as client:
    health = client.get("/health").json()
    reply = client.post("/api/predict", json={"activations": [0.5, 0.0, 0.0, 0.0, 0.0]}).json()
print(f"health: {health['status']}, {health['n_nodes']} nodes, tiers {', '.join(health['tiers'])}")
print(f"biceps nodes in the reply: {len(reply['muscles']['biceps'])}")
served, python = reply["elbow_angle_deg"], net.predict_angle([[0.5, 0.0, 0.0, 0.0, 0.0]])[0]
print(f"elbow angle: {served:.2f} deg served, {python:.2f} deg in Python")
print(f"server vs Python: {abs(served - python):.1e} deg")
