"""SPEC 3.3's "no muscle pushes", read off the response tables.

A muscle's insertion transmits a pull: its tension along the line of action is at least
``PUSH_LIMIT_N`` (-2 N) in every table state, and a passive extensor (the triceps and anconeus at
activation 0) never flexes the elbow, its moment at most 0 at every angle. The tables hold both
(tension and moment per angle and level, docs/theory.md 4.1), so the check costs nothing after
the build; the tables stage reports it with every run.
"""

from __future__ import annotations

import numpy as np

from persival.tables.moment_table import MomentTable
from persival.vocabulary import MUSCLES

__all__ = ["PUSH_LIMIT_N", "push_check"]

PUSH_LIMIT_N = -2.0


def push_check(table: MomentTable, extensors: tuple[str, ...], joint_limits_deg: tuple[float, float] | None = None) -> dict:
    """Per muscle the least tension in the table (N, with its angle and level), for the
    ``extensors`` the largest passive moment (N mm, flexion positive, with its angle); and the
    muscles that push (least tension below -2 N) or, passive, flex the elbow (moment above 0).

    With ``joint_limits_deg`` the same again over the angles within the joint's limits
    (``in_joint_range`` per muscle, ``pushing_in_joint_range``, ...): the tables run past the
    limits for the joint balance's brackets, where the arm goes only when driven against them."""
    report = {"limit_N": PUSH_LIMIT_N, "muscles": {}}
    ranges = {"": np.ones(len(table.angles_deg), dtype=bool)}
    if joint_limits_deg is not None:
        low, high = joint_limits_deg
        ranges["_in_joint_range"] = (table.angles_deg >= low) & (table.angles_deg <= high)
        report["joint_limits_deg"] = [float(low), float(high)]
    for suffix in ranges:
        report["pushing" + suffix], report["passive_extensors_flexing" + suffix] = [], []
    for m, name in enumerate(MUSCLES):
        if not np.isfinite(table.tension[m]).any():
            continue
        for suffix, rows in ranges.items():
            entry = _extremes(table, m, rows, name in extensors)
            if entry.get("least_tension_N", 0.0) < PUSH_LIMIT_N:
                report["pushing" + suffix].append(name)
            if entry.get("passive_moment_max_Nmm", -1.0) > 0.0:
                report["passive_extensors_flexing" + suffix].append(name)
            if suffix:
                report["muscles"][name]["in_joint_range"] = entry
            else:
                report["muscles"][name] = entry
    return report


def _extremes(table: MomentTable, m: int, rows: np.ndarray, extensor: bool) -> dict:
    """Muscle m's least tension over the table's ``rows`` (angles), and an extensor's largest passive moment."""
    angles, tension = table.angles_deg[rows], table.tension[m][rows]
    entry = {}
    if np.isfinite(tension).any():
        i, j = np.unravel_index(np.nanargmin(tension), tension.shape)
        entry.update(least_tension_N=float(tension[i, j]), at_deg=float(angles[i]), at_level=float(table.levels[j]))
    passive = table.moments[m, rows, 0]
    if extensor and np.isfinite(passive).any():
        k = int(np.nanargmax(passive))
        entry.update(passive_moment_max_Nmm=float(passive[k]), passive_moment_at_deg=float(angles[k]))
    return entry
