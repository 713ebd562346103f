"""The structured surrogate as one PyTorch graph, exportable to ONNX with its root search inside.

``activations`` (b, 5) and ``load_kg`` (b, 1) -> ``positions`` (b, N, 3) mm and
``elbow_angle_deg`` (b, 1). The same arithmetic as the numpy reference
(:class:`~persival.surrogate.structured.moment_model.MomentModel`, :class:`MuscleShape`), written
with dense products, comparisons and gathers (no loops that depend on the data), and with few
operators and little memory traffic, since at batch 1 each operator costs a fraction of a
microsecond and every byte of a product's matrix is read once per state: a sign scan brackets the
stable root nearest the hanging arm, the bracket's table interval gives the balance as one cubic,
and regula falsi plus a fixed number of Newton steps on that cubic converge it; then only the four
Hermite data of that interval (values and slopes at its two angles) are gathered to read every
muscle's surface at that angle (docs/theory.md 7.7).
"""

from __future__ import annotations

import numpy as np
import torch

from persival.surrogate.structured.cardinal import torch_weights
from persival.surrogate.structured.moment_model import NEWTON_SLOPE_CAP, NEWTON_STEPS

__all__ = ["StructuredGraph"]

# Rank of a scan interval without a stable root: behind every real distance (at most 360 deg), and
# among themselves by index, first or last. 1e4 +- index is exact in float32 (integers below 2^24
# are, and 1e4 + 1e4 is far below); at 1e9 float32 numbers are 64 apart and the index was lost.
_FAR = 1e4


