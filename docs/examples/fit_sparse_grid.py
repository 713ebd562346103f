"""Fit a B-spline sparse grid (docs/theory.md, section 5) to a campaign and test it on new states.

The campaign runs the analytic stand-in (a closed-form arm: seconds, no FE solve) on the 243
points of the level-1 sparse grid; 20 random activation vectors that the grid never saw are the
held-out test (docs/theory.md, 8.3). With `SimulatorSpec("arm")` the same code runs the FE arm.

    python docs/examples/fit_sparse_grid.py [OUT]

Prints the sparse grid's worst node error (MaxAE) over the held-out states.
"""

import sys
import tempfile
from pathlib import Path

import numpy as np

from persival.campaign.design import Design
from persival.campaign.runner import INLINE, run_campaign
from persival.campaign.simulator import SimulatorSpec
from persival.evaluate.metrics import state_errors
from persival.surrogate.dataset import Dataset
from persival.surrogate.sparse_grid_surrogate import SparseGridSurrogate

out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(tempfile.mkdtemp(prefix="persival-example-"))
simulator = SimulatorSpec("analytic")
run_campaign(out / "campaign.zarr", Design.sparse_grid(1), simulator, scheduler=INLINE, progress=False)
run_campaign(out / "held_out.zarr", Design.random(20, seed=1), simulator, scheduler=INLINE, progress=False)

sg = SparseGridSurrogate(muscles=None).fit(out / "campaign.zarr")  # every muscle + the elbow angle
sg.save(out / "sg")
test = Dataset.from_store(out / "held_out.zarr")
errors = state_errors(sg.predict(test.activations), test.positions, test.displacements)
angle_error = np.abs(sg.predict_angle(test.activations) - test.elbow_angles)
print(f"{sg.grid.n_points} grid points, {sg.surfaces.n_nodes} surface nodes")
print(f"mean MAE {errors['MAE_mm'].mean():.3f} mm, worst angle error {angle_error.max():.2f} deg")
print(f"worst MaxAE: {errors['MaxAE_mm'].max():.3f} mm")
