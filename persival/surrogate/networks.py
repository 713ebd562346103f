"""The network architectures (docs/theory.md, 7.2 and 7.3): the paper's exponential net and the POD net.

Both map activations (b, 5) to *normalized* targets while training, and both can be folded
into one plain graph ``alpha -> positions (b, N, 3) mm [, elbow angle (b, 1) deg]`` for
deployment (:meth:`deployable`), with every normalization and the reference coordinates X
moved into the last layer's weights and bias, as the paper does.

- :class:`PaperNet`: one dense net per coordinate (x, y, z), 5 -> 5 hidden layers -> N, widths
  ``w(s) = a e^(b s) + c`` (:func:`paper_widths`), trained on displacements u = x - X.
- :class:`PodNet` (beyond the paper): u ~ u_mean + Phi c with Phi the leading POD modes of the
  training displacements; a small net alpha -> (c, elbow angle); Phi is the last linear layer.
"""

from __future__ import annotations

import math

import numpy as np
import torch
from torch import nn

from persival.surrogate.reduction import POD

__all__ = ["ACTIVATIONS", "mlp", "paper_widths", "PaperNet", "PodNet", "count_parameters"]

PAPER_NODES, PAPER_MID = 2809, 700  # docs/theory.md, 7.2: the paper's output and middle widths
ACTIVATIONS = {"relu": nn.ReLU, "tanh": nn.Tanh, "silu": nn.SiLU, "elu": nn.ELU}


def paper_widths(n_in: int, n_mid: int, n_out: int, n_hidden: int = 5) -> list[int]:
    """docs/theory.md, 7.2: w(s) = a e^(b s) + c through w(0) = n_in, w(1/2) = n_mid, w(1) = n_out, at s = n/(n_hidden+1)."""
    if not n_in < n_mid < n_out:
        raise ValueError(f"need n_in < n_mid < n_out, got {n_in}, {n_mid}, {n_out}")
    q = (n_out - n_mid) / (n_mid - n_in)
    a = (n_mid - n_in) / (q - 1.0) if q != 1.0 else None
    if a is None:  # q = 1: the exponential degenerates to a straight line
        return [round(n_in + (n_out - n_in) * n / (n_hidden + 1)) for n in range(1, n_hidden + 1)]
    b, c = 2.0 * math.log(q), n_in - a
    return [round(a * math.exp(b * n / (n_hidden + 1)) + c) for n in range(1, n_hidden + 1)]


def mlp(widths: list[int], activation: str) -> nn.Sequential:
    """Dense layers of the given widths with the activation between them (none after the last)."""
    layers: list[nn.Module] = []
    for k in range(len(widths) - 1):
        layers.append(nn.Linear(widths[k], widths[k + 1]))
        if k < len(widths) - 2:
            layers.append(ACTIVATIONS[activation]())
    return nn.Sequential(*layers)


def count_parameters(module: nn.Module) -> int:
    return sum(p.numel() for p in module.parameters())


class PaperNet(nn.Module):
    """Three per-coordinate nets; forward gives normalized displacements (b, 3, N)."""

    def __init__(self, n_nodes: int, activation: str = "relu", n_mid: int | None = None, n_hidden: int = 5) -> None:
        super().__init__()
        # docs/theory.md, 7.2: n_mid = 700 for the paper's 2809 nodes; other meshes keep that ratio
        n_mid = n_mid if n_mid is not None else max(6, round(n_nodes * PAPER_MID / PAPER_NODES))
        self.config = {"arch": "paper", "n_nodes": n_nodes, "activation": activation, "n_mid": n_mid,
                       "n_hidden": n_hidden}
        self.widths = paper_widths(5, n_mid, n_nodes, n_hidden)
        self.nets = nn.ModuleList([mlp([5, *self.widths, n_nodes], activation) for _ in range(3)])
        self.register_buffer("scale", torch.ones(()))  # displacement scale (mm) of the training set

    def forward(self, alpha: torch.Tensor) -> torch.Tensor:
        return torch.stack([net(alpha) for net in self.nets], dim=1)

    def fit_normalization(self, u: np.ndarray, angles: np.ndarray, pod=None) -> None:
        self.scale.fill_(float(np.std(u) + 1e-12))

    def targets(self, u: np.ndarray, angles: np.ndarray) -> np.ndarray:
        """What the net is trained to output: displacements / scale, per coordinate (n, 3, N)."""
        return np.ascontiguousarray(np.transpose(u, (0, 2, 1)) / float(self.scale))

    def physical(self, out: torch.Tensor) -> torch.Tensor:
        return out  # the paper's loss: MSE of (scaled) displacements

    def displacements(self, out: torch.Tensor) -> torch.Tensor:
        return out.transpose(1, 2) * self.scale

    def deployable(self, reference: np.ndarray) -> nn.Module:
        """The combined graph: one input, the three last layers concatenated, X in the bias."""
        return _CombinedPaperNet(self, reference, float(self.scale))


