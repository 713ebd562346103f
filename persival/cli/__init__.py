"""The `persival` command line (typer): one module of commands per pipeline stage, and `run`."""

from persival.cli.app import app

__all__ = ["app"]
