"""The coarse fixtures of tests/data belong to the built-in model as it is now: a changed model
file or physics version fails here, fast, with the command that rebuilds them, instead of
making the tests they feed skip or compare against another arm."""

from __future__ import annotations

from pathlib import Path

from conftest import REBUILD_TABLES

from persival.model.arm.model_file import load_model_file
from persival.tables.moment_table import MomentTable
from persival.tables.response_table import ResponseTable

DATA = Path(__file__).parents[1] / "data"


def test_the_coarse_tables_are_of_the_built_in_model():
    model_hash = load_model_file(None)[1]
    moments = MomentTable.load(DATA / "moments_coarse.npz")
    response = ResponseTable.open(DATA / "response_table_coarse")
    for name, built_for in (("moments_coarse.npz", moments.meta.get("model_hash")),
                            ("response_table_coarse", response.header["model_hash"])):
        assert built_for == model_hash, (f"tests/data/{name} was built for model {str(built_for)[:12]}, the built-in "
                                         f"model is {model_hash[:12]}: rebuild it: {REBUILD_TABLES}")
    assert moments.meta.get("profile") == response.header["profile"] == "coarse"
