"""The folders of an end-to-end run (``persival run --out OUT``) that the evaluation stage reads.

    OUT/campaign/campaign.zarr   SG design campaign          OUT/campaign/held_out.zarr  held-out states
    OUT/sg/                      SG of all muscles + angle   OUT/inverse/activation_model.json (+ .png)
    OUT/data/                    SG training data            OUT/networks/{paper,pod}/   trained networks
    OUT/export/                  ONNX + metadata.json        OUT/evaluate/, OUT/report/  this stage's output

Every input is checked here, once, with a message that names the missing file and the command
that makes it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["RunLayout", "LoadedRun", "load_run", "network_scopes"]

NETWORK_LABELS = ("paper", "pod")


@dataclass(frozen=True)
class RunLayout:
    root: Path

    @property
    def campaign(self) -> Path:
        return self.root / "campaign" / "campaign.zarr"

    @property
    def held_out(self) -> Path:
        return self.root / "campaign" / "held_out.zarr"

    @property
    def held_out_table_only(self) -> Path:
        """The held-out design through the FE arm's table-only path (FE-arm runs only)."""
        return self.root / "campaign" / "held_out_table_only.zarr"

    @property
    def sg(self) -> Path:
        return self.root / "sg"

    @property
    def activation_model(self) -> Path:
        return self.root / "inverse" / "activation_model.json"

    @property
    def data(self) -> Path:
        return self.root / "data"

    def network(self, label: str) -> Path:
        return self.root / "networks" / label

    @property
    def structured(self) -> Path:
        """The structured surrogate (FE-arm runs): the deployed model."""
        return self.root / "structured"

    @property
    def export(self) -> Path:
        """The deployed model's export (the viewer's and the server's default)."""
        return self.root / "export"

    @property
    def export_pod(self) -> Path:
        """The POD network's export, when the deployed model is the structured one."""
        return self.root / "export_pod"

    @property
    def evaluate(self) -> Path:
        return self.root / "evaluate"

    @property
    def report(self) -> Path:
        return self.root / "report"

    def networks(self) -> dict[str, Path]:
        return {label: self.network(label) for label in NETWORK_LABELS
                if (self.network(label) / "surrogate.json").is_file()}

    def check(self) -> None:
        """The inputs every table needs: the run folder, the SG and at least one network."""
        if not self.root.is_dir():
            raise FileNotFoundError(f"--run {self.root}: no such run folder (make one with `persival run --out DIR`)")
        if not (self.sg / "surrogate.json").is_file():
            raise FileNotFoundError(f"{self.sg}: no sparse-grid surrogate (surrogate.json) in this run folder; "
                                    "`persival run --out DIR` or `persival surrogate fit-sg` makes it")
        if not self.networks():
            raise FileNotFoundError(f"{self.root / 'networks'}: no trained network (paper/ or pod/ with surrogate.json); "
                                    "`persival train` makes one")


@dataclass
class LoadedRun:
    layout: RunLayout
    sg: object  # SparseGridSurrogate of all muscles
    networks: dict = field(default_factory=dict)  # label -> NetworkSurrogate
    activation_model: object | None = None
    structured: object | None = None  # StructuredSurrogate (FE-arm runs)

    @property
    def source_label(self) -> str:
        return str(self.sg.metadata.get("label", "unknown source"))


def load_run(out: str | Path) -> LoadedRun:
    from persival.surrogate.activation_model import AngleActivationModel
    from persival.surrogate.open import load_surrogate

    layout = RunLayout(Path(out))
    layout.check()
    sg = load_surrogate(layout.sg)
    if sg.kind != "sparse-grid":
        raise ValueError(f"{layout.sg} holds a {sg.kind} surrogate, not the sparse grid")
    networks = {label: load_surrogate(path) for label, path in layout.networks().items()}
    for label, net in networks.items():
        for name in net.surfaces.names:
            if name not in sg.surfaces.names:
                raise ValueError(f"network {label} predicts {name!r}, which the SG of {layout.sg} does not have")
            if net.surfaces.node_counts[net.surfaces.names.index(name)] != sg.surfaces.node_counts[sg.surfaces.names.index(name)]:
                raise ValueError(f"network {label} and the SG disagree on the node count of {name}: "
                                 "they were not made from the same model")
    model = AngleActivationModel.load(layout.activation_model) if layout.activation_model.is_file() else None
    structured = load_surrogate(layout.structured) if (layout.structured / "surrogate.json").is_file() else None
    return LoadedRun(layout, sg, networks, model, structured)


def network_scopes(net) -> list[str]:
    """What a network is compared on: the biceps alone (the paper) and all its muscles if several."""
    names = list(net.surfaces.names)
    scopes = ["all"] if len(names) > 1 else []
    if "biceps" in names:
        scopes.append("biceps")
    return scopes or names[:1]


def scope_slice(surfaces, scope: str) -> slice:
    """Node range of ``scope`` ("all" or one muscle) in ``surfaces``."""
    return slice(0, surfaces.n_nodes) if scope == "all" else surfaces.nodes_of(scope)
