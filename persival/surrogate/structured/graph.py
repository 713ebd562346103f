"""The structured surrogate as one PyTorch graph, exportable to ONNX with its root search inside.

``activations`` (b, 5) and ``load_kg`` (b, 1) -> ``positions`` (b, N, 3) mm and
``elbow_angle_deg`` (b, 1). The same arithmetic as the numpy reference
(:class:`~persival.surrogate.structured.moment_model.MomentModel`, :class:`MuscleShape`), written
with dense products, comparisons and one-hot selections only (no gathers, no loops that depend on
the data), and with few operators, since at batch 1 each costs about a microsecond: a sign scan
brackets the stable root nearest the hanging arm, the bracket's table interval gives the
balance as one cubic, and regula falsi plus a fixed number of Newton steps on that cubic
converge it; every muscle's surface is then read at that angle (docs/theory.md
7.7).
"""

from __future__ import annotations

import numpy as np
import torch

from persival.surrogate.structured.cardinal import torch_weights
from persival.surrogate.structured.moment_model import NEWTON_STEPS

__all__ = ["StructuredGraph"]

_FAR = 1e9  # distance of a scan interval without a stable root


class StructuredGraph(torch.nn.Module):
    def __init__(self, moments, shapes, dtype=torch.float32, mode_dtype=None):
        """``mode_dtype``: storage of the POD modes (default: float16 beside float32 arithmetic,
        which halves the file and moves a surface by at most about 0.02 mm; the mean surfaces stay
        in ``dtype``: in float16 they would move by 0.1 mm). The runtime casts them back once,
        when it loads the graph (constant folding)."""
        super().__init__()
        as_t = lambda a: torch.as_tensor(np.asarray(a), dtype=dtype)  # noqa: E731
        basis = moments.theta_basis
        n_t2, n_a = moments.data.shape[1], len(moments.levels)
        n_int = len(basis.breaks) - 1
        self.n_levels, self.n_t2 = n_a, n_t2
        self.activation_tables = moments.activation_basis.torch_tables(dtype)
        self.moment_rows = as_t(np.transpose(moments.data, (0, 2, 1)).reshape(5 * n_a, n_t2))
        self.external_row, self.load_row = as_t(moments.external_data[None]), as_t(moments.load_data[None])
        # the sign scan
        grid = moments.scan_deg
        self.scan_weights = as_t(moments.scan_weights.T)  # (2 n_t, n_g)
        self.scan_lo, self.scan_hi = as_t(grid[:-1, None]), as_t(grid[1:, None])
        self.scan_distance = as_t(np.abs(grid[:-1] - moments.near_deg))
        self.scan_index = as_t(np.arange(len(grid) - 1))
        self.scan_interval = as_t(np.eye(n_int)[moments.scan_interval])  # (n_g - 1, n_int) one-hot
        # per table interval: its start and the power-form rows (t^3, t^2, t, 1) of the theta weights
        self.interval_start = as_t(basis.breaks[:-1, None])
        self.interval_rows = as_t(np.transpose(basis.coefficients, (1, 0, 2)).reshape(n_int, 4 * n_t2))
        self.weight_rows = as_t(basis.coefficients.reshape(4 * n_int, n_t2))  # power-major, as torch_weights
        # shapes: every muscle's coefficient data side by side, (2 n_t, n_a * R), each followed by a
        # constant coefficient 1 (value 1, slope 0: the weights reproduce constants) that carries the
        # muscle's mean surface and the homogeneous coordinate of its affine turn (below)
        one = np.zeros((n_t2, n_a, 1))
        one[: n_t2 // 2] = 1.0
        data = np.concatenate([np.concatenate([s.coefficient_data, one], axis=2) for s in shapes], axis=2)
        self.coefficient_rows = as_t(data.reshape(n_t2, -1))
        counts = [s.modes.shape[0] + 1 for s in shapes]
        expand = np.zeros((5, sum(counts)))
        ends = np.cumsum(counts)
        for s, end, r in zip(shapes, ends, counts):
            expand[s.muscle_index, end - r:end] = 1.0
        self.expand = as_t(expand)  # (5, R): which muscle's activation weighs each coefficient
        self.slices = [(int(end - r), int(end)) for end, r in zip(ends, counts)]
        self.n_coefficients = int(sum(counts))
        self.node_counts = [s.n_nodes for s in shapes]
        if mode_dtype is None:
            mode_dtype = torch.float16 if dtype == torch.float32 else dtype
        # buffers, not constants: the tracer then keeps the float16 storage and the cast in the graph
        for i, s in enumerate(shapes):
            self.register_buffer(f"modes_{i}", torch.as_tensor(s.modes, dtype=mode_dtype))
        self.n_muscles = len(shapes)
        for i, s in enumerate(shapes):  # float32 storage: the mean surfaces are hundreds of mm
            self.register_buffer(f"means_{i}", torch.as_tensor(s.mean.reshape(-1, 3) - s.origin, dtype=dtype))
        # the affine turn of every muscle, [Q(theta)^T; O] (4 x 3) in homogeneous coordinates, as
        # Hermite data: (2 n_t, 12 n_m) (O's slopes are 0)
        affine = []
        for s in shapes:
            q = s.rotation_data.reshape(-1, 3, 3).transpose(0, 2, 1)
            o = np.zeros((len(q), 1, 3))
            o[: len(q) // 2] = s.origin
            affine.append(np.concatenate([q, o], axis=1).reshape(len(q), 12))
        self.affine_rows = as_t(np.concatenate(affine, axis=1))

    def _surface_rows(self, i: int, dtype) -> torch.Tensor:
        """Muscle i's (r + 1, 4 n) rows: its modes and mean surface in homogeneous coordinates
        (x, y, z, 0) and (x, y, z, 1). Built from the stored tensors by operators on constants only,
        which the runtime folds once when it loads the graph."""
        modes, mean = getattr(self, f"modes_{i}").to(dtype), getattr(self, f"means_{i}")
        r, n = modes.shape[0], mean.shape[0]
        modes = torch.nn.functional.pad(modes.reshape(r, n, 3), (0, 1)).reshape(r, 4 * n)  # pads, not stored zeros
        mean = torch.nn.functional.pad(mean, (0, 1), value=1.0).reshape(1, 4 * n)
        return torch.cat([modes, mean], dim=0)

    def _bracket(self, g):
        """One-hot (b, n_g - 1) of the scan interval holding the stable root nearest the hanging
        arm; without one, the first interval (extends everywhere) or the last (flexes everywhere)."""
        down = (g[:, :-1] > 0) & (g[:, 1:] <= 0)
        fallback = _FAR + torch.where(g[:, :1] > 0, -self.scan_index, self.scan_index)
        k = torch.argmin(torch.where(down, self.scan_distance, fallback), dim=1, keepdim=True)
        return (self.scan_index == k).to(g.dtype)

    def _angle(self, profile):
        """Elbow angle (b, 1) and the one-hot (b, n_int) of its table interval."""
        g = profile @ self.scan_weights
        pick = self._bracket(g)
        lo, hi = pick @ self.scan_lo, pick @ self.scan_hi
        g_lo = (pick * g[:, :-1]).sum(1, keepdim=True)
        g_hi = (pick * g[:, 1:]).sum(1, keepdim=True)
        interval = pick @ self.scan_interval
        start = interval @ self.interval_start
        a3, a2, a1, a0 = ((interval @ self.interval_rows).reshape(-1, 4, self.n_t2) * profile[:, None, :]).sum(2).split(1, 1)
        falls = g_lo > g_hi
        theta = torch.where(falls, lo + (hi - lo) * g_lo / torch.where(falls, g_lo - g_hi, 1.0), torch.where(g_lo > 0, hi, lo))
        b3, b2 = 3 * a3, 2 * a2
        for _ in range(NEWTON_STEPS):
            t = theta - start
            value, slope = ((a3 * t + a2) * t + a1) * t + a0, (b3 * t + b2) * t + a1
            descends = slope < 0
            step = torch.where(descends, value / torch.where(descends, slope, -1.0), 0.0)
            theta = torch.minimum(torch.maximum(theta - step, lo), hi)
        return theta, interval, theta - start

    def forward(self, activations, load_kg):
        # every reshape keeps the batch as -1 and names the other sizes: no Shape operators in the graph
        act_w = torch_weights(self.activation_tables, activations.reshape(-1, 1))  # (5 b, n_a)
        profile = act_w.reshape(-1, 5 * self.n_levels) @ self.moment_rows + self.external_row + load_kg * self.load_row
        theta, interval, t = self._angle(profile)
        t2 = t * t
        w = torch.cat([interval * (t2 * t), interval * t2, interval * t, interval], dim=1) @ self.weight_rows  # (b, 2 n_t)
        by_level = act_w.reshape(-1, 5, self.n_levels).transpose(1, 2) @ self.expand  # (b, n_a, R)
        coefficients = ((w @ self.coefficient_rows).reshape(-1, self.n_levels, self.n_coefficients) * by_level).sum(1)
        affine = (w @ self.affine_rows).reshape(-1, self.n_muscles, 4, 3)
        surfaces = [(coefficients[:, lo:hi] @ self._surface_rows(i, w.dtype)).reshape(-1, n, 4) @ affine[:, i]
                    for i, ((lo, hi), n) in enumerate(zip(self.slices, self.node_counts))]
        return torch.cat(surfaces, dim=1), theta
