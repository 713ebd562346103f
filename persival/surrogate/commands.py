"""CLI commands of the surrogate stage."""

from __future__ import annotations

import typer


def register(app: typer.Typer, bench_app: typer.Typer) -> None:
    """Attach this stage's commands to the main app and the benchmark group."""
