"""Training of the networks (docs/theory.md, 7.5): k-fold cross-validation, best-by-validation, resumable.

Every fold trains a fresh net for ``epochs`` epochs (Adam, cosine learning rate, MSE loss on
the net's targets) and reports, per epoch, the training loss, the validation loss and the
validation MAE in mm of each coordinate (the paper's per-coordinate-net metric). The model kept
is the one with the lowest validation loss over all folds and epochs. After every epoch the
whole state (fold, epoch, weights, optimizer, best model, history) goes to ``checkpoint.pt``
by write-and-rename, so a killed training resumes at the next epoch.
"""

from __future__ import annotations

import copy
import os
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch

from persival.surrogate.networks import ACTIVATIONS, PaperNet, PodNet
from persival.surrogate.reduction import POD

__all__ = ["TrainingConfig", "build_net", "train", "choose_rank"]


@dataclass
class TrainingConfig:
    arch: str = "pod"  # "paper" or "pod"
    folds: int = 5
    epochs: int = 400  # per fold (the paper: 5 x 400)
    batch_size: int = 64
    learning_rate: float = 1e-3
    activation: str = "relu"  # chosen by validation on FE-arm SG data (docs/surrogates.md)
    seed: int = 0
    # POD net
    rank: int | None = None  # None: chosen by `energy`
    energy: float = 0.99999
    max_rank: int = 48
    hidden: list[int] = field(default_factory=lambda: [64, 64, 64])
    # paper net
    n_mid: int | None = None  # None: 700 / 2809 of the node count (docs/theory.md, 7.2)

    def __post_init__(self) -> None:
        if self.arch not in ("paper", "pod"):
            raise ValueError(f"arch must be 'paper' or 'pod', got {self.arch!r}")
        if self.activation not in ACTIVATIONS:
            raise ValueError(f"activation must be one of {sorted(ACTIVATIONS)}, got {self.activation!r}")
        for name in ("folds", "epochs", "batch_size"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")


def choose_rank(u: np.ndarray, config: TrainingConfig):
    """(rank, POD): the reduction of the displacements, the smallest rank keeping ``energy`` of
    their fluctuations, at most ``max_rank`` (or ``config.rank``)."""
    pod = POD(rank=config.rank, energy=config.energy, max_rank=None if config.rank is not None else config.max_rank).fit(u)
    return pod.rank, pod


def build_net(config: TrainingConfig, n_nodes: int, rank: int | None = None):
    if config.arch == "paper":
        return PaperNet(n_nodes, config.activation, config.n_mid)
    return PodNet(n_nodes, rank, tuple(config.hidden), config.activation)


def _folds(n: int, k: int, seed: int) -> list[tuple[np.ndarray, np.ndarray]]:
    order = np.random.default_rng(seed).permutation(n)
    if k == 1:  # no cross-validation: hold out a fifth
        cut = max(1, n // 5)
        return [(order[cut:], order[:cut])]
    parts = np.array_split(order, k)
    return [(np.concatenate(parts[:i] + parts[i + 1:]), parts[i]) for i in range(k)]


def _save_atomic(obj, path: Path) -> None:
    tmp = path.with_suffix(".tmp")
    torch.save(obj, tmp)
    os.replace(tmp, path)


def _epoch(net, optimizer, x, y, batch: int, generator) -> float:
    net.train()
    total = 0.0
    for rows in torch.randperm(len(x), generator=generator).to(x.device).split(batch):
        optimizer.zero_grad(set_to_none=True)
        loss = torch.mean((net.physical(net(x[rows])) - y[rows]) ** 2)
        loss.backward()
        optimizer.step()
        total += loss.item() * len(rows)
    return total / len(x)


@torch.no_grad()
def _validate(net, x, y, u, chunk: int = 128) -> tuple[float, list[float]]:
    net.eval()
    out = net(x)
    loss = float(torch.mean((net.physical(out) - y) ** 2))
    # the displacements in chunks: whole, four (n, 3N) temporaries a validation (75 MB each for
    # the main job's POD net) cost more than its training epoch
    total = torch.zeros(3, dtype=torch.float64, device=x.device)
    for rows in torch.arange(len(x), device=x.device).split(chunk):
        total += torch.abs(net.displacements(out[rows]) - u[rows]).sum(dim=(0, 1), dtype=torch.float64)
    mae = total.cpu() / (len(x) * u.shape[1])  # per coordinate, mm
    return loss, [float(v) for v in mae]


def resolve_device(device: str = "auto") -> torch.device:
    """``auto``: CUDA when a GPU is there, else the CPU; ``cpu`` / ``cuda`` as asked (a missing GPU is an error)."""
    if device not in ("auto", "cpu", "cuda"):
        raise ValueError(f"device must be auto, cpu or cuda, got {device!r}")
    if device == "cuda" and not torch.cuda.is_available():
        raise ValueError("--device cuda: no CUDA device here (torch.cuda.is_available() is False); use auto or cpu")
    return torch.device("cuda" if device == "cuda" or (device == "auto" and torch.cuda.is_available()) else "cpu")


def epoch_label(fold: int, folds: int, epoch: int, epochs: int) -> str:
    """"fold 2/5 epoch 12/100" (fold counted from 1): epochs restart every fold, so a running count
    over all folds ("epoch 202/500") would read like a blow-up when the validation loss jumps back."""
    return f"fold {fold + 1}/{folds} epoch {epoch}/{epochs}"


def train(dataset, config: TrainingConfig, out: str | Path, progress=None, device: str = "auto"):
    """Train on ``dataset`` (its displacements and elbow angles); returns (best net, history).
    ``device``: where the epochs run (:func:`resolve_device`); the result is a CPU net either way,
    and the device is not part of the configuration (a checkpoint resumes on another one).

    ``progress(done, total, val_loss, mae_xyz, where)`` after every epoch: ``done`` of ``total``
    epochs over all folds (for a progress bar), ``where`` = :func:`epoch_label`."""
    place = resolve_device(device)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    torch.manual_seed(config.seed)
    u = dataset.displacements.astype(np.float32)
    angles = np.asarray(dataset.elbow_angles, dtype=np.float64)
    rank, pod = choose_rank(u, config) if config.arch == "pod" else (None, None)
    checkpoint = out / "checkpoint.pt"
    state = _resume(checkpoint, config, dataset)
    template = build_net(config, u.shape[1], rank)
    template.fit_normalization(u, angles, pod)  # POD and scales from all training states, as deployed
    x = torch.as_tensor(dataset.activations, dtype=torch.float32, device=place)
    y = torch.as_tensor(template.targets(u, angles), dtype=torch.float32, device=place)
    ut = torch.as_tensor(u, device=place)
    if state is None:
        state = {"config": asdict(config), "digest": dataset.digest(), "fold": 0, "epoch": 0, "net": None,
                 "optimizer": None, "best": None, "history": [], "wall_time_s": 0.0}
    folds = _folds(len(x), config.folds, config.seed)
    generator = torch.Generator().manual_seed(config.seed)
    if state.get("generator") is not None:  # the batch order continues where it stopped
        generator.set_state(state["generator"])
    while state["fold"] < len(folds):
        data = (x, y, ut, *(torch.as_tensor(r, device=place) for r in folds[state["fold"]]))
        _train_fold(state, template, data, config, generator, checkpoint, progress, len(folds), place)
        state.update(fold=state["fold"] + 1, epoch=0, net=None, optimizer=None, schedule=None)
        _save_atomic(state, checkpoint)
    best = copy.deepcopy(template)
    best.load_state_dict(state["best"]["net"])
    best.eval()
    summary = {"best": {k: v for k, v in state["best"].items() if k != "net"}, "history": state["history"],
               "wall_time_s": state["wall_time_s"], "rank": rank, "config": asdict(config)}
    return best, summary


def _train_fold(state: dict, template, data, config: TrainingConfig, generator, checkpoint: Path, progress,
                n_folds: int, place) -> None:
    """The epochs of ``state``'s fold, from where the state stopped: after each one the best net so
    far and the whole state (net, optimizer, schedule, batch order) are saved, so a kill loses an
    epoch at most."""
    x, y, ut, train_rows, val_rows = data
    net = copy.deepcopy(template).to(place)
    optimizer = torch.optim.Adam(net.parameters(), lr=config.learning_rate)
    schedule = torch.optim.lr_scheduler.CosineAnnealingLR(optimizer, T_max=config.epochs, eta_min=config.learning_rate / 50)
    if state["net"] is not None:  # resuming inside this fold
        net.load_state_dict(state["net"])
        optimizer.load_state_dict(state["optimizer"])
        schedule.load_state_dict(state["schedule"])
    x_train, y_train = x[train_rows], y[train_rows]
    x_val, y_val, u_val = x[val_rows], y[val_rows], ut[val_rows]  # once a fold, not every epoch
    while state["epoch"] < config.epochs:
        t0 = time.perf_counter()
        train_loss = _epoch(net, optimizer, x_train, y_train, config.batch_size, generator)
        schedule.step()
        val_loss, mae = _validate(net, x_val, y_val, u_val)
        state["epoch"] += 1
        state["history"].append({"fold": state["fold"], "epoch": state["epoch"], "train_loss": train_loss,
                                 "val_loss": val_loss, "val_mae_mm": mae})
        if state["best"] is None or val_loss < state["best"]["val_loss"]:
            state["best"] = {"val_loss": val_loss, "fold": state["fold"], "epoch": state["epoch"],
                             "net": {k: v.detach().to("cpu", copy=True) for k, v in net.state_dict().items()}}
        state.update(net=net.state_dict(), optimizer=optimizer.state_dict(), schedule=schedule.state_dict(),
                     generator=generator.get_state(), wall_time_s=state["wall_time_s"] + time.perf_counter() - t0)
        _save_atomic(state, checkpoint)
        if progress is not None:
            progress(state["fold"] * config.epochs + state["epoch"], n_folds * config.epochs, val_loss, mae,
                     epoch_label(state["fold"], n_folds, state["epoch"], config.epochs))


def _resume(checkpoint: Path, config: TrainingConfig, dataset):
    if not checkpoint.exists():
        return None
    state = torch.load(checkpoint, weights_only=False)
    if state["config"] != asdict(config) or state["digest"] != dataset.digest():
        raise ValueError(f"{checkpoint} belongs to another training (config or data differ); "
                         "use another --out folder or delete it")
    return state
