"""The paper's prototype comparison (its Table "Prototyping"), on our biceps.

Four dense shapes from 5 activations to the N biceps nodes, one coordinate (x), as the paper:
T-shaped (the width changes as late as possible), rectangular (as early as possible),
triangular (linearly), each with 10 hidden layers, and the paper's exponential net (5 hidden
layers, docs/theory.md, 7.2). The first hidden layer of the 10-layer prototypes has the input's width: with
that rule the paper's three parameter counts (17,154; 71,056,494; 26,103,046 for N = 2809) come
out exactly.

Each prototype is trained briefly (``epochs``, default 10 as in the paper, on ``samples`` SG
training states: Adam, MSE of the standardized x displacement) and reported with its
in-training MAE in mm. The exponential shape is trained as the whole paper net (x, y and z
nets), so that its short-trained copy also feeds the hot-spot map after a short training.
"""

from __future__ import annotations

import time

import numpy as np
import torch
from torch import nn

from persival.evaluate import paper_values
from persival.evaluate.tables import make_table
from persival.surrogate.networks import PaperNet, mlp, paper_widths

__all__ = ["SHAPES", "prototype_widths", "dense_parameters", "prototype_table"]

SHAPES = ("T-shaped", "rectangular", "triangular", "exponential")


def prototype_widths(shape: str, n_in: int, n_out: int, n_hidden: int = 10, n_mid: int = 700) -> list[int]:
    """Hidden widths of a prototype (the exponential one: docs/theory.md, 7.2, 5 hidden layers through n_mid)."""
    if shape == "T-shaped":
        return [n_in] * n_hidden
    if shape == "rectangular":
        return [n_in] + [n_out] * (n_hidden - 1)
    if shape == "triangular":
        return [round(n_in + (n_out - n_in) * k / n_hidden) for k in range(n_hidden)]
    if shape == "exponential":
        return paper_widths(n_in, n_mid, n_out, 5)
    raise ValueError(f"unknown prototype shape {shape!r} (known: {', '.join(SHAPES)})")


def dense_parameters(widths: list[int]) -> int:
    """Weights and biases of a dense chain through ``widths`` (input and output included)."""
    return int(sum(a * b + b for a, b in zip(widths[:-1], widths[1:])))


def _fit(net: nn.Module, x: torch.Tensor, y: torch.Tensor, epochs: int, batch: int, lr: float, seed: int,
         max_seconds: float) -> int:
    """Adam on the MSE; stops early once ``max_seconds`` are spent. Returns the epochs done."""
    generator = torch.Generator().manual_seed(seed)
    optimizer = torch.optim.Adam(net.parameters(), lr=lr)
    net.train()
    t0, done = time.perf_counter(), 0
    while done < epochs and (done == 0 or time.perf_counter() - t0 < max_seconds):
        for rows in torch.randperm(len(x), generator=generator).split(batch):
            optimizer.zero_grad(set_to_none=True)
            loss = torch.mean((net(x[rows]) - y[rows]) ** 2)
            loss.backward()
            optimizer.step()
        done += 1
    net.eval()
    return done


def _train_x_prototype(widths, alpha, ux, activation, epochs, batch, lr, seed, max_seconds) -> tuple[float, int]:
    """In-training MAE (mm) of the x displacement after a short training, and the epochs done."""
    torch.manual_seed(seed)
    scale = float(ux.std() + 1e-12)
    net = mlp([5, *widths, ux.shape[1]], activation)
    x, y = torch.as_tensor(alpha, dtype=torch.float32), torch.as_tensor(ux / scale, dtype=torch.float32)
    done = _fit(net, x, y, epochs, batch, lr, seed, max_seconds)
    with torch.no_grad():
        return float(torch.mean(torch.abs(net(x) - y)) * scale), done


