"""Opening any saved surrogate folder: its manifest names the kind, and the kind's class loads it.

Kept apart from persival.surrogate.base so that the base class does not import its own subclasses."""

from __future__ import annotations

from pathlib import Path

from persival.surrogate.base import Surrogate, manifest_of

__all__ = ["KINDS", "load_surrogate"]


def _kinds() -> dict:
    from persival.surrogate.network_surrogate import NetworkSurrogate
    from persival.surrogate.sparse_grid_surrogate import SparseGridSurrogate
    from persival.surrogate.structured.surrogate import StructuredSurrogate
    from persival.surrogate.table_surrogate import ResponseTableSurrogate

    return {cls.kind: cls for cls in (SparseGridSurrogate, NetworkSurrogate, ResponseTableSurrogate, StructuredSurrogate)}


KINDS = ("sparse-grid", "network", "response-table", "structured")


def load_surrogate(path: str | Path) -> Surrogate:
    """Open any saved surrogate folder (its ``surrogate.json`` names the kind)."""
    path = Path(path)
    kind = manifest_of(path).get("kind", "sparse-grid")
    kinds = _kinds()
    if kind not in kinds:
        raise ValueError(f"{path}: unknown surrogate kind {kind!r} (known: {', '.join(kinds)})")
    return kinds[kind].load(path)