class StructuredGraph(torch.nn.Module):
    def __init__(self, moments, shapes, dtype=torch.float32, mode_dtype=None):
        """``mode_dtype``: storage of the POD modes (default: float16 beside float32 arithmetic,
        which halves the file and moves a surface by at most about 0.02 mm; the mean surfaces stay
        in ``dtype``: in float16 they would move by 0.1 mm). The runtime casts them back once,
        when it loads the graph (constant folding)."""
        super().__init__()
        self.n_levels, self.n_t2 = len(moments.levels), moments.data.shape[1]
        self._root_tables(moments, dtype)
        self._shape_tables(shapes, dtype)
        if mode_dtype is None:
            mode_dtype = torch.float16 if dtype == torch.float32 else dtype
        # buffers, not constants: the tracer then keeps the float16 storage and the cast in the graph
        for i, s in enumerate(shapes):
            self.register_buffer(f"modes_{i}", torch.as_tensor(s.modes, dtype=mode_dtype))
        for i, s in enumerate(shapes):  # float32 storage: the mean surfaces are hundreds of mm
            self.register_buffer(f"means_{i}", torch.as_tensor(s.mean.reshape(1, -1), dtype=dtype))

    def _root_tables(self, moments, dtype) -> None:
        """The balance's data: activation weights, moment rows, the scan and the intervals' cubics."""
        as_t = lambda a: torch.as_tensor(np.asarray(a), dtype=dtype)  # noqa: E731
        basis = moments.theta_basis
        n_t2, n_a = self.n_t2, self.n_levels
        n_t, n_int = n_t2 // 2, len(basis.breaks) - 1
        self.activation_tables = moments.activation_basis.torch_tables(dtype)
        self.moment_rows = as_t(np.transpose(moments.data, (0, 2, 1)).reshape(5 * n_a, n_t2))
        self.external_row, self.load_row = as_t(moments.external_data[None]), as_t(moments.load_data[None])
        # the sign scan, and per scan interval: its two ends and the start of its table interval
        grid, interval = moments.scan_deg, moments.scan_interval
        self.scan_weights = as_t(moments.scan_weights.T)  # (2 n_t, n_g)
        self.scan_distance = as_t(np.abs(grid[:-1] - moments.near_deg))
        if len(grid) >= _FAR - 360.0:
            raise ValueError(f"a sign scan of {len(grid)} angles does not fit the fallback's rank {_FAR:g} (float32)")
        self.scan_index = torch.as_tensor(np.arange(len(grid) - 1), dtype=dtype)
        start = basis.breaks[interval]
        self.scan_ends = as_t(np.stack([grid[:-1] - start, grid[1:] - start, start], axis=1))  # (n_g - 1, 3)
        self.scan_interval = torch.as_tensor(interval, dtype=torch.int64)
        # per table interval: the power-form rows (t^3, t^2, t, 1) of the whole balance's weights and
        # of their t-derivative, side by side (the balance's cubic and its slope as one (4, 2) matrix),
        # and of the weights of its four Hermite data (values and slopes at its two angles)
        c = basis.coefficients
        slope = np.stack([np.zeros_like(c[0]), 3 * c[0], 2 * c[1], c[2]])
        self.interval_rows = as_t(np.transpose(np.stack([c, slope], axis=1), (2, 0, 1, 3)).reshape(n_int, 8 * n_t2))
        i = np.arange(n_int)
        self.local_data = torch.as_tensor(np.stack([i, i + 1, n_t + i, n_t + i + 1], axis=1), dtype=torch.int64)
        local = basis.coefficients[:, i[:, None], self.local_data.numpy()]  # (4 powers, n_int, 4 data)
        self.local_rows = as_t(np.transpose(local, (1, 0, 2)))  # (n_int, 4, 4)

    def _shape_tables(self, shapes, dtype) -> None:
        """Every muscle's Hermite data in theta, per level, side by side, and its turn if it has one."""
        as_t = lambda a: torch.as_tensor(np.asarray(a), dtype=dtype)  # noqa: E731
        n_t2, n_a = self.n_t2, self.n_levels
        n_t = n_t2 // 2
        # every muscle's coefficients side by side, per level: its POD coefficients, then 1 (value 1,
        # slope 0: the weights reproduce constants) for its mean surface; a muscle reduced in its own
        # frame (Q not I) then has the shift O (Q - I) of its turn x = (y + O (Q - I)) Q^T, which
        # carries it on three unit rows (below)
        identity = np.concatenate([np.tile(np.eye(3).ravel(), (n_t, 1)), np.zeros((n_t, 9))])
        self.turned = [not np.array_equal(s.rotation_data, identity) for s in shapes]
        parts, turns = [], []
        for s, turned in zip(shapes, self.turned):
            fixed = np.r_[np.ones(n_t), np.zeros(n_t)][:, None]
            q = s.rotation_data.reshape(-1, 3, 3)
            if turned:
                shift = np.einsum("i,kij->kj", s.origin, q)
                shift[: n_t] -= s.origin
                fixed = np.concatenate([fixed, shift], axis=1)
                turns.append(np.transpose(q, (0, 2, 1)).reshape(len(q), 9))  # Q^T
            parts.append(np.concatenate([s.coefficient_data, np.repeat(fixed[:, None], n_a, axis=1)], axis=2))
        counts = [s.modes.shape[0] + (4 if turned else 1) for s, turned in zip(shapes, self.turned)]
        self.counts = counts
        data = np.concatenate(parts, axis=2)  # (2 n_t, n_a, R)
        self.n_coefficients = int(sum(counts))
        self.n_muscles = len(shapes)
        self.n_turned = len(turns)
        self.theta_data = as_t(np.concatenate([data.reshape(n_t2, -1)] + turns, axis=1))
        expand = np.zeros((5, sum(counts)))
        ends = np.cumsum(counts)
        for s, end, r in zip(shapes, ends, counts):
            expand[s.muscle_index, end - r:end] = 1.0
        self.expand = as_t(expand)  # (5, R): which muscle's activation weighs each coefficient
        self.node_counts = [s.n_nodes for s in shapes]

    def _surface_rows(self, i: int, dtype) -> torch.Tensor:
        """Muscle i's rows: its modes and its mean surface, (r + 1, 3 n), and for a muscle turned
        from its own frame the unit rows of x, y and z too. Built from the stored tensors by
        operators on constants only, which the runtime folds once when it loads the graph."""
        rows = [getattr(self, f"modes_{i}").to(dtype), getattr(self, f"means_{i}")]
        if self.turned[i]:
            rows.append(torch.eye(3, dtype=dtype).repeat(1, rows[1].shape[1] // 3))
        return torch.cat(rows, dim=0)

    def _bracket(self, g):
        """Index (b, 1) of the scan interval holding the stable root nearest the hanging arm;
        without one, the first interval (extends everywhere) or the last (flexes everywhere)."""
        down = (g[:, :-1] > 0) & (g[:, 1:] <= 0)
        fallback = _FAR + torch.where(g[:, :1] > 0, -self.scan_index, self.scan_index)
        return torch.argmin(torch.where(down, self.scan_distance, fallback), dim=1, keepdim=True)

    def _angle(self, profile):
        """Elbow angle (b, 1), its table interval (b,), its offset t in it and 1 (each (b, 1, 1))."""
        g = profile @ self.scan_weights
        k = self._bracket(g)
        lo, hi, start = self.scan_ends[k[:, 0]].reshape(-1, 1, 3).split(1, 2)  # lo, hi: offsets in the interval
        g_lo, g_hi = torch.gather(g, 1, torch.cat([k, k + 1], dim=1)).reshape(-1, 1, 2).split(1, 2)
        interval = self.scan_interval[k[:, 0]]
        # [[a3, 0], [a2, 3 a3], [a1, 2 a2], [a0, a1]]: (t^3, t^2, t, 1) @ it = (g, dg/dt)
        cubic = (self.interval_rows[interval].reshape(-1, 8, self.n_t2) * profile[:, None, :]).sum(2).reshape(-1, 4, 2)
        falls = g_lo > g_hi
        t = torch.where(falls, lo + (hi - lo) * g_lo / torch.where(falls, g_lo - g_hi, 1.0), torch.where(g_lo > 0, hi, lo))
        one = torch.ones_like(t)
        for _ in range(NEWTON_STEPS):
            t2 = t * t
            value, slope = (torch.cat([t2 * t, t2, t, one], dim=2) @ cubic).split(1, 2)
            t = torch.minimum(torch.maximum(t - value / slope.clamp(max=NEWTON_SLOPE_CAP), lo), hi)
        return (start + t).reshape(-1, 1), interval, t, one

    def forward(self, activations, load_kg):
        # every reshape keeps the batch as -1 and names the other sizes: no Shape operators in the graph
        act_w = torch_weights(self.activation_tables, activations.reshape(-1, 1))  # (5 b, n_a)
        profile = act_w.reshape(-1, 5 * self.n_levels) @ self.moment_rows + self.external_row + load_kg * self.load_row
        theta, interval, t, one = self._angle(profile)
        t2 = t * t
        powers = torch.cat([t2 * t, t2, t, one], dim=2)  # (b, 1, 4)
        weights = powers @ self.local_rows[interval]  # (b, 1, 4): the interval's four Hermite data
        local = self.theta_data[self.local_data[interval]]  # (b, 4, n_a R + 9 n_m)
        at_theta = (weights @ local).reshape(-1, self.theta_data.shape[1])
        by_coefficient, turns = at_theta.split([self.n_levels * self.n_coefficients, 9 * self.n_turned], dim=1)
        by_level = act_w.reshape(-1, 5, self.n_levels).transpose(1, 2) @ self.expand  # (b, n_a, R)
        coefficients = (by_coefficient.reshape(-1, self.n_levels, self.n_coefficients) * by_level).sum(1)
        turns = iter(turns.reshape(-1, self.n_turned, 3, 3).unbind(1)) if self.n_turned else iter(())
        surfaces = []
        for i, (c, n) in enumerate(zip(coefficients.split(self.counts, dim=1), self.node_counts)):
            surface = (c @ self._surface_rows(i, t.dtype)).reshape(-1, n, 3)
            surfaces.append(surface @ next(turns) if self.turned[i] else surface)
        return torch.cat(surfaces, dim=1), theta
