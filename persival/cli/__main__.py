"""`python -m persival.cli`: the same as the `persival` command."""

from persival.cli.app import app

app()
