"""Opening the FE arm's response tables: the complete table of a model (or a clear error), built
or finished when missing, and the hanging arm solved from it by the exact path."""

from __future__ import annotations

import numpy as np

from persival.model.arm.arm_model import ArmModel
from persival.model.fe.solver import ConvergenceError


def open_tables(arm: ArmModel, tables: str | None = None):
    """The complete response table of ``arm`` (default folder: its state cache), or a clear error."""
    from persival.model.arm.state_cache import mesh_fingerprint
    from persival.tables.response_table import ResponseTable, default_table_dir, refuse_touching_muscles

    refuse_touching_muscles(arm)
    root = tables or default_table_dir(arm)
    command = f"persival tables --profile {arm.profile}" + (f" --model {arm.model_file}" if arm.model_file else "")
    try:
        table = ResponseTable.open(root, arm.model_hash, arm.profile, mesh_fingerprint(arm.mesh))
    except FileNotFoundError:
        raise FileNotFoundError(f"no response table of this model at {root}: build it with "
                                f"`{command}` (or use --option method=direct)") from None
    if not table.complete:
        raise ValueError(f"the response table at {root} is unfinished ({int(table.done.sum())} of {table.done.size} "
                         f"columns): finish it with `{command}`")
    return table


def ensure_tables(model_file=None, profile: str = "quick", tables: str | None = None, progress=None,
                  scheduler: str | None = None, n_workers: int | None = None, angles=None, levels=None):
    """Build (or finish) the response tables the ``tables`` method needs; returns the table.
    ``angles``, ``levels``: the grid (default: response_table's DEFAULT_ANGLES, DEFAULT_LEVELS)."""
    from persival.tables.response_table import DEFAULT_ANGLES, DEFAULT_LEVELS
    from persival.tables.table_build import build_response_table

    arm = ArmModel(model_file, profile)
    arm.rest_states()  # cached: the table workers read each muscle's rest state from it
    table = build_response_table(arm, tables, DEFAULT_ANGLES if angles is None else angles,
                                 DEFAULT_LEVELS if levels is None else levels, model_file=model_file, scheduler=scheduler,
                                 n_workers=n_workers, progress=progress)
    if not arm.has_cached_base():
        hanging_from_tables(arm, table)
    return table


def hanging_from_tables(arm, table):
    """The hanging arm (activations 0) by the tables' exact path, kept in the state cache: a
    converged FE equilibrium in seconds, where the continuation from the mesh poses took 80 s
    (quick mesh; the a = 0 column already holds every muscle near where it hangs)."""
    from persival.tables.table_solve import OutsideTableError, TableSolver

    if not table.complete:
        return None
    try:
        state = TableSolver(arm, table).solve(np.zeros(5), near_deg=arm.start_angle_deg)
    except (ConvergenceError, OutsideTableError):
        return None  # base_state solves it directly when first asked
    arm.adopt_base_state(state)
    return state
