"""Recorded elbow movements: read a CSV or an OpenSim motion file, resample and smooth it.

Two formats (docs/viewer.md, "Recorded movements"):

- CSV with a header row: a time column (``time``, ``time_s``, ``t``; seconds), an elbow-angle
  column in degrees (named with ``--column``, else the one column whose name holds ``elbow``,
  else one named ``angle`` / ``angle_deg``) and optionally a load column (``load`` / ``load_kg``).
- OpenSim ``.mot`` / ``.sto``: header lines up to ``endheader`` (``inDegrees=no`` means radians;
  without the line the values are read as degrees), then a row of column labels (``time`` first)
  and the data, whitespace separated. The elbow column is found by name: ``r_elbow_flex``,
  ``elbow_flex_r``, ``elbow_flexion``, ... (a name holding ``elbow`` and ``flex``; the right side
  when both are there), or given with ``--column``.

:func:`prepare` turns a recording into the motion model's rows: a Gaussian-weighted local linear
regression (sigma 25 ms, or the median sample interval where that is longer; window +-4 sigma)
evaluated on a uniform 100 Hz grid resamples and smooths in one step, for any input rate, with
no lag; inside the recording its gain is exp(-(2 pi f sigma)^2 / 2), -3 dB at 5.3 Hz; within
about 2 sigma of either end the fitted line leans on one side, which biases the velocity and
acceleration there (a cosine starting at rest: 2.6 deg/s and half the acceleration at t = 0). Velocity
and acceleration are central differences of the smoothed angle (second-order one-sided ones at
the ends); frames outside the model's reachable range are counted and their angle clamped to it
(their velocity and acceleration stay the recording's: one that enters the range moving keeps
its speed instead of a corner).
The viewer (persival/deploy/web/src/recording.js) does the same in the browser.
"""

from __future__ import annotations

import csv
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["Recording", "PreparedMotion", "read_recording", "prepare", "RATE_HZ", "SIGMA_S"]

RATE_HZ = 100.0
SIGMA_S = 0.025
_TIME_NAMES = ("time", "time_s", "t", "time(s)", "time (s)")
_LOAD_NAMES = ("load", "load_kg", "load (kg)", "load(kg)")
_ANGLE_NAMES = ("angle", "angle_deg", "angle (deg)")


@dataclass
class Recording:
    time_s: np.ndarray
    angle_deg: np.ndarray
    load_kg: np.ndarray | None
    column: str
    source: dict = field(default_factory=dict)  # file, format, units, columns


@dataclass
class PreparedMotion:
    time_s: np.ndarray  # uniform, RATE_HZ
    target_deg: np.ndarray  # smoothed and clamped to the range
    velocity_deg_s: np.ndarray
    acceleration_deg_s2: np.ndarray
    load_kg: np.ndarray
    clamped: np.ndarray  # bool: the smoothed recording left the range here
    sigma_s: float


def _numbers(rows: list[list[str]], names: list[str], path: Path, first_line: int) -> np.ndarray:
    try:
        values = np.array([[float(v) for v in r] for r in rows], dtype=np.float64)
    except ValueError:
        for k, r in enumerate(rows):
            for name, v in zip(names, r):
                try:
                    float(v)
                except ValueError:
                    raise ValueError(f"{path}: line {first_line + k}: {name} = {v!r} is not a number") from None
        raise
    bad = ~np.isfinite(values)
    if bad.any():
        k, j = np.argwhere(bad)[0]
        raise ValueError(f"{path}: line {first_line + k}: {names[j]} is {values[k, j]} (not a finite number)")
    return values


def _pick(names: list[str], wanted: str | None, path: Path) -> int:
    """The elbow-angle column: --column, else by name (see the module docstring)."""
    lower = [n.strip().lower() for n in names]
    if wanted is not None:
        if wanted.strip().lower() not in lower:
            raise ValueError(f"{path}: no column {wanted!r} (columns: {', '.join(names)})")
        return lower.index(wanted.strip().lower())
    elbow = [k for k, n in enumerate(lower) if "elbow" in n and "flex" in n] or [k for k, n in enumerate(lower) if "elbow" in n]
    if len(elbow) > 1:  # both arms: the right one, as OpenSim names it (r_elbow_flex, elbow_flex_r)
        right = [k for k in elbow if re.search(r"(^r_|_r$|right)", lower[k])]
        elbow = right if len(right) == 1 else elbow
    if len(elbow) == 1:
        return elbow[0]
    plain = [k for k, n in enumerate(lower) if n in _ANGLE_NAMES]
    if not elbow and len(plain) == 1:
        return plain[0]
    found = f"several ({', '.join(names[k] for k in elbow)})" if elbow else "none"
    raise ValueError(f"{path}: which column is the elbow angle? by name: {found} (columns: {', '.join(names)}); "
                     "name it with --column")


def _split(line: str, delimiter: str | None) -> list[str]:
    return next(csv.reader([line], delimiter=delimiter)) if delimiter else line.split()


