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


def push_check(table: MomentTable, extensors: tuple[str, ...]) -> dict:
    """Per muscle the least tension in the table (N, with its angle and level), for the
    ``extensors`` the largest passive moment (N mm, flexion positive, with its angle); and the
    muscles that push (least tension below -2 N) or, passive, flex the elbow (moment above 0)."""
    report = {"limit_N": PUSH_LIMIT_N, "muscles": {}, "pushing": [], "passive_extensors_flexing": []}
    for m, name in enumerate(MUSCLES):
        tension = table.tension[m]
        if not np.isfinite(tension).any():
            continue
        i, j = np.unravel_index(np.nanargmin(tension), tension.shape)
        entry = {"least_tension_N": float(tension[i, j]), "at_deg": float(table.angles_deg[i]),
                 "at_level": float(table.levels[j])}
        if tension[i, j] < PUSH_LIMIT_N:
            report["pushing"].append(name)
        passive = table.moments[m, :, 0]
        if name in extensors and np.isfinite(passive).any():
            k = int(np.nanargmax(passive))
            entry.update(passive_moment_max_Nmm=float(passive[k]), passive_moment_at_deg=float(table.angles_deg[k]))
            if passive[k] > 0.0:
                report["passive_extensors_flexing"].append(name)
        report["muscles"][name] = entry
    return report