def _train_paper_net(n_nodes, n_mid, alpha, u, activation, epochs, batch, lr, seed, max_seconds):
    """The whole paper net (x, y, z nets) after a short training, and its in-training x MAE (mm)."""
    torch.manual_seed(seed)
    net = PaperNet(n_nodes, activation, n_mid)
    net.fit_normalization(u, np.zeros(len(u)))
    x = torch.as_tensor(alpha, dtype=torch.float32)
    y = torch.as_tensor(net.targets(u, np.zeros(len(u))), dtype=torch.float32)
    done = _fit(net, x, y, epochs, batch, lr, seed, max_seconds)
    with torch.no_grad():
        mae_x = float(torch.mean(torch.abs(net.displacements(net(x))[:, :, 0] - torch.as_tensor(u[:, :, 0]))))
    return net, mae_x, done


def prototype_table(data, n_mid: int | None = None, activation: str = "silu", samples: int = 64, epochs: int = 10,
                    batch: int = 16, learning_rate: float = 1e-3, seed: int = 0, max_seconds: float = 60.0,
                    progress=None) -> tuple[dict, PaperNet]:
    """``data``: the SG training data of the biceps (a Dataset). Returns the table and the short-trained paper net."""
    n = data.surfaces.n_nodes
    if n_mid is None or not 5 < n_mid < n:  # docs/theory.md, 7.2: 700 of 2809, the same ratio for other meshes
        n_mid = max(6, round(n * 700 / 2809))
    rows_used = np.random.default_rng(seed).permutation(len(data))[:samples]
    alpha = data.activations[rows_used]
    u = data.displacements[rows_used].astype(np.float32)
    rows, short_net = [], None
    for k, shape in enumerate(SHAPES):
        widths = prototype_widths(shape, 5, n, 10, n_mid)
        t0 = time.perf_counter()
        if shape == "exponential":
            short_net, mae, done = _train_paper_net(n, n_mid, alpha, u, activation, epochs, batch, learning_rate, seed,
                                                    max_seconds)
        else:
            mae, done = _train_x_prototype(widths, alpha, u[:, :, 0], activation, epochs, batch, learning_rate, seed,
                                           max_seconds)
        rows.append({"shape": shape, "hidden_layers": len(widths), "widths": " ".join(map(str, widths)),
                     "parameters": dense_parameters([5, *widths, n]), "parameters_at_2809": dense_parameters(
                         [5, *prototype_widths(shape, 5, 2809, 10, 700), 2809]),
                     "mae_mm": mae, "epochs": done, "train_s": time.perf_counter() - t0})
        if progress is not None:
            progress(k + 1, len(SHAPES), shape)
    columns = [("shape", "shape", "{}"), ("hidden_layers", "hidden layers", "{:d}"), ("widths", "hidden widths", "{}"),
               ("parameters", f"parameters (N = {n})", "{:,d}"), ("parameters_at_2809", "parameters (N = 2809)", "{:,d}"),
               ("epochs", "epochs", "{:d}"), ("mae_mm", "in-training MAE mm", "{:.3f}"), ("train_s", "training s", "{:.1f}")]
    notes = [f"x coordinate of the biceps ({n} nodes), {len(alpha)} SG training states, {epochs} epochs, batch {batch}, "
             f"Adam lr {learning_rate}, {activation}; trained on standardized displacements (the paper's prototypes "
             "learned coordinates, hence its 430 mm for the T shape).",
             "The exponential row is the paper's final net (5 hidden layers, n_mid "
             f"{n_mid}); its x, y and z nets were trained together, the MAE is the x net's. The paper gives no "
             "prototype figure for it."]
    paper = [{**r, "parameters_at_2809": r["parameters"], "parameters": None, "epochs": 10} for r in paper_values.PROTOTYPES]
    notes += [f"{r['shape']}: stopped after {r['epochs']} epochs by the {max_seconds:.0f} s budget"
              for r in rows if r["epochs"] < epochs]
    table = make_table("prototypes", "Prototype comparison (network shapes, short training)",
                       f"Parameters and in-training MAE of four dense shapes 5 -> {n} on {data.source.get('label', 'SG data')}.",
                       columns, rows, paper, notes,
                       config={"samples": len(alpha), "epochs": epochs, "batch": batch, "learning_rate": learning_rate,
                               "activation": activation, "n_mid": n_mid, "seed": seed, "max_seconds": max_seconds})
    return table, short_net
