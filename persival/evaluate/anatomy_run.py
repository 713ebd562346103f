"""The anatomy of a run: bodies inside each other and muscles off their beds in the FE stage's
states and the held-out campaign states (docs/design/arm_model_record.md, "Overlap between bodies"): every
state in ``OUT/anatomy/states.json``, and a table of the report (``anatomy.json``, ``anatomy.md``).

One row per pair of bodies that overlap anywhere: its limits (1 mm muscle-bone, 2 mm muscle-muscle
in the functional arc, 2 and 5 mm beyond 130 deg, none bone-bone), the deepest penetration among
the FE states and among the held-out states, and how many states exceed the limit at their angle;
then one row per muscle: the largest gap between its belly and its bed (the triceps' limited to 10 mm).
"""

from __future__ import annotations

import json
from pathlib import Path

from persival.evaluate.anatomy import (
    TRICEPS_BED_LIMIT_MM,
    check_state_dirs,
    check_store,
    limit_text,
    over_limit,
    worst_cases,
    write_json,
)
from persival.evaluate.run_layout import RunLayout
from persival.evaluate.tables import make_table, save_table

__all__ = ["measure_run", "anatomy_table"]

ATTACHMENT_MM = 10.0  # nodes this close to a muscle's ends are its attachments (docs/design/arm_model_record.md)


def _fe_state_dirs(out: Path) -> list[Path]:
    folder = out / "fe"
    return sorted(d for d in folder.iterdir() if (d / "state.json").is_file()) if folder.is_dir() else []


def _deepest(worst: dict, pair: tuple[str, str]) -> dict | None:
    return next((e for e in worst["overlaps"] if (e["body"], e["inside"]) == pair), None)


def _where(entry: dict | None) -> str | None:
    return None if entry is None else f"{entry['deepest_state']} ({entry['deepest_angle_deg']:.0f} deg)"


TRICEPS_OFF_BED = ("triceps", "off its bed")


def _over_limit(state: dict) -> set[tuple[str, str]]:
    """The pairs of one state that reach into each other deeper than their limit at its angle, and
    the triceps if its belly lies further than its limit off the humerus."""
    over = {(r["body"], r["inside"]) for r in state["overlaps"]
            if over_limit(r["body"], r["inside"], state["elbow_angle_deg"], r["deepest_mm"])}
    if any(g["muscle"] == "triceps" and g["largest_gap_mm"] > TRICEPS_BED_LIMIT_MM for g in state["bed_gaps"]):
        over.add(TRICEPS_OFF_BED)
    return over


def _largest_gap(worst: dict, muscle: str) -> float | None:
    return next((g["largest_gap_mm"] for g in worst["bed_gaps"] if g["muscle"] == muscle), None)


def anatomy_table(fe: list[dict], held_out: list[dict], model: str) -> dict:
    """The report's table of a run's anatomy (module docstring) from the two sets of measured states."""
    every = fe + held_out
    worst_fe, worst_held, worst_all = worst_cases(fe), worst_cases(held_out), worst_cases(every)
    over = [_over_limit(state) for state in every]
    rows = []
    for entry in worst_all["overlaps"]:
        pair, limit = (entry["body"], entry["inside"]), entry["limit_mm"]
        in_fe, in_held = _deepest(worst_fe, pair), _deepest(worst_held, pair)
        rows.append({"pair": f"{pair[0]} in {pair[1]}", "limit_mm": limit, "limits": limit_text(*pair),
                     "fe_mm": None if in_fe is None else in_fe["deepest_mm"], "fe_state": _where(in_fe),
                     "held_mm": None if in_held is None else in_held["deepest_mm"], "held_state": _where(in_held),
                     "over": "-" if limit is None else f"{sum(pair in o for o in over)}/{len(every)}"})
    for entry in worst_all["bed_gaps"]:
        limited = entry["muscle"] == "triceps"
        rows.append({"pair": f"{entry['muscle']} off its bed ({', '.join(entry['bed'])})",
                     "limit_mm": TRICEPS_BED_LIMIT_MM if limited else None,
                     "limits": f"{TRICEPS_BED_LIMIT_MM:g}" if limited else "-",
                     "fe_mm": _largest_gap(worst_fe, entry["muscle"]), "held_mm": _largest_gap(worst_held, entry["muscle"]),
                     "over": f"{sum(TRICEPS_OFF_BED in o for o in over)}/{len(every)}" if limited else "-"})
    total = sum(len({tuple(sorted(pair)) for pair in o}) for o in over)  # a pair once, either body in the other
    clean = sum(not o for o in over)
    return make_table(
        "anatomy", f"Bodies inside each other and muscles off their beds ({model})",
        f"{len(fe)} FE states and {len(held_out)} held-out states of this run; surface nodes within "
        f"{ATTACHMENT_MM:g} mm of a muscle's ends (its attachments) left out. Deepest penetration of the "
        "first body into the second (mm), and a muscle's largest gap to its bed along the middle of its belly (mm).",
        [("pair", "pair", "{}"), ("limits", "limit mm", "{}"), ("fe_mm", "FE states mm", "{:.1f}"),
         ("fe_state", "deepest FE state", "{}"), ("held_mm", "held-out mm", "{:.1f}"),
         ("held_state", "deepest held-out state", "{}"), ("over", "states over the limit", "{}")],
        rows, notes=[f"{total} pair-states over their limits (a pair counted once per state); {clean} of "
                     f"{len(every)} states within every limit"],
        pair_states_over_limit=total, states_within_limits=clean, states=len(every))


def _model_name(out: Path) -> str:
    geometry = out / "model" / "geometry.json"
    return json.loads(geometry.read_text())["model"] if geometry.is_file() else "the run's arm"


def measure_run(out: str | Path, model_file=None, progress=None) -> dict:
    """Measure the run folder's FE states and held-out states: ``OUT/anatomy/states.json`` (every
    state) and the table (``anatomy.json``, ``anatomy.md``). Returns the table."""
    out = Path(out)
    fe = check_state_dirs(_fe_state_dirs(out), model_file, ATTACHMENT_MM)
    held_path = RunLayout(out).held_out
    held_out = check_store(held_path, model_file, ATTACHMENT_MM, progress=progress) if held_path.exists() else []
    if not fe + held_out:
        raise FileNotFoundError(f"{out}: no FE states (fe/) and no held-out store (campaign/held_out.zarr) to measure")
    folder = out / "anatomy"
    write_json(fe + held_out, folder / "states.json", f"{out / 'fe'}, {held_path}", ATTACHMENT_MM)
    table = anatomy_table(fe, held_out, _model_name(out))
    save_table(table, folder)
    return table