def read_recording(path: str | Path, column: str | None = None) -> Recording:
    """A recording from a CSV, .mot or .sto file; ValueError saying what is wrong with it."""
    path = Path(path)
    text = path.read_text(encoding="utf-8", errors="replace")
    lines = text.splitlines()
    in_degrees, fmt, start = True, "csv", 0
    if path.suffix.lower() in (".mot", ".sto") or any(ln.strip().lower() == "endheader" for ln in lines[:200]):
        fmt = "opensim"
        ends = [k for k, ln in enumerate(lines) if ln.strip().lower() == "endheader"]
        if not ends:
            raise ValueError(f"{path}: an OpenSim motion file needs a header ending in a line 'endheader'")
        header = {k.strip().lower(): v.strip().lower() for k, _, v in (ln.partition("=") for ln in lines[:ends[0]]) if _}
        in_degrees = header.get("indegrees", "yes") != "no"
        start = ends[0] + 1
    body = [(k, ln) for k, ln in enumerate(lines[start:], start + 1) if ln.strip() and not ln.lstrip().startswith("#")]
    if not body:
        raise ValueError(f"{path}: no column labels and no data")
    delimiter = None if fmt == "opensim" else next((d for d in ",;\t" if d in body[0][1]), ",")
    names = [n.strip() for n in _split(body[0][1], delimiter)]
    lower = [n.lower() for n in names]
    time_col = next((k for k, n in enumerate(lower) if n in _TIME_NAMES), None)
    if time_col is None:
        raise ValueError(f"{path}: no time column (a column named time or time_s; columns: {', '.join(names)})")
    angle_col = _pick(names, column, path)
    load_col = next((k for k, n in enumerate(lower) if n in _LOAD_NAMES), None)
    rows = [_split(ln, delimiter) for _, ln in body[1:]]
    short = next((body[1 + k][0] for k, r in enumerate(rows) if len(r) < len(names)), None)
    if short is not None:
        raise ValueError(f"{path}: line {short} has fewer values than the {len(names)} column labels")
    used = [time_col, angle_col] + ([load_col] if load_col is not None else [])
    values = _numbers([[r[j] for j in used] for r in rows], [names[j] for j in used], path, body[1][0] if rows else 0)
    if len(values) < 2:
        raise ValueError(f"{path}: {len(values)} frame(s); a movement needs at least 2")
    time, angle = values[:, 0], values[:, 1] if in_degrees else np.degrees(values[:, 1])
    step = np.diff(time)
    if (step <= 0).any():
        k = int(np.argmax(step <= 0))
        raise ValueError(f"{path}: time does not increase at frame {k + 2} ({time[k]:g} s, then {time[k + 1]:g} s)")
    load = values[:, 2] if load_col is not None else None
    if load is not None and (load < 0).any():
        raise ValueError(f"{path}: load {load[load < 0][0]:g} kg is negative")
    units = "deg" if in_degrees else "rad (converted to deg)"
    return Recording(time, angle, load, names[angle_col], {"file": str(path), "format": fmt, "angle_units": units,
                                                            "columns": names, "load_column": names[load_col]
                                                            if load_col is not None else None})


def _local_linear(t: np.ndarray, y: np.ndarray, grid: np.ndarray, sigma: float) -> np.ndarray:
    """Gaussian-weighted local linear regression of y(t) at the grid times (window +-4 sigma)."""
    out = np.empty(len(grid))
    lo, hi = np.searchsorted(t, grid - 4 * sigma), np.searchsorted(t, grid + 4 * sigma, side="right")
    for k, (g, a, b) in enumerate(zip(grid, lo, hi)):
        a, b = max(0, min(a, len(t) - 2)), max(b, a + 2)  # at least the two nearest samples
        dt, w = t[a:b] - g, np.exp(-0.5 * ((t[a:b] - g) / sigma) ** 2)
        s0, s1, s2 = w.sum(), (w * dt).sum(), (w * dt * dt).sum()
        r0, r1 = (w * y[a:b]).sum(), (w * dt * y[a:b]).sum()
        det = s0 * s2 - s1 * s1
        out[k] = (s2 * r0 - s1 * r1) / det if det > 1e-12 * s0 * s2 else r0 / s0
    return out


def prepare(recording: Recording, range_deg: tuple[float, float], load_kg: float | None = None,
            rate_hz: float = RATE_HZ, sigma_s: float = SIGMA_S) -> PreparedMotion:
    """Uniform, smoothed frames inside the range; ValueError if no frame is inside it."""
    t, angle = recording.time_s, recording.angle_deg
    lo, hi = range_deg
    sigma = max(sigma_s, float(np.median(np.diff(t))))
    grid = t[0] + np.arange(int(np.floor((t[-1] - t[0]) * rate_hz + 1e-9)) + 1) / rate_hz
    smooth = _local_linear(t, angle, grid, sigma)
    clamped = (smooth < lo) | (smooth > hi)
    if clamped.all():
        raise ValueError(f"{recording.source.get('file')}: no frame lies inside the model's reachable range "
                         f"{lo:.1f} to {hi:.1f} deg (the recording's {recording.column} spans {angle.min():.1f} "
                         f"to {angle.max():.1f} deg)")
    # velocity and acceleration from the recording itself, not from the clamped angle: a
    # recording that enters the range moving must not show a corner (a spike of acceleration)
    dt, order = 1.0 / rate_hz, 2 if len(grid) >= 3 else 1  # second order at the ends too
    velocity = np.gradient(smooth, dt, edge_order=order) if len(grid) > 1 else np.zeros(1)
    acceleration = np.gradient(velocity, dt, edge_order=order) if len(grid) > 1 else np.zeros(1)
    target = np.clip(smooth, lo, hi)
    if load_kg is not None:
        load = np.full(len(grid), float(load_kg))
    elif recording.load_kg is not None:
        load = np.interp(grid, t, recording.load_kg)
    else:
        load = np.zeros(len(grid))
    return PreparedMotion(grid, target, velocity, acceleration, load, clamped, sigma)

