"""A trained network as a surrogate (the common interface of :mod:`persival.surrogate.base`).

``NetworkSurrogate(config).fit(dataset)`` trains (:func:`persival.surrogate.training.train`),
keeps the best net and answers ``predict(alpha) -> positions (n, N, 3)`` through the same
deployable graph that the ONNX export writes (reference coordinates folded into the last bias),
so Python and the exported model compute the same thing.
"""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch

from persival.surrogate.base import Surrogate
from persival.surrogate.dataset import Dataset, Surfaces
from persival.surrogate.training import TrainingConfig, build_net, train

__all__ = ["NetworkSurrogate"]


class NetworkSurrogate(Surrogate):
    kind = "network"

    def __init__(self, config: TrainingConfig | None = None) -> None:
        self.config = config or TrainingConfig()
        self.net = None
        self.surfaces: Surfaces | None = None
        self.metadata: dict = {}
        self.history: list[dict] = []
        self._graph = None

    def fit(self, dataset: Dataset, out: str | Path | None = None, progress=None, device: str = "auto") -> NetworkSurrogate:
        """Train on ``dataset``; ``out`` holds the checkpoint (resume) and then the saved surrogate;
        ``device``: auto (CUDA when present), cpu or cuda."""
        import tempfile

        work = Path(out) if out is not None else Path(tempfile.mkdtemp(prefix="persival-train-"))
        self.net, summary = train(dataset, self.config, work, progress, device)
        self.surfaces = dataset.surfaces
        self.history = summary.pop("history")
        self.metadata = {"kind": self.kind, "arch": self.config.arch, "net": self.net.config,
                         "training": {**summary, "dataset_sha256": dataset.digest(), "samples": len(dataset)},
                         "source": dataset.source, "muscles": list(dataset.surfaces.names),
                         # weights of the deployed graph: the POD basis is a buffer there, but it is weights
                         "parameters": int(sum(t.numel() for t in [*self.deployable().parameters(),
                                                                    *self.deployable().buffers()]))}
        if out is not None:
            self.save(work)
        return self

    def deployable(self) -> torch.nn.Module:
        """alpha (b, 5) -> positions (b, N, 3) mm [, elbow angle (b, 1)]: the graph to export."""
        self._require_fit()
        if self._graph is None:
            self._graph = self.net.deployable(self.surfaces.reference_points).eval()
        return self._graph

    @property
    def fitted(self) -> bool:
        return self.net is not None

    @property
    def has_angle(self) -> bool:
        return self.config.arch == "pod"

    @torch.no_grad()
    def _run(self, activations):
        from persival.vocabulary import check_activations

        x = torch.as_tensor(check_activations(activations), dtype=torch.float32)
        return self.deployable()(x)

    def predict_with_angle(self, activations) -> tuple[np.ndarray, np.ndarray | None]:
        out = self._run(activations)
        if not isinstance(out, tuple):
            return out.numpy().astype(np.float64), None
        return out[0].numpy().astype(np.float64), out[1][:, 0].numpy().astype(np.float64)

    @property
    def n_nodes(self) -> int:
        return self.surfaces.n_nodes

    def save(self, path: str | Path) -> Path:
        path = Path(path)
        path.mkdir(parents=True, exist_ok=True)
        torch.save({"state": self.net.state_dict(), "config": asdict(self.config), "net": self.net.config},
                   path / "network.pt")
        self.surfaces.save(path / "surfaces.npz")
        (path / "history.json").write_text(json.dumps(self.history))
        self.write_manifest(path, self.metadata)
        return path

    @classmethod
    def load(cls, path: str | Path) -> NetworkSurrogate:
        path = Path(path)
        blob = torch.load(path / "network.pt", weights_only=False)
        surrogate = cls(TrainingConfig(**blob["config"]))
        net = build_net(surrogate.config, blob["net"]["n_nodes"], blob["net"].get("rank"))
        net.load_state_dict(blob["state"])
        surrogate.net = net.eval()
        surrogate.surfaces = Surfaces.load(path / "surfaces.npz")
        surrogate.metadata = cls.read_manifest(path)
        history = path / "history.json"
        surrogate.history = json.loads(history.read_text()) if history.exists() else []
        return surrogate
