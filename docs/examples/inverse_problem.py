"""Least-effort activations for elbow angles (docs/theory.md, section 6) on a sparse grid.

alpha_opt(Theta) = argmin |Theta - theta(alpha)| + 0.05 sum(alpha) over [0, 1]^5, with theta the
sparse grid's elbow angle. The grid is fitted to a level-1 campaign of the analytic stand-in.

    python docs/examples/inverse_problem.py [OUT]

Prints the activations per target and the largest distance of an achieved angle from its target.
"""

import sys
import tempfile
from pathlib import Path

from persival.campaign.design import Design
from persival.campaign.runner import INLINE, run_campaign
from persival.campaign.simulator import SimulatorSpec
from persival.surrogate.inverse import InverseProblem
from persival.surrogate.sparse_grid_surrogate import SparseGridSurrogate
from persival.vocabulary import ABBREVIATIONS

out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(tempfile.mkdtemp(prefix="persival-example-"))
run_campaign(out / "campaign.zarr", Design.sparse_grid(1), SimulatorSpec("analytic"), scheduler=INLINE, progress=False)
sg = SparseGridSurrogate(muscles="biceps").fit(out / "campaign.zarr")

problem = InverseProblem(sg)
low, high = problem.reachable_range()
solution = problem.solve([30.0, 60.0, 90.0, 120.0])
print(f"reachable: {low:.1f} to {high:.1f} deg")
print("target  " + "  ".join(ABBREVIATIONS) + "  achieved")
for row in solution.rows():
    print(f"{row['target_deg']:6.1f}  " + "  ".join(f"{a:.2f}" for a in row["activations"]) + f"  {row['achieved_deg']:.3f}")
print(f"largest angle miss: {abs(solution.achieved_deg - solution.target_deg).max():.2e} deg")
