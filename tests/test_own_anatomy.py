"""Bring your own anatomy (docs/own_anatomy.md): the model file for editing, muscles from surfaces."""

from __future__ import annotations

from typer.testing import CliRunner

from persival.cli import app
from persival.model.arm_file import load_model_file
from persival.model.defaults import default_model_path


def test_model_init_writes_the_built_in_model(tmp_path):
    out = tmp_path / "sub" / "my_arm.toml"
    result = CliRunner().invoke(app, ["model", "init", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert out.read_text() == default_model_path().read_text()
    assert load_model_file(out)[1] == load_model_file()[1]  # the same model, the same provenance
