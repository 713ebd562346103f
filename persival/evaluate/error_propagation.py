"""Error propagation (docs/theory.md, 8.3): the SG and the networks against states of the campaign's simulator.

The held-out states (``OUT/campaign/held_out.zarr``, random activations the SG never saw) are
solved by the same simulator as the SG's campaign; the table compares the SG with them, each
network with them, and each network with the campaign's own states (the SG's support points,
where the SG itself is exact). The source label says which simulator that is: the analytic
stand-in is never called FE.
"""

from __future__ import annotations

import numpy as np

from persival.evaluate import paper_values
from persival.evaluate.metrics import state_errors, summarize
from persival.evaluate.run_layout import LoadedRun, network_scopes, scope_slice
from persival.evaluate.tables import make_table

__all__ = ["error_propagation_table"]

COLUMNS = [
    ("surrogate", "surrogate", "{}"), ("scope", "muscles", "{}"), ("tested_on", "tested on", "{}"),
    ("states", "states", "{:d}"), ("max MaxAE_mm", "MaxAE mm (worst state)", "{:.3f}"),
    ("max MaxRE_pct", "MaxRE % (worst state)", "{:.2f}"), ("mean MAE_mm", "MAE mm (mean)", "{:.3f}"),
    ("mean MRE_pct", "MRE % (mean)", "{:.3f}"), ("max angle_error_deg", "angle err deg (worst)", "{:.3f}"),
    ("added_pct", "MAE vs SG's %", "{:+.1f}"),
]


def _truth(path, sg, n_states: int | None):
    from persival.surrogate.dataset import Dataset

    data = Dataset.from_store(path)
    if data.model_hash != sg.metadata.get("model_hash"):
        raise ValueError(f"{path} holds states of model {str(data.model_hash)[:12]}, the SG was fitted to "
                         f"{str(sg.metadata.get('model_hash'))[:12]}: they are not comparable")
    data = data.select(list(sg.surfaces.names))
    return data.subset(np.arange(min(n_states, len(data)))) if n_states else data


def _row(name, scope, tested_on, predicted, truth, surfaces, angle=None) -> dict:
    sl = scope_slice(surfaces, scope)
    ref = truth.positions[:, sl]
    errors = state_errors(predicted, ref, ref - truth.surfaces.reference_points[sl])
    if angle is not None:
        errors["angle_error_deg"] = np.abs(angle - truth.elbow_angles)
    return {"surrogate": name, "scope": scope, "tested_on": tested_on, "states": len(truth), **summarize(errors)}


def _sg_rows(run, truth, scopes, tested_on) -> list[dict]:
    pos, angle = run.sg.predict_with_angle(truth.activations)
    return [_row("SG", scope, tested_on, pos[:, scope_slice(run.sg.surfaces, scope)], truth, run.sg.surfaces,
                 angle if scope == "all" else None) for scope in scopes]


def _net_rows(run, truth, tested_on) -> list[dict]:
    rows = []
    for label, net in run.networks.items():
        pos = net.predict(truth.activations)
        angle = net.predict_angle(truth.activations) if getattr(net, "has_angle", False) else None
        for scope in network_scopes(net):
            predicted = pos[:, scope_slice(net.surfaces, scope)]
            rows.append(_row(f"{label} NN", scope, tested_on, predicted, truth, run.sg.surfaces,
                             angle if scope == "all" else None))
    return rows


def _structured_rows(run, truth, tested_on) -> list[dict]:
    """The structured surrogate (per-muscle models from the response tables), when the run has one."""
    if run.structured is None:
        return []
    positions, angle = run.structured.predict_with_angle(truth.activations)
    return [_row("structured (tables)", "all", tested_on, positions, truth, run.sg.surfaces, angle)]


def _table_rows(layout, run, truth, tested_on) -> list[dict]:
    """The FE arm's table-only path (docs/theory.md, 4.4: five 2-D interpolations and a scalar root)
    on the same held-out activations, when the run solved them that way too."""
    if not layout.held_out_table_only.exists():
        return []
    table_only = _truth(layout.held_out_table_only, run.sg, len(truth))
    if not np.allclose(table_only.activations, truth.activations):
        raise ValueError(f"{layout.held_out_table_only} holds other activations than {layout.held_out}")
    return [_row("FE response tables (table-only)", "all", tested_on, table_only.positions, truth, run.sg.surfaces,
                 table_only.elbow_angles)]


def error_propagation_table(run: LoadedRun, n_states: int = 25) -> dict:
    layout = run.layout
    if not layout.held_out.exists():
        raise FileNotFoundError(f"{layout.held_out}: no held-out campaign (persival campaign run --design random)")
    held = _truth(layout.held_out, run.sg, n_states)
    label = held.source.get("label", "held-out states")
    scopes = sorted({s for net in run.networks.values() for s in network_scopes(net)}, key=lambda s: s != "all")
    held_on = f"{len(held)} held-out states"
    rows = (_sg_rows(run, held, scopes, held_on) + _net_rows(run, held, held_on) + _structured_rows(run, held, held_on)
            + _table_rows(layout, run, held, held_on))
    sg_mae = {r["scope"]: r["mean MAE_mm"] for r in rows if r["surrogate"] == "SG"}
    for r in rows[len(scopes):]:
        r["added_pct"] = 100.0 * (r["mean MAE_mm"] / sg_mae[r["scope"]] - 1.0) if sg_mae[r["scope"]] > 0 else None
    notes = [f"Truth: {label} ({layout.held_out}); the SG's support points: the campaign's own states "
             f"({layout.campaign}).",
             "'MAE vs SG's %': how much the network's mean MAE against the truth exceeds the SG's own on the "
             "same states (the target: at most +10 %)."]
    if layout.campaign.exists():
        support = _truth(layout.campaign, run.sg, None)
        on = f"{len(support)} SG support points"
        rows += _sg_rows(run, support, scopes, on) + _net_rows(run, support, on)
        notes.append("At its support points the SG interpolates the campaign: its row there is the check that "
                     "the comparison is wired right (about zero).")
    simulator = held.source.get("simulator", "unknown")
    return make_table("error_propagation", "Error propagation (SG and networks vs the simulator's own states)",
                      f"Truth: {label} (simulator {simulator!r}); SG of {run.source_label}.",
                      COLUMNS, rows, paper_values.ERROR_PROPAGATION, notes, truth_source=held.source)