class _CombinedPaperNet(nn.Module):
    def __init__(self, net: PaperNet, reference: np.ndarray, scale: float) -> None:
        super().__init__()
        self.hidden = nn.ModuleList([n[:-1] for n in net.nets])
        last = [n[-1] for n in net.nets]
        x = torch.as_tensor(np.asarray(reference, dtype=np.float32))  # (N, 3)
        self.out = nn.ModuleList()
        for k, layer in enumerate(last):  # u = scale * (W h + b); x = X + u
            lin = nn.Linear(layer.in_features, layer.out_features)
            with torch.no_grad():
                lin.weight.copy_(layer.weight * scale)
                lin.bias.copy_(layer.bias * scale + x[:, k])
            self.out.append(lin)

    def forward(self, alpha):
        coords = [out(h(alpha)) for h, out in zip(self.hidden, self.out)]
        return torch.stack(coords, dim=2)  # (b, N, 3): interleaved xyz


class PodNet(nn.Module):
    """alpha -> normalized (POD coefficients, elbow angle); the basis is applied outside training."""

    def __init__(self, n_nodes: int, rank: int, hidden=(64, 64, 64), activation: str = "relu") -> None:
        super().__init__()
        self.config = {"arch": "pod", "n_nodes": n_nodes, "rank": rank, "hidden": list(hidden),
                       "activation": activation}
        self.net = mlp([5, *hidden, rank + 1], activation)
        self.register_buffer("mean", torch.zeros(3 * n_nodes))
        self.register_buffer("basis", torch.zeros(rank, 3 * n_nodes))  # orthonormal rows
        self.register_buffer("coef_scale", torch.ones(rank))  # std of each coefficient
        self.register_buffer("angle_shift", torch.zeros(1))
        self.register_buffer("angle_scale", torch.ones(1))

    def fit_normalization(self, u: np.ndarray, angles: np.ndarray, pod=None) -> None:
        """The POD of the training displacements (or ``pod``, a fitted :class:`POD`) and the scales
        of the coefficients and the angle."""
        pod = pod if pod is not None else POD(rank=self.config["rank"]).fit(u)
        mean, basis = pod.mean, pod.modes[: self.config["rank"]]
        coefficients = (u.reshape(len(u), -1) - mean) @ basis.T
        with torch.no_grad():
            self.mean.copy_(torch.as_tensor(mean, dtype=torch.float32))
            self.basis.copy_(torch.as_tensor(basis, dtype=torch.float32))
            self.coef_scale.copy_(torch.as_tensor(np.std(coefficients, axis=0) + 1e-12, dtype=torch.float32))
            self.angle_shift.fill_(float(np.mean(angles)))
            self.angle_scale.fill_(float(np.std(angles) + 1e-12))

    def targets(self, u: np.ndarray, angles: np.ndarray) -> np.ndarray:
        """(POD coefficients in mm, elbow angle in deg) per sample, (n, r + 1)."""
        coefficients = (u.reshape(len(u), -1) - self.mean.double().numpy()) @ self.basis.double().numpy().T
        return np.column_stack([coefficients, angles])

    def physical(self, out: torch.Tensor) -> torch.Tensor:
        """Net output in the targets' units. The basis is orthonormal, so the squared coefficient
        error is the squared node error of the projected displacements: the loss is in mm^2
        (and deg^2 for the angle) without a (b, 3N) product per step."""
        scale = torch.cat([self.coef_scale, self.angle_scale])
        shift = torch.cat([torch.zeros_like(self.coef_scale), self.angle_shift])
        return out * scale + shift

    def displacements(self, out: torch.Tensor) -> torch.Tensor:
        coef = self.physical(out)[:, :-1]
        return (self.mean + coef @ self.basis).reshape(len(out), -1, 3)

    def forward(self, alpha):
        return self.net(alpha)

    def deployable(self, reference: np.ndarray) -> nn.Module:
        return _DeployedPodNet(self, reference)


class _DeployedPodNet(nn.Module):
    """alpha -> hidden -> (POD coefficients in mm, angle) -> positions: the basis is the last layer.

    Kept as two layers (h -> r -> 3N) rather than folded into one (h -> 3N): with r below the
    hidden width the factored form is the smaller and faster one.
    """

    def __init__(self, net: PodNet, reference: np.ndarray) -> None:
        super().__init__()
        self.hidden = net.net[:-1]
        head = net.net[-1]
        rank = net.config["rank"]
        self.n_nodes = net.config["n_nodes"]
        x = torch.as_tensor(np.asarray(reference, dtype=np.float32)).reshape(-1)
        self.coefficients = nn.Linear(head.in_features, rank + 1)
        # the basis as an explicit MatMul + Add (not one Gemm): the float16 tier keeps the Add,
        # whose bias X + mean is hundreds of mm, in float32 (float16 resolves 0.25 mm there)
        self.register_buffer("basis", net.basis.clone())  # (r, 3N)
        self.register_buffer("offset", x + net.mean)  # (3N,)
        scale = torch.cat([net.coef_scale, net.angle_scale])
        shift = torch.cat([torch.zeros(rank), net.angle_shift])
        with torch.no_grad():
            self.coefficients.weight.copy_(head.weight * scale[:, None])
            self.coefficients.bias.copy_(head.bias * scale + shift)

    def forward(self, alpha):
        c = self.coefficients(self.hidden(alpha))
        u = torch.matmul(c[:, :-1], self.basis) + self.offset
        return u.reshape(-1, self.n_nodes, 3), c[:, -1:]
