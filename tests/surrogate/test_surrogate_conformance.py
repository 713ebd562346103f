"""Every surrogate kind answers the one interface of persival.surrogate.base the same way.

Fitted instances: the sparse grid and the two networks of the small real run (conftest), the
response-table and structured surrogates on the coarse FE tables fixture.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from persival.surrogate.base import MANIFEST, NotFittedError, Surrogate
from persival.surrogate.open import KINDS, load_surrogate

pytestmark = pytest.mark.slow  # a shared fixture of this module takes minutes (make test-fast skips it)

FIXTURE = Path(__file__).parents[1] / "data" / "response_table_coarse"


def _coarse_dataset():
    from persival.campaign.arm_simulator import muscle_surface
    from persival.campaign.simulator import SurfaceTopology
    from persival.model.arm.arm_model import ArmModel
    from persival.surrogate.dataset import Dataset, Surfaces

    arm = ArmModel(profile="coarse")
    names = ("biceps", "triceps")
    surfaces = Surfaces.from_topologies([SurfaceTopology(n, arm.mesh.points[muscle_surface(arm, n)[0]],
                                                         muscle_surface(arm, n)[1]) for n in names])
    return Dataset(np.zeros((0, 5)), np.zeros((0, surfaces.n_nodes, 3)), np.zeros(0), surfaces,
                   {"model_hash": arm.model_hash, "label": "FE arm (coarse)"})


@pytest.fixture(scope="module")
def surrogates(small_run) -> dict[str, Surrogate]:
    from persival.surrogate.structured.surrogate import StructuredSurrogate
    from persival.surrogate.table_surrogate import ResponseTableSurrogate

    found = {"sparse-grid": load_surrogate(small_run / "sg"), "network/pod": load_surrogate(small_run / "networks" / "pod"),
             "network/paper": load_surrogate(small_run / "networks" / "paper")}
    coarse = _coarse_dataset()
    found["response-table"] = ResponseTableSurrogate("coarse", tables=str(FIXTURE)).fit(coarse)
    found["structured"] = StructuredSurrogate("coarse", tables=str(FIXTURE)).fit(coarse)
    return found


def test_every_kind_is_covered(surrogates):
    assert {label.split("/")[0] for label in surrogates} == set(KINDS)


@pytest.mark.parametrize("label", ["sparse-grid", "network/pod", "network/paper", "response-table", "structured"])
def test_one_interface(label, surrogates, tmp_path):
    surrogate = surrogates[label]
    assert isinstance(surrogate, Surrogate) and surrogate.kind in KINDS
    alpha = np.array([[0.2, 0.1, 0.0, 0.3, 0.1], [0.6, 0.5, 0.4, 0.0, 0.0]])
    positions, angles = surrogate.predict_with_angle(alpha)
    assert positions.shape == (2, surrogate.surfaces.n_nodes, 3) and np.isfinite(positions).all()
    assert np.allclose(surrogate.predict(alpha), positions, rtol=0, atol=1e-4)
    assert np.allclose(surrogate.predict(alpha[0]), positions[:1], rtol=0, atol=1e-4)  # one vector: a batch of one
    if surrogate.has_angle:
        assert angles.shape == (2,) and np.allclose(surrogate.predict_angle(alpha), angles, rtol=0, atol=1e-4)
    else:
        assert angles is None
        with pytest.raises(ValueError, match="no elbow-angle output"):
            surrogate.predict_angle(alpha)
    with pytest.raises(ValueError, match="outside"):
        surrogate.predict([[0.5, 0.5, 0.5, 0.5, 1.5]])

    folder = surrogate.save(tmp_path / "saved")
    manifest = json.loads((folder / MANIFEST).read_text())
    assert manifest["kind"] == surrogate.kind and manifest["format_version"] == type(surrogate).format_version
    again = load_surrogate(folder)
    assert type(again) is type(surrogate)
    assert np.allclose(again.predict(alpha), positions, atol=1e-9)

    with pytest.raises(NotFittedError, match="call fit"):
        type(surrogate)().predict(alpha)
    manifest["format_version"] = 99
    (folder / MANIFEST).write_text(json.dumps(manifest))
    with pytest.raises(ValueError, match="format version 99"):
        load_surrogate(folder)
